"""The controller node's logic without ROS: checked inputs, arming, set points, step, mixing.

The node turns messages into calls of this class and its results into messages; every decision
(refuse a sample, refuse to arm, ride through a gap, fail safe, adopt a set point, freeze
adaptation, the diagnostics level and its reasons) is made here, so it is tested without rclpy.
"""

import math
from typing import Dict, Generic, List, Optional, Sequence, Tuple, Union, cast

from geoctl_ros.core.actuation.motors import MotorOutput
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.quaternions import quaternion_problem
from geoctl_ros.core.geometry.so3 import FloatArray, Vector
from geoctl_ros.core.law.control import AttitudeController, SetpointRejected
from geoctl_ros.core.law.hold import hold_attitude
from geoctl_ros.core.law.step_types import ControlOutput
from geoctl_ros.core.sensors.consistency import SensorAgreement
from geoctl_ros.core.supervisor import loop_status, preflight
from geoctl_ros.core.supervisor.control_tick import ControlTick
from geoctl_ros.core.supervisor.gaps import GapBridge
from geoctl_ros.core.supervisor.loop_types import LoopSettings, LoopTick, Setup, StampT
from geoctl_ros.core.supervisor.safety import (
    ArmResult,
    EscHealth,
    EscStatus,
    Stream,
    Supervisor,
    angular_velocity_problem,
    esc_problem,
    specific_force_problem,
)
from geoctl_ros.core.telemetry.diagnostics import Status, failsafe
from geoctl_ros.core.telemetry.stats import WindowStats

NON_FINITE = failsafe('non-finite control output')
SPOOL_MOVE_DEG = 2.0     # the attitude may move this far while the rotors spool up


def _unlearnt_bound(controller: AttitudeController) -> float:
    """The approach brake's a_u (rad/s^2), which the acceleration the model does not know is
    watched against; inf without the brake (no derivation to hold).
    """
    return math.inf if controller.brake is None else controller.brake.unmodelled


def spool_movement(R_armed: FloatArray, R: FloatArray) -> Optional[str]:
    """Why the spool-up must stop (the vehicle moved more than SPOOL_MOVE_DEG from where it was
    armed: it was neither held nor resting on its stops, and the brake's take-over did not
    reckon with the fall), or None.
    """
    moved = math.degrees(so3.angle(so3.matmul(so3.transpose(R_armed), R)))
    if moved <= SPOOL_MOVE_DEG:
        return None
    return ('the vehicle moved %.1f deg while the rotors spooled up (more than %.1f deg): hold '
            'it, or rest it on its stops, until the controller takes over' % (moved,
                                                                             SPOOL_MOVE_DEG))


class ControlLoop(Generic[StampT]):
    """State and decisions of the controller node (StampT: the type of the stamps its caller
    gives offer_pose in its own form, handed back on the ticks).
    """

    def __init__(self, setup: Setup, unconfigured: Optional[str] = None) -> None:
        """unconfigured: None, or why the node has no configuration anyone gave (it then
        refuses every arm request with that reason).
        """
        self.setup = setup
        self.unconfigured = unconfigured
        self.controller = AttitudeController(setup.config)
        self.controller.set_setpoint(setup.setpoint)
        s = setup.loop
        self.pose = Stream('pose', s.pose_timeout, s.pose_ride_through, s.measurement_delay,
                           s.age_from_stamps)
        self.rate = Stream('angular velocity', s.imu_timeout, s.imu_ride_through,
                           s.measurement_delay, s.age_from_stamps)
        self.supervisor = Supervisor([self.pose, self.rate])
        self.bridge = GapBridge(s.pose_rate_window)
        self.frames = setup.frames      # the inputs' conventions, applied as they come in
        self.agreement = SensorAgreement(setup.agreement, setup.frames)
        self.R: Optional[FloatArray] = None       # last accepted measurements
        self.Omega: Optional[FloatArray] = None
        self.setpoint_note: Optional[str] = None  # last set-point refusal, for diagnostics
        # the last accepted pose's stamp, as given
        self._pose_stamp: Union[float, StampT, None] = None
        self.last_tick: Optional[LoopTick[StampT]] = None
        # (the inputs' ages, measurement_delay included, are the streams': see tick)
        self.step = ControlTick(self.controller, setup.mixer)
        self._schedule_index = -1
        # per diagnostics window: input ages at the ticks, armed ticks saturated / bridging
        self.pose_age = WindowStats()
        self.rate_age = WindowStats()
        self.window = loop_status.Window()
        # the sensor inside a cone while armed, latched until the next arming: entries counted,
        # the deepest (cone name, depth deg)
        self.cone_entries = 0
        self.entry: Optional[Tuple[str, float]] = None
        self._inside = False
        self.esc: Optional[EscStatus] = None   # the ESC node's last report (None: no ESC node)
        # count, longest (s)
        self.gaps: Dict[str, List[float]] = {'pose': [0, 0.0], 'angular velocity': [0, 0.0]}
        # the acceleration the model did not know, against the approach brake's a_u
        self.unlearnt_bound = _unlearnt_bound(self.controller)
        self.unlearnt_over = 0          # rate samples past it since the take-over
        self._spool_from: Optional[FloatArray] = None   # the attitude at arming, while the
                                                        # rotors spool up

    # --- inputs ------------------------------------------------------------------------------
    def offer_pose(self, q: Vector, stamp: float, receipt: float,
                   stamp_as_given: Optional[StampT] = None,
                   delay: Optional[float] = None) -> Optional[str]:
        """A motion-capture attitude (x, y, z, w) of stamp (s) received at receipt (s, the loop's
        clock); None if accepted, else why it was refused. stamp_as_given: the stamp in the
        caller's own form, handed back on the ticks that use this pose (default: stamp). delay:
        the stamp's age at receipt against this computer's clock (s; None: not known, the
        stream's ``measurement_delay`` is assumed; see ``core.supervisor.safety.Stream``).
        """
        previous = self.pose.last_receipt
        problem = self.pose.offer(stamp, receipt, quaternion_problem(q), delay)
        if problem is None:
            self._pose_stamp = stamp if stamp_as_given is None else stamp_as_given
            self._end_gap(self.pose, previous, receipt)
            raw = so3.quat_to_rot(q)
            self.R = self.frames.attitude(raw)
            self.bridge.pose(self.R, stamp, receipt)
            self.agreement.pose(self.R, stamp, receipt, raw)
        return problem

    def offer_angular_velocity(self, w: Vector, stamp: float, receipt: float,
                               delay: Optional[float] = None,
                               specific_force: Optional[Vector] = None) -> Optional[str]:
        """An IMU sample: the gyro's angular velocity (rad/s) and, if the IMU gives it, the
        specific force (m/s^2), both in the IMU's own axes; None if accepted, else why it was
        refused (delay: as offer_pose's).
        """
        previous = self.rate.last_receipt
        problem = self.rate.offer(
            stamp, receipt, angular_velocity_problem(w, self.setup.loop.max_angular_velocity)
            or specific_force_problem(specific_force), delay)
        if problem is None:
            self._end_gap(self.rate, previous, receipt)
            self.Omega = self.frames.angular_velocity(w)
            self.bridge.gyro(self.Omega)
            self.agreement.imu(self.Omega, None if specific_force is None
                               else self.frames.imu_vector(specific_force), stamp, receipt)
        return problem

    def offer_esc_health(self, command_max: int, escs: Sequence[str],
                         receipt: float) -> Optional[str]:
        """The ESC node's report: its motor.command_max and each ESC's health (EscHealth names,
        in rotor order); None if taken, else why not.
        """
        if len(escs) != self.rotor_count or any(e not in EscHealth.__members__ for e in escs):
            return 'expected %d ESC healths (OK, IGNORED, LOST or FAULT), got %r' % (
                self.rotor_count, [e[:12] for e in escs[:12]])
        self.esc = EscStatus(int(command_max), tuple(EscHealth[e] for e in escs), receipt)
        return None

    def esc_report_problem(self, now: float) -> Optional[str]:
        """Why the ESC node's report forbids flight now, or None (no ESC node: None)."""
        return esc_problem(self.esc, now, self.setup.mixer.curve.command_max)

    def _end_gap(self, stream: Stream, previous: Optional[float], receipt: float) -> None:
        """Count a gap (a stale spell) of stream that the sample received at receipt ends."""
        if previous is not None:
            age = receipt - previous
            if age >= stream.timeout:
                g = self.gaps[stream.name]
                g[0] += 1
                g[1] = max(g[1], age)

    def request_setpoint(self, q: Vector) -> Optional[str]:
        """A new desired attitude; None if adopted, else why it was refused (old one stays)."""
        problem = quaternion_problem(q)
        if problem is None:
            problem = self._adopt(so3.quat_to_rot(q))
        self.setpoint_note = None if problem is None else 'setpoint rejected: ' + problem
        return problem

    def hold(self) -> Optional[str]:
        """Adopt the attitude measured last as the set point, lifted off the joint's stops
        (``hold_attitude``; what an arming does with ``arming_setpoint`` hold); None if adopted,
        else why not (the old one stays).
        """
        R_hold = self.hold_attitude()
        if R_hold is None:
            return 'no pose received yet'
        return self._adopt(R_hold)

    def hold_attitude(self) -> Optional[FloatArray]:
        """The attitude a hold flies now (``core.law.hold.hold_attitude`` of the attitude
        measured last), or None before the first pose.
        """
        if self.R is None:
            return None
        config = self.controller.config
        return hold_attitude(self.R, config.gravity, config.tilt_max)

    def _adopt(self, R_d: FloatArray) -> Optional[str]:
        """Fly R_d from now on, if the controller takes it; else why not."""
        try:
            self.controller.set_setpoint(R_d)
        except SetpointRejected as e:
            return str(e)
        return None

    # --- commands ----------------------------------------------------------------------------
    def arm_problems(self, now: float, extra_problem: Optional[str] = None) -> List[str]:
        """Every reason not to arm now (``core.supervisor.preflight.arm_problems``; empty: it
        may).
        """
        return preflight.arm_problems(self, now, extra_problem)

    def arm(self, now: float, extra_problem: Optional[str] = None) -> ArmResult:
        """Arm unless arm_problems names a reason; the refusal names every one. An arming
        (from disarmed) with ``arming_setpoint`` hold flies the attitude measured now, lifted
        off the joint's stops (``hold_attitude``).
        """
        problems = self.arm_problems(now, extra_problem)
        was_armed = self.supervisor.armed
        result = self.supervisor.arm(now, '; '.join(problems) or None)
        if result.ok:
            self._schedule_index = -1
            self.agreement.reset_flight()
            if not was_armed:
                self.cone_entries, self.entry, self._inside = 0, None, False
                self.unlearnt_over = 0
                self._spool_from = self.R       # (the take-over starts the flight's model)
                R_hold = self.hold_attitude()   # (arm_problems has checked it as a set point;
                if self.holds_at_arming and R_hold is not None:     # an arming needs a pose)
                    self._adopt(R_hold)
        return result

    @property
    def holds_at_arming(self) -> bool:
        """An arming holds the attitude measured then (``arming_setpoint`` hold), rather than
        flying the set point and the schedule.
        """
        return self.setup.loop.arming_setpoint == 'hold'

    def disarm(self, reason: str = 'disarm requested', failed: bool = False) -> ArmResult:
        """Disarm; failed: by a failsafe (reason from core.telemetry.diagnostics.failsafe)."""
        return self.supervisor.disarm(reason, failed)

    def reset_adaptation(self) -> None:
        self.controller.reset_adaptation()

    def reconfigure(self, setup: Setup, setpoint_changed: bool = False,
                    schedule_changed: bool = False) -> Optional[str]:
        """Adopt a new setup (validated by params.controller_setup); None, or why not.

        The set point parameter is applied only when it changed, so that a gain change does not
        undo a set point that came in on the topic.
        """
        try:
            self.controller.reconfigure(setup.config)
        except SetpointRejected as e:
            return str(e)
        self.setup = setup
        self.unlearnt_bound = _unlearnt_bound(self.controller)
        self.agreement.configure(setup.agreement)
        self.step.reconfigure(setup.mixer)
        s = setup.loop
        self.pose.fallback_delay = self.rate.fallback_delay = s.measurement_delay
        self.pose.age_from_stamps = self.rate.age_from_stamps = s.age_from_stamps
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
    def tick(self, now: float, dt: float, settle: bool = True) -> LoopTick[StampT]:
        """One control step at time now (the node's clock); dt is the control period (the time
        the step's command is expected to be held). settle: False leaves the step's bookkeeping
        for the next tick and the sensor checks' closed windows (``settle``) to the caller, once
        the command is out.
        """
        armed = self.supervisor.check(now)
        if armed and self.esc is not None:          # the documented action: fail safe
            problem = self.esc_report_problem(now)
            if problem:
                self.disarm(failsafe(problem), failed=True)
                armed = False
        if armed and self.agreement.flight_note and self.setup.agreement.enabled:
            self.disarm(failsafe(self.agreement.flight_note), failed=True)
            armed = False
        schedule = self.setup.schedule
        if armed and len(schedule) and not self.holds_at_arming:
            i = schedule.due(now - cast(float, self.supervisor.armed_since), self._schedule_index)
            if i >= 0:
                self.controller.set_setpoint(schedule.rotations[i])   # checked at configuration
                self._schedule_index = i
        state = self.bridge.update(now, self.pose.fresh(now), self.rate.fresh(now))
        if state is None:
            command = self.step.idle(dt, now)
            tick = self._result(None, command.motors, armed, False, None)
        else:
            bridging = self.bridge.bridging
            R, Omega = state
            # the measurements' ages: a bridged state is already propagated (not predicted
            # again), but the loop is as blind as its last samples are old (the barrier's
            # blind widening and the bound's watch count it); a stream that never came counts
            # as fresh. The estimate learns only from measurements.
            ages = (0.0 if self.pose.last_receipt is None else self.pose.capture_age(now),
                    0.0 if self.rate.last_receipt is None else self.rate.capture_age(now))
            command = self.step(R, Omega, dt, now, ages, armed=armed,
                                adapt=armed and not bridging, predict=not bridging,
                                settle=settle)
            out, motors, spooling, took_over = command[:4]
            if took_over:
                self.unlearnt_over = 0
                self._spool_from = None
            elif spooling and self._spool_from is not None:
                moved = spool_movement(self._spool_from, R)
                if moved is not None:
                    self.disarm(failsafe(moved), failed=True)
                    armed = False
            if self.window.note_unlearnt(command.residual, self.unlearnt_bound):
                self.unlearnt_over += 1
            if out is None:
                self.disarm(NON_FINITE, failed=True)
                armed = False
            elif armed and out.violated:
                self._note_entry(out)
            else:
                self._inside = False
            tick = self._result(out, motors, armed, bridging, state)
        if self.pose.last_receipt is not None:
            self.pose_age.add(self.pose.age(now))
        if self.rate.last_receipt is not None:
            self.rate_age.add(self.rate.age(now))
        self.window.note(armed, tick.motors.allocation.saturated, tick.bridging, command.blind,
                         command.gain_scale)
        self.last_tick = tick
        if settle:
            self.agreement.settle()
        return tick

    def settle(self) -> None:
        """The last tick's bookkeeping for the next one (``ControlTick.settle``) and the sensor
        checks' windows the last poses closed (``SensorAgreement.settle``): the node's, once the
        motor command is published.
        """
        self.step.settle()
        self.agreement.settle()

    def _note_entry(self, out: ControlOutput) -> None:
        """The sensor is inside a cone while armed: count the entry, keep the deepest (latched
        until the next arming).
        """
        name, margin = self.setup.config.cones.closest(out.margins_deg)
        depth = -margin
        if not self._inside:
            self.cone_entries += 1
            self._inside = True
        if self.entry is None or depth > self.entry[1]:
            self.entry = (name, depth)

    def _result(self, out: Optional[ControlOutput], motors: MotorOutput, armed: bool,
                bridging: bool,
                state: Optional[Tuple[FloatArray, FloatArray]]) -> LoopTick[StampT]:
        b = self.bridge
        return LoopTick(out, motors, armed, self._pose_stamp, self.pose.last_receipt,
                    self.supervisor.reason, self.supervisor.failed,
                    (b.attitude_source, b.rate_source),
                    self.controller.R_d, bridging, state)

    @property
    def settings(self) -> LoopSettings:
        """The LoopSettings in effect."""
        return self.setup.loop

    @property
    def rotor_count(self) -> int:
        return self.setup.mixer.allocator.count

    def reconfiguration_problem(self, setup: Setup) -> Optional[str]:
        """Why setup (validated on its own) cannot replace the running one, or None: the set
        point now being flown (it may have come in on the topic) against the new cones.
        """
        problem = self.controller.setpoint_problem(self.controller.R_d, setup.config.cones)
        return None if problem is None else 'the current ' + problem

    # --- what the diagnostics say ------------------------------------------------------------
    def status(self, now: float, other_commanders: Optional[str] = None) -> Status:
        """The diagnostics: level, message and figures (``core.supervisor.loop_status.status``).
        other_commanders is the node's sentence when another node publishes the motor commands
        (an error while armed).
        """
        return loop_status.status(self, now, other_commanders)

    def gap_notes(self, now: float) -> List[str]:
        """Sentences for the gaps being ridden through
        (``core.supervisor.loop_status.gap_notes``).
        """
        return loop_status.gap_notes(self, now)

    def end_window(self) -> None:
        """Start a new diagnostics window (the node calls this on its fixed period)."""
        self.pose_age.reset()
        self.rate_age.reset()
        self.pose.end_window()
        self.rate.end_window()
        self.window = loop_status.Window()
