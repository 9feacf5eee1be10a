"""Calibration: ``ros2 run geoctl_ros calibrate --params-file FILE [--seconds 5] [--heading-deg
PSI] [--out calibration.yaml] [--ros-args -r pose:=... -r imu:=...]``.

With the vehicle level and at rest, it listens to ``pose`` and ``imu`` for --seconds, measures
the gyro's bias, the marker set's rotation against the level airframe (its heading PSI stated,
or the markers' own: then only the tilt), the IMU's tilt and the sensors' noise
(``geoctl_ros.core.sensors.calibration``), with the conventions of FILE's controller section, and
writes a parameter file for the controller to load after FILE. PSI is the angle from the
motion-capture world's x axis to the airframe's nose, counter-clockwise seen from above: the nose
along that x axis is 0, whether the motion capture streams ENU, NED or Y-up.

    ros2 run geoctl_ros calibrate --params-file FILE --heading-deg 0 --out calibration.yaml

and the controller loads that file after FILE:

    ros2 run geoctl_ros controller --ros-args --params-file FILE --params-file calibration.yaml

Exit code 0 when written, 1 when the samples cannot calibrate (the reason on stderr), 2 for bad
arguments or parameters.
"""
import argparse
import datetime
import math
import sys
import time

from geometry_msgs.msg import PoseStamped
import numpy as np
import rclpy
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
from sensor_msgs.msg import Imu

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.quaternions import quaternion_problem
from geoctl_ros.core.sensors.calibration import CalibrationError, calibrate
from geoctl_ros.core.supervisor.safety import angular_velocity_problem, specific_force_problem
from geoctl_ros.nodes import qos
from geoctl_ros.params import (
    CONTROLLER,
    ConfigError,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
    write_parameter_file,
)
from geoctl_ros.records.fields import quaternion, vector

MAX_RATE = 100.0      # rad/s: a gyro reading beyond this is not a vehicle at rest


class Listener(Node):
    """Collects the poses (as rotation matrices) and the IMU's samples as they come."""

    def __init__(self):
        super().__init__('calibrate')
        self.poses, self.gyros, self.forces = [], [], []
        self.create_subscription(PoseStamped, 'pose', self._on_pose, qos.SENSOR)
        self.create_subscription(Imu, 'imu', self._on_imu, qos.SENSOR)

    def _on_pose(self, msg):
        q = quaternion(msg.pose.orientation)
        if quaternion_problem(q) is None:        # (the controller's own check)
            self.poses.append(so3.quat_to_rot(q))

    def _on_imu(self, msg):
        w, f = vector(msg.angular_velocity), vector(msg.linear_acceleration)
        if (angular_velocity_problem(w, MAX_RATE) is None
                and specific_force_problem(f) is None):
            self.gyros.append(w)
            self.forces.append(f)


def main(argv=None):
    argv = remove_ros_args(sys.argv if argv is None else argv)[1:]
    parser = argparse.ArgumentParser(prog='calibrate', description=__doc__.split('\n\n')[1])
    parser.add_argument('--params-file', required=True,
                        help="the controller's parameter file (its conventions)")
    parser.add_argument('--seconds', type=float, default=5.0, help='seconds of samples (5)')
    parser.add_argument('--heading-deg', type=float, default=None,
                        help="the airframe's heading: deg from the motion-capture world's x "
                        'axis to the nose, counter-clockwise seen from above (nose along x: 0, '
                        "in ENU, NED and Y-up alike); default: the marker set's own (only the "
                        'tilt is calibrated)')
    parser.add_argument('--out', default='calibration.yaml', help='(calibration.yaml)')
    parser.add_argument('--wait', type=float, default=30.0,
                        help='seconds to wait for the first samples (30)')
    args = parser.parse_args(argv)
    if not 0.5 <= args.seconds <= 600.0:
        parser.error('--seconds must be within 0.5 and 600')
    if args.heading_deg is not None and not -360.0 <= args.heading_deg <= 360.0:
        parser.error('--heading-deg must be within -360 and 360')
    try:
        setup = controller_setup(resolve(CONTROLLER, node_overrides(
            load_parameter_file(args.params_file), CONTROLLER)))
    except ConfigError as e:
        print('calibrate: %s' % e, file=sys.stderr)
        return 2
    # (the conventions of the file; its own gyro_bias is not used: calibrate measures the raw one)
    frames, told = setup.frames, setup.agreement
    gravity = float(np.linalg.norm(told.gravity))
    rclpy.init()
    node = Listener()
    try:
        end = time.monotonic() + args.wait
        while (not node.poses or not node.gyros) and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
        if not node.poses or not node.gyros:
            print('calibrate: no %s within %g s (topics: %s, %s)'
                  % ('pose' if not node.poses else 'imu', args.wait,
                     node.resolve_topic_name('pose'), node.resolve_topic_name('imu')),
                  file=sys.stderr)
            return 1
        del node.poses[:], node.gyros[:], node.forces[:]
        print('calibrate: %g s of samples; keep the vehicle level and still ...' % args.seconds,
              file=sys.stderr)
        end = time.monotonic() + args.seconds
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
        try:
            c = calibrate(np.array(node.poses), np.array(node.gyros), np.array(node.forces),
                          frames, gravity, args.heading_deg)
        except CalibrationError as e:
            print('calibrate: %s' % e, file=sys.stderr)
            return 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    write_parameter_file(
        {CONTROLLER: {'gyro_bias': c.gyro_bias, 'marker_rotation_deg': c.marker_rotation_deg,
                      'imu_rotation_deg': c.imu_rotation_deg}}, args.out,
        'Written by calibrate at %s from %d poses and %d IMU samples over %g s, level and at '
        "rest (spread %.2f deg), heading %.1f deg from the motion capture's x axis, "
        'counter-clockwise seen from above (%s); measured noise: attitude %.3f deg, '
        'gyro %.4f rad/s, accelerometer %.3f m/s^2 (the file %s says %g deg, %g rad/s, %g '
        'm/s^2). Load after %s.'
        % (datetime.datetime.now().isoformat(timespec='seconds'), c.poses, c.imu_samples,
           args.seconds, c.spread_deg, c.heading_deg,
           'stated' if args.heading_deg is not None else "the markers' own",
           c.attitude_noise_deg, c.gyro_noise, c.accelerometer_noise, args.params_file,
           math.degrees(told.attitude_noise), told.gyro_noise, told.accelerometer_noise,
           args.params_file))
    print("heading: %.1f deg from the motion capture's x axis (%s; yaw %.1f deg in ENU)\n"
          'gyro_bias: [%s] rad/s\nmarker_rotation_deg: [%s]\nimu_rotation_deg: [%s]\n'
          'noise: attitude %.3f deg, gyro %.4f rad/s, accelerometer %.3f m/s^2\nwrote %s'
          % (c.heading_deg, 'stated' if args.heading_deg is not None else "the markers' own",
             c.yaw_deg, ', '.join('%.5f' % b for b in c.gyro_bias),
             ', '.join('%.2f' % a for a in c.marker_rotation_deg),
             ', '.join('%.2f' % a for a in c.imu_rotation_deg), c.attitude_noise_deg,
             c.gyro_noise, c.accelerometer_noise, args.out))
    return 0


if __name__ == '__main__':
    sys.exit(main())
