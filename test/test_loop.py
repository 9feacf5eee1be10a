"""The controller node's decisions without ROS: input checks, arming, failsafe, set points,
schedule, adaptation only while armed."""
import math

import numpy as np
import pytest

from geoctl_ros import so3
from geoctl_ros.loop import ControlLoop
from geoctl_ros.params import CONTROLLER, ConfigError, controller_setup, resolve

YAW90 = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))
CONE = {'cones.names': ['obstacle'], 'cones.obstacle.axis': [1.0, 1.0, 0.0],
        'cones.obstacle.half_angle_deg': 12.0}


def make_loop(**overrides):
    return ControlLoop(controller_setup(resolve(CONTROLLER, dict(CONE, **overrides))))


def feed(loop, t, q=YAW90, w=(0.0, 0.0, 0.0)):
    assert loop.offer_pose(q, t, t) is None
    assert loop.offer_angular_velocity(w, t, t) is None


def test_disarmed_until_armed_with_fresh_inputs():
    loop = make_loop()
    tick = loop.tick(0.0, 0.01)
    assert tick.control is None and not tick.motors.commands.any()
    refused = loop.arm(0.0)
    assert not refused.ok and 'no pose received yet' in refused.message
    feed(loop, 1.0)
    tick = loop.tick(1.0, 0.01)
    assert tick.control is not None and not tick.armed and not tick.motors.commands.any()
    assert loop.arm(1.0).ok
    tick = loop.tick(1.01, 0.01)
    assert tick.armed and np.all(tick.motors.commands > 0)


def test_stale_input_disarms_with_the_reason_and_stays_disarmed():
    loop = make_loop(imu_timeout=0.05, pose_timeout=0.1)
    feed(loop, 0.0)
    assert loop.arm(0.0).ok
    assert loop.offer_pose(YAW90, 0.04, 0.04) is None        # pose goes on, imu stops
    assert loop.tick(0.04, 0.01).armed
    tick = loop.tick(0.06, 0.01)
    assert not tick.armed and not tick.motors.commands.any()
    assert loop.supervisor.reason.startswith('failsafe: angular velocity stale')
    feed(loop, 0.07)                                          # data back: still disarmed
    assert not loop.tick(0.08, 0.01).armed
    assert not loop.arm(0.5).ok                               # now stale again
    feed(loop, 0.5)
    assert loop.arm(0.5).ok


@pytest.mark.parametrize('q, reason', [
    ((math.nan, 0.0, 0.0, 1.0), 'not finite'),
    ((0.0, 0.0, 0.0, 1.01), 'not unit length'),
    ((0.0, 0.0, 0.0, 0.0), 'not unit length'),
])
def test_bad_poses_are_refused_and_the_last_good_one_stays(q, reason):
    loop = make_loop()
    feed(loop, 1.0)
    R_before = loop.R.copy()
    assert reason in loop.offer_pose(q, 1.1, 1.1)
    assert np.array_equal(loop.R, R_before) and loop.pose.refused == 1
    assert reason in loop.pose.take_refusals()[0]


def test_out_of_order_and_too_fast_samples_are_refused():
    loop = make_loop()
    feed(loop, 1.0)
    assert 'not newer' in loop.offer_pose(YAW90, 0.5, 1.01)
    assert 'not newer' in loop.offer_angular_velocity((0, 0, 0), 1.0, 1.01)
    assert 'max_angular_velocity' in loop.offer_angular_velocity((0, 0, 150.0), 1.1, 1.1)
    assert 'not finite' in loop.offer_angular_velocity((0, math.inf, 0), 1.2, 1.2)


def test_setpoint_requests():
    loop = make_loop()
    assert "inside cone 'obstacle'" in loop.request_setpoint(
        so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(45))))
    assert loop.setpoint_note.startswith('setpoint rejected')
    assert np.allclose(loop.controller.R_d, np.eye(3))
    assert loop.request_setpoint((0.0, 0.0, 0.0, 3.0)) is not None
    assert loop.request_setpoint(YAW90) is None and loop.setpoint_note is None
    assert np.allclose(loop.controller.R_d @ [1, 0, 0], [0, 1, 0])


def test_schedule_plays_from_arming():
    q1 = list(so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(80))))
    loop = make_loop(**{'setpoint_schedule.times': [0.0, 2.0],
                        'setpoint_schedule.quaternions': q1 + [0.0, 0.0, 0.0, 1.0]})
    feed(loop, 10.0)
    loop.tick(10.0, 0.01)
    assert np.allclose(loop.controller.R_d, np.eye(3))        # not before arming
    assert loop.arm(10.0).ok
    loop.tick(10.0, 0.01)
    assert np.allclose(loop.controller.R_d, so3.quat_to_rot(q1))
    feed(loop, 12.05)
    loop.tick(12.05, 0.01)
    assert np.allclose(loop.controller.R_d, np.eye(3))


def test_schedule_through_a_cone_is_refused_at_configuration():
    inside = list(so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(45))))
    with pytest.raises(ConfigError, match='set point 1: setpoint puts the sensor axis inside'):
        make_loop(**{'setpoint_schedule.times': [1.0],
                     'setpoint_schedule.quaternions': inside})
    with pytest.raises(ConfigError, match='4 values per time'):
        make_loop(**{'setpoint_schedule.times': [1.0, 2.0],
                     'setpoint_schedule.quaternions': [0.0, 0.0, 0.0, 1.0]})


def test_adaptation_runs_only_while_armed():
    loop = make_loop()
    feed(loop, 0.0, w=(0.0, 0.0, -0.5))
    for k in range(10):
        loop.tick(0.001 * k, 0.01)
    assert not loop.controller.delta_bar.any()
    assert loop.arm(0.01).ok
    loop.tick(0.02, 0.01)
    assert loop.controller.delta_bar.any()
