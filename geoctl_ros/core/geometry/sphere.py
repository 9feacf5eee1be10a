"""Directions on the unit sphere: a vector made unit, and the direction at an angle from an axis
(the campaign's cones and goals, the figures' cone rims).
"""
import math

import numpy as np

from geoctl_ros.core.geometry.so3 import cross

_I3 = np.eye(3)


def unit(v: np.ndarray) -> np.ndarray:
    """v scaled to unit length (v not zero)."""
    return v / math.sqrt(float(v @ v))


def direction(axis: np.ndarray, angle: float, azimuth: float) -> np.ndarray:
    """The unit vector at angle from the unit vector axis, at azimuth round it."""
    e1 = unit(cross(axis, _I3[int(np.argmin(np.abs(axis)))]))
    e2 = cross(axis, e1)
    return (math.cos(angle) * axis
            + math.sin(angle) * (math.cos(azimuth) * e1 + math.sin(azimuth) * e2))
