"""The control tick of the closed loop, written once: prediction, control step, mixing, and the
bookkeeping of how long each command was held.

``ControlLoop.tick`` (the controller node) and ``geoctl_ros.sim.closed_loop`` (the simulated
closed loop of the scenario runner and the campaigns) both call :class:`ControlTick`. Like the
core's formulas it takes one run (R (3, 3), Omega (3,)) or a batch of N ((N, 3, 3), (N, 3)).
"""
import math
from typing import NamedTuple, Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.actuation.motors import Mixer, MotorOutput, RotorModel
from geoctl_ros.core.geometry.so3 import FloatArray, Scalars, matvec
from geoctl_ros.core.law import prediction
from geoctl_ros.core.law.brake import ApproachBrake, BrakeInputs, rows
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.core.law.prediction import CommandHistory, Observer
from geoctl_ros.core.law.step_types import ControlOutput

ON_TIME_S = 1e-6       # a step less late than this is on time (the clock's rounding)
HISTORY_TICKS = 128    # the commands remembered for prediction (1.28 s at 100 Hz, 0.26 at 500)


def blind_time(ages: Tuple[Scalars, Scalars], dt: float, held: Optional[float]) -> Scalars:
    """How long the loop is blind beyond its nominal period (s; one per run of a batch): the age
    of its older input (from its stamp, or the assumed measurement_delay) plus how much later than
    the period this step comes. The barrier widens each cone by the sensor's travel towards it
    over this time (``core.law.configuration_error.blind_widening``); it is 0 for fresh inputs on
    time.
    """
    age = np.maximum(ages[0], ages[1])
    if held is None or held - dt < ON_TIME_S:
        return age
    return age + (held - dt)


# The delay envelope (docs/safety.md, "The bound"): the blind time at any tick, and sustained,
# that the safety campaign draws and the falsifier searches (tested and attacked, not derived)
BLIND_BOUND_S = 0.10
SUSTAINED_BLIND_BOUND_S = 0.06
SUSTAINED_TAU_S = 0.25      # s, the low-pass that tells a sustained blindness from a stall
PEAK_RELEASE_S = 1.0        # s, how long a blind peak past the bound keeps the gains down


class Degraded(NamedTuple):
    """Past the delay bound, the feedback gains come down with the blindness (docs/safety.md,
    "Past the bound"): the loop's bandwidth scales by s = min(1, SUSTAINED_BLIND_BOUND_S /
    (blind time low-passed over SUSTAINED_TAU_S), BLIND_BOUND_S / (blind time peak-held over
    PEAK_RELEASE_S)), k_R by s^2 and k_Omega by s, so the loop's phase lag at its crossover
    stays what it was at the bound. Within the bound s = 1 and nothing changes. The state of
    that scale (``degraded``), one value per run of a batch.
    """

    sustained: Scalars = 0.0   # s, the low-passed blind time
    peak: Scalars = 0.0        # s, the blind time held from its last peak
    scale: Scalars = 1.0       # the scale s after the last tick (1 within the bound)


def degraded(state: Degraded, blind: Scalars, held: float) -> Degraded:
    """``Degraded`` after a tick of blind time ``blind`` that came ``held`` s after the last."""
    sustained = state.sustained + (blind - state.sustained) * (held / (SUSTAINED_TAU_S + held))
    if np.ndim(blind) == 0 and np.ndim(state.peak) == 0:     # one run: plain floats
        peak = max(float(blind), state.peak * math.exp(-held / PEAK_RELEASE_S))
        return Degraded(sustained, peak, min(1.0, SUSTAINED_BLIND_BOUND_S / max(sustained, 1e-9),
                                             BLIND_BOUND_S / max(peak, 1e-9)))
    peaks = np.maximum(blind, state.peak * np.exp(-held / PEAK_RELEASE_S))
    return Degraded(sustained, peaks, np.minimum(1.0, np.minimum(
        SUSTAINED_BLIND_BOUND_S / np.maximum(sustained, 1e-9),
        BLIND_BOUND_S / np.maximum(peaks, 1e-9))))


class Command(NamedTuple):
    """What one control tick commands, and what it found on the way."""

    control: Optional[ControlOutput]   # the step's; None when its moment was not finite
    motors: MotorOutput      # zero commands unless armed
    spooling: bool = False   # armed, the rotors spooling up (the vehicle held, not yet flown)
    took_over: bool = False  # the first tick the controller flies after the spool-up
    blind: Scalars = 0.0     # s: the blind time the step allowed for (``blind_time``; an idle
                             # tick's: the last step's)
    gain_scale: Scalars = 1.0   # the bandwidth's scale past the delay bound (``Degraded``)
    residual: Optional[float] = None   # rad/s^2: the unlearnt acceleration at the last rate
                                       # sample (``Learnt.residual``; one run alone)


class ControlTick:
    """One control tick, with the state that ties a tick to the one before: the moments the rotors
    were told to produce, with when (the prediction's input), the rotors' lag model (the
    mixer's, which keeps none), and when the last command went out (the lag compensation's real
    hold).
    """

    def __init__(self, controller: AttitudeController, mixer: Mixer) -> None:
        """controller: AttitudeController (one run or a batch); mixer: Mixer. (The inputs' ages
        come with each tick, the assumed ``measurement_delay`` already in them where a stamp
        does not tell: ``core.supervisor.safety.Stream`` for the node, the closed loop alike.)
        """
        self.controller = controller
        self.observer = Observer()      # the prediction's observer of the model's error
        self.mixer = mixer
        self.rotors: Optional[RotorModel] = None   # the lag model (None: the rotors at rest)
        # what the rotors were told to produce, with when (the prediction's input)
        self.history = CommandHistory(HISTORY_TICKS, mixer.lag)
        self._last_now: Optional[float] = None
        self.blind: Scalars = 0.0                # the last tick's blind time (blind_time)
        self.degraded = Degraded()      # the gains' scale past the delay bound
        self._clock = 0.0               # the tick's time: now, or (untimed) periods counted
        self._ticked = False
        self.flying = False             # armed and past the spool-up
        # (a tick's bookkeeping not yet done: ``settle``)
        self._unsettled: Optional[Tuple[float, float, ControlOutput, MotorOutput, bool]] = None

    def reconfigure(self, mixer: Mixer) -> None:
        """A new mixer, at run time (the rotors' lag model goes on under it)."""
        self.mixer = mixer
        self.history.lag = mixer.lag

    def _held(self, now: Optional[float]) -> Optional[float]:
        """How long the last command was held: the time since the last tick, or None (a period)
        for ticks that are not timed (now None).
        """
        held = None if now is None or self._last_now is None else now - self._last_now
        if now is not None:
            self._last_now = now
        return held

    def _time(self, now: Optional[float], dt: float) -> float:
        """The tick's time on the history's clock: now, or for untimed ticks the periods so
        far.
        """
        if now is not None:
            self._clock = now
        elif self._ticked:
            self._clock += dt
        self._ticked = True
        return self._clock

    def __call__(self, R: FloatArray, Omega: FloatArray, dt: float, now: Optional[float] = None,
                 ages: Tuple[Scalars, Scalars] = (0.0, 0.0), armed: bool = True,
                 adapt: bool = True, predict: bool = True, settle: bool = True) -> Command:
        """Command the rotors from a measured attitude R and rate Omega.

        dt: the control period (how long this command is expected to be held); now: the tick's
        time on the loop's clock (None: every tick on time, as in a batch); ages: how old the
        attitude and rate measurements are (s; from their stamps, or the assumed
        measurement_delay plus any wait); predict: bring the
        measurements forward by their age (off for a state that is already
        propagated, as a gap's); adapt: let the estimate learn from this step.

        Armed, the rotors first spool up (``Mixer.spools``: SPOOL_LAGS motor time constants)
        to the model's feed-forward, the gravity moment and the estimate, while the vehicle
        rests on its stops or is held: the controller does not fly it yet, and nothing of that
        time is predicted or learnt. At the take-over the command history and the observer
        start afresh, and the approach brake keeps the cones from then on.

        A step whose moment is not finite commands zero and returns control None: for one run the
        caller then disarms; a batch raises FloatingPointError, as a diverged simulation does.

        settle: the tick's bookkeeping for the next (``settle``) at its end; False leaves it to
        the caller once the command is out (the node: after publishing it), or to the next tick.
        """
        self.settle()
        held = self._held(now)
        t = self._time(now, dt)
        mixer = self.mixer
        rotors = self.rotors
        spooling = bool(armed) and mixer.spools(rotors, held, dt)
        took_over = bool(armed) and not spooling and not self.flying
        self.flying = bool(armed) and not spooling
        if took_over:
            # nothing of the spool-up is predicted or learnt (the vehicle was held): the history
            # starts with the moment the spooled rotors make now
            self.history.clear()
            made = mixer.moments(rotors, dt if held is None else held)
            if made is not None:
                self.history.push(t, made[0], made[1])
            self.observer = Observer()
            self.controller.replan()           # guidance's way from where the vehicle is
        R_b, W_b = R, Omega
        residual = None
        if predict:
            # with a model of the motors' lag, the law aims at the middle of the command's hold
            self.observer, (R_b, W_b), (R, Omega), residual = prediction.predict(
                self.observer, self.controller.dynamics, R, Omega, ages[0], ages[1], self.history,
                t, 0.5 * dt if mixer.lag > 0.0 else 0.0)
        blind = self.blind = blind_time(ages, dt, held)
        controller = self.controller
        self.degraded = degraded(self.degraded, blind, dt if held is None else held)
        gain_scale = self.degraded.scale
        brake = None
        if controller.brake is not None and self.flying:
            brake = self.brake_inputs(R_b, W_b, np.maximum(ages[0], ages[1]),
                                      mixer.design_hold_for(rotors, dt, held), t,
                                      mixer.thrust_offsets(rotors, dt if held is None else held))
        out: Optional[ControlOutput]        # (None: a moment not finite, not commanded)
        out = controller.control(R, Omega, adapt=adapt and self.flying, blind=blind,
                                 brake=brake, guide=not spooling, gain_scale=gain_scale)
        learnt = out                        # (the estimate's stage learns from it: ``settle``)
        if spooling:                        # the feed-forward alone, the vehicle held
            out = out._replace(u=controller.feedforward(R))
        if not np.isfinite(out.u).all():           # a last line of defence: never command it
            if np.ndim(out.u) > 1:
                raise FloatingPointError('a run of the batch produced a non-finite moment')
            out, armed = None, False
        motors = mixer.mix(np.zeros(3) if out is None else out.u, rotors, armed=armed, dt=dt,
                           held=held)
        self.rotors = motors.rotors
        self._unsettled = (t, dt, learnt, motors, armed)
        if settle:
            self.settle()
        return Command(out, motors, spooling, took_over, blind, gain_scale, residual)

    def settle(self) -> None:
        """The last tick's bookkeeping for the next one, which its command does not wait for: the
        estimate's stage (``core.law.control.adapted``) and the moments the rotors were told to
        produce, with when (the prediction's history). Nothing when it is done already.
        """
        unsettled = self._unsettled
        if unsettled is None:
            return
        self._unsettled = None
        t, dt, learnt, motors, armed = unsettled
        self.controller.adapt(learnt, dt)
        self.history.push(t, *self._produced(motors, armed))

    def brake_inputs(self, R: FloatArray, Omega: FloatArray, age: Scalars, hold: float,
                     t: float, thrusts: Optional[FloatArray] = None) -> BrakeInputs:
        """The approach brake's inputs at the tick (``core.law.brake.BrakeInputs``): the state
        predicted at the tick, the measurements' age, the hold, the moment the rotors make now
        (the command history's lag model) and the model's other moments there, its observed
        error included (the prediction's model is the brake's).
        """
        model = self.controller.dynamics
        M_g, f = model.moments(R, Omega)
        error = self.observer.acc_error         # (0.0 until the observer has learnt)
        if np.ndim(error):
            f = f - matvec(model.config.J, cast(FloatArray, error))
        return BrakeInputs(R, Omega, age, hold, self.history.at(t), f, M_g, thrusts)

    def takeover_inputs(self, R: FloatArray, Omega: FloatArray, age: Scalars,
                        dt: float) -> BrakeInputs:
        """The approach brake's inputs as they will be at the take-over after an arming now,
        the vehicle held or resting where it is: the rotors spooled up to the feed-forward for
        SPOOL_LAGS time constants from rest (uncompensated: the moment is the feed-forward's
        1 - exp(-SPOOL_LAGS) share), the model's other moments at (R, Omega), the measurements
        age old.
        """
        controller = self.controller
        spooled = (1.0 - math.exp(-self.mixer.SPOOL_LAGS)) if self.mixer.lag > 0.0 else 1.0
        M_g, f = controller.dynamics.moments(R, Omega)
        return BrakeInputs(R, Omega, age, dt, spooled * controller.feedforward(R), f, M_g)

    def takeover_margins(self, R: FloatArray, Omega: FloatArray, age: Scalars,
                         dt: float) -> FloatArray:
        """Per cone (one row per run of a batch), the approach brake's margin Phi (rad) at the
        take-over after an arming now (``takeover_inputs``; core.law.brake): below 0, the brake
        could not keep the cone in the worst case of the spool-up and its bounds.
        """
        controller = self.controller
        x = self.takeover_inputs(R, Omega, age, dt)
        return rows(cast(ApproachBrake, controller.brake), controller.config.cones,
                    controller.J_inv, x).margin

    def _produced(self, motors: MotorOutput,
                  armed: bool) -> Tuple[FloatArray, Optional[FloatArray]]:
        """The moments the rotors make from this tick on: the one they settle to and the one they
        make now (by the mixer's lag model, if it keeps one: at arming, none, the rotors
        spooling up from rest), about the pivot.
        """
        if not armed:
            return np.zeros(3), None
        made = self.mixer.moments(motors.rotors)
        return (motors.allocation.moment, None) if made is None else made

    def idle(self, dt: float, now: Optional[float] = None) -> Command:
        """A tick without a state to control from (before the first pose and rate): zero
        commands, and the time noted.
        """
        self.settle()
        self.flying = False
        self.rotors = None
        self._held(now)
        self.history.push(self._time(now, dt), np.zeros(3))
        return Command(None, self.mixer.mix(np.zeros(3), armed=False, dt=dt), blind=self.blind,
                       gain_scale=self.degraded.scale)
