"""The controller node's logic without ROS: checked inputs, arming, set points, step, mixing.

The node turns messages into calls of this class and its results into messages; every decision
(refuse a sample, refuse to arm, ride through a gap, fail safe, adopt a set point, freeze
adaptation, the diagnostics level and its reasons) is made here, so it is tested without rclpy.
"""
from dataclasses import dataclass
import math

import numpy as np

from geoctl_ros.core import so3
from geoctl_ros.core.control import AttitudeController, SetpointRejected
from geoctl_ros.core.diagnostics import (
    ERROR,
    OK,
    WARN,
    Counts,
    Figures,
    Gaps,
    Status,
    failsafe,
)
from geoctl_ros.core.gaps import GYRO, POSE, GapBridge
from geoctl_ros.core.safety import (
    EscHealth,
    EscStatus,
    Stream,
    Supervisor,
    angular_velocity_problem,
    esc_problem,
    quaternion_problem,
)
from geoctl_ros.core.stats import WindowStats
from geoctl_ros.core.step import BLIND_BOUND_S, SUSTAINED_BLIND_BOUND_S, ControlTick

NEAR_CONE_DEG = 2.0           # a cone margin below this is reported (WARN)
ARM_RATE_DISAGREE = 0.3      # rad/s (+ half the poses' rate): gyro against poses, at arming
NON_FINITE = failsafe('non-finite control output')


def step_period(since, period):
    """The dt of a step started by a sample (``step_on``): the time since the last step, within
    half to twice the control period. A burst of samples must not make a step of almost no time:
    the mixer's lag compensation would then command the extreme thrust, and the motors would hold
    it for the whole wait until the next sample.
    """
    return min(max(since, 0.5 * period), 2.0 * period)


@dataclass(frozen=True)
class LoopSettings:
    """The loop's and the node's settings, typed, built once from the parameters at configuration
    (``geoctl_ros.params.controller_setup``); nothing on the hot path reads the parameter dict.
    """

    rate_hz: float                 # the control timer
    step_on: str                   # 'timer', 'pose' or 'imu': what starts a control step
    pose_timeout: float            # s: a pose older than this is stale
    pose_ride_through: float       # s: how long a stale pose is ridden through (0: not at all)
    imu_timeout: float
    imu_ride_through: float
    pose_rate_window: float        # s: the poses a rate is differenced from during an imu gap
    max_angular_velocity: float    # rad/s: an imu sample faster than this is refused
    measurement_delay: float       # s: the inputs' latency when their stamps do not give it
    age_from_stamps: bool          # the inputs' ages from their capture stamps (synced clocks)
    allow_default_configuration: bool   # may arm without a parameter file (the opt-in)
    frame_id: str                  # the body frame of the published vectors
    world_frame_id: str


@dataclass
class Tick:
    """One control tick's results: everything the node publishes and logs."""

    control: object          # ControlOutput, or None before the first pose and rate
    motors: object           # MotorOutput (zero commands unless armed)
    armed: bool
    stamp: object            # stamp of the pose the step used, as offer_pose was given it
                             # (the node's header stamp, for exact-time matching; or None)
    pose_receipt: float      # when that pose was received, on the loop's clock (or None)
    state: str               # the supervisor's state: 'armed', or why not
    failed: bool             # disarmed by a failsafe
    sources: tuple           # (attitude source, rate source): POSE/GYRO, or a gap's stand-ins
    setpoint: np.ndarray     # R_d being flown (the same object until a new one is adopted)
    bridging: bool = False   # a gap is being ridden through (see geoctl_ros.core.gaps)


class ControlLoop:
    """State and decisions of the controller node."""

    def __init__(self, setup, unconfigured=None):
        """unconfigured: None, or why the node has no configuration anyone gave (it then
        refuses every arm request with that reason).
        """
        self.setup = setup
        self.unconfigured = unconfigured
        self.controller = AttitudeController(setup.config)
        self.controller.set_setpoint(setup.setpoint)
        s = setup.loop
        self.pose = Stream('pose', s.pose_timeout, s.pose_ride_through, s.measurement_delay)
        self.rate = Stream('angular velocity', s.imu_timeout, s.imu_ride_through,
                           s.measurement_delay)
        self.supervisor = Supervisor([self.pose, self.rate])
        self.bridge = GapBridge(s.pose_rate_window)
        self.R = None                   # last accepted measurements
        self.Omega = None
        self.setpoint_note = None       # last set-point refusal, for diagnostics
        self._pose_stamp = None         # the last accepted pose's stamp, as given
        self.last_tick = None
        # (the inputs' ages, measurement_delay included, are the streams': see tick)
        self.step = ControlTick(self.controller, setup.mixer, 0.0)
        self._schedule_index = -1
        # per diagnostics window: input ages at the ticks, armed ticks saturated / bridging
        self.pose_age = WindowStats()
        self.rate_age = WindowStats()
        self._window = {'ticks': 0, 'saturated': 0, 'bridging': 0, 'blind_ms': 0,
                        'armed_ticks': 0, 'steady_blind_ms': 0, 'gain_pct': 100}
        # the sensor inside a cone while armed, latched until the next arming: entries counted,
        # the deepest (cone name, depth deg)
        self.cone_entries = 0
        self.entry = None
        self._inside = False
        self.esc = None                 # the ESC node's last EscStatus (None: no ESC node)
        self.gaps = {'pose': [0, 0.0], 'angular velocity': [0, 0.0]}   # count, longest (s)

    # --- inputs ------------------------------------------------------------------------------
    def offer_pose(self, q, stamp, receipt, stamp_as_given=None, delay=None):
        """A motion-capture attitude (x, y, z, w) of stamp (s) received at receipt (s, the loop's
        clock); None if accepted, else why it was refused. stamp_as_given: the stamp in the
        caller's own form, handed back on the ticks that use this pose (default: stamp). delay:
        the stamp's age at receipt against this computer's clock (s; None: not known, the
        stream's ``measurement_delay`` is assumed; see ``core.safety.Stream``).
        """
        previous = self.pose.last_receipt
        problem = self.pose.offer(stamp, receipt, quaternion_problem(q), self._delay(delay))
        if problem is None:
            self._pose_stamp = stamp if stamp_as_given is None else stamp_as_given
            self._end_gap(self.pose, previous, receipt)
            self.R = so3.quat_to_rot(q)
            self.bridge.pose(self.R, stamp, receipt)
        return problem

    def offer_angular_velocity(self, w, stamp, receipt, delay=None):
        """A body angular velocity (rad/s); None if accepted, else why it was refused (delay: as
        offer_pose's).
        """
        previous = self.rate.last_receipt
        problem = self.rate.offer(
            stamp, receipt, angular_velocity_problem(w, self.setup.loop.max_angular_velocity),
            self._delay(delay))
        if problem is None:
            self._end_gap(self.rate, previous, receipt)
            self.Omega = np.array(w, dtype=float)
            self.bridge.gyro(self.Omega)
        return problem

    def offer_esc_health(self, command_max, escs, receipt):
        """The ESC node's report: its motor.command_max and each ESC's health (EscHealth values,
        in rotor order); None if taken, else why not.
        """
        if len(escs) != self.rotor_count or any(e not in EscHealth._value2member_map_
                                                 for e in escs):
            return 'expected %d ESC health codes of 0-3, got %r' % (self.rotor_count,
                                                                     list(escs)[:12])
        self.esc = EscStatus(int(command_max), tuple(EscHealth(e) for e in escs), receipt)
        return None

    def _esc_problem(self, now):
        return esc_problem(self.esc, now, self.setup.mixer.curve.command_max)

    def _delay(self, delay):
        """The delay a sample's stamp gives, if this loop takes ages from stamps."""
        return delay if self.setup.loop.age_from_stamps else None

    def _end_gap(self, stream, previous, receipt):
        """Count a gap (a stale spell) of stream that the sample received at receipt ends."""
        if previous is not None:
            age = receipt - previous
            if age >= stream.timeout:
                g = self.gaps[stream.name]
                g[0] += 1
                g[1] = max(g[1], age)

    def request_setpoint(self, q):
        """A new desired attitude; None if adopted, else why it was refused (old one stays)."""
        problem = quaternion_problem(q)
        if problem is None:
            try:
                self.controller.set_setpoint(so3.quat_to_rot(q))
            except SetpointRejected as e:
                problem = str(e)
        self.setpoint_note = None if problem is None else 'setpoint rejected: ' + problem
        return problem

    # --- commands ----------------------------------------------------------------------------
    def arm_problems(self, now, extra_problem=None):
        """Every reason not to arm now (sentences; empty: it may), as a preflight check names
        them: no configuration given, extra_problem (the caller's, e.g. another publisher of the
        motor commands), each stale input, and the measured sensor inside a cone or within its
        guard (the barrier's widening cone_guard_deg plus its floor band barrier_floor_deg).
        """
        problems = [p for p in (self.unconfigured, extra_problem, self._esc_problem(now)) if p]
        problems += [p for p in (s.staleness(now) for s in self.supervisor.streams) if p]
        if self.Omega is not None:
            w_poses = self.bridge.pose_rate()
            # (judged only where the poses resolve the rate: at most 1 rad turned per window)
            if w_poses is not None and self.bridge.rate_window * max(
                    np.linalg.norm(self.Omega), np.linalg.norm(w_poses)) < 1.0:
                gap = float(np.linalg.norm(self.Omega - w_poses))
                # (the poses' rate is a mean over the window: it lags a turning vehicle)
                if gap > ARM_RATE_DISAGREE + 0.5 * float(np.linalg.norm(w_poses)):
                    problems.append('the gyro and the poses disagree by %.2f rad/s (the imu '
                                    'frame or axes wrong?)' % gap)
        setpoint = self.controller.setpoint_problem(self.controller.R_d)
        if setpoint:
            problems.append('set point: ' + setpoint)
        cones = self.setup.config.cones
        if self.R is not None and len(cones):
            guard = math.degrees(cones.guard + cones.floor)
            margins = cones.margins_deg(self.R)
            for name, margin in zip(cones.names, margins):
                if margin <= 0.0:
                    problems.append('sensor inside cone %r (%.2f deg in)' % (name, -margin))
                elif margin < guard:
                    problems.append('sensor within the guard of cone %r (margin %.2f deg, '
                                    'guard %.2f deg)' % (name, margin, guard))
        return problems

    def arm(self, now, extra_problem=None):
        """Arm unless arm_problems names a reason; the refusal names every one."""
        problems = self.arm_problems(now, extra_problem)
        was_armed = self.supervisor.armed
        result = self.supervisor.arm(now, '; '.join(problems) or None)
        if result.ok:
            self._schedule_index = -1
            if not was_armed:
                self.cone_entries, self.entry, self._inside = 0, None, False
                self.step.history.clear()
                self.step.predict.reset()
        return result

    def disarm(self, reason='disarm requested', failed=False):
        """Disarm; failed: by a failsafe (reason from core.diagnostics.failsafe)."""
        return self.supervisor.disarm(reason, failed)

    def reset_adaptation(self):
        self.controller.reset_adaptation()

    def reconfigure(self, setup, setpoint_changed=False, schedule_changed=False):
        """Adopt a new setup (validated by params.controller_setup); None, or why not.

        The set point parameter is applied only when it changed, so that a gain change does not
        undo a set point that came in on the topic.
        """
        try:
            self.controller.reconfigure(setup.config)
        except SetpointRejected as e:
            return str(e)
        setup.mixer.adopt_state(self.setup.mixer)
        self.setup = setup
        self.step.reconfigure(setup.mixer, 0.0)
        s = setup.loop
        self.pose.fallback_delay = self.rate.fallback_delay = s.measurement_delay
        self.pose.timeout, self.pose.ride_through = s.pose_timeout, s.pose_ride_through
        self.rate.timeout, self.rate.ride_through = s.imu_timeout, s.imu_ride_through
        self.bridge.rate_window = s.pose_rate_window
        if setpoint_changed:
            self.controller.set_setpoint(setup.setpoint)
        if schedule_changed:
            self._schedule_index = -1
        if s.allow_default_configuration:      # the opt-in, given at run time
            self.unconfigured = None
        return None

    # --- the control tick --------------------------------------------------------------------
    def tick(self, now, dt):
        """One control step at time now (the node's clock); dt is the control period (the time
        the step's command is expected to be held).
        """
        armed = self.supervisor.check(now)
        if armed and self.esc is not None:          # the documented action: fail safe
            problem = self._esc_problem(now)
            if problem:
                self.disarm(failsafe(problem), failed=True)
                armed = False
        schedule = self.setup.schedule
        if armed and len(schedule):
            i = schedule.index_at(now - self.supervisor.armed_since)
            if i != self._schedule_index and i >= 0:
                self.controller.set_setpoint(schedule.rotations[i])   # checked at configuration
                self._schedule_index = i
        state = self.bridge.update(now, self.pose.fresh(now), self.rate.fresh(now))
        if state is None:
            out, motors = self.step.idle(dt, now)
            tick = self._result(None, motors, armed, False)
        else:
            bridging = self.bridge.bridging
            R, Omega = state
            # the measurements' ages: a bridged state is already propagated (not predicted
            # again), but the loop is as blind as its last samples are old (the barrier's
            # blind widening and the bound's watch count it); a stream that never came counts
            # as fresh. The estimate learns only from measurements.
            ages = tuple(0.0 if s.last_receipt is None else s.capture_age(now)
                         for s in (self.pose, self.rate))
            out, motors = self.step(R, Omega, dt, now, ages, armed=armed,
                                    adapt=armed and not bridging, predict=not bridging)
            if out is None:
                self.disarm(NON_FINITE, failed=True)
                armed = False
            elif armed and out.violated:
                self._note_entry(out)
            else:
                self._inside = False
            tick = self._result(out, motors, armed, bridging)
        if self.pose.last_receipt is not None:
            self.pose_age.add(self.pose.age(now))
        if self.rate.last_receipt is not None:
            self.rate_age.add(self.rate.age(now))
        w = self._window
        w['ticks'] += 1
        w['saturated'] += bool(armed and tick.motors.allocation.saturated)
        w['bridging'] += bool(armed and tick.bridging)
        if armed:
            blind_ms = int(1e3 * self.step.blind)
            w['blind_ms'] = max(w['blind_ms'], blind_ms)
            w['steady_blind_ms'] = (min(w['steady_blind_ms'], blind_ms) if w['armed_ticks']
                                    else blind_ms)
            gain_pct = int(round(100.0 * float(self.step.degraded.scale_now)))
            w['gain_pct'] = min(w['gain_pct'], gain_pct) if w['armed_ticks'] else gain_pct
            w['armed_ticks'] += 1
        self.last_tick = tick
        return tick

    def _note_entry(self, out):
        """The sensor is inside a cone while armed: count the entry, keep the deepest (latched
        until the next arming).
        """
        margins = out.margins_deg
        i = int(np.argmin(margins))
        depth = -float(margins[i])
        if not self._inside:
            self.cone_entries += 1
            self._inside = True
        if self.entry is None or depth > self.entry[1]:
            self.entry = (self.setup.config.cones.names[i], depth)

    def _result(self, out, motors, armed, bridging):
        b = self.bridge
        return Tick(out, motors, armed, self._pose_stamp, self.pose.last_receipt,
                    self.supervisor.reason, self.supervisor.failed,
                    (b.attitude_source, b.rate_source),
                    self.controller.R_d, bridging)

    @property
    def settings(self):
        """The LoopSettings in effect."""
        return self.setup.loop

    @property
    def rotor_count(self):
        return self.setup.mixer.allocator.count

    def reconfiguration_problem(self, setup):
        """Why setup (validated on its own) cannot replace the running one, or None: the set
        point now being flown (it may have come in on the topic) against the new cones.
        """
        problem = self.controller.setpoint_problem(self.controller.R_d, setup.config.cones)
        return None if problem is None else 'the current ' + problem

    # --- what the diagnostics say ------------------------------------------------------------
    def gap_notes(self, now):
        """Sentences for the gaps being ridden through (empty in normal flight)."""
        notes = []
        b = self.bridge
        if b.attitude_source is not POSE:
            notes.append('pose gap: attitude %s (pose %.3f s old, failsafe at %.3f s)'
                         % (b.attitude_source.value, self.pose.age(now), self.pose.limit))
        if b.rate_source is not GYRO:
            notes.append('angular velocity gap: rate %s (imu %.3f s old, failsafe at %.3f s)'
                         % (b.rate_source.value, self.rate.age(now), self.rate.limit))
        return notes

    def status(self, now, other_commanders=None):
        """The diagnostics: level, message and figures. other_commanders is the node's sentence
        when another node publishes the motor commands (an error while armed).
        """
        errors, warnings = [], []
        sup = self.supervisor
        if not sup.armed:
            (errors if sup.failed else warnings).append(sup.reason)
            if self.unconfigured:
                warnings.append(self.unconfigured)
            stale = sup.input_problem(now)
            if stale:
                warnings.append(stale)
            escs = self._esc_problem(now)
            if escs:
                warnings.append(escs)
        else:
            lost = sup.input_loss(now)
            if lost:
                errors.append(lost)
            warnings += self.gap_notes(now)
        for s in (self.pose, self.rate):
            reasons = s.take_refusals()
            if reasons:
                warnings.append('%s refused: %s (%d so far)' % (s.name, ' | '.join(reasons),
                                                                 s.refused))
        tick = self.last_tick
        out = tick.control if tick else None
        if sup.armed and self.entry is not None:
            errors.append('sensor entered cone %r, %.2f deg deep (%d entr%s since arming)'
                          % (self.entry[0], self.entry[1], self.cone_entries,
                             'y' if self.cone_entries == 1 else 'ies'))
        if out is not None and len(out.margins_deg):
            i = int(np.argmin(out.margins_deg))
            name = self.setup.config.cones.names[i]
            cones = self.setup.config.cones
            near = max(NEAR_CONE_DEG, math.degrees(cones.guard + cones.floor))
            if out.violated:
                errors.append('sensor inside cone %r (margin %.2f deg)'
                              % (name, out.margins_deg[i]))
            elif out.margins_deg[i] < near:
                warnings.append('near cone %r (margin %.2f deg)' % (name, out.margins_deg[i]))
        w = self._window
        if sup.armed and w['steady_blind_ms'] > 1e3 * SUSTAINED_BLIND_BOUND_S:
            warnings.append('loop blind at least %d ms at every tick of the window (a sustained '
                            'latency): beyond the %.0f ms the cone is kept for'
                            % (w['steady_blind_ms'], 1e3 * SUSTAINED_BLIND_BOUND_S))
        elif sup.armed and w['blind_ms'] > 1e3 * BLIND_BOUND_S:
            warnings.append('loop blind up to %d ms (inputs up to %.0f ms old by receipt, plus '
                            'their delay to receipt and late steps): beyond the %.0f ms the cone '
                            'is kept for' % (w['blind_ms'], 1e3 * max(
                                np.max(self.pose_age.samples(), initial=0.0),
                                np.max(self.rate_age.samples(), initial=0.0)),
                                1e3 * BLIND_BOUND_S))
        if sup.armed and w['armed_ticks'] and w['gain_pct'] < 100:
            warnings.append('degraded: feedback gains down to %d %% of their bandwidth while '
                            'blind past the bound' % w['gain_pct'])
        if w['saturated']:
            warnings.append('allocation saturated in %d of %d ticks'
                            % (w['saturated'], w['ticks']))
        if self.setpoint_note:
            warnings.append(self.setpoint_note)
        if other_commanders:
            (errors if sup.armed else warnings).append(other_commanders)
        level = ERROR if errors else WARN if warnings else OK
        margin = None
        if out is not None and len(out.margins_deg):
            margin = float(np.min(out.margins_deg))
        figures = Figures(
            armed=sup.armed, state=sup.reason,
            pose_age=self.pose.age(now), imu_age=self.rate.age(now),
            pose_counts=Counts(self.pose.accepted, self.pose.refused),
            imu_counts=Counts(self.rate.accepted, self.rate.refused),
            pose_age_at_tick=self.pose_age.window(), imu_age_at_tick=self.rate_age.window(),
            pose_gaps=Gaps(*self.gaps['pose']), imu_gaps=Gaps(*self.gaps['angular velocity']),
            ticks_bridging=w['bridging'], ticks=w['ticks'], cone_entries=self.cone_entries,
            psi=None if out is None else float(out.psi), min_cone_margin_deg=margin,
            motor_commands=None if out is None else tuple(int(c) for c in tick.motors.commands))
        message = '; '.join(errors + warnings) or 'armed, all inputs fresh'
        return Status(level, message, figures)

    def end_window(self):
        """Start a new diagnostics window (the node calls this on its fixed period)."""
        self.pose_age.reset()
        self.rate_age.reset()
        self._window = dict.fromkeys(self._window, 0)
