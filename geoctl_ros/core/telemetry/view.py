"""What the live 3D view draws, as plain geometry in the world frame (no ROS): the cones as
surfaces, the sensor axis, its trail, the body axes and the set point. The view node
(``geoctl_ros.nodes.view``) turns these into visualization_msgs/MarkerArray.
"""
from typing import Tuple

import numpy as np

from geoctl_ros.core.geometry.so3 import BoolArray, FloatArray


def _perpendiculars(axis: FloatArray) -> Tuple[FloatArray, FloatArray]:
    """Two unit vectors that make a right-handed frame with the unit vector axis."""
    p = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    p /= np.linalg.norm(p)
    return p, np.cross(axis, p)


def cone_triangles(axis: FloatArray, half_angle: float, length: float = 1.0,
                   segments: int = 32) -> FloatArray:
    """The cone's surface from its apex (the pivot) to a rim at distance length, as a triangle
    list (3 * segments, 3): each triangle is the apex and two neighbouring rim points.
    """
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    p, q = _perpendiculars(a)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    rim = length * (np.cos(half_angle) * a[None, :] + np.sin(half_angle) * (
        np.cos(phi)[:, None] * p[None, :] + np.sin(phi)[:, None] * q[None, :]))
    tris = np.empty((segments, 3, 3))
    tris[:, 0] = 0.0
    tris[:, 1] = rim[:-1]
    tris[:, 2] = rim[1:]
    return tris.reshape(-1, 3)


def in_warning(margins_deg: FloatArray, band_deg: float) -> BoolArray:
    """Per cone: is the sensor within band_deg of the cone (or inside it)?"""
    return np.asarray(margins_deg, dtype=float) < band_deg


class Trail:
    """The last n sensor directions, oldest first, in a preallocated ring."""

    def __init__(self, n: int) -> None:
        self._points = np.zeros((n, 3))
        self.count = 0

    def add(self, point: FloatArray) -> None:
        self._points[self.count % len(self._points)] = point
        self.count += 1

    def points(self) -> FloatArray:
        n = len(self._points)
        if self.count <= n:
            return self._points[:self.count].copy()
        k = self.count % n
        return np.concatenate((self._points[k:], self._points[:k]))
