"""The calibration's heading, one convention in ENU, NED and Y-up (docs/sensors.md,
"Calibration"): a vehicle resting as the runbook puts it (level, its nose along the motion-capture
world's x axis) and calibrated with the runbook's own ``--heading-deg`` gets the marker set's true
rotation, whatever the motion capture's world; so does one turned 30 deg to the left with
``--heading-deg 30``. Without ROS (``core.sensors.calibration``, where the formula lives), and the
``calibrate`` command over DDS on NED poses, the convention where a heading taken as the package's
own ENU yaw would be 90 deg off.
"""
import math
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.sensors.calibration import airframe_yaw_deg, calibrate
from geoctl_ros.core.sensors.frames import InputFrames, matrix_rpy, rpy_matrix

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUNBOOK = os.path.join(ROOT, 'docs', 'first-flight.md')
UP = np.array([0.0, 0.0, 9.81])
NOISE_DEG, GYRO_NOISE, FORCE_NOISE = 0.1, 0.005, 0.05
# world: (body convention, the marker set's true rotation against the airframe: roll, pitch, yaw)
SOURCES = {
    'enu': ('flu', (1.5, -2.0, 7.0)),
    'ned': ('frd', (1.5, -2.0, 7.0)),
    'y_up': ('flu', (90.0, 0.0, 7.0)),       # a Y-up rigid body, created 7 deg off in yaw
}


def documented_heading():
    """The --heading-deg of the runbook's calibrate command (the vehicle's nose along the
    motion-capture world's x axis).
    """
    found = re.findall(r'geoctl_ros calibrate [^\n]*?--heading-deg (\S+)',
                       open(RUNBOOK).read())
    assert found, 'no calibrate command with --heading-deg in docs/first-flight.md'
    assert len(set(found)) == 1, found
    return float(found[0])


def at_rest(source, heading_deg, n, seed):
    """n poses and n // 2 IMU samples, as a source of these conventions streams them, of the
    airframe resting level at heading_deg (from the source world's x axis, counter-clockwise
    seen from above: the test's own geometry, not the calibration's function).
    """
    rng = np.random.default_rng(seed)
    x_axis = source.pose_left[:, 0]             # the source world's x axis in ENU
    yaw = math.degrees(math.atan2(x_axis[1], x_axis[0])) + heading_deg
    R = rpy_matrix((0.0, 0.0, yaw))
    poses = np.array([source.source_attitude(R @ so3.exp(rng.normal(0.0, math.radians(
        NOISE_DEG), 3))) for _ in range(n)])
    gyros = np.array([source.source_vector(rng.normal(0.0, GYRO_NOISE, 3))
                      for _ in range(n // 2)])
    forces = np.array([source.source_vector(R.T @ UP) + rng.normal(0.0, FORCE_NOISE, 3)
                       for _ in range(n // 2)])
    return poses, gyros, forces


@pytest.mark.odroid
@pytest.mark.parametrize('world', sorted(SOURCES))
def test_the_documented_heading_calibrates_the_marker_set_in_each_world(world):
    body, truth = SOURCES[world]
    source = InputFrames.of(world, body, marker_rpy_deg=truth)
    told = InputFrames.of(world, body)
    for heading in (documented_heading(), 30.0):
        poses, gyros, forces = at_rest(source, heading, 400, seed=3)
        c = calibrate(poses, gyros, forces, told, 9.81, heading_deg=heading)
        assert abs(c.marker_rotation_deg[2] - truth[2]) < 1.0, (world, heading, c)
        assert so3.angle(rpy_matrix(c.marker_rotation_deg).T @ rpy_matrix(truth)) < math.radians(
            1.0), (world, heading, c.marker_rotation_deg)
        assert c.heading_deg == pytest.approx(heading)
        # what the controller then flies on is the airframe's true attitude, yaw included
        fixed = InputFrames.of(world, body, marker_rpy_deg=c.marker_rotation_deg)
        yaw = matrix_rpy(fixed.attitude(poses[0]))[2]
        assert abs(yaw - airframe_yaw_deg(heading, world)) < 1.0, (world, heading, yaw)
    assert documented_heading() == 0.0


@pytest.mark.dds
def test_calibrate_over_dds_writes_the_true_marker_yaw_from_ned_poses(tmp_path):
    """The command as the runbook runs it, on NED/FRD poses of a vehicle whose nose is along
    NED's x axis (north) and whose marker set is 7 deg off in yaw.
    """
    from geometry_msgs.msg import PoseStamped  # noqa: PLC0415
    import rclpy  # noqa: PLC0415  (the DDS tests only)
    from sensor_msgs.msg import Imu  # noqa: PLC0415

    from geoctl_ros.nodes import qos  # noqa: PLC0415
    from geoctl_ros.nodes.conversions import set_quaternion, set_vector  # noqa: PLC0415
    from geoctl_ros.sil.processes import executable  # noqa: PLC0415
    from geoctl_ros.sil.rosenv import node_env  # noqa: PLC0415

    body, truth = SOURCES['ned']
    params = tmp_path / 'lab.yaml'
    params.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'pose_world_frame': 'ned', 'body_frame': body}}}))
    heading = documented_heading()
    poses, _, forces = at_rest(InputFrames.of('ned', body, marker_rpy_deg=truth), heading, 2, 4)
    out = tmp_path / 'calibration.yaml'
    exe = executable('calibrate')
    cmd = ([exe] if exe else [sys.executable, '-m', 'geoctl_ros.nodes.calibrate'])
    cmd += ['--params-file', str(params), '--heading-deg', '%g' % heading, '--seconds', '1',
            '--wait', '20', '--out', str(out)]
    rclpy.init()
    node = rclpy.create_node('calibration_source')
    pub_pose = node.create_publisher(PoseStamped, 'pose', qos.SENSOR)
    pub_imu = node.create_publisher(Imu, 'imu', qos.SENSOR)
    proc = subprocess.Popen(cmd, env=node_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        while proc.poll() is None:             # level and still, until calibrate has written
            p, i = PoseStamped(), Imu()
            p.header.stamp = i.header.stamp = node.get_clock().now().to_msg()
            set_quaternion(p.pose.orientation, so3.rot_to_quat(poses[0]))
            set_vector(i.angular_velocity, (0.0, 0.0, 0.0))
            set_vector(i.linear_acceleration, forces[0])
            pub_pose.publish(p)
            pub_imu.publish(i)
            time.sleep(0.01)
        text = proc.communicate(timeout=10)[0]
    finally:
        if proc.poll() is None:
            proc.kill()
        node.destroy_node()
        rclpy.try_shutdown()
    assert proc.returncode == 0, text
    written = yaml.safe_load(out.read_text())['controller']['ros__parameters']
    assert abs(written['marker_rotation_deg'][2] - truth[2]) < 1.0, (written, text)
    assert "heading: 0.0 deg from the motion capture's x axis (stated; yaw 90.0 deg in ENU)" \
        in text, text
