"""ROS <-> MAVLink frames, converted here and nowhere else.

ROS (REP-103): world ENU (x east, y north, z up), body FLU (x forward, y left, z up), quaternions
(x, y, z, w). MAVLink: world NED (x north, y east, z down), body FRD (x forward, y right, z down),
quaternions (w, x, y, z). With T the world change of axes (ENU <-> NED, its own inverse) and F the
body one (FLU <-> FRD, likewise):

    R_NED<-FRD = T R_ENU<-FLU F,      omega_FRD = F omega_FLU

So a ROS attitude "nose east" (R = I) is MAVLink yaw +90 deg, and ROS yaw +90 (nose north) is
MAVLink yaw 0.
"""
import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.sensors.frames import BODY_FRAMES, WORLD_FRAMES

# (core.sensors.frames: the controller's inputs use the same)
T = WORLD_FRAMES['ned']       # ENU <-> NED
F = BODY_FRAMES['frd']        # FLU <-> FRD


def ned_frd(R_enu_flu):
    """A ROS attitude as MAVLink's rotation NED <- FRD."""
    return T @ R_enu_flu @ F


def enu_flu(R_ned_frd):
    """A MAVLink attitude as ROS's rotation ENU <- FLU."""
    return T @ R_ned_frd @ F


def body_vector(v):
    """A body vector FLU -> FRD, or FRD -> FLU (the same map)."""
    return F @ np.asarray(v, dtype=float)


def wxyz(R):
    """MAVLink quaternion (w, x, y, z) of a rotation matrix (w >= 0)."""
    x, y, z, w = so3.rot_to_quat(R)
    return (float(w), float(x), float(y), float(z))


def from_wxyz(q):
    """Rotation matrix of a MAVLink quaternion (w, x, y, z)."""
    return so3.quat_to_rot((q[1], q[2], q[3], q[0]))
