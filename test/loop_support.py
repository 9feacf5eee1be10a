"""What the loop tests share (test_loop, test_gaps): a loop of one cone, fed level at yaw 90."""
import math
import os

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.supervisor.loop import ControlLoop
from geoctl_ros.params import CONTROLLER, controller_setup, resolve

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

YAW90 = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))
CONE = {'cones.names': ['obstacle'], 'cones.obstacle.axis': [1.0, 1.0, 0.0],
        'cones.obstacle.half_angle_deg': 12.0}


def make_loop(**overrides):
    """A loop of the cone's; its sensor checks off unless asked for (they need half a second of
    samples at rest to arm, and have their own tests: test_sensors.py).
    """
    overrides.setdefault('consistency_checks', False)
    return ControlLoop(controller_setup(resolve(CONTROLLER, dict(CONE, **overrides))))


def feed(loop, t, q=YAW90, w=(0.0, 0.0, 0.0)):
    assert loop.offer_pose(q, t, t) is None
    assert loop.offer_angular_velocity(w, t, t) is None


SPIN = np.array([0.1, -0.2, 0.5])          # rad/s, body frame
R0 = so3.quat_to_rot(YAW90)


def spinning(t):
    """The attitude of a body turning at the constant body rate SPIN from R0."""
    return R0 @ so3.exp(SPIN * t)


def fly_spinning(loop, t_end, pose_until=np.inf, imu_until=np.inf, dt=0.005):
    """Feed poses and gyro of the spinning body every dt (each stream until its cut-off) and
    tick every 2 dt; returns the last tick.
    """
    tick = None
    for k in range(int(round(t_end / dt)) + 1):
        t = k * dt
        if t <= pose_until:
            assert loop.offer_pose(so3.rot_to_quat(spinning(t)), t, t) is None
        if t <= imu_until:
            assert loop.offer_angular_velocity(SPIN, t, t) is None
        if k == 0:
            assert loop.arm(t).ok
        if k % 2 == 0:
            tick = loop.tick(t, 2 * dt)
    return tick
