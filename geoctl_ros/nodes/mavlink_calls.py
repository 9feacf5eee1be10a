"""The MAVLink bridge's parts (mixins of ``MavlinkBridge``): what it asks of the other nodes for a
ground station (arm, set a parameter or the set point, test a motor) through their services,
answering the ground station when they answer; and what it reports (STATUSTEXT, its own
diagnostics).
"""
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.srv import SetParameters, SetParametersAtomically
from rclpy.parameter import Parameter
from std_srvs.srv import SetBool, Trigger

from geoctl_ros.mavlink import health
from geoctl_ros.mavlink.params import BY_ROS, to_ros
from geoctl_ros.nodes.conversions import refusal_reason
from geoctl_ros.params import SETPOINT

GCS_TIMEOUT = 3.0          # s without a ground-station heartbeat: "no ground station"
UNSIGNED_WARNING = 'MAVLink unsigned: anyone on the link can arm the vehicle'
STATUSTEXT_LEN = 50


class ControllerCalls:
    """The MavlinkBridge's calls of the controller's and the ESC node's services (a mixin: it
    uses the bridge's clients, link, vehicle, counts and ``_text``).
    """

    def _arm(self, on, command):
        self.counts[health.ARM_REQUESTS] += 1
        if not self.arm_client.service_is_ready():
            self.link.send(self.vehicle.command_ack(command, 'MAV_RESULT_TEMPORARILY_REJECTED'))
            self._text('arm: the controller is not reachable', 'MAV_SEVERITY_ERROR')
            return
        self.link.send(self.vehicle.command_ack(command, 'MAV_RESULT_IN_PROGRESS'))
        future = self.arm_client.call_async(SetBool.Request(data=on))

        def done(f):
            r = f.result()
            ok = r is not None and r.success
            self.link.send(self.vehicle.command_ack(
                command, 'MAV_RESULT_ACCEPTED' if ok else 'MAV_RESULT_DENIED'))
            if not ok:
                self._text(r.message if r is not None else 'arm: no answer', 'MAV_SEVERITY_ERROR')
        future.add_done_callback(done)

    def _set_attitude(self, q):
        """SET_ATTITUDE_TARGET's set point q (x, y, z, w; ENU <- FLU) through the controller's
        ``setpoint`` parameter, checked there as every set point is. One at a time: one that
        comes while another is asked waits, replaced by any later one. A refusal is answered
        with a STATUSTEXT giving the reason (once: a stream of the same set point is not asked
        again), an acceptance with an INFO one (at most statustext_rate_hz).
        """
        if self._attitude_pending:
            self._attitude_next = q
            return
        if q == self._attitude_refused:
            return
        if not self.set_client.service_is_ready():
            self._text('set point refused: the controller is not reachable',
                       'MAV_SEVERITY_ERROR', limited=True)
            return
        self._attitude_pending = True
        param = Parameter(SETPOINT, value=list(q)).to_parameter_msg()
        future = self.set_client.call_async(SetParameters.Request(parameters=[param]))

        def done(f):
            self._attitude_pending = False
            r = f.result()
            res = r.results[0] if r is not None and r.results else None
            if res is not None and res.successful:
                self._attitude_refused = None
                self._text('set point accepted', 'MAV_SEVERITY_INFO', limited=True)
            else:
                self._attitude_refused = q
                self._text('set point refused: ' + refusal_reason(
                    res.reason if res is not None else 'no answer'), 'MAV_SEVERITY_ERROR')
            waiting, self._attitude_next = self._attitude_next, None
            if waiting is not None:
                self._set_attitude(waiting)
        future.add_done_callback(done)

    def _motor_test(self, rotor, command, duration, mav_command):
        """MAV_CMD_DO_MOTOR_TEST through the ESC node: its motor_test.* parameters, then its
        ~/motor_test service (which refuses while armed, or with a value out of its range).
        """
        ack = self.vehicle.command_ack
        if not (self.esc_set.service_is_ready() and self.esc_test.service_is_ready()):
            self.link.send(ack(mav_command, 'MAV_RESULT_TEMPORARILY_REJECTED'))
            self._text('motor test: the ESC node is not reachable', 'MAV_SEVERITY_ERROR')
            return
        self.link.send(ack(mav_command, 'MAV_RESULT_IN_PROGRESS'))
        params = [Parameter('motor_test.rotor', value=rotor).to_parameter_msg(),
                  Parameter('motor_test.command', value=command).to_parameter_msg(),
                  Parameter('motor_test.duration', value=duration).to_parameter_msg()]

        def answer(ok, why):
            self.link.send(ack(mav_command, 'MAV_RESULT_ACCEPTED' if ok else 'MAV_RESULT_DENIED'))
            self._text('motor test: ' + why, 'MAV_SEVERITY_INFO' if ok
                       else 'MAV_SEVERITY_WARNING')

        def tested(f):
            r = f.result()
            answer(r is not None and r.success, r.message if r is not None else 'no answer')

        def set_done(f):
            r = f.result()
            if r is None or not r.result.successful:
                answer(False, ' '.join((r.result.reason if r is not None else 'no answer')
                                       .split()))
                return
            self.esc_test.call_async(Trigger.Request()).add_done_callback(tested)
        self.esc_set.call_async(SetParametersAtomically.Request(
            parameters=params)).add_done_callback(set_done)

    def _set_param(self, name, value, index):
        self.counts[health.PARAM_SETS] += 1

        def answer(ok, reason=''):
            if ok:
                self.vehicle.view.params[name] = to_ros(name, value)
            elif reason:
                self._text('%s refused: %s' % (BY_ROS[name][0], reason), 'MAV_SEVERITY_ERROR')
            p = self.vehicle.param_value(index)
            if p is not None:
                self.link.send(p)
        if not self.set_client.service_is_ready():
            answer(False, 'the controller is not reachable')
            return
        try:
            param = Parameter(name, value=to_ros(name, value)).to_parameter_msg()
        except Exception as e:
            answer(False, str(e))
            return
        future = self.set_client.call_async(SetParameters.Request(parameters=[param]))

        def done(f):
            r = f.result()
            res = r.results[0] if r is not None and r.results else None
            answer(bool(res and res.successful),
                   ' '.join((res.reason if res else 'no answer').split()))
        future.add_done_callback(done)


class GroundStationReports:
    """The MavlinkBridge's reports: STATUSTEXT to the ground station and its own /diagnostics."""

    def _text(self, text, severity, limited=False):
        """STATUSTEXT, in 50-character chunks (MAVLink 2 id/chunk_seq) when longer."""
        now = time.monotonic()
        if limited and now - self._last_text < self._text_period:
            return
        self._last_text = now
        self.counts[health.STATUSTEXT] += 1
        chunks = [text[i:i + STATUSTEXT_LEN] for i in range(0, len(text), STATUSTEXT_LEN)] or ['']
        tid = (self.counts[health.STATUSTEXT] % 65535) + 1 if len(chunks) > 1 else 0
        for k, chunk in enumerate(chunks):
            msg = self.vehicle.statustext(chunk, severity)
            msg.id, msg.chunk_seq = tid, k
            self.link.send(msg)

    # --- own health --------------------------------------------------------------------------
    def _publish_diagnostics(self):
        now = time.monotonic()
        gcs_age = None if self.gcs_heartbeat is None else now - self.gcs_heartbeat
        warnings = []
        if self.link.verifier is None:
            warnings.append(UNSIGNED_WARNING)
        if gcs_age is None or gcs_age > GCS_TIMEOUT:
            warnings.append(health.NO_GCS_HEARTBEAT)
        ap_age = ap_messages = None
        if self.autopilot is not None:
            ap_age, ap_messages, ap_warning = self.autopilot.health(now)
            if ap_warning:
                warnings.append(ap_warning)
        verifier = self.link.verifier
        last = self.link.refusals[-1] if verifier is not None and self.link.refusals else None
        figures = health.BridgeStatus(
            url=self.link.url, gcs_age=gcs_age, link_counts=dict(self.link.counts),
            counts=dict(self.counts), signing_link_id=None if verifier is None else self.link_id,
            refused={} if verifier is None else dict(verifier.refused),
            last_refused='' if last is None else '%s %s from %s' % tuple(last),
            last_error=self.link.last_error if self.link.counts['bad data'] else '',
            autopilot_age=ap_age, autopilot_messages=ap_messages, scheduling=self.scheduling)
        status = DiagnosticStatus(level=bytes([1 if warnings else 0]), name=health.NAME,
                                  hardware_id='mavlink',
                                  message='; '.join(warnings) or 'ground station connected',
                                  values=[KeyValue(key=k, value=v)
                                          for k, v in health.to_values(figures)])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(msg)
