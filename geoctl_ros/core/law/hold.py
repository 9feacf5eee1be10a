"""The attitude an arming holds (``arming_setpoint`` hold): the attitude measured at arming,
lifted off the joint's stops where the vehicle rests on them.

A vehicle resting on its stops (the body's z axis tilt_max from up) would be held pressed
against them: the law would fight the stops' reaction, and the spring of the stops, with the
rotors spooled up. The hold instead tilts it STOP_CLEARANCE inside them, by the least rotation
towards upright: about the horizontal axis across its tilt (the axis the stops' own moment acts
about), which keeps the direction it leans in and the turn about its own z axis.
"""
import math

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import FloatArray

# rad: how far inside the stops a hold keeps the body's z axis (a choice, not derived: clear of
# the stops' spring, which a resting vehicle sinks into, and of the attitude's noise)
STOP_CLEARANCE = math.radians(5.0)


def tilt(R: FloatArray, up: FloatArray) -> float:
    """The angle (rad) of the body's z axis (R e3) from up (unit, world frame)."""
    z = R[:, 2]
    return math.atan2(float(np.linalg.norm(so3.cross(z, up))), float(so3.dot(z, up)))


def hold_attitude(R: FloatArray, gravity: FloatArray, tilt_max: float) -> FloatArray:
    """The attitude to hold from the measured R: R itself within tilt_max - STOP_CLEARANCE of
    upright (up: against gravity, world frame), else R turned towards upright by the excess
    about the horizontal axis z x up (z = R e3). tilt_max of pi (or more): no stops, R itself.
    """
    g = float(np.linalg.norm(gravity))
    if tilt_max >= math.pi - 1e-9 or g == 0.0:
        return np.array(R, dtype=float)
    up = -np.asarray(gravity, dtype=float) / g
    excess = tilt(R, up) - max(0.0, tilt_max - STOP_CLEARANCE)
    if excess <= 0.0:
        return np.array(R, dtype=float)
    axis = so3.cross(R[:, 2], up)
    n = float(np.linalg.norm(axis))
    if n < 1e-12:          # upside down (beyond any stops): no axis is nearer than another
        axis, n = so3.cross(R[:, 0], up), float(np.linalg.norm(so3.cross(R[:, 0], up)))
    return so3.matmul(so3.exp(axis / n * excess), R)
