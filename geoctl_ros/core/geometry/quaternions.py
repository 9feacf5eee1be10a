"""Quaternions in ROS order (x, y, z, w) and rotation matrices (``so3.quat_to_rot`` and
``so3.rot_to_quat`` are these), and the check that a quaternion given as an attitude is a unit
quaternion (``quaternion_problem``, which every reader of an attitude applies: the controller, the
bridge, the calibration, the parameters).
"""
import math
from typing import Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]    # an array of floats: a vector, a matrix, or a stack
BoolArray = npt.NDArray[np.bool_]       # an array of flags (one per run of a batch)
IntArray = npt.NDArray[np.int_]         # an array of integers (ESC commands, indices)
Scalars = Union[float, FloatArray]      # one run's number, or one per run of a batch
Vector = Union[Sequence[float], FloatArray]     # a vector given as a list or an array

QUATERNION_TOLERANCE = 1e-3     # |q| off 1 by more than this: not a unit quaternion


def quat_to_rot(q: Vector) -> FloatArray:
    """Rotation matrix of a quaternion in ROS order (x, y, z, w); q is normalised first."""
    x, y, z, w = (float(v) for v in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ])


def rot_to_quat(R: FloatArray) -> FloatArray:
    """Unit quaternion (x, y, z, w) of R with w >= 0 (Shepperd's method, stable for any R)."""
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    i = int(np.argmax([tr, R[0, 0], R[1, 1], R[2, 2]]))
    if i == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif i == 1:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif i == 2:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    x, y, z, w = (float(v) for v in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)       # (in floats: the same bits on any CPU)
    out = np.array([x / n, y / n, z / n, w / n])
    return -out if out[3] < 0.0 else out


def quaternion_problem(q: Vector) -> Optional[str]:
    """Why q (x, y, z, w) is not an acceptable attitude, or None."""
    if not all(math.isfinite(v) for v in q):
        return 'quaternion is not finite'
    n = math.sqrt(sum(v * v for v in q))
    if abs(n - 1.0) > QUATERNION_TOLERANCE:
        return 'quaternion is not unit length (norm %.6g)' % n
    return None
