"""Forbidden cones for a body-fixed sensor: the logarithmic barrier of the paper, vectorised.

Cone i has a unit axis v_i (world frame) and half-angle theta_i; the body-fixed unit sensor axis is
r. The constraint (paper eq. 9) is ``s_i = r^T R^T v_i <= cos(theta_i)``: the angle between the
sensor's world direction R r and v_i stays above theta_i. With the gap ``g_i = cos(theta_i) - s_i``
the paper's barrier and its gradient (eqs. 14, 16) are

    B_i    = 1 - (1/alpha) ln(g_i / (1 + cos theta_i))
    e_RB,i = hat(R^T v_i) r / (alpha (s_i - cos theta_i)) = -(R^T v_i x r) / (alpha g_i)

and they blow up as g_i -> 0. A controller sampled at 100 Hz can see the sensor on or past the
boundary (the paper reports "numerical exceptions" on the testbed), so this module extends the
barrier below a floor gap g0_i, the gap at ``floor`` radians outside the boundary, by its tangent
line in s_i (the classical extended log barrier):

    B_i    = B_i(g0_i) + (g0_i - g_i) / (alpha g0_i)          for g_i < g0_i
    e_RB,i = -(R^T v_i x r) / (alpha g0_i)

B_i stays C^1 and e_RB,i is exactly its gradient for every attitude outside the cones, so the
paper's identities hold there, band included. Inside a cone (g_i <= 0) the gradient of that
extension would fade towards the cone's axis like sin(angle to axis); instead e_RB,i keeps the
magnitude it has on the boundary, sin(theta_i) / (alpha g0_i), the strongest repulsion anywhere,
and points the sensor away from the axis by the shortest way (on the axis itself, where that way
is undefined, along a fixed direction perpendicular to r). Nothing is ever inf or NaN, whatever R
is, and evaluations report which cones are violated (g_i <= 0) and which are in the saturated band
(g_i < g0_i), so callers can flag them.

A guard (``guard_rad``, the ``cone_guard_deg`` parameter) puts the barrier on cones wider than the
real ones by that angle: a sampled controller with latency sees the sensor a control period or two
late, and at the testbed's speeds (up to about 3 rad/s, 1.7 deg per 10 ms period) that is enough to
cross the floor band unseen (docs/campaigns.md, "Safety campaign"). Margins and violations are
always reported against the real half-angles theta_i; the barrier, its floor band and the inside
field use theta_i + guard.

A batch of cone sets (one per run of a campaign, each with the same number of cones) is one
ConeSet with axes (batch, n, 3) and half-angles (batch, n); it evaluates a stack of attitudes
(batch, 3, 3) with the same formulas.
"""
import math
from typing import Iterable, List, Optional, Tuple, cast

import numpy as np
import numpy.typing as npt

from geoctl_ros.core.geometry.elementwise import ARRAYS, Ops, Value
from geoctl_ros.core.geometry.flags import Flags, any_flag
from geoctl_ros.core.geometry.so3 import BoolArray, FloatArray, Scalars, hat, matmul, vecmat

# ``ConeSet.widened``: cos, floor gap, B offset, 1 / (alpha g0), the inside field's magnitude
Widened = Tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]


def barrier_constants(ops: Ops, theta_b: Value, floor: float,
                      alpha: float) -> Tuple[Value, Value, Value, Value, Value]:
    """A cone's barrier constants for the half-angle theta_b it acts on (an ``elementwise``
    formula): cos theta_b, the floor gap g0, the B offset 1 + ln(1 + cos theta_b) / alpha,
    1 / (alpha g0) and the inside field's magnitude sin theta_b / (alpha g0) (``Widened``).
    """
    cos_theta = ops.cos(theta_b)
    g0 = cos_theta - ops.cos(theta_b + floor)
    return (cos_theta, g0, 1.0 + ops.log(1.0 + cos_theta) / alpha, 1.0 / (alpha * g0),
            ops.sin(theta_b) / (alpha * g0))


def log_barrier(ops: Ops, g: Value, B_offset: Value, inv_alpha: float) -> Tuple[Value, Value]:
    """A cone's barrier at the gap g = cos theta - s outside its floor band (g >= g0; within it
    ``ConeSet.evaluate_terms`` extends it; an ``elementwise`` formula): B_i, and the weight
    -1 / (alpha g_i) of its gradient e_RB,i = weight ((R^T v_i) x r).
    """
    return B_offset - ops.log(g) * inv_alpha, -inv_alpha / g


def angle_deg(s: FloatArray) -> FloatArray:
    """The angle (degrees) whose cosine is s = r^T R^T v_i (clipped to [-1, 1] against
    round-off).
    """
    return cast(FloatArray, np.degrees(np.arccos(np.clip(s, -1.0, 1.0))))


class ConeEval:
    """The cone terms at one attitude; arrays have one entry (row) per cone (after the batch axis,
    if any).

    s: r^T R^T v_i, the cosine of the angle between R r and v_i. B: barrier values B_i >= 1.
    e_RB: (n, 3) gradients of B_i in the body frame, weight_i ((R^T v_i) x r) outside the cones
    (formed when asked; the control step needs only their sum, ``e_RB_sum``). violated: sensor on
    or inside cone i. saturated: within the floor band (barrier extended linearly).
    any_saturated: saturated.any(axis=-1), one flag per run of a batch.
    """

    __slots__ = ('s', 'B', 'cross', 'weight', 'violated', 'saturated', 'any_saturated', '_e_RB',
                 '_e_RB_sum')

    def __init__(self, s: FloatArray, B: FloatArray, cross: FloatArray, weight: FloatArray,
                 violated: BoolArray, saturated: BoolArray, any_saturated: Flags,
                 e_RB: Optional[FloatArray] = None,
                 e_RB_sum: Optional[FloatArray] = None) -> None:
        self.s, self.B, self.cross, self.weight = s, B, cross, weight
        self.violated, self.saturated, self.any_saturated = violated, saturated, any_saturated
        self._e_RB = e_RB
        self._e_RB_sum = e_RB_sum      # (where worked out with the rest: the same sums)

    @property
    def e_RB(self) -> FloatArray:
        if self._e_RB is None:
            self._e_RB = self.cross * self.weight[..., None]
        return self._e_RB

    @property
    def e_RB_sum(self) -> FloatArray:
        """sum_i e_RB,i (per run of a batch)."""
        if self._e_RB_sum is not None:
            return self._e_RB_sum
        if self._e_RB is None:
            return vecmat(self.weight, self.cross)
        return cast(FloatArray, self._e_RB.sum(axis=-2))

    def margins_deg(self, half_angles_deg: FloatArray) -> FloatArray:
        """Angle between R r and v_i minus theta_i, degrees (negative inside the cone)."""
        return angle_deg(self.s) - half_angles_deg


class ConeSet:
    """Any number of forbidden cones (possibly none) for one body-fixed sensor axis."""

    def __init__(self, sensor_axis: npt.ArrayLike, axes: npt.ArrayLike,
                 half_angles_rad: npt.ArrayLike, alpha: float, floor_rad: float,
                 names: Optional[Iterable[str]] = None, guard_rad: float = 0.0) -> None:
        """Build the set; inputs are assumed validated (see ``geoctl_ros.params``).

        sensor_axis: r, body frame (normalised here). axes: (n, 3) world-frame cone axes
        (normalised here). half_angles_rad: (n,) in (0, pi/2). alpha: barrier shape, > 0.
        floor_rad: angle outside the boundary below which the barrier is extended linearly.
        A batch: axes (batch, n, 3) and half_angles_rad (batch, n). guard_rad: the barrier acts
        on the half-angles plus this (see the module's docstring).
        """
        r = np.asarray(sensor_axis, dtype=float)
        self.r = r / np.linalg.norm(r)
        # V @ (R @ self.r_cols): column 0 is s_i = r^T R^T v_i, columns 1-3 (R^T v_i) x r
        self.r_cols = np.column_stack((self.r, hat(self.r)))
        # the same as floats, made once (the brake's view of a cone takes them: core.law.brake)
        self.r_floats: List[float] = self.r.tolist()
        self.r_cols_floats: List[List[float]] = self.r_cols.tolist()
        V = np.asarray(axes, dtype=float)
        V = V.reshape(-1, 3) if V.ndim < 3 else V
        self.V = V / np.linalg.norm(V, axis=-1, keepdims=True) if V.size else V
        theta = np.asarray(half_angles_rad, dtype=float)
        self.theta = theta.reshape(-1) if theta.ndim < 2 else theta
        n = self.theta.shape[-1]
        self.names = list(names) if names is not None else [f'cone{i}' for i in range(n)]
        self.alpha = float(alpha)
        self.floor = float(floor_rad)
        self.guard = float(guard_rad)
        self.theta_b = self.theta + self.guard        # the half-angles the barrier acts on
        self.cos_real = np.cos(self.theta)
        # cos theta_b, the floor gap (> 0), the B offset, 1 / (alpha g0), |e_RB,i| in cone i
        self.constants = cast(Widened, barrier_constants(ARRAYS, self.theta_b, self.floor,
                                                         self.alpha))
        self.cos_theta, self.g0, self._B_offset, self._inv_alpha_g0, self.e_RB_inside = (
            self.constants)
        # the same as floats, cone by cone (one run's barrier: ``barrier_floats``)
        self.constants_floats: List[Tuple[float, ...]] = (
            list(zip(*(c.tolist() for c in self.constants))) if self.theta.ndim == 1 else [])
        self.theta_b_floats: List[float] = (self.theta_b.tolist() if self.theta.ndim == 1
                                            else [])
        self._inv_alpha = 1.0 / self.alpha
        self.theta_deg: FloatArray = np.degrees(self.theta)
        least = int(np.argmin(np.abs(self.r)))
        perp = np.cross(self.r, np.eye(3)[least])
        self._r_perp = perp / np.linalg.norm(perp)  # fallback direction on a cone's axis

    def __len__(self) -> int:
        return cast(int, self.theta.shape[-1])

    @property
    def band_deg(self) -> float:
        """The barrier's band outside each real cone (deg): the guard (cone_guard_deg) plus the
        floor band (barrier_floor_deg). Arming and set points must clear it; the near-cone warning
        starts at it (or at 2 deg, if that is more).
        """
        return math.degrees(self.guard + self.floor)

    def axes_in_body(self, R: FloatArray) -> FloatArray:
        """The cones' axes in the body frame at R: rows b_i = R^T v_i ((..., n, 3); per run of a
        batch), the same float operations for one run and a batch (no BLAS).
        """
        return vecmat(self.V, R[..., None, :, :])

    def terms(self, R: FloatArray) -> FloatArray:
        """(n, 4) per cone: s_i = r^T R^T v_i, then (R^T v_i) x r; both linear in R (the control
        step evaluates them as part of one precomputed linear map, see ``core.law.control``).
        """
        return matmul(self.V, matmul(R, self.r_cols))

    def evaluate(self, R: FloatArray) -> 'ConeEval':
        """Barrier values, gradients and flags at attitude R."""
        return self.evaluate_terms(self.terms(R))

    def widened(self, extra_rad: Scalars) -> Widened:
        """The barrier's constants for every cone widened by extra_rad more (an array of one
        angle per cone, or per run and cone): cos, floor gap, B offset, 1 / (alpha g0) and the
        inside field's magnitude, as ``evaluate_terms`` takes them.
        """
        return cast(Widened, barrier_constants(ARRAYS, self.theta_b + extra_rad, self.floor,
                                               self.alpha))

    def evaluate_terms(self, sc: FloatArray, widened: Optional[Widened] = None) -> 'ConeEval':
        """Barrier values, gradients and flags from ``terms(R)``; widened: None, or the constants
        of ``widened(extra)`` for a barrier on wider cones (margins and violations are still
        against the real cones).
        """
        s, cross = sc[..., 0], sc[..., 1:]
        cos_theta, g0, B_offset, inv_alpha_g0, inside_norm = (
            self.constants if widened is None else widened)
        g = cos_theta - s
        saturated = g < g0
        any_saturated = saturated.any(axis=-1)
        if not any_flag(any_saturated):
            # the usual case: the paper's barrier, nothing to flag
            B, weight = log_barrier(ARRAYS, g, B_offset, self._inv_alpha)
            return ConeEval(s, cast(FloatArray, B), cross, cast(FloatArray, weight), saturated,
                            saturated, any_saturated)
        g_eff = np.maximum(g, g0)
        # log barrier at g_eff, plus the tangent-line extension below the floor (zero above it)
        B_eff, weight_eff = log_barrier(ARRAYS, g_eff, B_offset, self._inv_alpha)
        B = B_eff + (g_eff - g) * inv_alpha_g0       # g_eff - g = max(g0 - g, 0)
        weight = cast(FloatArray, weight_eff)
        e_RB = cross * weight[..., None]
        inside = g <= 0.0                         # inside the barrier's (guarded) cone
        if inside.any():
            e_RB[inside] = self._inside_field(cross[inside],
                                              np.broadcast_to(inside_norm, g.shape)[inside])
        violated = (inside if self.guard == 0.0 and widened is None
                    else s >= self.cos_real)
        return ConeEval(s, B, cross, weight, violated, saturated, any_saturated, e_RB)

    def _inside_field(self, cross: FloatArray, magnitude: FloatArray) -> FloatArray:
        """e_RB for cones the sensor is in: the boundary's magnitude, away from the axis."""
        n = np.linalg.norm(cross, axis=-1)
        unit: FloatArray = np.where((n > 1e-12)[:, None], cross / np.maximum(n, 1e-12)[:, None],
                        self._r_perp[None, :])
        return -unit * magnitude[:, None]

    def cosines(self, R: FloatArray) -> FloatArray:
        """s_i = v_i . R r per cone: the cosine of the angle between the sensor's world direction
        and each cone's axis, for R or a stack of them (any leading axes before the batch's).

        Written out element by element (not through matmul), so a run's figure is the same bits
        whatever the batch it flies in: a stacked matmul may go to BLAS as one product, whose
        kernel (OpenBLAS's Prescott one, for example) rounds a row by where it falls in its
        blocks.
        """
        r = self.r
        d = R[..., :, 0] * r[0] + R[..., :, 1] * r[1] + R[..., :, 2] * r[2]     # R r
        V = self.V
        return cast(FloatArray, V[..., 0] * d[..., None, 0] + V[..., 1] * d[..., None, 1]
                    + V[..., 2] * d[..., None, 2])

    def angles_deg(self, R: FloatArray) -> FloatArray:
        """Angle between the sensor's world direction R r and each cone axis, degrees."""
        return angle_deg(self.cosines(R))

    def closest(self, margins_deg: FloatArray) -> Tuple[str, float]:
        """The cone the sensor is closest to, by its margins (deg, one per cone; one run), and
        that margin: (name, margin).
        """
        i = int(np.argmin(margins_deg))
        return self.names[i], float(margins_deg[i])

    def margins_deg(self, R: FloatArray) -> FloatArray:
        """Cone margins (angle to axis minus half-angle, degrees) at attitude R."""
        return self.angles_deg(R) - self.theta_deg
