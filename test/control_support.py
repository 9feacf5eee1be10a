"""What the control-law tests share (test_control, test_control_loop, test_gains, test_laws): the
paper's inertia and Table I cones, a ControllerConfig with the paper's gains, finite differences
on SO(3), random attitudes.
"""
import math

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.control import ControllerConfig

rng = np.random.default_rng(7)
G = np.array([0.9, 1.1, 1.0])
J_PAPER = np.array([[5.57e-3, 6.17e-5, -2.50e-5], [6.17e-5, 5.57e-3, 1.00e-5],
                    [-2.50e-5, 1.00e-5, 1.05e-2]])
TABLE_I = ([[0.174, -0.934, -0.034], [0.0, 0.7071, 0.7071], [-0.853, 0.436, -0.286],
            [-0.122, -0.140, -0.983]], np.radians([40.0, 40.0, 40.0, 20.0]))


def four_cones(alpha=15.0, floor_deg=0.25):
    return ConeSet([1, 0, 0], TABLE_I[0], TABLE_I[1], alpha, math.radians(floor_deg),
                   ['a', 'b', 'c', 'd'])


def one_cone(theta_deg=12.0, alpha=8.0):
    return ConeSet([1, 0, 0], [[1.0, 1.0, 0.0]], [math.radians(theta_deg)], alpha,
                   math.radians(0.25), ['obstacle'])


def config(cones, **kw):
    base = dict(k_R=0.4, k_Omega=0.296, k_Delta=0.5, c=1.0, G=G, cones=cones, inertia=J_PAPER,
                mass=1.0, cog_offset=np.zeros(3), gravity=np.array([0.0, 0.0, -9.81]))
    base.update(kw)
    return ControllerConfig(**base)


def directional_fd(f, R, eta, h=1e-6):
    """d/de f(R exp(e eta)) at e = 0, central difference."""
    return (f(R @ so3.exp(h * eta)) - f(R @ so3.exp(-h * eta))) / (2 * h)


def random_attitudes(n):
    return [so3.exp(rng.normal(size=3) * 2.0) for _ in range(n)]
