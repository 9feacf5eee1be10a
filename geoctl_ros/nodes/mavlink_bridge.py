"""The MAVLink bridge: ``ros2 run geoctl_ros mavlink_bridge`` shows the testbed to a ground
station.

A thin shell: topics of the controller feed ``geoctl_ros.mavlink.vehicle.Vehicle``, its messages go
out through ``geoctl_ros.mavlink.link.Link`` (a thread of its own), and what a ground station asks
is carried out through the controller's own services: ``~/arm`` for MAV_CMD_COMPONENT_ARM_DISARM,
``set_parameters`` for PARAM_SET (validated exactly as ``ros2 param set`` is) and for
SET_ATTITUDE_TARGET (its ``setpoint``, checked as every set point is); and the ESC node's
``~/motor_test`` for MAV_CMD_DO_MOTOR_TEST (refused while armed). Optionally a second
link reads a PX4/ArduPilot board's HIGHRES_IMU and publishes it on ``imu`` (FLU). Its own health
goes to /diagnostics. Parameters: ``mavlink.*`` in docs/parameters.md.
"""
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.srv import GetParameters, SetParameters, SetParametersAtomically
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray
from std_srvs.srv import SetBool, Trigger

from geoctl_ros.core.telemetry.diagnostics import ERROR, WARN
from geoctl_ros.core.telemetry.diagnostics import NAME as CONTROLLER_STATUS
from geoctl_ros.core.telemetry.scheduling import scheduling
from geoctl_ros.mavlink import health, identity, signing
from geoctl_ros.mavlink.actions import (
    Arm,
    Ignored,
    MotorTest,
    Say,
    Send,
    SetAttitude,
    SetParameter,
    m_const,
)
from geoctl_ros.mavlink.link import Link, encoder
from geoctl_ros.mavlink.params import TABLE
from geoctl_ros.mavlink.vehicle import Vehicle
from geoctl_ros.nodes import qos, ros_params
from geoctl_ros.nodes.autopilot_imu import AutopilotImu
from geoctl_ros.nodes.conversions import commands_of, python_value, status_of
from geoctl_ros.nodes.mavlink_calls import (
    UNSIGNED_WARNING,
    ControllerCalls,
    GroundStationReports,
)
from geoctl_ros.nodes.runtime import Periodic, RefusalLog, spin
from geoctl_ros.params import MAVLINK, ConfigError, settings
from geoctl_ros.records.fields import quaternion, vector

TIMESTAMP_LEAD = 10 * 100_000   # signing units saved ahead of the last sent (10 s of clock):
                                # a crash between two saves cannot make a restart reuse one
PARAM_REFRESH = 5.0        # s between reads of the controller's parameters
TICK = 0.01                # s: the bridge's one timer (the rates are at most 100 Hz)


class MavlinkBridge(ControllerCalls, GroundStationReports, Node):
    """The MAVLink bridge: the testbed as a MAVLink vehicle to a ground station."""

    def __init__(self, **kwargs):
        super().__init__('mavlink_bridge', **kwargs)
        cfg = settings(ros_params.load(self, MAVLINK), 'mavlink.')
        self.sysid = cfg.system_id
        self.vehicle = Vehicle(encoder(self.sysid, m_const('MAV_COMP_ID_AUTOPILOT1')), self.sysid,
                               identity.version(), identity.git_hash())
        # the key before the link: a key file that cannot be used stops the node first
        self.timestamps, self.streams, key = self._signing_key(cfg)
        self.link_id = cfg.signing_link_id
        self.link = Link(cfg.url, self.sysid, m_const('MAV_COMP_ID_AUTOPILOT1'),
                         signing=None if key is None else
                         (key, self.link_id, self.timestamps.start(), self.streams.load()))
        # one timer (TICK) runs the pump and every periodic job
        self.jobs = Periodic()
        if key is not None:
            self._save_timestamp()
            self.jobs.every(1.0, self._save_timestamp)
        else:
            self.get_logger().warning(UNSIGNED_WARNING + ' (set mavlink.signing_key_file)')
        self._refusals_logged = 0
        self.autopilot = (AutopilotImu(self, cfg.autopilot_url, self.sysid,
                                       cfg.autopilot_imu_rate_hz, self.vehicle.mav)
                          if cfg.autopilot_url else None)
        self.counts = dict.fromkeys(health.BRIDGE_COUNTS, 0)
        self.scheduling = scheduling()      # (the realtime prefix's class: read once)
        self.gcs_heartbeat = None
        self._text_period = 1.0 / cfg.statustext_rate_hz
        self._last_text = -1e9
        self._last_diag = (None, None)
        self._cone_entries = 0          # the controller's cone entries last reported
        # SET_ATTITUDE_TARGET: one asked at a time, the next waiting, the last one refused
        self._attitude_pending, self._attitude_next, self._attitude_refused = False, None, None
        ctl = '/' + cfg.controller.strip('/')

        view = self.vehicle.view
        self.refusals = RefusalLog(self.get_logger())
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, qos.EVENT)

        def taking(topic, take):
            """A callback that hands a message's value to the view; a refusal is logged."""
            def callback(msg):
                problem = take(msg)
                if problem:
                    self.counts[health.REFUSED_INPUT] += 1
                    self.refusals.warn('%s refused: ' % topic, problem)
            return callback
        for kind, topic, take, profile in (
                (QuaternionStamped, 'attitude',      # (the controller's: the package's frames)
                 lambda m: view.take_attitude(quaternion(m.quaternion)), qos.TELEMETRY),
                (Vector3Stamped, 'body_rate', lambda m: view.take_rate(vector(m.vector)),
                 qos.TELEMETRY),
                (QuaternionStamped, 'active_setpoint',
                 lambda m: view.take_attitude(quaternion(m.quaternion), setpoint=True),
                 qos.LATCHED),
                (JointState, 'motor_commands', lambda m: view.take_commands(commands_of(m)),
                 qos.COMMAND),
                (Float64, 'configuration_error', lambda m: view.take_psi(m.data), qos.TELEMETRY),
                (Float64MultiArray, 'cone_margins', lambda m: view.take_array('margins', m.data),
                 qos.TELEMETRY),
                (Float64MultiArray, 'disturbance_estimate',
                 lambda m: view.take_array('dbar', m.data), qos.TELEMETRY)):
            self.create_subscription(kind, topic, taking(topic, take), profile)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', qos.EVENT)
        self.arm_client = self.create_client(SetBool, ctl + '/arm')
        self.get_client = self.create_client(GetParameters, ctl + '/get_parameters')
        self.set_client = self.create_client(SetParameters, ctl + '/set_parameters')
        esc = '/' + cfg.esc.strip('/')
        self.esc_set = self.create_client(SetParametersAtomically,
                                          esc + '/set_parameters_atomically')
        self.esc_test = self.create_client(Trigger, esc + '/motor_test')

        send = self.link.send
        now = time.monotonic
        for rate, make in ((cfg.heartbeat_rate_hz, lambda: [self.vehicle.heartbeat()]),
                           (cfg.status_rate_hz, lambda: [self.vehicle.sys_status()]),
                           (cfg.attitude_rate_hz,
                            lambda: [self.vehicle.attitude(now()),
                                     self.vehicle.attitude_target(now())]),
                           (cfg.actuator_rate_hz,
                            lambda: [self.vehicle.actuators(now())]),
                           (cfg.internals_rate_hz,
                            lambda: self.vehicle.internals(now()))):
            self.jobs.every(1.0 / rate, lambda make=make: [send(m) for m in make() if m])
        self._params_loaded = False
        self._list_pending = False      # a PARAM_REQUEST_LIST waiting for the first read
        self.jobs.every(0.5, lambda: None if self._params_loaded else self._read_params())
        self.jobs.every(PARAM_REFRESH, self._read_params)
        self.jobs.every(1.0, self._publish_diagnostics)
        self.jobs.every(1.0, self._log_refusals)
        self.create_timer(TICK, self._on_tick)
        self._read_params()
        self.get_logger().info('mavlink_bridge: system %d component 1 on %s%s' % (
            self.sysid, cfg.url,
            ', autopilot IMU from ' + cfg.autopilot_url if self.autopilot else ''))

    # --- signing -----------------------------------------------------------------------------
    def _signing_key(self, cfg):
        """(TimestampStore, StreamStore, key) when a key file is set, else Nones; a key file
        that cannot be used stops the node (exit 2) with the reason.
        """
        path = cfg.signing_key_file
        if not path:
            return None, None, None
        try:
            key = signing.load_key(path)
        except signing.SigningKeyError as e:
            raise ConfigError([('mavlink.signing_key_file', str(e))]) from None
        outgoing = cfg.signing_timestamp_file or path + '.timestamp'
        return signing.TimestampStore(outgoing), signing.StreamStore(outgoing + '.streams'), key

    def _save_timestamp(self):
        if self.timestamps is not None:
            try:
                self.timestamps.save(self.link.signing_timestamp + TIMESTAMP_LEAD)
                self.streams.save(self.link.verifier.streams.copy())
            except OSError as e:
                self.get_logger().error('signing timestamp not saved: %s' % e)

    def _log_refusals(self):
        """At most one line a second: how many were refused since, the latest and its sender."""
        n = self.link.counts['refused']
        if n > self._refusals_logged and self.link.refusals:
            why, kind, sender = self.link.refusals[-1]
            self.get_logger().warning('refused %d MAVLink message(s) without a valid signature; '
                                      'latest: %s %s from %s' % (n - self._refusals_logged, why,
                                                                 kind, sender))
            self._refusals_logged = n

    # --- from the controller -----------------------------------------------------------------
    def _on_diagnostics(self, msg):
        for s in msg.status:
            if s.name != CONTROLLER_STATUS:
                continue
            status = status_of(s)
            self.vehicle.view.diagnostics = status
            entries = status.figures.cone_entries
            if entries > self._cone_entries:      # the sensor entered a cone: never rate-limited
                self._text(s.message, 'MAV_SEVERITY_CRITICAL')
            self._cone_entries = entries
            if status.level >= WARN and (status.level, s.message) != self._last_diag:
                self._text(s.message, 'MAV_SEVERITY_ERROR' if status.level >= ERROR else
                           'MAV_SEVERITY_WARNING', limited=True)
            self._last_diag = (status.level, s.message)

    def _read_params(self):
        if not self.get_client.service_is_ready():
            return
        names = [ros for ros, _, _ in TABLE]
        future = self.get_client.call_async(GetParameters.Request(names=names))

        def done(f):
            result = f.result()
            if result is None:
                return
            for name, value in zip(names, result.values):
                p = Parameter.from_parameter_msg(ParameterMsg(name=name, value=value))
                if p.value is not None:
                    self.vehicle.view.params[name] = python_value(p.value)
            self._params_loaded = True
            if self._list_pending:
                self._list_pending = False
                for i in range(len(TABLE)):
                    msg = self.vehicle.param_value(i)
                    if msg is not None:
                        self.link.send(msg)
        future.add_done_callback(done)

    # --- from the ground station -------------------------------------------------------------
    def _on_tick(self):
        self._pump()
        self.jobs.run()

    def _pump(self):
        for msg in self.link.receive():
            try:
                self._take(msg)
            except Exception as e:     # a defect must never end the bridge on one frame
                self.counts[health.HANDLER_ERRORS] += 1
                self.get_logger().error('%s not handled (%s: %s); the bridge goes on'
                                        % (msg.get_type(), type(e).__name__, e),
                                        throttle_duration_sec=1.0)
                if msg.get_type() == 'COMMAND_LONG':
                    self.link.send(self.vehicle.command_ack(msg.command, 'MAV_RESULT_FAILED'))
        if self.autopilot is not None:
            self.autopilot.pump()

    def _take(self, msg):
        kind = msg.get_type()
        if kind == 'HEARTBEAT':
            if msg.type == m_const('MAV_TYPE_GCS'):
                self.gcs_heartbeat = time.monotonic()
            return
        if kind == 'PARAM_REQUEST_LIST' and not self._params_loaded:
            self._list_pending = True          # answered when the controller has answered
            self._read_params()
            return
        for action in self.vehicle.handle(msg):
            self._act(action, msg)

    def _act(self, action, msg):
        if isinstance(action, Send):
            self.link.send(action.message)
        elif isinstance(action, Say):
            self._text(action.text, action.severity, action.limited)
        elif isinstance(action, Ignored):
            self.counts[health.IGNORED] += 1
        elif isinstance(action, Arm):
            self._arm(action.on, action.command)
        elif isinstance(action, SetParameter):
            self._set_param(action.name, action.value, action.index)
        elif isinstance(action, SetAttitude):
            self._set_attitude(action.q)
        elif isinstance(action, MotorTest):
            self._motor_test(action.rotor, action.command, action.seconds, action.mav_command)
        else:
            raise TypeError('not an action: %r' % (action,))

    def on_shutdown(self):
        self.link.close()
        self._save_timestamp()
        if self.autopilot is not None:
            self.autopilot.close()


def main():
    sys.exit(spin(MavlinkBridge, 'mavlink_bridge'))


if __name__ == '__main__':
    main()
