"""MAVLink without a network: frames against known rotations, the parameter-id table, and what the
vehicle sends and answers (pymavlink's encoder and parser, no socket).
"""
import math
import os

import numpy as np
import pytest

os.environ['MAVLINK20'] = '1'
from pymavlink.dialects.v20 import common as mav  # noqa: E402

from geoctl_ros.core.geometry import so3  # noqa: E402
from geoctl_ros.core.telemetry.diagnostics import ERROR, OK, WARN, Figures, Status
from geoctl_ros.mavlink import frames  # noqa: E402
from geoctl_ros.mavlink.actions import (  # noqa: E402
    Arm,
    Ignored,
    MotorTest,
    Say,
    SetAttitude,
    SetParameter,
)
from geoctl_ros.mavlink.link import encoder  # noqa: E402
from geoctl_ros.mavlink.params import BY_ID, TABLE, to_mavlink, to_ros  # noqa: E402
from geoctl_ros.mavlink.vehicle import Vehicle  # noqa: E402
from geoctl_ros.params import BY_NAME  # noqa: E402

pytestmark = pytest.mark.odroid


def yaw(deg):
    return so3.axis_angle([0, 0, 1], math.radians(deg))


@pytest.mark.parametrize('R_ros, R_mav, what', [
    (np.eye(3), yaw(90.0), 'ROS nose east is MAVLink yaw +90 (east of north)'),
    (yaw(90.0), np.eye(3), 'ROS nose north is MAVLink yaw 0'),
    (yaw(180.0), yaw(-90.0), 'ROS nose west is MAVLink yaw -90'),
    # nose east and pitched 30 deg up: about ROS -y (right); in NED/FRD pitch up is +30 about y
    (so3.axis_angle([0, 1, 0], math.radians(-30.0)),
     yaw(90.0) @ so3.axis_angle([0, 1, 0], math.radians(30.0)), 'pitch up stays pitch up'),
    # right wing down: ROS +20 about x (the left wing, +y, rises towards +z); FRD roll +20
    (so3.axis_angle([1, 0, 0], math.radians(20.0)),
     yaw(90.0) @ so3.axis_angle([1, 0, 0], math.radians(20.0)), 'right wing down'),
])
def test_attitude_frames_with_known_rotations(R_ros, R_mav, what):
    assert np.allclose(frames.ned_frd(R_ros), R_mav, atol=1e-12), what
    assert np.allclose(frames.enu_flu(R_mav), R_ros, atol=1e-12), what
    q = frames.wxyz(frames.ned_frd(R_ros))
    assert np.allclose(frames.from_wxyz(q), R_mav, atol=1e-12)
    assert q[0] >= 0.0


def test_body_rates_and_the_quaternion_order():
    # yawing left (counter-clockwise seen from above) is +z in FLU and -z (yaw rate < 0) in FRD
    assert np.allclose(frames.body_vector([0.1, 0.2, 0.3]), [0.1, -0.2, -0.3])
    q = frames.wxyz(yaw(90.0))                 # MAVLink (w, x, y, z)
    assert np.allclose(q, [math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])


def test_parameter_ids_are_short_unique_scalars_of_the_controller():
    ids = [pid for _, pid, _ in TABLE]
    assert len(set(ids)) == len(ids) and all(len(i) <= 16 for i in ids)
    for ros, pid, kind in TABLE:
        p = BY_NAME[ros]
        assert 'controller' in p.nodes and p.type in ('double', 'integer', 'bool'), ros
        assert (kind == 'REAL32') == (p.type == 'double'), ros
    assert to_mavlink(True) == 1.0 and to_ros('adaptive', 0.0) is False
    assert to_ros('k_R', 0.5) == 0.5 and isinstance(to_ros('k_R', 1.0), float)
    assert BY_ID['GC_K_R'][0] == 'k_R'


def test_the_manual_names_every_mavlink_parameter_with_its_ros_name():
    """docs/mavlink.md's parameter list is the bridge's table: each id beside its ROS name."""
    with open(os.path.join(os.path.dirname(__file__), '..', 'docs', 'mavlink.md')) as f:
        text = ' '.join(f.read().split())
    missing = [pid for ros, pid, _ in TABLE if '`%s` %s' % (pid, ros) not in text]
    assert not missing, 'docs/mavlink.md, "Parameters", lacks %s' % missing


def parse(msg, sysid=7):
    """What a ground station would decode from a message the vehicle built."""
    m = encoder(sysid, 1)
    buf = msg.pack(m)
    return mav.MAVLink(None).decode(bytearray(buf))


def vehicle(**view):
    v = Vehicle(encoder(7, 1), 7, version=(1, 2, 3), git_hash='0123456789abcdef0123')
    for k, val in view.items():
        setattr(v.view, k, val)
    return v


def test_heartbeat_identity_and_state():
    v = vehicle()
    hb = parse(v.heartbeat())
    assert hb.get_srcSystem() == 7 and hb.get_srcComponent() == mav.MAV_COMP_ID_AUTOPILOT1
    assert hb.type == mav.MAV_TYPE_HEXAROTOR and hb.autopilot == mav.MAV_AUTOPILOT_GENERIC
    assert hb.system_status == mav.MAV_STATE_BOOT
    v.view.diagnostics = Status(WARN, '', Figures(armed=False, state='disarmed at start-up'))
    assert parse(v.heartbeat()).system_status == mav.MAV_STATE_STANDBY
    v.view.diagnostics = Status(OK, '', Figures(armed=True, state='armed'))
    hb = parse(v.heartbeat())
    assert hb.system_status == mav.MAV_STATE_ACTIVE
    assert hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
    v.view.diagnostics = Status(ERROR, '', Figures(armed=False, failsafe=True,
                                                   state='failsafe: pose lost'))
    hb = parse(v.heartbeat())
    assert hb.system_status == mav.MAV_STATE_CRITICAL
    assert not hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED


def test_the_motor_test_goes_to_the_esc_node_and_is_refused_while_armed():
    """MAV_CMD_DO_MOTOR_TEST as QGroundControl sends it: motor 3 at 12 % for 2 s."""
    v = vehicle()
    g = encoder(255, 190)

    def motor_test(throttle_type=mav.MOTOR_TEST_THROTTLE_PERCENT, count=0):
        return v.handle(g.command_long_encode(7, 1, mav.MAV_CMD_DO_MOTOR_TEST, 0, 3,
                                              throttle_type, 12.0, 2.0, count, 0, 0))
    v.view.diagnostics = Status(OK, '', Figures(armed=False, state='disarmed'))
    assert motor_test() == [MotorTest(3, 0.12, 2.0, mav.MAV_CMD_DO_MOTOR_TEST)]
    v.view.diagnostics = Status(OK, '', Figures(armed=True, state='armed'))
    ack, text = (parse(a.message) for a in motor_test())
    assert ack.result == mav.MAV_RESULT_TEMPORARILY_REJECTED
    assert text.text == 'motor test refused: the controller is armed'
    v.view.diagnostics = Status(OK, '', Figures(armed=False, state='disarmed'))
    for refused in (motor_test(throttle_type=mav.MOTOR_TEST_THROTTLE_PWM), motor_test(count=6)):
        assert parse(refused[0].message).result == mav.MAV_RESULT_UNSUPPORTED


def test_attitude_and_target_go_out_in_ned_frd():
    v = vehicle(R=np.eye(3), omega=np.array([0.0, 0.0, 0.2]), R_d=yaw(90.0))
    att = parse(v.attitude(0.0))
    assert np.allclose([att.q1, att.q2, att.q3, att.q4], frames.wxyz(yaw(90.0)), atol=1e-6)
    assert att.yawspeed == pytest.approx(-0.2)
    tgt = parse(v.attitude_target(0.0))
    assert np.allclose(tgt.q, [1.0, 0.0, 0.0, 0.0], atol=1e-6)


def test_a_set_attitude_target_is_a_set_point_in_the_packages_frames():
    """SET_ATTITUDE_TARGET as a ground station sends it (NED/FRD, w x y z; rates and thrust
    ignored): MAVLink yaw -30 deg is the package's yaw 120 (ENU/FLU). The set point in force
    again asks nothing; one that ignores its attitude, or whose quaternion is not one, is
    refused with a STATUSTEXT saying why; one for another system is not ours.
    """
    v = vehicle(R_d=yaw(90.0))
    g = encoder(255, 190)
    rates_and_thrust = (mav.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
                        | mav.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
                        | mav.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
                        | mav.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE)

    def target(q, mask=rates_and_thrust, system=7):
        return v.handle(g.set_attitude_target_encode(0, system, 1, mask, q, 0.0, 0.0, 0.0, 0.0))
    [act] = target(frames.wxyz(frames.ned_frd(yaw(120.0))))
    assert isinstance(act, SetAttitude)
    assert np.allclose(so3.quat_to_rot(act.q), yaw(120.0), atol=1e-6)
    assert np.allclose(act.q, so3.rot_to_quat(yaw(120.0)), atol=1e-6)
    assert target(frames.wxyz(frames.ned_frd(yaw(90.0)))) == [Ignored('the set point in force')]
    for q, mask, why in (
            ((1.0, 0.0, 0.0, 0.0), rates_and_thrust | mav.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE,
             'set point refused: SET_ATTITUDE_TARGET ignores its attitude (only an attitude '
             'is taken)'),
            ((0.0, 0.0, 0.0, 0.0), rates_and_thrust,
             'set point refused: SET_ATTITUDE_TARGET quaternion is not unit length (norm 0)'),
            ((math.nan, 0.0, 0.0, 1.0), rates_and_thrust,
             'set point refused: SET_ATTITUDE_TARGET quaternion is not finite')):
        assert target(q, mask) == [Say(why, limited=True)]
    assert isinstance(target((1.0, 0.0, 0.0, 0.0), system=9)[0], Ignored)


def test_connect_sequence_answers():
    v = vehicle(params={'k_R': 0.4, 'adaptive': True})
    g = encoder(255, 190)                                   # a ground station
    acts = v.handle(g.command_long_encode(7, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0,
                                          mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0))
    ack, ver = (parse(a.message) for a in acts)
    assert ack.result == mav.MAV_RESULT_ACCEPTED and ver.get_type() == 'AUTOPILOT_VERSION'
    assert ver.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert ver.flight_sw_version >> 8 == (1 << 16) | (2 << 8) | 3
    assert bytes(ver.flight_custom_version) == bytes.fromhex('0123456789abcdef')
    values = [parse(a.message) for a in v.handle(g.param_request_list_encode(7, 1))]
    assert [p.param_id for p in values] == ['GC_K_R', 'GC_ADAPTIVE']   # those the controller gave
    assert values[0].param_count == len(TABLE) and values[1].param_value == 1.0
    count = parse(v.handle(g.mission_request_list_encode(7, 1))[0].message)
    assert count.get_type() == 'MISSION_COUNT' and count.count == 0
    arm = v.handle(g.command_long_encode(7, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0,
                                         0, 0, 0))
    assert arm == [Arm(True, mav.MAV_CMD_COMPONENT_ARM_DISARM)]
    other = parse(v.handle(g.command_long_encode(7, 1, mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0,
                                                 0, 0, 0))[0].message)
    assert other.result == mav.MAV_RESULT_UNSUPPORTED
    setp = v.handle(g.param_set_encode(7, 1, b'GC_K_R', 0.5, mav.MAV_PARAM_TYPE_REAL32))
    assert setp == [SetParameter('k_R', 0.5, 0)]
    other_system = v.handle(g.param_set_encode(9, 1, b'GC_K_R', 0.5, mav.MAV_PARAM_TYPE_REAL32))
    assert other_system == [Ignored('for system 9')]
