r"""Rotor geometry, effectiveness matrix, allocation with saturation, and the motors' thrust curve.

Frames: ROS body frame (REP-103: x forward, y left, z up), origin at the centre of mass for the
rotor positions; moments are taken about the pivot, which is at -rho from the centre of mass.

Rotor i (1-based) has a position p_i (from the centre of mass), a unit thrust axis n_i, a spin
direction s_i (+1: counter-clockwise about n_i, seen from above) and the airframe's yaw-reaction
coefficient k (moment per newton of thrust). Its thrust f_i >= 0 gives the force f_i n_i and the
moment about the pivot f_i ((rho + p_i) x n_i - s_i k n_i): a rotor spinning counter-clockwise
pushes the body clockwise.

The lab's hexrotor (``tilted_ring`` layout, the defaults), seen from above, nose up the page:

                 x (forward)
                 ^
           6     |     2            rotor i at azimuth -(i - 1) 60 deg, i.e. numbered clockwise
            \    1    /             from the nose, as in the lab's forward-right-down code
             \   |   /              (the lab's rotor i is this rotor i and ESC address 0x28 + i)
     y <------ (pivot)              arm 0.31 m; each thrust axis tilted 15 deg tangentially;
             /       \              odd rotors spin counter-clockwise (s = +1), even clockwise;
            /    4    \             each tilt leans towards the rotor's direction of travel
           5           3            ... (so that tilt and reaction moments add up in yaw)

Allocation (``Allocator``) serves the testbed: the spherical joint carries any net force except
the collective thrust along body z, so it solves for the collective thrust and the three moments
about the pivot (the minimum-norm thrusts when more rotors than that are alive), within
[thrust_min, thrust_max] per rotor. A feasible request is met exactly. An infeasible one is
degraded in strict priority: roll and pitch first, then yaw, then collective thrust, each scaled
down only as far as needed, and the moment not delivered is reported.
"""
from dataclasses import dataclass
import math

import numpy as np

from geoctl_ros.core.flags import all_flag
from geoctl_ros.core.so3 import matvec


class AirframeError(ValueError):
    """A rotor layout that cannot produce every moment (with the reason)."""


@dataclass(frozen=True)
class RotorGeometry:
    """Per-rotor geometry (n rotors): positions (n, 3) from the centre of mass, unit axes (n, 3),
    spins (n,) of +-1, and the yaw-reaction coefficient (m).
    """

    positions: np.ndarray
    axes: np.ndarray
    spins: np.ndarray
    yaw_coefficient: float

    @property
    def count(self):
        return len(self.spins)


def tilted_ring(count=6, arm_length=0.31, tilt_deg=15.0, first_azimuth_deg=0.0, height=0.0,
                yaw_coefficient=0.1):
    """The usual layout: rotors numbered clockwise seen from above, alternating spin and tilt."""
    i = np.arange(count)
    azimuth = np.radians(first_azimuth_deg) - 2.0 * np.pi * i / count     # clockwise from above
    radial = np.column_stack((np.cos(azimuth), np.sin(azimuth), np.zeros(count)))
    tangential = np.column_stack((-np.sin(azimuth), np.cos(azimuth), np.zeros(count)))  # CCW
    spins = np.where(i % 2 == 0, 1.0, -1.0)
    # A CCW rotor's reaction pushes the body clockwise (-z); tilting its thrust towards -tangential
    # (clockwise travel) gives a moment arm x axis with the same sign: the two add in yaw.
    tilt = math.radians(tilt_deg)
    axes = (math.cos(tilt) * np.array([0.0, 0.0, 1.0])[None, :]
            - math.sin(tilt) * spins[:, None] * tangential)
    positions = arm_length * radial + np.array([0.0, 0.0, height])[None, :]
    return RotorGeometry(positions, axes, spins, float(yaw_coefficient))


def effectiveness(geometry, rho):
    """The 6 x n matrix mapping rotor thrusts to [force; moment about the pivot] (body frame);
    a stack of them for a stack of centre-of-mass offsets rho (batch, 3).
    """
    arms = geometry.positions + np.asarray(rho, dtype=float)[..., None, :]    # from the pivot
    moments = (np.cross(arms, geometry.axes)
               - (geometry.spins * geometry.yaw_coefficient)[:, None] * geometry.axes)
    forces = np.broadcast_to(geometry.axes.T, moments.shape[:-2] + geometry.axes.T.shape)
    return np.concatenate((forces, np.swapaxes(moments, -1, -2)), axis=-2)


@dataclass
class AirframeHealth:
    """What the start-up check found."""

    rank: int               # of the 6 x n effectiveness (6: fully actuated)
    moment_rank: int        # of its moment rows (must be 3)
    condition: float        # of the allocated rows [F_z; M]
    alive: list             # 1-based numbers of the rotors in use
    warnings: list


def check(B, alive):
    """Check an effectiveness matrix (6 x n_alive); raises AirframeError when a moment cannot be
    produced, returns AirframeHealth with warnings for what is merely degraded.
    """
    rank = int(np.linalg.matrix_rank(B))
    moment_rank = int(np.linalg.matrix_rank(B[3:]))
    if moment_rank < 3:
        raise AirframeError('the rotors %s cannot produce every moment (moment rank %d of 3)'
                            % (alive, moment_rank))
    B4 = B[2:]
    if np.linalg.matrix_rank(B4) < 4:
        raise AirframeError('the rotors %s cannot produce collective thrust independently of the '
                            'moments' % (alive,))
    s = np.linalg.svd(B4, compute_uv=False)
    warnings = []
    if rank < 6:
        warnings.append('not fully actuated (effectiveness rank %d of 6): lateral forces '
                        'follow from the moments, which the joint absorbs' % rank)
    cond = float(s[0] / s[-1])
    if cond > 100.0:
        warnings.append('poorly conditioned allocation (condition number %.0f)' % cond)
    return AirframeHealth(rank, moment_rank, cond, list(alive), warnings)


@dataclass
class Allocation:
    """One allocation's result (for a batch of moments: each field with the batch axis first)."""

    thrusts: np.ndarray        # N, one per rotor (failed rotors: 0)
    moment: np.ndarray         # moment the thrusts produce about the pivot
    collective: float          # thrust they produce along body z
    moment_lost: np.ndarray    # requested minus produced moment
    saturated: bool            # the request was not met exactly
    valid: bool                # False: the request was not finite (thrusts at thrust_min)


class Allocator:
    """Thrusts for a desired moment (about the pivot) and collective thrust, within limits.

    It knows rotors only through their effectiveness matrix B (6 x n: thrusts -> [force; moment
    about the pivot], from ``effectiveness`` or written by hand), as PX4's control allocation
    receives its matrix from the airframe's ActuatorEffectiveness.
    """

    def __init__(self, B, thrust_min, thrust_max, failed=()):
        B = np.asarray(B, dtype=float)
        n = B.shape[1]
        self.count = n
        self.alive = [i for i in range(n) if i + 1 not in set(failed)]
        self.B_full = B
        self.B = self.B_full[:, self.alive]
        self.health = check(self.B, [i + 1 for i in self.alive])
        if failed:
            self.health.warnings.insert(0, 'rotor(s) %s marked failed: flying on %s'
                                        % (sorted(failed), self.health.alive))
        self.B4 = self.B[2:]                                  # rows F_z, M_x, M_y, M_z
        P = np.linalg.pinv(self.B4)                           # n_alive x 4, minimum norm
        self._d, self._p_rp, self._p_y = P[:, 0], P[:, 1:3], P[:, 3]
        self._p_moment = np.ascontiguousarray(P[:, 1:])
        if np.any(self._d <= 1e-9):
            raise AirframeError('collective thrust would need rotor(s) %s to push the other way'
                                % [self.alive[i] + 1 for i in np.nonzero(self._d <= 1e-9)[0]])
        self.lo, self.hi = float(thrust_min), float(thrust_max)
        self._inv_d = 1.0 / self._d
        self._thrusts = np.zeros(n)

    def allocate(self, moment, collective):
        """Allocation for the desired moment (3,) about the pivot and collective thrust (N); a
        stack of moments (batch, 3) gives one allocation per row.
        """
        moment = np.asarray(moment, dtype=float)
        valid = np.isfinite(moment).all(axis=-1) & math.isfinite(collective)
        all_valid = all_flag(valid)
        m = moment if all_valid else np.where(np.asarray(valid)[..., None], moment, 0.0)
        f = collective * self._d + matvec(self._p_moment, m)
        met = (f.min(axis=-1) >= self.lo) & (f.max(axis=-1) <= self.hi)
        if not all_flag(met):
            f_rp = matvec(self._p_rp, m[..., :2])
            f_y = self._p_y * m[..., 2:]
            # roll and pitch scaled first, then yaw (only when roll and pitch are whole), then the
            # collective thrust moved within what the rotors allow
            s_rp = self._max_scale(np.zeros_like(f_rp), f_rp)
            base = (f_rp.T * s_rp).T
            s_y = np.where(s_rp >= 1.0, self._max_scale(base, f_y), 0.0)
            base = base + (f_y.T * s_y).T
            t_lo, t_hi = self._t_interval(base)
            t = np.minimum(np.maximum(collective, t_lo), t_hi)
            degraded = np.minimum(np.maximum(np.multiply.outer(t, self._d) + base, self.lo),
                                  self.hi)                                        # round-off
            f = np.where(np.asarray(met)[..., None], f, degraded)
        if not all_valid:
            f = np.where(np.asarray(valid)[..., None], f, self.lo)
            moment = np.where(np.asarray(valid)[..., None], moment, 0.0)
        return self._result(f, moment, saturated=~met | ~valid, valid=valid)

    def _t_interval(self, base):
        """The collective levels t with lo <= t d + base <= hi for every rotor."""
        return (np.max((self.lo - base) * self._inv_d, axis=-1),
                np.min((self.hi - base) * self._inv_d, axis=-1))

    def _max_scale(self, base, a):
        """Largest s in [0, 1] such that some t gives lo <= t d + base + s a <= hi per rotor.

        Per rotor, L_i - s A_i <= t <= H_i - s A_i; some t exists iff for every pair (i, j)
        s (A_j - A_i) <= H_j - L_i. (0 when base itself is infeasible.)
        """
        L = (self.lo - base) * self._inv_d
        H = (self.hi - base) * self._inv_d
        A = a * self._inv_d
        D = A[..., None, :] - A[..., :, None]
        N = H[..., None, :] - L[..., :, None]
        ratio = np.divide(N, D, out=np.full(D.shape, np.inf), where=D > 1e-12).min(axis=(-2, -1))
        return np.where((N < -1e-12).any(axis=(-2, -1)), 0.0,
                        np.minimum(np.maximum(ratio, 0.0), 1.0))

    def _result(self, f_alive, moment, saturated, valid):
        """The Allocation of the alive rotors' thrusts; moment is the request (0 where invalid)."""
        if len(self.alive) == self.count:
            thrusts = f_alive
        else:
            thrusts = np.zeros(f_alive.shape[:-1] + (self.count,))
            thrusts[..., self.alive] = f_alive
        wrench = matvec(self.B, f_alive)
        return Allocation(thrusts=thrusts, moment=wrench[..., 3:], collective=wrench[..., 2],
                          moment_lost=moment - wrench[..., 3:], saturated=saturated, valid=valid)


@dataclass(frozen=True)
class ThrustCurve:
    """Per-motor quadratic thrust curve f = a x^2 + b x + c, x = voltage_scale * command, with an
    integer command in 0..command_max (the lab's BL-Ctrl 2.0 fit by default).
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    voltage_scale: float
    command_max: int

    def thrust(self, command):
        """Thrust (N) of integer commands (n,); never negative."""
        x = self.voltage_scale * np.asarray(command, dtype=float)
        return np.maximum(self.a * x * x + self.b * x + self.c, 0.0)

    def __post_init__(self):
        # command(f) = ceil(x / voltage_scale) with x the root of a x^2 + b x + c = f, i.e.
        # ceil(sqrt(b^2 - 4 a c + 4 a f) / (2 a vs) - b / (2 a vs)), constants folded once
        k = 1.0 / (2.0 * self.a * self.voltage_scale)
        for name, value in (('_disc0', self.b * self.b - 4.0 * self.a * self.c),
                            ('_four_a', 4.0 * self.a), ('_k', k),
                            ('_k0', -self.b * k - 1e-9), ('_zero_up_to', np.maximum(self.c, 0.0))):
            object.__setattr__(self, name, value)

    def command(self, thrust):
        """Smallest integer command whose thrust is at least the requested one (the lab's ceil),
        clipped to 0..command_max; negative thrust counts as 0, and a request that command 0
        already meets (the curve is clipped at 0 N) gives 0.
        """
        f = np.maximum(np.asarray(thrust, dtype=float), 0.0)
        x = np.sqrt(self._disc0 + self._four_a * f) * self._k + self._k0     # x / vs, less 1e-9
        cmd = np.minimum(np.maximum(np.ceil(x), 0.0), self.command_max).astype(int)
        cmd[f <= self._zero_up_to] = 0
        return cmd

    def max_thrust(self):
        """Thrust of each motor at command_max."""
        return self.thrust(np.full(len(self.a), self.command_max))

    def normalised(self, command):
        """Command as a fraction of command_max, in [0, 1]."""
        return np.asarray(command, dtype=float) / self.command_max


@dataclass
class MotorOutput:
    """What the mixer sends to the motors for one control step."""

    commands: np.ndarray     # integer ESC commands, 0..command_max
    normalised: np.ndarray   # commands / command_max, in [0, 1]
    allocation: Allocation


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
    narrow corridor between two cones bounce between them into one (README, "Safety campaign").
    A batch of moments keeps one model per run. The model starts at the first armed step's own
    allocation (no kick at arming) and is dropped when disarmed.
    """

    HOLD_MEMORY = 1.0     # s: how long a late step keeps the compensation designed for its hold

    def __init__(self, allocator, curve, collective_thrust, lag=0.0):
        self.allocator = allocator
        self.curve = curve
        self.collective_thrust = float(collective_thrust)
        self.lag = float(lag)
        self._dead = np.array([i for i in range(allocator.count) if i not in allocator.alive],
                              dtype=int)
        # the lag model's thrusts at the last command (None: at rest)
        self.modelled_thrusts = None
        self.sent_thrusts = None         # the thrusts the last command asked for
        self.design_hold = None          # H of the last command (s)

    def adopt_state(self, other):
        """Carry the lag model over from the mixer this one replaces (a run-time
        reconfiguration).
        """
        if other.modelled_thrusts is not None:
            self.modelled_thrusts = other.modelled_thrusts.copy()
            self.sent_thrusts = other.sent_thrusts.copy()
            self.design_hold = other.design_hold

    def mix(self, moment, armed=True, dt=None, held=None):
        """Motor commands for the moment (or a stack of them); all zero when not armed.

        dt: how long this command is expected to be held (the control period); held: how long the
        previous command really was (the time since the last step; dt when not given). Both are
        needed for the lag compensation only.
        """
        allocation = self.allocator.allocate(moment, self.collective_thrust)
        thrusts = allocation.thrusts
        if not armed:
            zero = np.zeros_like(thrusts, dtype=int)
            self.modelled_thrusts = self.sent_thrusts = self.design_hold = None
            return MotorOutput(zero, np.zeros(zero.shape), allocation)
        compensate = self.lag > 0.0 and dt is not None and dt > 0.0
        if compensate:
            model = self.modelled_thrusts
            if model is None or model.shape != thrusts.shape:
                # arming: no kick to spin the motors up (a motor starting from rest does not
                # follow the first-order lag anyway); compensation from the next step
                model, hold = thrusts, dt
            else:
                held = dt if held is None else max(held, 0.0)
                sent = self.sent_thrusts
                model = sent + math.exp(-held / self.lag) * (model - sent)
                hold = max(dt, held)
                if self.design_hold > hold:       # a late step not long ago: back to dt slowly
                    hold = max(hold, dt + (self.design_hold - dt) * math.exp(
                        -held / self.HOLD_MEMORY))
            a = math.exp(-hold / self.lag)
            thrusts = np.minimum(np.maximum((thrusts - a * model) / (1.0 - a), self.allocator.lo),
                                 self.allocator.hi)
        commands = self.curve.command(thrusts)
        if len(self._dead):
            commands[..., self._dead] = 0
        if compensate:
            self.modelled_thrusts = model
            self.sent_thrusts = self.curve.thrust(commands)
            self.design_hold = hold
        elif self.modelled_thrusts is not None:     # compensation turned off: a stale model
            self.modelled_thrusts = self.sent_thrusts = self.design_hold = None   # is not kept
        return MotorOutput(commands, self.curve.normalised(commands), allocation)
