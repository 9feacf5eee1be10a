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

B_i stays C^1 and e_RB,i is still exactly its gradient, so every identity of the paper holds
everywhere; the repulsion saturates at its value on the floor (the strongest it ever is) and never
becomes inf or NaN, whatever R is. Evaluations report which cones are violated (g_i <= 0) and which
are in the saturated band, so callers can flag them.
"""
from dataclasses import dataclass
import math

import numpy as np

from geoctl_ros.so3 import hat


@dataclass
class ConeEval:
    """The cone terms at one attitude; arrays have one entry (row) per cone."""

    s: np.ndarray          # r^T R^T v_i, the cosine of the angle between R r and v_i
    B: np.ndarray          # barrier values B_i >= 1
    e_RB: np.ndarray       # (n, 3) gradients of B_i in the body frame
    violated: np.ndarray   # bool: sensor on or inside cone i
    saturated: np.ndarray  # bool: within the floor band (barrier extended linearly)

    def margins_deg(self, half_angles_rad):
        """Angle between R r and v_i minus theta_i, degrees (negative inside the cone)."""
        return np.degrees(np.arccos(np.clip(self.s, -1.0, 1.0)) - half_angles_rad)


class ConeSet:
    """Any number of forbidden cones (possibly none) for one body-fixed sensor axis."""

    def __init__(self, sensor_axis, axes, half_angles_rad, alpha, floor_rad, names=None):
        """Build the set; inputs are assumed validated (see ``geoctl_ros.params``).

        sensor_axis: r, body frame (normalised here). axes: (n, 3) world-frame cone axes
        (normalised here). half_angles_rad: (n,) in (0, pi/2). alpha: barrier shape, > 0.
        floor_rad: angle outside the boundary below which the barrier is extended linearly.
        """
        r = np.asarray(sensor_axis, dtype=float)
        self.r = r / np.linalg.norm(r)
        V = np.asarray(axes, dtype=float).reshape(-1, 3)
        self.V = V / np.linalg.norm(V, axis=1, keepdims=True) if len(V) else V
        self.theta = np.asarray(half_angles_rad, dtype=float).reshape(-1)
        self.names = list(names) if names is not None else [f'cone{i}' for i in range(len(V))]
        self.alpha = float(alpha)
        self.floor = float(floor_rad)
        self.cos_theta = np.cos(self.theta)
        self.log_scale = 1.0 + self.cos_theta
        self.g0 = self.cos_theta - np.cos(self.theta + self.floor)   # floor gap, > 0
        self.B_floor = 1.0 - np.log(self.g0 / self.log_scale) / self.alpha

    def __len__(self):
        return len(self.theta)

    def evaluate(self, R):
        """Barrier values, gradients and flags at attitude R."""
        RTv = self.V @ R                 # row i: (R^T v_i)^T
        s = RTv @ self.r
        g = self.cos_theta - s
        saturated = g < self.g0
        g_eff = np.maximum(g, self.g0)
        B = np.where(saturated, self.B_floor + (self.g0 - g) / (self.alpha * self.g0),
                     1.0 - np.log(g_eff / self.log_scale) / self.alpha)
        e_RB = np.cross(RTv, self.r) / (-self.alpha * g_eff)[:, None]
        return ConeEval(s=s, B=B, e_RB=e_RB, violated=g <= 0.0, saturated=saturated)

    def margins_deg(self, R):
        """Cone margins (angle to axis minus half-angle, degrees) at attitude R."""
        return self.evaluate(R).margins_deg(self.theta)

    def F(self, R):
        """The paper's F(R) (eq. 28) for each cone, (n, 3, 3): d/dt e_RB,i = F_i Omega.

        Valid outside the floor band, where the barrier is the paper's; used by tests and the gain
        check, not by the control step.
        """
        out = np.empty((len(self), 3, 3))
        r = self.r
        r_hat = hat(r)
        for i, v in enumerate(self.V):
            RTv = R.T @ v
            d = float(r @ RTv) - self.cos_theta[i]        # s - cos(theta)
            term = np.outer(R.T @ (hat(v) @ (R @ r)), v @ R @ r_hat)
            out[i] = (float(v @ R @ r) * np.eye(3) - np.outer(RTv, r) + term / d) / (self.alpha * d)
        return out

    def feasible_margin_deg(self, R):
        """Smallest margin over all cones (inf when there are none), degrees."""
        return float(np.min(self.margins_deg(R))) if len(self) else math.inf

