"""The geometric baseline filtered by a control-barrier-function QP: each cone a pointing
constraint of relative degree 2, solved exactly by its active set every step.
"""
from typing import Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import FloatArray, cross, matvec
from geoctl_ros.core.law.brake import BrakeInputs, braked
from geoctl_ros.core.law.projection import Polytope, closest_admissible
from geoctl_ros.core.law.step_types import ControlOutput, Law, LawModel, StepTerms


def pointing_cbf(model: LawModel, R: FloatArray, Omega: FloatArray,
                 terms: StepTerms) -> Tuple[FloatArray, FloatArray, FloatArray, FloatArray,
                                            FloatArray, FloatArray]:
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
    cfg = model.config
    cones = cfg.cones
    ev = terms.cones
    b = cones.axes_in_body(R)                                      # rows R^T v_i
    c = ev.cross
    h = cones.cos_theta - ev.s
    h_dot = so3.dot(c, Omega[..., None, :])
    c_dot = cross(cross(b, Omega[..., None, :]), np.broadcast_to(cones.r, b.shape))
    f = terms.M_g - cross(Omega, matvec(cfg.J, Omega))
    A = so3.vecmat(c, model.J_inv)        # J symmetric: rows (J^-1 c_i)^T = c_i^T J^-1 (no BLAS)
    lam = cfg.cbf_rate
    beta = -(so3.dot(c_dot, Omega[..., None, :]) + so3.dot(A, f[..., None, :])
             + 2.0 * lam * h_dot + lam * lam * h)
    if cfg.cbf_moment_bound:                  # the worst unlearnt moment: a_i . d >= -D |a_i|
        beta = beta + cfg.cbf_moment_bound * np.sqrt(so3.dot(A, A))
    return A, beta, h, h_dot, b, f


def cbf_filter(out: ControlOutput, terms: StepTerms, R: FloatArray, Omega: FloatArray,
               model: LawModel, brake: Optional[BrakeInputs]) -> ControlOutput:
    """Lee's geometric moment (``out``, the attractive error alone; the estimate adapts as the
    baseline's) filtered by a control-barrier-function QP on SO(3): the moment closest to it that
    keeps every cone's pointing constraint (``pointing_cbf``) with a double pole at -``cbf_rate``,
    against any unlearnt moment up to ``cbf_moment_bound``, within the rotors' limits. With the
    approach brake on (``approach_brake``; brake: its inputs of the tick, or None), its condition
    for every cone joins the QP (``core.law.brake.braked``).
    """
    cfg = model.config
    if not len(cfg.cones):
        return out
    A, beta = pointing_cbf(model, R, Omega, terms)[:2]
    if brake is None or model.brake is None:
        return out._replace(u=closest_admissible(out.u, A, beta, cfg.moment_limits))
    b = braked(model.brake, cfg.cones, model.J_inv, cast(Polytope, cfg.moment_limits),
               brake, out.u, (A, beta))
    return out._replace(u=b.u, braking=b.braking, brake_unmet=b.unmet)


CBF = Law(barrier=False, widened=False, filter=cbf_filter)
