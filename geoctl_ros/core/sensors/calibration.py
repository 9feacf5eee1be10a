"""Calibration of the inputs, the vehicle level and at rest: the gyro's bias, the marker set's
rotation against the airframe, the IMU's tilt, and the sensors' noise figures.

With the conventions in effect (``core.sensors.frames.InputFrames``: world and body; the IMU's yaw
is kept), from poses R_s,k, gyro readings w_k and specific forces f_k taken at rest:

- the marker set: P = T R_s B, the marker body's attitude, averaged (the rotation nearest the
  mean); the airframe rests level at the stated heading, R = Rz(psi), so R_am = Rz(psi)^T P
  (``marker_rotation_deg``). Without a stated heading, psi is the marker body's own, and only
  the tilt is corrected;
- **the heading** (``heading_deg``, the one convention of ``calibrate --heading-deg``): the angle
  from the motion-capture world's x axis to the airframe's nose, counter-clockwise seen from
  above (turning left is positive), whatever the world's convention. The nose along the motion
  capture's x axis is heading 0 in ENU, NED and Y-up alike. In the package's ENU world that is
  the yaw psi = heading + the yaw of the source world's x axis (``airframe_yaw_deg``: 0 for ENU
  and Y-up, 90 for NED, whose x is north);
- the gyro's bias: the mean of w_k, in the IMU's own axes (``gyro_bias``);
- the IMU's tilt: its gravity direction v = B^T f (mean, unit) must map to the airframe's up,
  R_ai v = e3, with R_ai = Rz(yaw_i) Ry(pitch) Rx(roll) and yaw_i the configured one: pitch =
  -asin(v_x), roll = atan2(v_y, v_z) (``imu_rotation_deg``);
- the noise figures: the standard deviations per axis of the poses about their mean, of the gyro
  and of the accelerometer (``attitude_noise_deg``, ``gyro_noise``, ``accelerometer_noise``),
  from which the sensor checks' tolerances are derived (``core.sensors.consistency``).

It refuses (``CalibrationError``) a vehicle that moved, too few samples, or a specific force that
is not gravity.
"""
from dataclasses import dataclass
import math
from typing import Optional

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.sensors.frames import (
    BODY_FRAMES,
    WORLD_FRAMES,
    InputFrames,
    matrix_rpy,
    rpy_matrix,
    world_x_yaw_deg,
)

MIN_SAMPLES = 20            # poses and IMU samples each, at least
REST_DEG = 1.0              # the poses may spread this much (deg) about their mean, at rest
FORCE_SHARE = 0.1           # |f| within 10 % of |g|


class CalibrationError(ValueError):
    """Why the samples cannot calibrate (a sentence)."""


@dataclass(frozen=True)
class Calibration:
    """The parameters it measured, and the figures it measured them from."""

    gyro_bias: FloatArray            # rad/s, the IMU's axes
    marker_rotation_deg: FloatArray  # roll, pitch, yaw
    imu_rotation_deg: FloatArray     # roll, pitch, yaw (yaw as configured)
    attitude_noise_deg: float
    gyro_noise: float
    accelerometer_noise: float
    poses: int
    imu_samples: int
    spread_deg: float                # the poses' largest angle from their mean
    heading_deg: float               # the airframe's heading it took (stated or the markers'),
                                     # from the motion capture's x axis (``airframe_yaw_deg``)
    yaw_deg: float                   # the same, as the airframe's yaw in the package's ENU


def airframe_yaw_deg(heading_deg: float, world: str) -> float:
    """The airframe's yaw (deg) in the package's ENU world for a heading stated as
    ``calibrate --heading-deg`` takes it (module docstring): from the motion-capture world's x
    axis, counter-clockwise seen from above, in the world ``world`` (enu, ned, y_up).
    """
    return float(heading_deg) + world_x_yaw_deg(world)


def calibrate(poses: FloatArray, gyros: FloatArray, forces: FloatArray, frames: InputFrames,
              gravity: float, heading_deg: Optional[float] = None) -> Calibration:
    """The calibration of poses (n, 3, 3; as the source streams them), gyro readings and specific
    forces (m, 3; as the IMU gives them) taken level and at rest (module docstring).
    """
    poses, gyros, forces = (np.asarray(a, dtype=float) for a in (poses, gyros, forces))
    if len(poses) < MIN_SAMPLES or len(gyros) < MIN_SAMPLES or len(forces) < MIN_SAMPLES:
        raise CalibrationError('too few samples (%d poses, %d IMU samples; at least %d each): '
                               'are the pose and imu topics right?'
                               % (len(poses), len(gyros), MIN_SAMPLES))
    T, B = WORLD_FRAMES[frames.world], BODY_FRAMES[frames.body]
    P = T @ poses @ B
    mean = so3.project(P.mean(axis=0))
    deviations = np.array([so3.log(mean.T @ Pk) for Pk in P])
    spread = math.degrees(float(np.linalg.norm(deviations, axis=1).max()))
    if spread > REST_DEG:
        raise CalibrationError('the vehicle moved: its poses spread %.2f deg (at most %.1f): '
                               'calibrate it at rest' % (spread, REST_DEG))
    force = forces.mean(axis=0)
    size = float(np.linalg.norm(force))
    if abs(size - gravity) > FORCE_SHARE * gravity:
        raise CalibrationError('the specific force is %.2f m/s^2, not about %.2f: no '
                               'accelerometer data, or the vehicle not at rest' % (size, gravity))
    yaw = (float(matrix_rpy(mean)[2]) if heading_deg is None
           else airframe_yaw_deg(heading_deg, frames.world))
    marker = rpy_matrix((0.0, 0.0, yaw)).T @ mean
    v = B.T @ force / size
    imu_yaw = float(matrix_rpy(frames.imu_rotation)[2])
    imu = np.array([math.degrees(math.atan2(v[1], v[2])),
                    math.degrees(-math.asin(max(-1.0, min(1.0, float(v[0]))))), imu_yaw])
    return Calibration(
        gyro_bias=gyros.mean(axis=0), marker_rotation_deg=matrix_rpy(marker),
        imu_rotation_deg=imu,
        attitude_noise_deg=math.degrees(float(deviations.std(axis=0).mean())),
        gyro_noise=float(gyros.std(axis=0).mean()),
        accelerometer_noise=float(forces.std(axis=0).mean()), poses=len(poses),
        imu_samples=len(gyros), spread_deg=spread,
        heading_deg=_wrap_deg(yaw - world_x_yaw_deg(frames.world)), yaw_deg=_wrap_deg(yaw))


def _wrap_deg(a: float) -> float:
    """An angle (deg) in (-180, 180]."""
    return 180.0 - (180.0 - a) % 360.0
