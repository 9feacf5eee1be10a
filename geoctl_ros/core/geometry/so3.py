"""Rotations on SO(3): hat/vee, exp/log, projection; quaternions in ROS (x, y, z, w) order (from
``geoctl_ros.core.geometry.quaternions``).

Conventions (as in the paper): R maps body-frame vectors to the world frame, ``hat(x) @ y ==
np.cross(x, y)`` and ``vee`` is the inverse of ``hat`` on skew-symmetric matrices. Every function
takes and returns plain numpy arrays; none of them validates its input (that belongs at the
boundary, see ``geoctl_ros.params`` and the nodes), but all stay accurate for rotation angles near
0 and near pi.

Batches: ``hat``, ``cross``, ``vee``, ``exp``, ``matmul``, ``matvec``, ``vecmat``, ``dot`` and
``transpose`` also take a stack of vectors (..., 3) or matrices (..., 3, 3): a batch of runs uses
the formulas of one (``x.T[i]`` is component i of one vector and of each of a stack alike).

numpy 1.26 (Ubuntu 24.04's) has no ``ndarray.mT`` nor ``np.matvec``/``vecmat``/``vecdot``: the
products here are the package's own (``test_package.py`` fails on a numpy name 1.26 lacks).
"""
import math
from typing import List, Sequence, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry.quaternions import BoolArray as BoolArray  # (so3's own names)
from geoctl_ros.core.geometry.quaternions import FloatArray as FloatArray
from geoctl_ros.core.geometry.quaternions import IntArray as IntArray
from geoctl_ros.core.geometry.quaternions import Scalars as Scalars
from geoctl_ros.core.geometry.quaternions import Vector as Vector
from geoctl_ros.core.geometry.quaternions import quat_to_rot as quat_to_rot
from geoctl_ros.core.geometry.quaternions import rot_to_quat as rot_to_quat

_I3 = np.eye(3)


def hat(x: FloatArray) -> FloatArray:
    """The skew-symmetric matrix of x: ``hat(x) @ y == cross(x, y)``."""
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        return np.array([[0.0, -x[2], x[1]],
                         [x[2], 0.0, -x[0]],
                         [-x[1], x[0], 0.0]])
    H = np.zeros(x.shape + (3,))
    H[..., 0, 1], H[..., 0, 2], H[..., 1, 2] = -x[..., 2], x[..., 1], -x[..., 0]
    return H - np.swapaxes(H, -1, -2)


LARGE = 3000      # entries of two stacks above which their cross product is written in place
                  # (a transposed result costs its users twice the time on large stacks)


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross product of 3-vectors, or of stacks of them (np.cross: 10x the time for one pair)."""
    if a.ndim == 1 and b.ndim == 1:      # one pair: float arithmetic beats array indexing
        return np.array(cross_floats(a.tolist(), b.tolist()))
    if a.shape == ONE and b.shape == ONE:    # a batch of one: the same, in floats
        return cross(a[0], b[0])[None]
    if a.size + b.size > LARGE:     # a large stack: its entries into one C-ordered result
        out = np.empty(np.broadcast_shapes(a.shape, b.shape))
        a0, a1, a2, b0, b1, b2 = a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2]
        np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
        np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
        np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
        return out
    a, b = a.T, b.T
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]]).T


def cross_floats(a: Sequence[float], b: Sequence[float]) -> list[float]:
    """a x b for two 3-vectors as lists of floats (the formula of a stack's entries)."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def vee(M: FloatArray) -> FloatArray:
    """Inverse of :func:`hat`: the vector of a skew-symmetric matrix (or of each of a stack)."""
    M = M.T
    return np.array([M[1, 2], M[2, 0], M[0, 1]]).T


# A stack's products are multiplied out entry by entry (sums of products in index order), not
# through matmul, whose BLAS kernels round a pair by where it falls in memory (OpenBLAS 0.3.23's
# Prescott kernel: every other 3x3 matrix of a stack). A matrix of <= SMALL entries times a vector
# goes in floats in the same order, so a run alone (a batch of one, shapes ONE and ONE_M; one
# testbed's rotors) gives a stack's bits; a larger one, and v^T M unstacked (the node's), by a
# running sum in the same order (``_in_order``): no product of the package's goes through BLAS.
SMALL = 18
ONE, ONE_M = (1, 3), (1, 3, 3)


def matvec_floats(M: Sequence[Sequence[float]], v: Sequence[float]) -> list[float]:
    """M v for M by rows and v as lists of floats (each sum left to right, as a stack's)."""
    if len(v) == 3:
        x0, x1, x2 = v
        return [r[0] * x0 + r[1] * x1 + r[2] * x2 for r in M]
    if len(v) == 6:             # (the regressor's rows, the rotors')
        x0, x1, x2, x3, x4, x5 = v
        return [r[0] * x0 + r[1] * x1 + r[2] * x2 + r[3] * x3 + r[4] * x4 + r[5] * x5
                for r in M]
    out = []
    for r in M:
        acc = r[0] * v[0] if len(v) else 0.0
        for k in range(1, len(v)):
            acc = acc + r[k] * v[k]
        out.append(acc)
    return out


def _float_matvec(M: FloatArray, v: FloatArray) -> FloatArray:
    return np.array(matvec_floats(M.tolist(), v.tolist()), dtype=float)


def _in_order(products: FloatArray, axis: int) -> FloatArray:
    """The sums of products along axis, each left to right in index order (a running sum's
    last: numpy's accumulate adds in order, where BLAS and a reduction pair them by the CPU's
    kernel): a stack's order, for one matrix or vector of any size.
    """
    axis %= products.ndim
    if not products.shape[axis]:
        return np.zeros(products.shape[:axis] + products.shape[axis + 1:])
    return cast(FloatArray, products.cumsum(axis=axis)[(slice(None),) * axis + (-1,)])


def matmul(A: FloatArray, B: FloatArray) -> FloatArray:
    """A B for two matrices, or for each pair of stacks of them (broadcasting)."""
    if A.ndim == 2 and B.ndim == 2:
        if A.shape == (3, 3) and B.shape == (3, 3):
            a, b = A.tolist(), B.tolist()
            return np.array([[r[0] * b[0][j] + r[1] * b[1][j] + r[2] * b[2][j] for j in range(3)]
                             for r in a])
        return _in_order(A[:, :, None] * B[None, :, :], 1)
    if A.shape == ONE_M and B.shape == ONE_M:
        return matmul(A[0], B[0])[None]
    if A.shape[-1] == 3:
        return (A[..., :, 0, None] * B[..., None, 0, :] + A[..., :, 1, None] * B[..., None, 1, :]
                + A[..., :, 2, None] * B[..., None, 2, :])
    out = A[..., :, 0, None] * B[..., None, 0, :]
    for k in range(1, A.shape[-1]):
        out = out + A[..., :, k, None] * B[..., None, k, :]
    return out


def matvec(M: FloatArray, v: FloatArray) -> FloatArray:
    """M v for a matrix and a vector, or for each of a stack of them (broadcasting)."""
    if M.ndim <= 2 and v.ndim == 1:
        return _float_matvec(M, v) if M.size <= SMALL else _in_order(M * v, -1)
    if v.shape == ONE and (M.ndim == 2 and M.size <= SMALL or M.shape == ONE_M):
        return _float_matvec(M[0] if M.ndim == 3 else M, v[0])[None]
    v = v[..., None, :]
    if M.shape[-1] == 0:
        return np.zeros(np.broadcast_shapes(M.shape[:-1], v.shape[:-2] + (1,)))
    if M.shape[-1] == 3:
        return M[..., :, 0] * v[..., 0] + M[..., :, 1] * v[..., 1] + M[..., :, 2] * v[..., 2]
    out = M[..., :, 0] * v[..., 0]
    for k in range(1, M.shape[-1]):
        out = out + M[..., :, k] * v[..., k]
    return out


def vecmat(v: FloatArray, M: FloatArray) -> FloatArray:
    """v^T M (= M^T v) for a vector and a matrix, or for each of a stack of them."""
    if v.ndim == 1 and M.ndim <= 2:
        if not len(v):              # (no rows: no sum)
            return np.zeros(M.shape[1:])
        return _in_order(v[:, None] * M if M.ndim == 2 else v * M, 0)
    if v.shape == ONE and (M.ndim == 2 and M.size <= SMALL or M.shape == ONE_M):
        return _float_matvec((M[0] if M.ndim == 3 else M).T, v[0])[None]
    v = v[..., None]
    if M.shape[-2] == 0:
        return np.zeros(np.broadcast_shapes(M.shape[:-2] + M.shape[-1:], v.shape[:-2] + (1,)))
    if M.shape[-2] == 3:
        return (v[..., 0, :] * M[..., 0, :] + v[..., 1, :] * M[..., 1, :]
                + v[..., 2, :] * M[..., 2, :])
    out = v[..., 0, :] * M[..., 0, :]
    for k in range(1, M.shape[-2]):
        out = out + v[..., k, :] * M[..., k, :]
    return out


def dot(a: FloatArray, b: FloatArray) -> FloatArray:
    """a . b for two vectors (a numpy float, which indexes and broadcasts as a 0-d array), or for
    each pair of two stacks of them (an array).
    """
    if not a.shape[-1]:
        return np.zeros(np.broadcast_shapes(a.shape[:-1], b.shape[:-1]))[()]
    if a.ndim == 1 and b.ndim == 1:
        x, y = a.tolist(), b.tolist()
        if len(x) == 3:
            return cast(FloatArray, np.float64(x[0] * y[0] + x[1] * y[1] + x[2] * y[2]))
        acc = x[0] * y[0]
        for k in range(1, len(x)):
            acc = acc + x[k] * y[k]
        return cast(FloatArray, np.float64(acc))
    if a.shape == ONE and b.shape == ONE:
        return np.array([dot(a[0], b[0])])
    if a.shape[-1] == 3:
        return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    out = a[..., 0] * b[..., 0]
    for k in range(1, a.shape[-1]):
        out = out + a[..., k] * b[..., k]
    return out


def transpose(M: FloatArray) -> FloatArray:
    """M^T for a matrix, or for each of a stack of them (a view)."""
    return M.swapaxes(-1, -2)


def exp(w: FloatArray) -> FloatArray:
    """The rotation matrix exp of hat(w) (Rodrigues), accurate for small angles; a stack (..., 3)
    gives a stack of rotations.

    Written out entry by entry, I + a hat(w) + b (w w^T - |w|^2 I), for one rotation in floats and
    for a stack in whole-array operations (no 3x3 products): each entry of a stack is then rounded
    as the same entry of a single-rotation stack, whatever the stack's size.
    """
    a: Scalars      # (floats for one rotation, arrays for a stack)
    b: Scalars
    w = np.asarray(w, dtype=float)
    if w.ndim == 1:       # one rotation, in floats
        x, y, z = w.tolist()
        a, b = rodrigues_ab(x, y, z)
        bxy, bxz, byz, ax, ay, az = b * x * y, b * x * z, b * y * z, a * x, a * y, a * z
        return np.array([1.0 - b * (y * y + z * z), bxy - az, bxz + ay,
                         bxy + az, 1.0 - b * (x * x + z * z), byz - ax,
                         bxz - ay, byz + ax, 1.0 - b * (x * x + y * y)]).reshape(3, 3)
    if w.shape == ONE:
        return exp(w[0])[None]
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    xx, yy, zz = x * x, y * y, z * z
    theta2 = xx + yy + zz
    theta = np.sqrt(theta2)
    a, b = _rodrigues(theta2, theta)
    bx, by = b * x, b * y
    bxy, bxz, byz, ax, ay, az = bx * y, bx * z, by * z, a * x, a * y, a * z
    out = np.empty(w.shape + (3,))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = 1.0 - b * (yy + zz), bxy - az, bxz + ay
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = bxy + az, 1.0 - b * (xx + zz), byz - ax
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = bxz - ay, byz + ax, 1.0 - b * (xx + yy)
    return out


def exp_parts(x: Scalars, y: Scalars, z: Scalars) -> List[List[Scalars]]:
    """``exp`` by components (floats for one rotation, arrays for a stack), by rows: the same
    operations as ``exp``'s on either.
    """
    a: Scalars
    b: Scalars
    xx: Scalars
    yy: Scalars
    zz: Scalars
    if isinstance(x, float):             # (y, z: floats as x)
        a, b = rodrigues_ab(x, cast(float, y), cast(float, z))
        xx, yy, zz = x * x, y * y, z * z
    else:
        X, Y, Z = x, cast(FloatArray, y), cast(FloatArray, z)
        xx, yy, zz = X * X, Y * Y, Z * Z
        theta2 = xx + yy + zz
        a, b = _rodrigues(theta2, np.sqrt(theta2))
    bx, by = b * x, b * y
    bxy, bxz, byz, ax, ay, az = bx * y, bx * z, by * z, a * x, a * y, a * z
    return [[1.0 - b * (yy + zz), bxy - az, bxz + ay],
            [bxy + az, 1.0 - b * (xx + zz), byz - ax],
            [bxz - ay, byz + ax, 1.0 - b * (xx + yy)]]


def matmul_parts(A: Sequence[Sequence[Scalars]],
                 B: Sequence[Sequence[Scalars]]) -> List[List[Scalars]]:
    """A B for 3x3 matrices by components (sums in index order, as ``matmul``'s)."""
    return [[r[0] * B[0][j] + r[1] * B[1][j] + r[2] * B[2][j] for j in range(3)] for r in A]


def exp_apply(w: FloatArray, v: FloatArray) -> FloatArray:
    """exp(hat(w)) v without forming the matrix: v + a w x v + b w x (w x v) (Rodrigues), for one
    pair or stacks of them; equal to matvec(exp(w), v) to rounding.
    """
    a: Scalars      # (floats for one pair, arrays for stacks)
    b: Scalars
    if w.ndim == 1 and v.ndim == 1:
        a, b = rodrigues_ab(*w.tolist())
    elif w.shape == ONE and v.shape == ONE:
        return exp_apply(w[0], v[0])[None]
    else:
        x, y, z = w[..., 0], w[..., 1], w[..., 2]
        theta2 = x * x + y * y + z * z
        theta = np.sqrt(theta2)
        a, b = _rodrigues(theta2, theta)
        a, b = a[..., None], b[..., None]
    wv = cross(w, v)
    return v + a * wv + b * cross(w, wv)


def rodrigues_ab(x: float, y: float, z: float) -> Tuple[float, float]:
    """(a, b) of exp(hat(w)) = I + a hat(w) + b hat(w)^2 for one w = (x, y, z), in floats: the
    formulas of ``_rodrigues`` for a stack, entry for entry, with numpy's sine and cosine (a
    stack's entries get numpy's, which need not round as the math module's do), taken only where
    the series is not.
    """
    theta2 = x * x + y * y + z * z
    if theta2 < 1e-8:
        return (1.0 - theta2 / 6.0 + theta2 * theta2 / 120.0,
                0.5 - theta2 / 24.0 + theta2 * theta2 / 720.0)
    theta = math.sqrt(theta2)
    return float(np.sin(theta)) / theta, (1.0 - float(np.cos(theta))) / theta2


def _rodrigues(theta2: FloatArray, theta: FloatArray) -> Tuple[FloatArray, FloatArray]:
    """sin(t)/t and (1 - cos t)/t^2 for arrays, entry by entry, by their Taylor series to O(t^4)
    where t^2 < 1e-8 (error below 1e-20); ``rodrigues_ab`` is the same for one. (A stack with no
    small angle, or only small ones, skips the other branch: the same bits.)
    """
    small = theta2 < 1e-8
    if not small.any():
        return np.sin(theta) / theta, (1.0 - np.cos(theta)) / theta2
    taylor = (1.0 - theta2 / 6.0 + theta2 * theta2 / 120.0,
              0.5 - theta2 / 24.0 + theta2 * theta2 / 720.0)
    if small.all():
        return taylor
    return (np.where(small, taylor[0], np.sin(theta) / np.where(small, 1.0, theta)),
            np.where(small, taylor[1], (1.0 - np.cos(theta)) / np.where(small, 1.0, theta2)))


def log(R: FloatArray) -> FloatArray:
    """Rotation vector w with |w| <= pi and exp(w) == R; accurate near 0 and near pi.

    The angle comes from atan2(sin, cos), so it keeps full precision near pi, where
    arccos((tr R - 1) / 2) loses half of its digits. Near pi the axis is read from the
    symmetric part of R; at exactly pi either sign of the axis is a valid answer.
    """
    skew = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])  # sin(t) n
    sin_t = math.sqrt(float(skew @ skew))
    cos_t = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    theta = math.atan2(sin_t, cos_t)
    if theta < 1e-4:
        return skew * (1.0 + theta * theta / 6.0)  # theta / sin(theta) to O(theta^4)
    if math.pi - theta > 1e-2:
        return skew * (theta / sin_t)
    # Near pi: (R + R^T)/2 = cos(t) I + (1 - cos t) n n^T.
    nn = (0.5 * (R + R.T) - cos_t * _I3) / (1.0 - cos_t)
    k = int(np.argmax(np.diag(nn)))
    n = nn[:, k] / math.sqrt(max(nn[k, k], 1e-300))
    if float(n @ skew) < 0.0:
        n = -n
    return cast(FloatArray, theta * n)


def angle(R: FloatArray) -> Scalars:
    """Geodesic rotation angle of R in [0, pi] (radians); of each rotation of a stack (..., 3, 3)
    as an array.
    """
    if np.ndim(R) == 2:
        skew_norm: Scalars = 0.5 * math.sqrt((R[2, 1] - R[1, 2]) ** 2 + (R[0, 2] - R[2, 0]) ** 2
                                    + (R[1, 0] - R[0, 1]) ** 2)
        return math.atan2(skew_norm, 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0))
    skew_norm = 0.5 * np.sqrt((R[..., 2, 1] - R[..., 1, 2]) ** 2
                              + (R[..., 0, 2] - R[..., 2, 0]) ** 2
                              + (R[..., 1, 0] - R[..., 0, 1]) ** 2)
    return cast(FloatArray,
                np.arctan2(skew_norm, 0.5 * (R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2] - 1.0)))


def project(M: FloatArray) -> FloatArray:
    """The rotation closest to M in the Frobenius norm (polar decomposition via SVD)."""
    U, _, Vt = np.linalg.svd(M)
    d = 1.0 if np.linalg.det(U @ Vt) > 0.0 else -1.0
    return cast(FloatArray, U @ np.diag([1.0, 1.0, d]) @ Vt)


def axis_angle(axis: Vector, angle_rad: float) -> FloatArray:
    """Rotation by angle_rad about a (not necessarily unit) axis."""
    a = np.asarray(axis, dtype=float)
    return exp(a * (angle_rad / np.linalg.norm(a)))


# Small linear algebra in the same arithmetic on every CPU: LAPACK's routines (np.linalg.inv,
# pinv, eigvalsh) call BLAS kernels chosen by the CPU (OPENBLAS_CORETYPE), which round
# differently, and the constants they give (the model's J^-1, the allocation's pseudo-inverse)
# would carry those bits into every flight.

def inverse3(M: FloatArray) -> FloatArray:
    """M^-1 for a 3x3 matrix or each of a stack, by its adjugate over its determinant (the
    same formula entry by entry, for one in floats).
    """
    M = np.asarray(M, dtype=float)
    if M.ndim == 2:
        (a, b, c), (d, e, f), (g, h, i) = M.tolist()
        adj = [[e * i - f * h, c * h - b * i, b * f - c * e],
               [f * g - d * i, a * i - c * g, c * d - a * f],
               [d * h - e * g, b * g - a * h, a * e - b * d]]
        det1 = a * adj[0][0] + b * adj[1][0] + c * adj[2][0]
        return np.array([[x / det1 for x in row] for row in adj])
    a, b, c = M[..., 0, 0], M[..., 0, 1], M[..., 0, 2]
    d, e, f = M[..., 1, 0], M[..., 1, 1], M[..., 1, 2]
    g, h, i = M[..., 2, 0], M[..., 2, 1], M[..., 2, 2]
    A = np.empty(M.shape)
    A[..., 0, 0], A[..., 0, 1], A[..., 0, 2] = e * i - f * h, c * h - b * i, b * f - c * e
    A[..., 1, 0], A[..., 1, 1], A[..., 1, 2] = f * g - d * i, a * i - c * g, c * d - a * f
    A[..., 2, 0], A[..., 2, 1], A[..., 2, 2] = d * h - e * g, b * g - a * h, a * e - b * d
    det = a * A[..., 0, 0] + b * A[..., 1, 0] + c * A[..., 2, 0]
    return A / det[..., None, None]


def symmetric_eigenvalues(M: FloatArray) -> Tuple[float, float, float]:
    """The eigenvalues of a symmetric 3x3 matrix, smallest first, in closed form (Smith 1961:
    the trigonometric solution of its characteristic cubic).
    """
    (a, b, c), (_, d, e), (_, _, f) = np.asarray(M, dtype=float).tolist()
    p1 = b * b + c * c + e * e
    q = (a + d + f) / 3.0
    if p1 == 0.0:
        lo, mid, hi = sorted((a, d, f))
        return lo, mid, hi
    p2 = (a - q) ** 2 + (d - q) ** 2 + (f - q) ** 2 + 2.0 * p1
    p = math.sqrt(p2 / 6.0)
    B = [[(a - q) / p, b / p, c / p], [b / p, (d - q) / p, e / p], [c / p, e / p, (f - q) / p]]
    r = 0.5 * (B[0][0] * (B[1][1] * B[2][2] - B[1][2] * B[2][1])
               - B[0][1] * (B[1][0] * B[2][2] - B[1][2] * B[2][0])
               + B[0][2] * (B[1][0] * B[2][1] - B[1][1] * B[2][0]))
    phi = math.acos(min(1.0, max(-1.0, r))) / 3.0
    hi = q + 2.0 * p * math.cos(phi)
    lo = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    return lo, 3.0 * q - hi - lo, hi


def right_inverse(A: FloatArray) -> FloatArray:
    """The minimum-norm right inverse A^T (A A^T)^-1 of a matrix of full row rank (m x n, m <= n),
    by Gauss-Jordan elimination with partial pivoting in floats: ``np.linalg.pinv`` of it, in
    the same arithmetic on every CPU.
    """
    rows = np.asarray(A, dtype=float).tolist()
    m, n = len(rows), len(rows[0])
    G = [[sum_products(rows[i], rows[j]) for j in range(m)] + [float(i == j) for j in range(m)]
         for i in range(m)]                                       # [A A^T | I]
    for col in range(m):
        pivot = max(range(col, m), key=lambda r: abs(G[r][col]))
        G[col], G[pivot] = G[pivot], G[col]
        p = G[col][col]
        G[col] = [x / p for x in G[col]]
        for r in range(m):
            if r != col and G[r][col] != 0.0:
                k = G[r][col]
                G[r] = [x - k * y for x, y in zip(G[r], G[col])]
    inv = [row[m:] for row in G]                                  # (A A^T)^-1
    return np.array([[sum_products([rows[k][i] for k in range(m)], [inv[k][j] for k in range(m)])
                      for j in range(m)] for i in range(n)])


def sum_products(x: Sequence[float], y: Sequence[float]) -> float:
    """x . y for lists of floats, summed left to right."""
    acc = 0.0
    for a, b in zip(x, y):
        acc = acc + a * b
    return acc
