"""The closed loop, written once: N >= 1 runs of the simulated testbed under the controller's tick.

``fly(scenarios)`` flies the scenarios together, as arrays with a leading run axis, through the
classes the node uses: ``ControlTick`` (the node's ``ControlLoop`` calls the same tick),
``AttitudeController``, ``Mixer``, and the testbed's ``Plant`` and ``RotorActuator``. The scenario
runner flies a batch of one; a campaign flies batches of many. A run in a batch gives the same
bits as the same run flown alone (test_closed_loop.py).

Each control step the controller sees the state ``latency`` before (a ring of past states, one
per integration step), with the motion-capture and gyro noise of the run's own seed; at a stalled
step (``stalls``) no sample arrives and the run flies on its last one, older by the wait. The tick
brings the samples forward by their age, the mixer turns the moment into integer commands (or,
with ``actuation: torque``, the moment acts itself) and the command is held while the plant
integrates: a control period, or longer with ``tick_jitter``. Set-point schedules switch at their
times after the start (the runs are armed at t = 0).

Per run may differ what a campaign varies (``PER_RUN``); everything else (gains, airframe, rates,
noise levels, duration, schedule, the disturbance's varying part) must be the same, and ``fly``
says which parameter differs otherwise. The node's input supervision (refusals, gap bridging,
failsafes) is the node's: a scenario's stalls are shorter than the inputs' timeouts.
"""
from __future__ import annotations

from dataclasses import dataclass
import math
import time
from typing import Any, Callable, List, Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.actuation.motors import MotorOutput
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.brake import (
    ApproachBrake,
    BrakeTerms,
    backup_margin,
    brake_terms,
    covered,
    opening,
)
from geoctl_ros.core.law.cones import angle_deg
from geoctl_ros.core.law.control import ControlOutput
from geoctl_ros.core.supervisor.control_tick import ControlTick
from geoctl_ros.core.telemetry.stats import SETTLE_PSI
from geoctl_ros.params import CONTROLLER, SIM
from geoctl_ros.params.scenario import PER_RUN, Scenario, differing
from geoctl_ros.sim.history import History
from geoctl_ros.sim.runs import Testbeds, late_holds, shared_holds
from geoctl_ros.sim.testbed import measured_attitude, measured_rate

SETTLED_DEG = 5.0       # attitude error below which a run has converged (at the end) or settled
FINE_DEG = 1.0          # attitude error below which a run has arrived (settle_fine_s)
SETTLE_WITHIN_S = 10.0  # the reports count the runs settled within this (a manoeuvre's figure)
STALL_MAX_S = 0.04      # s, the longest input stall a scenario has (scenario: stalls.duration)


@dataclass
class Flight:
    """Per-run figures of a flight (arrays with one entry per run, in the scenarios' order)."""

    names: list
    min_angle_deg: np.ndarray      # (runs, cones): smallest angle between the sensor and each
                                   # cone's axis, after every integration step
    half_angle_deg: np.ndarray     # (runs, cones)
    final_error_deg: np.ndarray    # (runs,): attitude error at the end (true attitude)
    final: ControlOutput           # ControlOutput of the true final state (no adaptation)
    final_angular_velocity: np.ndarray   # (runs, 3)
    saturated_steps: np.ndarray    # (runs,): control steps with the allocation saturated
    max_rate: np.ndarray           # (runs,): largest measured |Omega| (rad/s)
    effort: np.ndarray             # (runs,): the integral of the law's |u| over the flight (N m s)
    settle_s: np.ndarray           # (runs,): the time from which the attitude error stays below
                                   # SETTLED_DEG (NaN: not below at the end)
    settle_fine_s: np.ndarray      # (runs,): the same for FINE_DEG (NaN: not below at the end)
    psi_settle_s: np.ndarray       # (runs,): the time from which Psi stays below SETTLE_PSI
                                   # (the paper's; NaN: not below at the end)
    margin_series: Optional[np.ndarray]   # (steps, runs): min cone margin at each control step
                                          # (None unless asked for: series=True)
    sensor_series: Optional[np.ndarray]   # (steps, runs, 3): sensor direction R r, world frame
                                          # (float32; None unless asked for)
    error_series: Optional[np.ndarray]    # (steps, runs): attitude error to the goal (deg; the
                                          # true attitude; None unless asked for)
    history: Optional[History]     # History: every step's state and output (history=True)
    assumed: Optional['AssumedSeries']   # the approach brake's assumptions judged at every
                                         # control step (None unless asked for: assumed=True)
    times: np.ndarray              # (steps,): the control steps' times
    dt: float
    takeover_margin_deg: Optional[np.ndarray] = None   # (runs, cones): the arming check's
                                   # predicted margin at the take-over (below 0: it refuses the
                                   # arming; ControlTick.takeover_margins); None without a brake
    wall_s: float = 0.0

    @property
    def min_margin_deg(self) -> np.ndarray:
        """(runs, cones): the closest approach to each cone (angle minus half-angle, deg)."""
        return self.min_angle_deg - self.half_angle_deg

    @property
    def saturated_s(self) -> np.ndarray:
        """(runs,): time with the allocation saturated (s)."""
        return self.saturated_steps * self.dt

    @property
    def violated(self) -> np.ndarray:
        """(runs,): the sensor reached or entered a cone."""
        return np.any(self.min_margin_deg <= 0.0, axis=-1)


@dataclass
class AssumedSeries:
    """What the approach brake's derivation assumes (core.law.brake), judged at every control
    step of a flight, per run: arrays (steps, runs).
    """

    ok: np.ndarray           # every bound held over the step's hold: the allocation not
                             # saturated nor the compensation clipped, the brake's condition met,
                             # the hold within its design, what the brake's model (frozen at the
                             # tick) did not know of each approach's rate of change within a_u,
                             # and the measurements in use within e and e_w along each cone's
                             # opening direction
    safe: np.ndarray         # the true state on the safe set: every cone's backup margin
                             # (core.law.brake.backup_margin, no measurement error) >= 0
    unknown: np.ndarray      # the largest |dw/dt true - the brake's model's| over the hold, over
                             # the cones (rad/s^2)
    hold_margin: np.ndarray  # the closest approach over the step's hold (deg; every cone)
    lead: int                # the steps before a safe one whose measurements it used

    def covered(self) -> np.ndarray:
        """(steps, runs): the steps the derivation speaks of (``core.law.brake.covered``)."""
        return covered(self.ok, self.safe, self.lead)


def fly(scenarios: List[Scenario], progress: Optional[Callable[[float], None]] = None,
        series: bool = False, history: bool = False, duration: Optional[float] = None,
        assumed: bool = False) -> Flight:
    """Fly the scenarios together; a Flight. progress(fraction) is called now and then.
    series: keep the margin and sensor direction at every control step (the figures of a few
    runs; a campaign's batches leave them out and fly its worst runs again for them); history:
    keep every step's state and output (the scenario runner's history.csv); duration: simulated
    seconds (default: the scenarios'); assumed: judge what the approach brake assumes at every
    control step (``AssumedSeries``: the falsifier's judge; it costs a model evaluation per
    integration step).

    The runs are armed before t = 0: the rotors spool up (``Mixer.spools``) while each vehicle
    is held at its initial attitude (``scenario.start: held``) or rests where gravity and its
    stops take it (``resting``), and the controller takes over at t = 0.
    """
    problem = differing(scenarios)
    if problem:
        raise ValueError('a batch shares everything but %s; differs: %s'
                         % (', '.join(PER_RUN[CONTROLLER] + PER_RUN[SIM]), problem))
    bed = Testbeds(scenarios)
    setup, controller, plant, cones, actuator = (bed.setup, bed.controller, bed.plant, bed.cones,
                                                 bed.actuator)
    n = len(scenarios)
    rate, rate_sub = setup.loop.rate_hz, bed.beds[0].integration_rate_hz
    n_sub = int(round(rate_sub / rate))
    dt, h = 1.0 / rate, 1.0 / (rate * n_sub)
    span = bed.options[0].duration if duration is None else duration
    holds = shared_holds(bed, rate, n_sub, span)
    steps = len(holds)
    j_at = np.cumsum(holds) - holds                   # integration steps before each step
    times = j_at / rate_sub
    noise = bed.noise(steps)
    schedule = setup.schedule
    delay = np.array([int(round(o.latency * rate_sub)) for o in bed.options])
    runs = np.arange(n)

    # each sample received at its step: its age the latency from its stamp (age_from_stamps),
    # else the measurement_delay the controller assumes; stalled, older by the wait since (the
    # ages a node's input streams give its tick: core.supervisor.safety.Stream)
    stamped = setup.loop.age_from_stamps
    assumed_age = setup.loop.measurement_delay
    tick = ControlTick(controller, setup.mixer)
    # the closest approach: the largest cosine to each cone's axis after any integration step
    # (arccos decreases), taken over each control step's steps at once
    R_0, W_0 = bed.state()
    max_cos = cones.cosines(R_0)
    # what the arming check says of each run's start (its measurements the latency old)
    arming = (np.degrees(tick.takeover_margins(R_0, W_0, delay * h, dt))
              if controller.brake is not None else None)
    takeover, max_cos = _spool_up(bed, tick, dt, n_sub, h, max_cos,
                                  (0.0, 0.0) if stamped else (assumed_age, assumed_age))
    R_now, W_now = bed.state()
    # latency: a ring of the last states, one per integration step
    ring = int(delay.max()) + 1
    R_past = np.repeat(R_now[None], ring, axis=0)
    W_past = np.repeat(W_now[None], ring, axis=0)
    stalled = np.stack([o.stalled(times) for o in bed.options], axis=1)
    any_stall = bool(stalled.any())
    receipt = np.zeros(n)
    ages = (delay * h,) * 2 if stamped else (assumed_age, assumed_age)
    R_seen, W_seen = R_now, W_now
    held = np.empty((int(holds.max()) if steps else 0,) + R_now.shape)   # a step's attitudes
    margin_series = np.empty((steps, n)) if series else None
    sensor_series = np.empty((steps, n, 3), dtype=np.float32) if series else None
    error_series = np.empty((steps, n)) if series else None
    record = History(steps, bed) if history else None
    judge = _Judge(bed, tick, steps, delay, h, dt) if assumed else None
    last_unsettled = np.full(n, -1)        # the last step with the error >= SETTLED_DEG
    last_coarse = np.full(n, -1)           # the last step with the error >= FINE_DEG
    last_psi_above = np.full(n, -1)        # the last step with Psi >= SETTLE_PSI
    settled_rad, fine_rad = math.radians(SETTLED_DEG), math.radians(FINE_DEG)
    saturated = np.zeros(n)
    max_rate = np.zeros(n)
    effort = np.zeros(n)
    scheduled = -1
    fresh = np.ones(n, dtype=bool)
    j = 0                                                     # integration steps so far
    t0 = time.perf_counter()
    for k in range(steps):
        t = times[k]
        i = schedule.due(t, scheduled)
        if i >= 0:                                     # (checked at configuration)
            controller.R_d = np.repeat(schedule.rotations[i][None], n, axis=0)
            scheduled = i
        seen = np.maximum(j - delay, 0) % ring
        R_new = measured_attitude(R_past[seen, runs], noise[0, k])
        W_new = measured_rate(W_past[seen, runs], bed.gyro_bias, noise[1, k])
        if any_stall:
            fresh = ~stalled[k]
            R_seen = np.where(fresh[:, None, None], R_new, R_seen)
            W_seen = np.where(fresh[:, None], W_new, W_seen)
            receipt = np.where(fresh, t, receipt)
            waited = np.maximum(t - receipt, 0.0)
            age = delay * h + waited if stamped else assumed_age + waited
            ages = (age, age)
        else:
            R_seen, W_seen = R_new, W_new
        max_rate = np.maximum(max_rate, np.sqrt(so3.dot(W_seen, W_seen)))
        # (a batch raises FloatingPointError rather than return no control: ControlTick)
        out, motors = cast(Tuple[ControlOutput, MotorOutput],
                           tick(R_seen, W_seen, dt, takeover + t, ages)[:2])
        saturated += motors.allocation.saturated
        effort += np.sqrt(so3.dot(out.u, out.u)) * (holds[k] * h)
        error = _error(controller.R_d, R_now)
        last_unsettled[error >= settled_rad] = k
        last_coarse[error >= fine_rad] = k
        last_psi_above[out.psi >= SETTLE_PSI] = k
        if margin_series is not None and sensor_series is not None and error_series is not None:
            margin_series[k] = cones.margins_deg(R_now).min(axis=-1)
            sensor_series[k] = so3.matvec(R_now, cones.r)
            error_series[k] = np.degrees(error)
        if record is not None:
            record.add(k, t, out, motors)
        command = out.u if actuator is None else motors.commands
        if judge is not None:
            judge.at_tick(k, takeover + t, out, motors, fresh, noise[:, k], holds[k] * h, dt)
        for i in range(holds[k]):
            tau = bed.moment(command, h)
            if judge is not None:
                judge.during(k, j * h, takeover + j * h, tau)
            plant.step(tau, h)
            j += 1
            R_now, W_now = bed.state()
            R_past[j % ring], W_past[j % ring] = R_now, W_now
            held[i] = R_now
        hold_cos = cones.cosines(held[:holds[k]]).max(axis=0)
        max_cos = np.maximum(max_cos, hold_cos)
        if judge is not None:
            judge.hold_margin[k] = (angle_deg(hold_cos) - cones.theta_deg).min(axis=-1)
        if progress is not None and (k + 1) % 100 == 0:
            progress((k + 1) / steps)
    wall = time.perf_counter() - t0
    final = controller.step(R_now, W_now, dt, adapt=False)
    return Flight(
        names=[s.name for s in scenarios], min_angle_deg=angle_deg(max_cos),
        half_angle_deg=cones.theta_deg * np.ones((n, 1)),
        final_error_deg=np.degrees(_error(controller.R_d, R_now)),
        final=final, final_angular_velocity=W_now, saturated_steps=saturated,
        max_rate=max_rate, effort=effort, settle_s=_settled(last_unsettled, times),
        settle_fine_s=_settled(last_coarse, times),
        psi_settle_s=_settled(last_psi_above, times),
        margin_series=margin_series, sensor_series=sensor_series, error_series=error_series,
        history=record, assumed=None if judge is None else judge.series(), times=times,
        dt=dt, takeover_margin_deg=arming, wall_s=wall)


def _spool_up(bed: Testbeds, tick: ControlTick, dt: float, n_sub: int, h: float,
              max_cos: np.ndarray, ages: tuple) -> tuple:
    """Arm the runs and spool their rotors up before the take-over (``Mixer.spools``: ticks as
    late as the flight's, each vehicle seen as it is, its inputs taken as ``ages`` old: 0 from
    their stamps, else the assumed measurement_delay), held still (``start: held``) or resting
    where gravity and the stops take it (``resting``). Returns (the tick clock's time of the
    take-over, the closest approach's cosines so far).
    """
    o, b = bed.options[0], bed.beds[0]
    seed = b.noise.seed if o.tick_jitter_seed < 0 else o.tick_jitter_seed
    holds = late_holds(n_sub, o.tick_jitter / h, seed, 2)
    plant = bed.plant
    plant.held = o.start == 'held'
    now, before = 0.0, None
    while tick.mixer.spools(tick.rotors, None if before is None else now - before, dt):
        R, W = bed.state()
        out, motors = cast(Tuple[ControlOutput, MotorOutput],   # (a batch: never no control)
                           tick(R, W, dt, now, ages)[:2])
        command = out.u if bed.actuator is None else motors.commands
        hold = next(holds)
        for _ in range(hold):
            plant.step(bed.moment(command, h), h)
        max_cos = np.maximum(max_cos, bed.cones.cosines(bed.state()[0]))
        before, now = now, now + hold * h
    plant.held = False
    plant.t = 0.0
    return now, max_cos


class _Judge:
    """The falsifier's judge of the approach brake's assumptions, flown along (``AssumedSeries``):
    at each tick the brake's view of the true state (``core.law.brake.brake_terms``), and over
    its hold the true rate of change of each approach against that view's.
    """

    def __init__(self, bed: Testbeds, tick: ControlTick, steps: int, delay: np.ndarray,
                 h: float, dt: float):
        self.bed, self.tick = bed, tick
        n = len(bed.beds)
        config = tick.controller.config
        self.brake = ApproachBrake.bounds_of(config)
        self.ok = np.zeros((steps, n), dtype=bool)
        self.safe = np.zeros((steps, n), dtype=bool)
        self.unknown = np.zeros((steps, n))
        self.hold_margin = np.full((steps, n), np.inf)
        # the measurements a step uses are at most the latency and the longest stall old
        self.lead = int(math.ceil((float(delay.max()) * h + STALL_MAX_S) / dt - 1e-9)) + 1
        self.noise = np.zeros((2, n, 3))       # the errors of the samples in use
        self.terms: Optional[BrakeTerms] = None

    def at_tick(self, k: int, t: float, out: Any, motors: Any, fresh: np.ndarray,
                noise: np.ndarray, held: float, dt: float) -> None:
        """Judge step k at its tick (after the controller's step): the true state's margin and
        the measurements in use, the allocation, the brake, the hold; keep the brake's view
        for the hold.
        """
        tick, bed = self.tick, self.bed
        R, W = bed.state()
        hold = dt if tick.rotors is None else tick.rotors.design_hold
        x = tick.brake_inputs(R, W, 0.0, hold, t)
        terms = self.terms = brake_terms(self.brake, bed.cones, tick.controller.J_inv, x)
        self.safe[k] = np.all(backup_margin(self.brake, terms.gap, terms.w, terms.D_s,
                                            terms.authority, hold) >= 0.0, axis=-1)
        self.noise = np.where(fresh[None, :, None], noise, self.noise)
        n_i = terms.n
        attitude = np.abs(so3.dot(n_i, self.noise[0][:, None, :]))
        rate = np.abs(so3.dot(n_i, (bed.gyro_bias + self.noise[1])[:, None, :]))
        within = (np.all(attitude <= self.brake.measurement, axis=-1)
                  & np.all(rate <= self.brake.rate_error, axis=-1))
        self.ok[k] = (within & ~np.asarray(motors.saturated) & ~np.asarray(out.brake_unmet)
                      & (held <= hold + 1e-9))

    def during(self, k: int, t: float, clock: float, tau: np.ndarray) -> None:
        """Within step k's hold at time t (the tick's clock: clock; the rotors' true moment
        tau): how far each approach's true rate of change is from the brake's model of it at the
        tick, under the moment in force by the command history; the hold's bound is judged at
        its end (``series``).
        """
        bed, terms = self.bed, self.terms
        assert terms is not None
        p = bed.plant
        R, W = bed.state()
        true = p.angular_acceleration(t, so3.vecmat(p.config.gravity, p.R), p.Omega, tau)
        true = true[None] if bed.single else true
        _, n_i, _, kin = opening(bed.cones, R, W)
        w_dot = kin - so3.dot(n_i, true[..., None, :])
        model = terms.model_rate_change(self.tick.history.at(clock))
        self.unknown[k] = np.maximum(self.unknown[k], np.abs(w_dot - model).max(axis=-1))

    def series(self) -> AssumedSeries:
        self.ok &= self.unknown <= self.brake.unmodelled
        return AssumedSeries(self.ok, self.safe, self.unknown, self.hold_margin, self.lead)


def _error(R_d: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The attitude error angle between R_d and R, per run (rad)."""
    return np.asarray(so3.angle(so3.matmul(so3.transpose(R_d), R)))


def _settled(last_above, times):
    """The time from which a quantity stays below its threshold, per run, from the last step it
    was above it: the next step's time (times[0] if never above; NaN if above at the end).
    """
    steps = len(times)
    after = np.minimum(last_above + 1, max(steps - 1, 0))
    return np.where(last_above == steps - 1, np.nan, times[after] if steps else 0.0)
