"""Mechanics of the testbed shared by the controller and the simulator.

The body turns about a spherical joint (the pivot). rho is the vector from the pivot to the centre
of mass in the body frame; g_w is the gravity vector in the world frame (REP-103, z up:
[0, 0, -9.81]). Every function also takes stacks (a leading batch axis: one testbed per run of a
campaign) and works on each.
"""

from typing import cast

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray, Scalars, cross, hat, vecmat


def pivot_inertia(inertia_cm: FloatArray, mass: Scalars, rho: FloatArray) -> FloatArray:
    """Inertia about the pivot (parallel-axis theorem): J_cm + m (|rho|^2 I - rho rho^T)."""
    rho = np.asarray(rho, dtype=float)
    m = np.asarray(mass, dtype=float)[..., None, None]
    rr: FloatArray = np.einsum('...i,...i->...', rho, rho)[..., None, None]
    return np.asarray(inertia_cm, dtype=float) + m * (rr * np.eye(3)
                                                      - rho[..., :, None] * rho[..., None, :])


def first_moment(mass: Scalars, rho: FloatArray) -> FloatArray:
    """m rho, the mass times the pivot -> centre of mass vector: what the gravity moment (and the
    constant+cog estimate) is linear in.
    """
    return cast(FloatArray,
                np.asarray(mass, dtype=float)[..., None] * np.asarray(rho, dtype=float))


def gravity_moment(R: FloatArray, m_rho: FloatArray, g_w: FloatArray) -> FloatArray:
    """Moment of gravity about the pivot in the body frame: (m rho) x (R^T g_w).

    With the centre of mass above the pivot this moment tips the body further over (an inverted
    pendulum). It is linear in m_rho = m * rho: gravity_moment = cog_regressor(R, g_w) @ m_rho.
    """
    return body_gravity_moment(m_rho, vecmat(g_w, R))       # g_w^T R = (R^T g_w)^T


def body_gravity_moment(m_rho: FloatArray, g_b: FloatArray) -> FloatArray:
    """The gravity moment (m rho) x g_b, with g_b = R^T g_w the gravity in the body frame."""
    return cross(m_rho, g_b)


def cog_regressor(R: FloatArray, g_w: FloatArray) -> FloatArray:
    """The 3x3 matrix Y with gravity_moment(R, m_rho, g_w) == Y @ m_rho, i.e. -hat(R^T g_w)."""
    return -hat(vecmat(g_w, R))
