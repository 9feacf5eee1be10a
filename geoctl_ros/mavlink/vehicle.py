"""The testbed as a MAVLink vehicle, without ROS and without I/O: what to send, what a message
asks.

A ground station makes a vehicle of heartbeats from component 1 (MAV_COMP_ID_AUTOPILOT1) with a
vehicle type, and on connecting asks for AUTOPILOT_VERSION, the parameter list and the mission
list. This class answers those from the controller's state, which the bridge node feeds in
(attitude, set point, motor commands, the controller's diagnostics, parameter values). Messages are
built with pymavlink's encoder (``mav`` is a ``MAVLink`` object of the common dialect, MAVLink 2);
sending them, and carrying out what ``handle`` asks of the controller (arm, set a parameter), is
the bridge's job.

Identity: MAV_TYPE_HEXAROTOR, MAV_AUTOPILOT_GENERIC (it is neither PX4 nor ArduPilot). Heartbeat
base_mode carries the armed flag; system_status is STANDBY (disarmed), ACTIVE (armed) or CRITICAL
(disarmed by a failsafe, until armed again).
"""
import math

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.quaternions import quaternion_problem
from geoctl_ros.core.telemetry.diagnostics import ERROR
from geoctl_ros.mavlink import frames
from geoctl_ros.mavlink.actions import (
    MESSAGE_ID_MAX,
    MOTORS_MAX,
    Arm,
    Ignored,
    MotorTest,
    Say,
    Send,
    SetAttitude,
    SetParameter,
    m_const,
    shown,
    whole,
)
from geoctl_ros.mavlink.controller_view import (
    NAME_DBAR,
    NAME_MARGIN,
    NAME_MARGINS,
    NAME_PSI,
    ControllerView,
)
from geoctl_ros.mavlink.params import BY_ID, TABLE, to_mavlink
from geoctl_ros.params.build import input_timeouts
from geoctl_ros.params.param import MOTOR_TEST_DURATION_MAX

ARRAY_MARGINS, ARRAY_DBAR = 1, 2
SAME_SETPOINT = 1e-4       # rad: a SET_ATTITUDE_TARGET this close to the set point in force is it


class Vehicle:
    """Builds the vehicle's messages and interprets the ground station's."""

    def __init__(self, mav, system_id, version=(0, 1, 0), git_hash=''):
        self.mav = mav
        self.system_id = system_id
        self.version = version
        self.git_hash = git_hash
        self.view = ControllerView()
        self.t0 = None

    # --- state -------------------------------------------------------------------------------
    @property
    def armed(self):
        d = self.view.diagnostics
        return d is not None and d.figures.armed

    @property
    def failsafe(self):
        d = self.view.diagnostics
        return d is not None and d.figures.failsafe

    def system_status(self):
        if self.view.diagnostics is None:
            return m_const('MAV_STATE_BOOT')
        if self.armed:
            return m_const('MAV_STATE_ACTIVE')
        return m_const('MAV_STATE_CRITICAL') if self.failsafe else m_const('MAV_STATE_STANDBY')

    def _boot_ms(self, now):
        if self.t0 is None:
            self.t0 = now
        return int((now - self.t0) * 1e3) & 0xFFFFFFFF

    # --- periodic messages -------------------------------------------------------------------
    def heartbeat(self):
        base = m_const('MAV_MODE_FLAG_CUSTOM_MODE_ENABLED')
        if self.armed:
            base |= m_const('MAV_MODE_FLAG_SAFETY_ARMED')
        return self.mav.heartbeat_encode(m_const('MAV_TYPE_HEXAROTOR'),
                                         m_const('MAV_AUTOPILOT_GENERIC'), base, 0,
                                         self.system_status())

    def sys_status(self):
        """Sensors present/enabled/healthy: gyro (imu), attitude (motion capture, as AHRS),
        attitude stabilisation and rate control (the controller), motor outputs.
        """
        d = self.view.diagnostics
        gyro, ahrs = m_const('MAV_SYS_STATUS_SENSOR_3D_GYRO'), m_const('MAV_SYS_STATUS_AHRS')
        stab = (m_const('MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION')
                | m_const('MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL'))
        motors = m_const('MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS')
        present = gyro | ahrs | stab | motors
        enabled = gyro | ahrs | (stab | motors if self.armed else 0)
        health = 0
        imu_timeout, pose_timeout = input_timeouts(self.view.params)
        if d is not None and d.figures.imu_age < imu_timeout:
            health |= gyro
        if d is not None and d.figures.pose_age < pose_timeout:
            health |= ahrs
        if d is not None and d.level != ERROR:
            health |= stab | motors
        return self.mav.sys_status_encode(present, enabled, health, 0, 0xFFFF, -1, -1,
                                          0, 0, 0, 0, 0, 0)

    def attitude(self, now):
        """ATTITUDE_QUATERNION of the body (NED/FRD), or None before the first pose."""
        v = self.view
        if v.R is None:
            return None
        q = frames.wxyz(frames.ned_frd(v.R))
        w = frames.body_vector(v.omega) if v.omega is not None else np.zeros(3)
        return self.mav.attitude_quaternion_encode(self._boot_ms(now), *q, *map(float, w))

    def attitude_target(self, now):
        """ATTITUDE_TARGET: the set point (NED/FRD); rates and thrust are not commanded."""
        v = self.view
        if v.R_d is None:
            return None
        ignore = (m_const('ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE')
                  | m_const('ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE')
                  | m_const('ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE')
                  | m_const('ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE'))
        q = frames.wxyz(frames.ned_frd(v.R_d))
        return self.mav.attitude_target_encode(self._boot_ms(now), ignore, q, 0.0, 0.0, 0.0, 0.0)

    def actuators(self, now):
        c = list(self.view.commands)[:32]
        if not c:
            return None
        return self.mav.actuator_output_status_encode(int(self._boot_ms(now) * 1000),
                                                      (1 << len(c)) - 1,
                                                      c + [0.0] * (32 - len(c)))

    def internals(self, now):
        """Psi and the smallest cone margin as NAMED_VALUE_FLOAT; every margin and the estimate as
        DEBUG_FLOAT_ARRAY.
        """
        v, t = self.view, self._boot_ms(now)
        out = []
        if not math.isnan(v.psi):
            out.append(self.mav.named_value_float_encode(t, NAME_PSI.encode(), float(v.psi)))
        if v.margins:
            out.append(self.mav.named_value_float_encode(t, NAME_MARGIN.encode(),
                                                         float(min(v.margins))))
        for name, aid, data in ((NAME_MARGINS, ARRAY_MARGINS, v.margins),
                                (NAME_DBAR, ARRAY_DBAR, v.dbar)):
            if data:
                d = [float(x) for x in data][:58]
                out.append(self.mav.debug_float_array_encode(t * 1000, name.encode(), aid,
                                                             d + [0.0] * (58 - len(d))))
        return out

    def statustext(self, text, severity='MAV_SEVERITY_WARNING'):
        return self.mav.statustext_encode(m_const(severity), text.encode()[:50])

    # --- answers -----------------------------------------------------------------------------
    def autopilot_version(self):
        major, minor, patch = self.version
        sw = (major << 24) | (minor << 16) | (patch << 8) | 0xFF       # 0xFF: a release
        custom = list(bytes.fromhex(self.git_hash[:16].ljust(16, '0')))[:8]
        caps = (m_const('MAV_PROTOCOL_CAPABILITY_MAVLINK2')
                | m_const('MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT'))
        return self.mav.autopilot_version_encode(caps, sw, 0, 0, 0, custom, [0] * 8, [0] * 8,
                                                 0, 0, self.system_id)

    def param_value(self, index):
        ros, pid, kind = TABLE[index]
        value = self.view.params.get(ros)
        if value is None:
            return None
        return self.mav.param_value_encode(pid.encode(), to_mavlink(value),
                                           m_const('MAV_PARAM_TYPE_' + kind), len(TABLE), index)

    def param_index(self, param_id, index):
        """The table index a PARAM_REQUEST_READ or PARAM_SET names (by id, or by index when the
        id is empty), or None.
        """
        pid = param_id.rstrip('\x00') if isinstance(param_id, str) else param_id
        if pid:
            if pid not in BY_ID:
                return None
            return [p for _, p, _ in TABLE].index(pid)
        return index if 0 <= index < len(TABLE) else None

    def for_us(self, msg):
        """True when msg targets this system (or every system)."""
        target = getattr(msg, 'target_system', 0)
        return target in (0, self.system_id)

    def handle(self, msg):
        """What an incoming message asks: a list of actions (Send, Say, Arm, SetParameter,
        SetAttitude, MotorTest; Ignored for anything not for us).
        """
        kind = msg.get_type()
        if not self.for_us(msg):
            return [Ignored('for system %d' % msg.target_system)]
        if kind == 'COMMAND_LONG':
            return self._command(msg)
        if kind == 'PARAM_REQUEST_LIST':
            return [Send(p) for p in (self.param_value(i) for i in range(len(TABLE))) if p]
        if kind == 'PARAM_REQUEST_READ':
            i = self.param_index(msg.param_id, msg.param_index)
            p = self.param_value(i) if i is not None else None
            return [Send(p)] if p else [Ignored('unknown parameter %r' % msg.param_id)]
        if kind == 'PARAM_SET':
            i = self.param_index(msg.param_id, -1)
            if i is None:
                return [Send(self.statustext('unknown parameter %s' % msg.param_id))]
            return [SetParameter(TABLE[i][0], float(msg.param_value), i)]
        if kind == 'SET_ATTITUDE_TARGET':
            return self._attitude_target(msg)
        if kind == 'SETUP_SIGNING':       # the key is the vehicle's file, never set over the link
            return [Send(self.statustext('SETUP_SIGNING refused: the signing key comes from '
                                             "the vehicle's key file only"))]
        if kind == 'MISSION_REQUEST_LIST':
            return [Send(self.mav.mission_count_encode(msg.get_srcSystem(),
                                                           msg.get_srcComponent(), 0,
                                                           getattr(msg, 'mission_type', 0)))]
        return []

    def _attitude_target(self, msg):
        """SET_ATTITUDE_TARGET (a ground station's or an offboard computer's set point): its
        attitude (NED/FRD, w x y z) as SetAttitude in the package's frames; the body rates and
        the thrust are not taken (the controller holds what it is given). Refused with a
        STATUSTEXT (at most statustext_rate_hz) when the message ignores the attitude or its
        quaternion is not one; nothing when it is the set point in force (a stream of the same
        one asks once).
        """
        if msg.type_mask & m_const('ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE'):
            return [Say('set point refused: SET_ATTITUDE_TARGET ignores its attitude (only an '
                        'attitude is taken)', limited=True)]
        w, x, y, z = (float(v) for v in msg.q)
        problem = quaternion_problem((x, y, z, w))
        if problem:
            return [Say('set point refused: SET_ATTITUDE_TARGET ' + problem, limited=True)]
        R = frames.enu_flu(frames.from_wxyz((w, x, y, z)))
        if self.view.R_d is not None and so3.angle(self.view.R_d.T @ R) < SAME_SETPOINT:
            return [Ignored('the set point in force')]
        return [SetAttitude(tuple(float(v) for v in so3.rot_to_quat(R)))]

    def denied(self, command, why):
        """COMMAND_ACK DENIED and a STATUSTEXT saying why: the answer to a malformed command."""
        return [Send(self.command_ack(command, 'MAV_RESULT_DENIED')),
                Send(self.statustext(why, 'MAV_SEVERITY_WARNING'))]

    def _command(self, msg):
        cmd = msg.command
        ack = self.command_ack
        if cmd == m_const('MAV_CMD_COMPONENT_ARM_DISARM'):
            if msg.param1 not in (0.0, 1.0):
                return self.denied(cmd, 'arm refused: param1 %s is not 0 or 1' % shown(msg.param1))
            return [Arm(msg.param1 == 1.0, cmd)]
        if cmd == m_const('MAV_CMD_DO_MOTOR_TEST'):
            return self._motor_test(msg)
        if cmd in (m_const('MAV_CMD_REQUEST_MESSAGE'),
                   m_const('MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES')):
            wanted = 148
            if cmd == m_const('MAV_CMD_REQUEST_MESSAGE'):
                wanted = whole(msg.param1, 0, MESSAGE_ID_MAX)
                if wanted is None:
                    return self.denied(cmd, 'REQUEST_MESSAGE refused: param1 %s is not a '
                                       'message id' % shown(msg.param1))
            if wanted == m_const('MAVLINK_MSG_ID_AUTOPILOT_VERSION'):
                return [Send(ack(cmd, 'MAV_RESULT_ACCEPTED')),
                        Send(self.autopilot_version())]
            if wanted == m_const('MAVLINK_MSG_ID_HEARTBEAT'):
                return [Send(ack(cmd, 'MAV_RESULT_ACCEPTED')), Send(self.heartbeat())]
        return [Send(ack(cmd, 'MAV_RESULT_UNSUPPORTED'))]

    def _motor_test(self, msg):
        """MAV_CMD_DO_MOTOR_TEST (QGroundControl's motor test): one motor, throttle in percent,
        for param4 seconds -> MotorTest(rotor, normalised command, seconds, command), carried
        out by the ESC node (which refuses it too while armed); refused here while armed.
        """
        cmd = msg.command
        rotor = whole(msg.param1, 1, MOTORS_MAX)
        kind, count = whole(msg.param2, 0, 255), whole(msg.param5, 0, MOTORS_MAX)
        malformed = [why for bad, why in (
            (rotor is None, 'motor %s is not 1 to %d' % (shown(msg.param1), MOTORS_MAX)),
            (kind is None, 'throttle type %s is not a whole number' % shown(msg.param2)),
            (not 0.0 <= msg.param3 <= 100.0, 'throttle %s is not 0 to 100 %%' % shown(msg.param3)),
            (not 0.0 < msg.param4 <= MOTOR_TEST_DURATION_MAX,
             'duration %s is not in (0, %g] s' % (shown(msg.param4), MOTOR_TEST_DURATION_MAX)),
            (count is None, 'motor count %s is not a whole number' % shown(msg.param5))) if bad]
        if malformed:
            return self.denied(cmd, 'motor test refused: ' + '; '.join(malformed))
        why = None
        if self.armed:
            why = 'refused: the controller is armed'
        elif kind != m_const('MOTOR_TEST_THROTTLE_PERCENT'):
            why = 'refused: only a throttle in percent (type %d) is supported' % (
                m_const('MOTOR_TEST_THROTTLE_PERCENT'))
        elif count > 1:
            why = 'refused: one motor at a time'
        if why:
            result = ('MAV_RESULT_TEMPORARILY_REJECTED' if self.armed
                      else 'MAV_RESULT_UNSUPPORTED')
            return [Send(self.command_ack(cmd, result)),
                    Send(self.statustext('motor test ' + why, 'MAV_SEVERITY_WARNING'))]
        return [MotorTest(rotor, float(msg.param3) / 100.0, float(msg.param4), cmd)]

    def command_ack(self, command, result):
        return self.mav.command_ack_encode(command, m_const(result))
