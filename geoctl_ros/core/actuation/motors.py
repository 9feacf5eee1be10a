"""The motors: the thrust curve of their ESC commands, and the mixer that turns a moment into
commands (allocation, the lag compensation, the curve).
"""
from dataclasses import dataclass, field
import math
from typing import NamedTuple, Optional, Tuple, Union, cast

import numpy as np

from geoctl_ros.core.actuation.allocation import Allocation, Allocator
from geoctl_ros.core.geometry.flags import Flags
from geoctl_ros.core.geometry.so3 import FloatArray, IntArray, matvec


@dataclass(frozen=True)
class ThrustCurve:
    """Per-motor quadratic thrust curve f = a x^2 + b x + c, x = voltage_scale * command, with an
    integer command in 0..command_max (the lab's BL-Ctrl 2.0 fit by default).
    """

    a: FloatArray
    b: FloatArray
    c: FloatArray
    voltage_scale: float
    command_max: int
    # the command's constants, folded once (__post_init__)
    _disc0: FloatArray = field(init=False, repr=False, compare=False)
    _four_a: FloatArray = field(init=False, repr=False, compare=False)
    _k: FloatArray = field(init=False, repr=False, compare=False)
    _k0: FloatArray = field(init=False, repr=False, compare=False)
    _zero_up_to: FloatArray = field(init=False, repr=False, compare=False)

    def thrust(self, command: IntArray) -> FloatArray:
        """Thrust (N) of integer commands (n,); never negative."""
        x = self.voltage_scale * np.asarray(command, dtype=float)
        return np.maximum(self.a * x * x + self.b * x + self.c, 0.0)

    def __post_init__(self) -> None:
        # command(f) = ceil(x / voltage_scale) with x the root of a x^2 + b x + c = f, i.e.
        # ceil(sqrt(b^2 - 4 a c + 4 a f) / (2 a vs) - b / (2 a vs)), constants folded once
        k = 1.0 / (2.0 * self.a * self.voltage_scale)
        for name, value in (('_disc0', self.b * self.b - 4.0 * self.a * self.c),
                            ('_four_a', 4.0 * self.a), ('_k', k),
                            ('_k0', -self.b * k - 1e-9), ('_zero_up_to', np.maximum(self.c, 0.0))):
            object.__setattr__(self, name, value)

    def command(self, thrust: FloatArray) -> IntArray:
        """Smallest integer command whose thrust is at least the requested one (the lab's ceil),
        clipped to 0..command_max; negative thrust counts as 0, and a request that command 0
        already meets (the curve is clipped at 0 N) gives 0.
        """
        f = np.maximum(np.asarray(thrust, dtype=float), 0.0)
        x = np.sqrt(self._disc0 + self._four_a * f) * self._k + self._k0     # x / vs, less 1e-9
        cmd: IntArray = np.minimum(np.maximum(np.ceil(x), 0.0), self.command_max).astype(int)
        cmd[f <= self._zero_up_to] = 0
        return cmd

    def max_thrust(self) -> FloatArray:
        """Thrust of each motor at command_max."""
        return self.thrust(np.full(len(self.a), self.command_max))

    def normalised(self, command: IntArray) -> FloatArray:
        """Command as a fraction of command_max, in [0, 1]."""
        return np.asarray(command, dtype=float) / self.command_max


@dataclass
class MotorOutput:
    """What the mixer sends to the motors for one control step."""

    commands: IntArray       # integer ESC commands, 0..command_max
    normalised: FloatArray   # commands / command_max, in [0, 1]
    allocation: Allocation
    clipped: Union[bool, Flags] = False   # the lag compensation was cut at a thrust limit (the
                                          # rotors do not reach the allocation by the end of the
                                          # hold: a saturation too)
    rotors: Optional['RotorModel'] = None   # the lag model after this command (the next
                                            # mix's; None: the rotors at rest, or no model)

    @property
    def saturated(self) -> Flags:
        """The rotors do not make the moment asked by the end of the hold: the allocation
        saturated, or the lag compensation was clipped (one flag per run of a batch).
        """
        return self.allocation.saturated | self.clipped


class RotorModel(NamedTuple):
    """The lag compensation's model of the rotors between two commands (one row of thrusts per
    run of a batch; None instead while the rotors are at rest: disarmed, or no compensation).
    The mixer keeps none of it: each mix takes the model the last one returned
    (``MotorOutput.rotors``), and the caller holds it between ticks.
    """

    sent: FloatArray        # N: the thrusts the last command asked for (the curve's, as sent)
    modelled: FloatArray    # N: the thrusts the rotors made, by the model, when it was sent
    design_hold: float      # s: the hold H the last command was designed for
    spool_left: float       # s: of the spool-up left after arming (0 or less: over)

    def after(self, held: float, lag: float) -> FloatArray:
        """The thrusts the rotors make held s after the last command, by their first-order lag
        (time constant lag, s).
        """
        return self.sent + math.exp(-held / lag) * (self.modelled - self.sent)


class Mixer:
    """Moment about the pivot -> six motor commands: allocation, then the thrust curve.

    With ``lag`` (the motors' thrust time constant tau, s; 0 for none) the mixer compensates the
    motors' first-order lag. It keeps a model of the thrust each rotor is producing, advanced
    exactly over the time each command was really held, and commands the thrust that brings the
    model to the allocated thrust at the end of a hold of H:
    f_cmd = (f - a f_model) / (1 - a), a = exp(-H / tau), within the allocator's
    thrust_min..thrust_max (the motors keep spinning, and keep their headroom).

    H is the expected hold (the control period) unless the loop has been late: then it is the
    longest recent hold, returning to the period over about ``HOLD_MEMORY`` seconds. A command
    designed for a 10 ms hold is 4.5 times the thrust change on the testbed; held 50 ms it would
    overshoot 3.3 times, and a loop that stays that late diverges (a live run went 9 deg into a
    cone that way). Designed for the longest hold, every hold up to it only brings the rotors
    part of the way, never past the allocation; one late step after a quiet spell overshoots
    once, and the model, advanced by the real hold, corrects it at the next step.

    Without it, the 40 ms lag of the lab's motors costs the attitude loop about 50 deg of phase
    at the barrier's stiffness near a cone; in the campaign that let a sensor starting in a
    narrow corridor between two cones bounce between them into one (docs/campaigns.md, "Safety
    campaign").
    The mixer holds no state: the lag model (``RotorModel``) comes in with each mix and goes
    out with its output, and the caller (``ControlTick``) keeps it between ticks, as PX4's
    control allocation keeps the actuators' state apart from the allocation.
    A batch of moments keeps one model per run. The model starts at rest at the first armed step
    (the rotors were stopped) and is dropped when disarmed. For ``SPOOL_LAGS`` time constants
    after arming the rotors spool up to the allocation uncompensated: no kick (a motor starting
    from rest need not follow the first-order lag), while the model follows them honestly, so
    the moments it reports (the prediction's history) are those the spooling rotors make. Before,
    the model started at the allocation: the compensation then read a spooling rotor as already
    there, and the next change of moment was asked of the rotors 4.5 times over (a campaign run
    yawed at -2 rad/s into a cone 90 ms after arming, unseen with 70 ms of latency).
    """

    HOLD_MEMORY = 1.0     # s: how long a late step keeps the compensation designed for its hold
    SPOOL_LAGS = 2.0      # time constants after arming without compensation

    def __init__(self, allocator: Allocator, curve: ThrustCurve, collective_thrust: float,
                 lag: float = 0.0) -> None:
        self.allocator = allocator
        self.curve = curve
        self.collective_thrust = float(collective_thrust)
        self.lag = float(lag)
        self._dead = np.array([i for i in range(allocator.count) if i not in allocator.alive],
                              dtype=int)

    def mix(self, moment: FloatArray, rotors: Optional[RotorModel] = None, armed: bool = True,
            dt: Optional[float] = None, held: Optional[float] = None) -> 'MotorOutput':
        """Motor commands for the moment (or a stack of them); all zero when not armed.

        rotors: the lag model the last command left (its ``MotorOutput.rotors``; None: the
        rotors at rest). dt: how long this command is expected to be held (the control period);
        held: how long the previous command really was (the time since the last step; dt when
        not given). The three are needed for the lag compensation only.
        """
        allocation = self.allocator.allocate(moment, self.collective_thrust)
        thrusts = allocation.thrusts
        if not armed:
            zero = np.zeros_like(thrusts, dtype=int)
            return MotorOutput(zero, np.zeros(zero.shape), allocation)
        compensate = self.lag > 0.0 and dt is not None and dt > 0.0
        clipped: Union[bool, Flags] = False
        if compensate:
            if rotors is None or rotors.modelled.shape != thrusts.shape:
                # arming: the rotors are at rest, and spool up to the allocation uncompensated
                model = np.zeros_like(thrusts)
                spool_left = self.SPOOL_LAGS * self.lag
            else:
                held = cast(float, dt) if held is None else max(held, 0.0)
                model = rotors.after(held, self.lag)
                spool_left = rotors.spool_left
                if spool_left > 0.0:
                    spool_left -= held
            hold = self.design_hold_for(rotors, cast(float, dt), held)
            if spool_left <= 0.0:
                a = math.exp(-hold / self.lag)
                wanted = (thrusts - a * model) / (1.0 - a)
                thrusts = np.minimum(np.maximum(wanted, self.allocator.lo), self.allocator.hi)
                clipped = np.any(thrusts != wanted, axis=-1)
        commands = self.curve.command(thrusts)
        if len(self._dead):
            commands[..., self._dead] = 0
        # (compensation turned off: a stale model is not kept)
        after = (RotorModel(self.curve.thrust(commands), model, hold, spool_left) if compensate
                 else None)
        return MotorOutput(commands, self.curve.normalised(commands), allocation, clipped, after)

    def design_hold_for(self, rotors: Optional[RotorModel], dt: float,
                        held: Optional[float]) -> float:
        """The hold H (s) the next command's lag compensation is designed for: the control
        period, or the previous command's real hold when that was longer, and after a late
        step the longest recent hold, back to the period over about HOLD_MEMORY (the approach
        brake takes the same H for the hold its command is reached in).
        """
        if rotors is None:
            return dt                          # arming
        held = dt if held is None else max(held, 0.0)
        hold = max(dt, held)
        last = rotors.design_hold
        if last > hold:                           # a late step not long ago: back to dt slowly
            hold = max(hold, dt + (last - dt) * math.exp(-held / self.HOLD_MEMORY))
        return hold

    def moments(self, rotors: Optional[RotorModel],
                held: float = 0.0) -> Optional[Tuple[FloatArray, FloatArray]]:
        """The moments about the pivot the rotors make by the lag model rotors (None: no model,
        at rest or uncompensated): (the one they settle to under the last command, the one they
        make ``held`` s after it).
        """
        if rotors is None:
            return None
        B = self.allocator.B_full[3:]
        now = rotors.modelled if held <= 0.0 else rotors.after(held, self.lag)
        return matvec(B, rotors.sent), matvec(B, now)

    def thrust_offsets(self, rotors: Optional[RotorModel], held: float) -> Optional[FloatArray]:
        """Each alive rotor's thrust by the lag model, held s after the last command, less its
        share of the collective thrust (N; the allocation's base): where the rotors are now
        within the moment polytope's frame (``Allocator.moment_polytope``); None without a
        lag model.
        """
        if rotors is None:
            return None
        now = rotors.modelled if held <= 0.0 else rotors.after(held, self.lag)
        return now[..., self.allocator.alive] - self.collective_thrust * self.allocator.base_share

    def spool_ticks(self, dt: float) -> int:
        """How many on-time ticks of period dt the spool-up takes (``spools``), the arming's
        included; 0 without a lag model.
        """
        if self.lag <= 0.0 or dt <= 0.0:
            return 0
        ticks, left = 1, self.SPOOL_LAGS * self.lag
        while left - dt > 0.0:
            left -= dt
            ticks += 1
        return ticks

    def spools(self, rotors: Optional[RotorModel], held: Optional[float], dt: float) -> bool:
        """Whether the next armed command is still part of the spool-up (the rotors at rest
        before it, or within SPOOL_LAGS time constants of the arming): sent uncompensated, while
        the vehicle rests on its stops or is held and the controller does not yet fly it.
        """
        if self.lag <= 0.0 or dt <= 0.0:
            return False
        if rotors is None:
            return True
        return rotors.spool_left - (dt if held is None else max(held, 0.0)) > 0.0
