"""The inputs' conventions, turned into this package's once, at the input boundary.

Inside the package the world is ENU (REP-103, z up) and the body FLU (x forward, y left, z up), and
R maps the airframe's body vectors to the world (docs/frames.md). The lab's sources differ:

- **the pose's world** (``pose_world_frame``): ``enu``; ``ned`` (north-east-down, the authors'
  code and PX4); ``y_up`` (motion capture that streams Y up: x kept, y up, z = x cross y);
- **the body convention** (``body_frame``) of the pose's body and of the IMU's axes: ``flu`` or
  ``frd`` (forward-right-down: the authors' code, the VN-100);
- **the marker set** (``marker_rotation_deg``): motion capture defines the body by its markers,
  rarely aligned with the airframe. The rotation R_am from the marker set's body (in the body
  convention's FLU form) to the airframe, as roll, pitch, yaw (deg, z-y-x). A Y-up system's rigid
  body has Y-up axes too: that is R_am = Rx(90 deg) (``Y_UP_BODY_DEG``), which ``calibrate``
  measures like any other;
- **the IMU's mounting** (``imu_rotation_deg``): the rotation R_ai from the IMU's axes (FLU form)
  to the airframe, as roll, pitch, yaw (deg);
- **the gyro's bias** (``gyro_bias``): rad/s in the IMU's own axes, as it reports them
  (``calibrate`` measures it), subtracted before anything else.

With T the world change of axes (the source's world -> ENU) and B the body one (FLU -> the
source's convention; FRD: diag(1, -1, -1), its own inverse), a pose R_s (the marker set's body
-> the source's world) and an IMU vector v (its own axes) become

    R = T R_s B R_am^T,        v_airframe = R_ai B^T v,        Omega = R_ai B^T (w - bias).

Each of T, B, R_am and R_ai is a proper rotation, so R stays one. ``InputFrames`` holds them, and
their inverses, which the simulator uses to emulate such sources.
"""
from dataclasses import dataclass, field
import math
from typing import Iterable, Sequence

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import FloatArray, Vector

# the source's world -> ENU
WORLD_FRAMES = {
    'enu': np.eye(3),
    'ned': np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
    'y_up': np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
}
# FLU -> the source's body convention (each its own inverse)
BODY_FRAMES = {
    'flu': np.eye(3),
    'frd': np.diag([1.0, -1.0, -1.0]),
}
Y_UP_BODY_DEG = (90.0, 0.0, 0.0)     # a Y-up rigid body's axes against an FLU airframe


def world_x_yaw_deg(world: str) -> float:
    """The yaw (deg) of a source world's x axis in the package's ENU world: 0 for ``enu`` and
    ``y_up`` (x kept), 90 for ``ned`` (its x is north, the package's y).
    """
    T = WORLD_FRAMES[world]
    return math.degrees(math.atan2(float(T[1, 0]), float(T[0, 0])))


def rpy_matrix(rpy_deg: Sequence[float]) -> FloatArray:
    """Rotation of roll, pitch, yaw (deg), applied z-y-x: Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (math.radians(float(a)) for a in rpy_deg)
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def matrix_rpy(R: FloatArray) -> FloatArray:
    """Roll, pitch, yaw (deg) of R (``rpy_matrix``'s inverse; pitch in [-90, 90])."""
    pitch = math.asin(max(-1.0, min(1.0, -float(R[2, 0]))))
    roll = math.atan2(float(R[2, 1]), float(R[2, 2]))
    yaw = math.atan2(float(R[1, 0]), float(R[0, 0]))
    return np.degrees([roll, pitch, yaw])


@dataclass(frozen=True)
class InputFrames:
    """The pose's and the IMU's conventions (module docstring); the default is the package's
    own, which passes every input through untouched.
    """

    world: str = 'enu'
    body: str = 'flu'
    marker_rotation: FloatArray = field(default_factory=lambda: np.eye(3))   # R_am
    imu_rotation: FloatArray = field(default_factory=lambda: np.eye(3))      # R_ai
    gyro_bias: FloatArray = field(default_factory=lambda: np.zeros(3))       # rad/s, IMU axes
    # derived: R = pose_left R_s pose_right; v_airframe = imu_map v
    pose_left: FloatArray = field(init=False, repr=False)
    pose_right: FloatArray = field(init=False, repr=False)
    imu_map: FloatArray = field(init=False, repr=False)
    pose_identity: bool = field(init=False, repr=False)
    imu_identity: bool = field(init=False, repr=False)
    bias_zero: bool = field(init=False, repr=False)

    def __post_init__(self) -> None:
        T, B = WORLD_FRAMES[self.world], BODY_FRAMES[self.body]
        set_ = object.__setattr__
        set_(self, 'pose_left', T)
        set_(self, 'pose_right', B @ self.marker_rotation.T)
        set_(self, 'imu_map', self.imu_rotation @ B.T)
        set_(self, 'pose_identity', bool(np.array_equal(T, np.eye(3)) and np.array_equal(
            self.pose_right, np.eye(3))))
        set_(self, 'imu_identity', bool(np.array_equal(self.imu_map, np.eye(3))))
        set_(self, 'bias_zero', not np.any(self.gyro_bias))

    @classmethod
    def of(cls, world: str = 'enu', body: str = 'flu',
           marker_rpy_deg: Sequence[float] = (0.0, 0.0, 0.0),
           imu_rpy_deg: Sequence[float] = (0.0, 0.0, 0.0),
           gyro_bias: Sequence[float] = (0.0, 0.0, 0.0)) -> 'InputFrames':
        """From the parameters' form: names, roll-pitch-yaw angles (deg) and the bias."""
        return cls(world, body, rpy_matrix(marker_rpy_deg), rpy_matrix(imu_rpy_deg),
                   np.array(gyro_bias, dtype=float))

    # --- source -> package ------------------------------------------------------------------
    def attitude(self, R_source: FloatArray) -> FloatArray:
        """The airframe's attitude (ENU <- FLU) of a pose R_s as the source streams it."""
        if self.pose_identity:
            return R_source
        return so3.matmul(so3.matmul(self.pose_left, R_source), self.pose_right)

    def imu_vector(self, v: Vector) -> FloatArray:
        """An IMU vector (its specific force) in the airframe's body axes."""
        a = np.asarray(v, dtype=float)
        return a if self.imu_identity else so3.matvec(self.imu_map, a)

    def angular_velocity(self, w: Vector) -> FloatArray:
        """The gyro's reading, less its bias, in the airframe's body axes."""
        a = np.asarray(w, dtype=float)
        if not self.bias_zero:
            a = a - self.gyro_bias
        return a if self.imu_identity else so3.matvec(self.imu_map, a)

    # --- package -> source (what a source of these conventions streams: the simulator) ------
    def source_attitude(self, R: FloatArray) -> FloatArray:
        """The pose such a source streams for the airframe's attitude R."""
        if self.pose_identity:
            return R
        return so3.matmul(so3.matmul(self.pose_left.T, R), self.pose_right.T)

    def source_vector(self, v: Vector) -> FloatArray:
        """An airframe body vector in such an IMU's axes (no bias)."""
        a = np.asarray(v, dtype=float)
        return a if self.imu_identity else so3.matvec(self.imu_map.T, a)

    def describe(self) -> str:
        """The conventions in words (for the start-up log)."""
        words = ['pose world %s, body %s' % (self.world, self.body)]
        if not np.array_equal(self.marker_rotation, np.eye(3)):
            words.append('marker set rpy %s deg' % _deg(matrix_rpy(self.marker_rotation)))
        if not np.array_equal(self.imu_rotation, np.eye(3)):
            words.append('IMU mounted rpy %s deg' % _deg(matrix_rpy(self.imu_rotation)))
        if not self.bias_zero:
            words.append('gyro bias %s rad/s' % ', '.join('%.4f' % b for b in self.gyro_bias))
        return '; '.join(words)


def _deg(v: Iterable[float]) -> str:
    return '[%s]' % ', '.join('%.1f' % a for a in v)
