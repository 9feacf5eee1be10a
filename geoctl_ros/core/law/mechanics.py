"""Mechanics of the testbed shared by the controller and the simulator.

The body turns about a spherical joint (the pivot). rho is the vector from the pivot to the centre
of mass in the body frame; g_w is the gravity vector in the world frame (REP-103, z up:
[0, 0, -9.81]). Every function also takes stacks (a leading batch axis: one testbed per run of a
campaign) and works on each.
"""

from typing import List, Sequence, cast

import numpy as np

from geoctl_ros.core.geometry.elementwise import (
    Value,
    joined,
    matrix_parts,
    one_run,
    vector_parts,
)
from geoctl_ros.core.geometry.so3 import FloatArray, Scalars, cross

Parts = Sequence[Value]                  # a 3-vector's components (floats, or one per run)
Rows = Sequence[Sequence[Value]]         # a 3x3 matrix's, by rows


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
    m_rho, g_w = np.asarray(m_rho, dtype=float), np.asarray(g_w, dtype=float)
    one = one_run(R) and m_rho.size == 3 and g_w.size == 3
    lead = np.broadcast_shapes(R.shape[:-2], m_rho.shape[:-1], g_w.shape[:-1])
    return joined(gravity_moment_parts(matrix_parts(R, one), vector_parts(m_rho, one),
                                       vector_parts(g_w, one)), lead, one)


def body_gravity_parts(R: Rows, g_w: Parts) -> List[Value]:
    """g_b = R^T g_w by components (the sums in index order, as every product here)."""
    return [R[0][j] * g_w[0] + R[1][j] * g_w[1] + R[2][j] * g_w[2] for j in range(3)]


def cross_parts(a: Parts, b: Parts) -> List[Value]:
    """a x b by components."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def gravity_moment_parts(R: Rows, m_rho: Parts, g_w: Parts) -> List[Value]:
    """``gravity_moment`` by components: (m rho) x (R^T g_w)."""
    return cross_parts(m_rho, body_gravity_parts(R, g_w))


def cog_regressor_parts(g_b: Parts) -> List[List[Value]]:
    """``cog_regressor`` by components from g_b = R^T g_w: -hat(g_b), by rows."""
    return [[-0.0, g_b[2], -g_b[1]], [-g_b[2], -0.0, g_b[0]], [g_b[1], -g_b[0], -0.0]]


def body_gravity_moment(m_rho: FloatArray, g_b: FloatArray) -> FloatArray:
    """The gravity moment (m rho) x g_b, with g_b = R^T g_w the gravity in the body frame."""
    return cross(m_rho, g_b)


def cog_regressor(R: FloatArray, g_w: FloatArray) -> FloatArray:
    """The 3x3 matrix Y with gravity_moment(R, m_rho, g_w) == Y @ m_rho, i.e. -hat(R^T g_w)."""
    g_w = np.asarray(g_w, dtype=float)
    one = one_run(R) and g_w.size == 3
    Y = cog_regressor_parts(body_gravity_parts(matrix_parts(R, one), vector_parts(g_w, one)))
    if one:
        return np.array(Y, dtype=float).reshape(R.shape)
    return np.stack([np.stack(np.broadcast_arrays(*row), axis=-1) for row in Y], axis=-2)
