"""The geometric baseline filtered by a control-barrier-function QP: each cone a pointing
constraint of relative degree 2, solved exactly by its active set every step.
"""
import math
from typing import Any, Optional

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


def project(u0: np.ndarray, A: np.ndarray, beta: np.ndarray, tol: float = 1e-9) -> tuple:
    """The point closest to u0 with A u >= beta (min |u - u0|^2; one run: u0 (3,), A (m, 3),
    beta (m,)), exactly, by Goldfarb and Idnani's dual active-set method (Math. Programming 27,
    1983) with the identity for its Hessian: from u0, the most violated constraint is added at
    a time, each step moving u along the part of its normal the active ones leave free, and
    an active constraint whose multiplier would turn negative is dropped. Every iterate keeps
    the multipliers of the active set nonnegative, so when no constraint is violated u is the
    optimum. Returns (u, True), or (u0, False) when the constraints contradict each other.
    """
    u = np.array(u0, dtype=float)
    active: list = []
    lam = np.zeros(0)
    for _ in range(4 * len(beta) + 8):           # (finite: each full step adds, no set recurs)
        slack = A @ u - beta
        p = int(np.argmin(slack))
        if slack[p] >= -tol:
            return u, True
        n_p = A[p]
        lam_p = 0.0
        while True:
            if active:
                N = A[active].T                        # 3 x q
                r = np.linalg.solve(N.T @ N, N.T @ n_p)
                z = n_p - N @ r
            else:
                r, z = np.zeros(0), n_p
            # partial step: the first active multiplier to reach zero
            t1, k = math.inf, -1
            for j in range(len(active)):
                if r[j] > tol and lam[j] / r[j] < t1:
                    t1, k = lam[j] / r[j], j
            zz = float(z @ n_p)
            # (a normal the active ones leave (nearly) no part of: a dual step only)
            t2 = (-(float(n_p @ u) - beta[p]) / zz if zz > 1e-10 * float(n_p @ n_p)
                  else math.inf)
            t = min(t1, t2)
            if t == math.inf:                          # the constraints contradict each other
                return np.array(u0, dtype=float), False
            lam = lam - t * r
            lam_p += t
            if t2 < math.inf:
                u = u + t * z
            if t == t2:                                # full step: p joins the active set
                active.append(p)
                lam = np.append(lam, lam_p)
                break
            del active[k]                              # partial step: k leaves
            lam = np.delete(lam, k)
    return np.array(u0, dtype=float), False


def closest_admissible(u0: np.ndarray, A: np.ndarray, beta: np.ndarray,
                       limits: Optional[tuple] = None) -> np.ndarray:
    """The moment closest to u0 with A u >= beta (the QP min |u - u0|^2; ``project``) and, given
    limits = (A_m, beta_m), within the moments the rotors make unsaturated
    (``Allocator.moment_polytope``). u0 itself where it is admissible. Where the cones' rows and
    the rotors' contradict each other, the cones' alone (the allocation then saturates); where
    the cones' rows contradict each other, the most violated one alone. A batch solves each run
    on its own, so a run gets the same bits alone and in a batch.
    """
    tol = 1e-9
    if limits is not None:
        A_m, beta_m = limits
        A = np.concatenate((A, np.broadcast_to(A_m, A.shape[:-2] + A_m.shape)), axis=-2)
        beta = np.concatenate((beta, np.broadcast_to(beta_m, beta.shape[:-1] + beta_m.shape)),
                              axis=-1)
    slack = so3.matvec(A, u0) - beta
    ok = np.all(slack >= -tol, axis=-1)
    if np.all(ok):
        return u0
    cones = A.shape[-2] - (0 if limits is None else len(limits[1]))
    out = np.array(u0, dtype=float, copy=True)
    for i in zip(*np.nonzero(~np.asarray(ok))) if out.ndim > 1 else [()]:
        u, feasible = project(u0[i], A[i], beta[i])
        if not feasible and limits is not None:
            u, feasible = project(u0[i], A[i][:cones], beta[i][:cones])
        if not feasible:                        # the most violated constraint alone
            j = int(np.argmin(slack[i][:cones]))
            a = A[i][j]
            u = u0[i] + a * (max(-slack[i][j], 0.0) / max(float(a @ a), 1e-12))
        out[i] = u
    return out


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
                                 cones.theta, cones.r, Omega, blind, dt)
        A = np.concatenate((A, A_b), axis=-2)
        beta = np.concatenate((beta, beta_b), axis=-1)
    return out._replace(u=closest_admissible(out.u, A, beta, controller.config.moment_limits))
