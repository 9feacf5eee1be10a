"""The controller node: ``ros2 run geoctl_ros controller --ros-args --params-file FILE``.

A thin shell over ``geoctl_ros.core.supervisor.loop.ControlLoop``: subscriptions feed it checked
measurements and set points, a timer at ``rate_hz`` runs one control step and publishes the
results, services arm, disarm and reset the estimate, and parameter changes are validated by the
shared schema before they touch the running controller. Topics, services and parameters:
docs/interface.md and docs/parameters.md.
"""
from dataclasses import replace
import sys
import time
from typing import NamedTuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, QuaternionStamped
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState
from std_srvs.srv import SetBool, Trigger

from geoctl_ros.core.actuation.esc_wire import ArmedState
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.gains import gain_condition
from geoctl_ros.core.supervisor.loop import ControlLoop
from geoctl_ros.core.supervisor.loop_types import step_period
from geoctl_ros.core.supervisor.safety import new_session
from geoctl_ros.core.telemetry.diagnostics import NAME as DIAGNOSTICS_NAME
from geoctl_ros.core.telemetry.diagnostics import failsafe
from geoctl_ros.core.telemetry.scheduling import scheduling
from geoctl_ros.core.telemetry.stats import WindowStats
from geoctl_ros.nodes import qos, ros_params
from geoctl_ros.nodes.controller_topics import Telemetry
from geoctl_ros.nodes.conversions import (
    armed_state_msg,
    esc_health_of,
    motor_commands_msg,
    set_stamp,
    stamp_seconds,
    status_msg,
)
from geoctl_ros.nodes.runtime import spin
from geoctl_ros.params import (
    CHANGE_WHILE_ARMED,
    CONTROLLER,
    ConfigError,
    change_problem,
    configuration_given,
    controller_setup,
    resolve,
    setpoint_change,
)
from geoctl_ros.records.fields import quaternion, vector

DIAGNOSTICS_PERIOD = 0.5      # s: the fixed statistics window
STATUS_NAME = DIAGNOSTICS_NAME


class SetpointChange(NamedTuple):
    """A change of the ``setpoint`` parameter alone (a command's, a ground station's), checked:
    the quaternion (x, y, z, w) to fly.
    """

    q: np.ndarray


def build(values):
    """The controller setup of a node's parameters: cones defined but not yet in cones.names are
    allowed (they are being added, one parameter at a time, or came from a dump).
    """
    return controller_setup(resolve(CONTROLLER, values, staged_cones=True))


class ControllerNode(Node):
    """The controller node (module docstring)."""

    def __init__(self, **kwargs):
        super().__init__('controller', allow_undeclared_parameters=True, **kwargs)
        errors = ros_params.declare(self, CONTROLLER)
        if errors:
            raise ConfigError(errors)
        setup = build(ros_params.values(self, CONTROLLER))
        self.loop = ControlLoop(setup, self._unconfigured(setup))
        if self.loop.unconfigured:
            self.get_logger().warning(self.loop.unconfigured)
        unnamed = ros_params.unnamed_cones(self)
        if unnamed:
            self.get_logger().warning('cone(s) %s are defined but not in cones.names: not in '
                                      'effect until named' % ', '.join(unnamed))
        check = gain_condition(setup.config)
        if not check.ok:
            self.get_logger().warning(check.message())
        if not (setup.frames.pose_identity and setup.frames.imu_identity
                and setup.frames.bias_zero):
            self.get_logger().info('inputs: ' + setup.frames.describe())
        for w in setup.mixer.allocator.health.warnings:
            self.get_logger().warning('airframe: ' + w)
        ros_params.watch(self, CONTROLLER, self._validate, self._apply)

        sim_time = self._sim_time = self.get_parameter('use_sim_time').value
        self.clock_ = self.get_clock() if sim_time else Clock(clock_type=ClockType.STEADY_TIME)
        self.period = 1.0 / setup.loop.rate_hz
        self.frame_id = setup.loop.frame_id
        self.world_frame_id = setup.loop.world_frame_id

        self.create_subscription(PoseStamped, 'pose', self._on_pose, qos.SENSOR)
        self.create_subscription(Imu, 'imu', self._on_imu, qos.SENSOR)
        self.create_subscription(QuaternionStamped, 'attitude_setpoint', self._on_setpoint,
                                 qos.EVENT)
        self.create_subscription(DiagnosticStatus, 'esc_health', self._on_esc_health,
                                 qos.COMMAND)
        self.pub_motors = self.create_publisher(JointState, 'motor_commands', qos.COMMAND)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', qos.EVENT)
        # the armed state and session the ESC node follows (core.actuation.esc_wire.ArmedState)
        self.session = new_session()
        self.pub_armed = self.create_publisher(DiagnosticStatus, '~/armed', qos.LATCHED)
        self._armed_sent = None
        self.create_service(SetBool, '~/arm', self._on_arm)
        self.create_service(Trigger, '~/reset_adaptation', self._on_reset)
        self.create_service(Trigger, '~/hold', self._on_hold)

        self.motors_msg = motor_commands_msg(self.session, self.loop.rotor_count)
        self.telemetry = Telemetry(self, self.frame_id, self.world_frame_id)
        self._last_tick = None
        self._period_stats = WindowStats()
        self._compute_stats = WindowStats()
        self._latency_stats = WindowStats()
        self._last_state = None
        self.scheduling = scheduling()      # (the realtime prefix's class: read once)
        self.create_timer(self.period, self._on_timer, clock=self.clock_)
        self.create_timer(DIAGNOSTICS_PERIOD, self._end_window, clock=self.clock_)
        self.get_logger().info('controller ready at %g Hz (%s clock), law %s, %d cone(s), '
                               'disarmed' % (setup.loop.rate_hz, 'ROS' if sim_time else 'steady',
                                             setup.config.law, len(setup.config.cones)))

    def _now(self):
        """Seconds on the node's clock: the ROS clock with use_sim_time, else the steady clock,
        read as time.monotonic() (the same CLOCK_MONOTONIC that rclpy's steady clock reads, at a
        tenth of the cost: it is read on every sample and tick).
        """
        if self._sim_time:
            return self.clock_.now().nanoseconds * 1e-9
        return time.monotonic()

    def on_shutdown(self):
        """Leave the motors at zero when the node stops."""
        self._publish_zero()

    def _publish_zero(self):
        msg = motor_commands_msg(self.session, self.loop.rotor_count)
        msg.effort = [0.0] * self.loop.rotor_count
        set_stamp(msg.header.stamp, self._ros_seconds())
        self.pub_motors.publish(msg)
        self._publish_armed(False)

    def _publish_armed(self, armed):
        """The typed armed state, when it changes (and with every diagnostics message)."""
        if armed != self._armed_sent:
            self.pub_armed.publish(armed_state_msg(ArmedState(armed, self.session)))
            self._armed_sent = armed

    # --- configuration: built from its parameters; run-time changes validated by the schema ---
    def _unconfigured(self, setup):
        """Why this node flies nothing it was given, or None: no parameter of its own reached it
        (no file, a launch file's missing params_file, which only warns and passes none, or a
        file whose sections name another node or namespace: its ``/**`` values alone do not
        configure a controller).
        """
        if (configuration_given(CONTROLLER, ros_params.file_overrides(self))
                or setup.loop.allow_default_configuration):
            return None
        return ('no configuration given for %s: no parameter file (or none addressed to this '
                'name and namespace), so every arm request is refused (give --params-file FILE '
                'with a section for it, or -p allow_default_configuration:=true to fly the '
                'built-in defaults deliberately)' % self.get_fully_qualified_name())

    def _validate(self, values, changed):
        """A run-time change: only gains and goals while armed (``CHANGE_WHILE_ARMED``), the
        whole configuration, and the set point now being flown (which may have come in on the
        topic) against the new cones. A change of the set point alone is checked as the
        controller takes a set point (``_setpoint_change``).
        """
        if self.loop.supervisor.armed:
            problem = change_problem(changed, CHANGE_WHILE_ARMED, 'while disarmed')
            if problem:
                raise ConfigError([('armed', problem)])
        q = setpoint_change(values, changed)
        if q is not None:
            return self._setpoint_change(q)
        setup = build(values)
        problem = self.loop.reconfiguration_problem(setup)
        if problem:
            raise ConfigError([('cones', problem)])
        return setup

    def _setpoint_change(self, q):
        """A new value q of ``setpoint`` alone (checked by the parameter's schema), checked by
        the controller as every set point is (``AttitudeController.setpoint_problem``: the
        cones' bands, ``unmodelled_moment_max``), without building the whole configuration again
        (tens of ms of the thread that runs the control steps): a SetpointChange, or ConfigError
        with the reason.
        """
        problem = self.loop.controller.setpoint_problem(so3.quat_to_rot(q))
        if problem:
            self.get_logger().warning('set point refused: ' + problem)
            raise ConfigError([('setpoint', problem)])
        return SetpointChange(q)

    def _apply(self, setup, changed):
        if isinstance(setup, SetpointChange):
            problem = self.loop.request_setpoint(setup.q)
            if problem:     # (checked just before, against the same controller: a defect)
                self.get_logger().error('set point not applied: ' + problem)
            else:
                self.get_logger().info('set point: flying %s (x, y, z, w)' % _shown(setup.q))
            return
        problem = self.loop.reconfigure(
            setup, setpoint_changed='setpoint' in changed,
            schedule_changed=any(n.startswith('setpoint_schedule.') for n in changed))
        if problem:       # validated before; only a set point that arrived since can do this
            self.get_logger().error('parameters not applied: ' + problem)
        else:
            self.get_logger().info('parameters applied: %s' % ', '.join(sorted(changed)))

    # --- inputs ------------------------------------------------------------------------------
    def _on_pose(self, msg):
        now = self._now()
        stamp = stamp_seconds(msg.header.stamp)
        problem = self.loop.offer_pose(quaternion(msg.pose.orientation), stamp, now,
                                       msg.header.stamp, self._stamp_delay(stamp))
        if problem:
            self.get_logger().warning('pose refused: ' + problem, throttle_duration_sec=1.0)
        elif self.loop.settings.step_on == 'pose':
            self._tick(now)

    def _stamp_delay(self, stamp):
        """How old a header stamp is by this computer's ROS clock: the capture-to-receipt
        delay, if the stamping clock is in sync.
        """
        return self._ros_seconds() - stamp

    def _ros_seconds(self):
        """The ROS clock (the system clock, or /clock with use_sim_time), in seconds: what
        stamps are on. (Without sim time it is the system clock, CLOCK_REALTIME: read directly,
        at a fraction of rclpy's cost, for every sample and command.)
        """
        if self._sim_time:
            return self.get_clock().now().nanoseconds * 1e-9
        return time.time()

    def _on_imu(self, msg):
        now = self._now()
        stamp = stamp_seconds(msg.header.stamp)
        # (a covariance of -1 says the message carries no such data: sensor_msgs/Imu)
        force = (None if msg.linear_acceleration_covariance[0] == -1.0
                 else vector(msg.linear_acceleration))
        problem = self.loop.offer_angular_velocity(vector(msg.angular_velocity), stamp, now,
                                                   self._stamp_delay(stamp), force)
        if problem:
            self.get_logger().warning('imu refused: ' + problem, throttle_duration_sec=1.0)
        elif self.loop.settings.step_on == 'imu':
            self._tick(now)

    def _on_esc_health(self, msg):
        report = esc_health_of(msg)
        problem = (report if isinstance(report, str)
                   else self.loop.offer_esc_health(report[0], report[1], self._now()))
        if problem:
            self.get_logger().warning('esc_health refused: ' + problem,
                                      throttle_duration_sec=1.0)

    def _on_setpoint(self, msg):
        problem = self.loop.request_setpoint(quaternion(msg.quaternion))
        if problem:
            self.get_logger().warning('setpoint rejected: ' + problem)
            self._publish_diagnostics()

    # --- services and parameters -------------------------------------------------------------
    def _other_commanders(self):
        """A sentence if another node publishes our motor_commands topic, else None."""
        n = self.count_publishers(self.pub_motors.topic_name)
        if n > 1:
            return ('%d other publisher(s) on %s (another controller running?)'
                    % (n - 1, self.pub_motors.topic_name))
        return None

    def _on_arm(self, request, response):
        result = (self.loop.arm(self._now(), self._other_commanders()) if request.data
                  else self.loop.disarm())
        response.success, response.message = result.ok, result.message
        self.get_logger().info(result.message)
        self._publish_diagnostics()
        return response

    def _on_reset(self, request, response):
        self.loop.reset_adaptation()
        response.success, response.message = True, 'disturbance estimate reset to zero'
        return response

    def _on_hold(self, request, response):
        """~/hold: fly the attitude measured last, if the controller takes it as a set point."""
        problem = self.loop.hold()
        response.success = problem is None
        if problem is None:
            response.message = 'holding %s (x, y, z, w)' % _shown(
                so3.rot_to_quat(self.loop.controller.R_d))
            self.get_logger().info('set point: ' + response.message)
        else:
            response.message = 'hold refused: ' + problem
            self.get_logger().warning('hold refused: ' + problem)
        return response

    # --- the control tick --------------------------------------------------------------------
    def _on_timer(self):
        """The rate_hz timer: a step, unless samples start the steps (step_on) and one did within
        the last 1.5 periods; then the timer only stands in when they stop.
        """
        now = self._now()
        if (self.loop.settings.step_on == 'timer' or self._last_tick is None
                or now - self._last_tick >= 1.5 * self.period):
            self._tick(now)

    def _failed_step(self, error):
        """A control step raised (a defect): disarm, command zero, and say so; the node stays
        up, so its topics, diagnostics and services still answer.
        """
        reason = failsafe('control step failed: %s: %s' % (type(error).__name__, error))
        self.loop.disarm(reason, failed=True)
        self.get_logger().error(reason, throttle_duration_sec=1.0)
        self._publish_zero()

    def _tick(self, now):
        """One control step at now: the motor command is published first, then the step's
        bookkeeping for the next tick and the monitoring topics.
        """
        t0 = time.perf_counter()
        dt = self.period
        if self._last_tick is not None:
            since = now - self._last_tick
            self._period_stats.add(since)
            if self.loop.settings.step_on != 'timer':   # steps as the samples come
                dt = step_period(since, self.period)
        self._last_tick = now
        try:
            tick = self.loop.tick(now, dt, settle=False)
        except Exception as e:      # a defect must not end the node with the motors running on
            self._failed_step(e)
            return
        msg = self.motors_msg
        msg.effort = commands = tick.motors.normalised.tolist()
        if len(commands) != len(msg.name):       # (an airframe of another rotor count since)
            self.motors_msg = msg = motor_commands_msg(self.session, len(commands))
            msg.effort = commands
        set_stamp(msg.header.stamp, self._ros_seconds())
        if tick.armed and self._armed_sent is not True:
            self._publish_armed(True)            # the ESC node's gate opens before the command
        self.pub_motors.publish(msg)
        if not tick.armed and self._armed_sent is not False:
            self._publish_armed(False)
        try:
            self.loop.settle()      # what the next tick needs, with the command already out
        except Exception as e:
            self._failed_step(e)
            return
        self._compute_stats.add(time.perf_counter() - t0)
        if tick.armed and tick.pose_receipt is not None:
            self._latency_stats.add(self._now() - tick.pose_receipt)
        try:
            self.telemetry.publish(tick)
        except Exception as e:      # (a defect in the monitoring must not end the node)
            self.get_logger().error('monitoring topics not published: %s: %s'
                                    % (type(e).__name__, e), throttle_duration_sec=1.0)
        state = (tick.armed, tick.state, tick.sources)
        if state != self._last_state:
            if (self._last_state is not None and tick.failed
                    and self._last_state[:2] != state[:2]):   # (once: not at each gap change)
                self.get_logger().error(tick.state)
            elif tick.bridging:
                self.get_logger().warning('; '.join(self.loop.gap_notes(now)))
            self._last_state = state
            self._publish_diagnostics()

    # --- diagnostics -------------------------------------------------------------------------
    def _publish_diagnostics(self):
        """Publish the loop's status with this window's timing figures so far."""
        st = self.loop.status(self._now(), self._other_commanders())
        st = replace(st, figures=st.figures.with_timing(self._period_stats.window(),
                                                        self._compute_stats.window(),
                                                        self._latency_stats.window(),
                                                        self.scheduling))
        self._armed_sent = None
        self._publish_armed(self.loop.supervisor.armed)
        msg = DiagnosticArray(status=[status_msg(st, STATUS_NAME, 'hexrotor')])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)

    def _end_window(self):
        """Every DIAGNOSTICS_PERIOD: publish, then start a new statistics window."""
        self._publish_diagnostics()
        for s in (self._period_stats, self._compute_stats, self._latency_stats):
            s.reset()
        self.loop.end_window()


def _shown(q):
    """A quaternion as the replies and log lines show it."""
    return '[%s]' % ', '.join('%.4f' % v for v in q)


def main():
    sys.exit(spin(ControllerNode, 'controller'))


if __name__ == '__main__':
    main()
