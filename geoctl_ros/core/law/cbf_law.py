"""The geometric baseline filtered by a control-barrier-function QP: each cone a pointing
constraint of relative degree 2, solved exactly by its active set every step.
"""
import itertools
from typing import Any

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import cross, matvec
from geoctl_ros.core.law.geometric_law import unconstrained


def pointing_cbf(controller: Any, R: np.ndarray, Omega: np.ndarray, terms: Any) -> tuple:
    """Each cone as a pointing constraint of relative degree 2, as the rows of A u >= beta.

    h_i = cos(theta_i + guard) - (R^T v_i) . r >= 0 (the sensor outside the guarded cone). With
    b_i = R^T v_i and c_i = b_i x r: b_i' = b_i x Omega, so h_i' = c_i . Omega and
    h_i'' = ((b_i x Omega) x r) . Omega + c_i . Omega', Omega' = J^-1 (u + f + d) with
    f = M_g - Omega x J Omega the model's moment besides u and d the disturbance. The exponential
    CBF condition h'' + 2 lambda h' + lambda^2 h >= 0 (a double pole at -lambda, ``cbf_rate``) is
    then linear in u: a_i . u >= beta_i with a_i = J^-1 c_i. It holds for any d with
    |d| <= D = ``cbf_moment_bound`` (a robust CBF): beta_i grows by D |a_i|. (The adaptive
    estimate is no bound, and overshoots on its way: the filter does not use it.)
    Returns (A (..., n, 3), beta (..., n), h, h', b, f) (b: the rows R^T v_i; f as above).
    """
    cfg = controller.config
    cones = cfg.cones
    ev = terms.cones
    b = so3.matmul(cones.V, R)                                     # rows R^T v_i
    c = ev.cross
    h = cones.cos_theta - ev.s
    h_dot = so3.dot(c, Omega[..., None, :])
    c_dot = cross(cross(b, Omega[..., None, :]), np.broadcast_to(cones.r, b.shape))
    f = terms.M_g - cross(Omega, matvec(cfg.J, Omega))
    A = so3.matmul(c, controller.J_inv)                            # J symmetric: rows (J^-1 c_i)^T
    lam = cfg.cbf_rate
    beta = -(so3.dot(c_dot, Omega[..., None, :]) + so3.dot(A, f[..., None, :])
             + 2.0 * lam * h_dot + lam * lam * h)
    if cfg.cbf_moment_bound:                  # the worst unlearnt moment: a_i . d >= -D |a_i|
        beta = beta + cfg.cbf_moment_bound * np.sqrt(so3.dot(A, A))
    return A, beta, h, h_dot, b, f


_SUBSETS: dict = {}


def _active_sets(n):
    """The nonempty sets of at most 3 of n constraints (a moment has 3 components), as index
    tuples, smallest first.
    """
    if n not in _SUBSETS:
        _SUBSETS[n] = [S for k in (1, 2, 3) for S in itertools.combinations(range(n), k)]
    return _SUBSETS[n]


def closest_admissible(u0: np.ndarray, A: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """The moment closest to u0 with A u >= beta (the QP min |u - u0|^2), exactly, by its active
    set: with none active u0 if it is admissible; else the first of the sets of at most 3
    constraints held with equality, smallest first, whose u = u0 + A_S^T lambda,
    (A_S A_S^T) lambda = beta_S - A_S u0, is admissible with lambda >= 0 (one cone: the closed
    form u0 + max(0, beta - a.u0) a / |a|^2). That is the KKT point, and the QP being strictly
    convex it is the optimum: the search stops there. Where no set is admissible (constraints
    that contradict each other), the most violated constraint alone. A batch solves each run on
    its own (a run's answer is kept from its first admissible set, as alone).
    """
    tol = 1e-9
    slack = so3.matvec(A, u0) - beta
    ok = np.all(slack >= -tol, axis=-1)
    if np.all(ok):
        return u0
    n = A.shape[-2]
    best, found = np.array(u0, dtype=float, copy=True), np.array(ok, copy=True)
    for S in _active_sets(n):
        A_S = A[..., S, :]
        G = A_S @ np.swapaxes(A_S, -1, -2)
        rhs = -slack[..., S]
        det = np.linalg.det(G)
        usable = np.abs(det) > 1e-12
        G = np.where(usable[..., None, None], G, np.eye(len(S)))
        lam = np.linalg.solve(G, rhs[..., None])[..., 0]
        u = u0 + np.einsum('...ki,...k->...i', A_S, lam)
        s_all = so3.matvec(A, u) - beta
        good = usable & np.all(lam >= -tol, axis=-1) & np.all(s_all >= -1e-7, axis=-1)
        first = good & ~found
        best = np.where(first[..., None], u, best)
        found = found | good
        if np.all(found):
            break
    stuck = ~found
    if np.any(stuck):                     # the most violated constraint alone
        i = np.argmin(slack, axis=-1)
        a = np.take_along_axis(A, i[..., None, None], axis=-2)[..., 0, :]
        gap = -np.take_along_axis(slack, i[..., None], axis=-1)[..., 0]
        u = u0 + (a.T * (np.maximum(gap, 0.0) / np.maximum(so3.dot(a, a), 1e-12))).T
        best = np.where(stuck[..., None], u, best)
    return best


def cbf_law(controller: Any, R: np.ndarray, Omega: np.ndarray, dt: float, adapt: bool,
            blind: Any) -> Any:
    """The geometric baseline filtered by a control-barrier-function QP on SO(3): the moment
    closest to Lee's geometric controller's that keeps every cone's pointing constraint
    (``pointing_cbf``) with a double pole at -``cbf_rate``, against any unlearnt moment up to
    ``cbf_moment_bound``. With the approach brake on (``approach_brake_rate``), its condition
    for every cone is a constraint of the QP too (``ApproachBrake.rows``): the sampled-data
    margin over the blind time and a hold, against the same unlearnt moment. The estimate adapts
    as the baseline's.
    """
    terms, out = unconstrained(controller, R, Omega, dt, adapt)
    cones = controller.config.cones
    if not len(cones):
        return out
    A, beta, _, _, b, f = pointing_cbf(controller, R, Omega, terms)
    brake = controller.brake
    if brake is not None:
        A_b, beta_b = brake.rows(controller.J_inv, f, b, terms.cones.s, terms.cones.cross,
                                 cones.theta, np.broadcast_to(cones.r, b.shape), Omega, blind, dt)
        A = np.concatenate((A, A_b), axis=-2)
        beta = np.concatenate((beta, beta_b), axis=-1)
    return out._replace(u=closest_admissible(out.u, A, beta))
