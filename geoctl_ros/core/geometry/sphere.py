"""Directions on the unit sphere: a vector made unit, and the direction at an angle from an axis
(the campaign's cones and goals, the figures' cone rims).
"""
import math

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray, cross

_I3 = np.eye(3)


def unit(v: FloatArray) -> FloatArray:
    """v scaled to unit length (v not zero)."""
    return v / math.sqrt(float(v @ v))


def direction(axis: FloatArray, angle: float, azimuth: float) -> FloatArray:
    """The unit vector at angle from the unit vector axis, at azimuth round it."""
    e1 = unit(cross(axis, _I3[int(np.argmin(np.abs(axis)))]))
    e2 = cross(axis, e1)
    return (math.cos(angle) * axis
            + math.sin(angle) * (math.cos(azimuth) * e1 + math.sin(azimuth) * e2))


def angle_between_deg(a: FloatArray, b: FloatArray) -> float:
    """The angle between two vectors of any length (deg, from atan2: exact near 0 and 180); 180
    if either is zero.
    """
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if na == 0.0 or nb == 0.0:
        return 180.0
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(a @ b)))
