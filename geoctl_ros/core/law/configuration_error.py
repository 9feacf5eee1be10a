"""The configuration error of the paper's law (notation: ``geoctl_ros.core.law.control``): the
attractive error A and its gradient e_RA, the cones' barrier folded in (Psi, e_R), the step's
linear map of R, and the barrier's widening by the blind time.
"""

from typing import List, Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.elementwise import ARRAYS, FLOATS, Ops, Value
from geoctl_ros.core.geometry.flags import any_flag
from geoctl_ros.core.geometry.so3 import FloatArray, Scalars, matvec, transpose, vee
from geoctl_ros.core.law.cones import ConeEval, ConeSet, barrier_constants, log_barrier
from geoctl_ros.core.law.controller_config import ControllerConfig
from geoctl_ros.core.law.mechanics import gravity_moment


def attractive_error(R: FloatArray, R_d: FloatArray,
                     G: FloatArray) -> Tuple[Scalars, FloatArray]:
    """A (eq. 13) and e_RA (eq. 15) for the diagonal weights G (3,)."""
    RdtR = so3.matmul(transpose(R_d), R)
    A = 0.5 * so3.dot(1.0 - np.diagonal(RdtR, 0, -2, -1), G)
    M = G[:, None] * RdtR            # G R_d^T R; its transpose is R^T R_d G
    return A, 0.5 * vee(M - transpose(M))


def with_cones(A: FloatArray, e_RA: FloatArray, ev: ConeEval) -> Tuple[Scalars, FloatArray]:
    """Psi = A (1 + sum_i (B_i - 1)) and e_R = e_RA (1 + sum_i (B_i - 1)) + A sum_i e_RB,i from
    A (with a trailing axis of 1), e_RA and the cones' evaluation.
    """
    B = ev.B
    if B.ndim == 1:                     # one run (the node's step): its one sum as a float
        scale = (1.0 - len(B)) + B.sum()
        return A[0] * scale, e_RA * scale + A * ev.e_RB_sum
    scale = (1.0 - B.shape[-1]) + B.sum(axis=-1, keepdims=True)
    return (A * scale)[..., 0], e_RA * scale + A * ev.e_RB_sum


_BASIS = np.eye(9).reshape(9, 3, 3)       # the unit matrices E_jk


def linear_terms(R: FloatArray, R_d: FloatArray, config: ControllerConfig) -> FloatArray:
    """The parts of the law that are affine in R, side by side (..., 5 + 4 n): A, e_RA (3), for
    each cone s_i and (R^T v_i) x r (``ConeSet.terms``), and the gravity moment M_g (3).
    """
    A, e_RA = attractive_error(R, R_d, config.G)
    sc = config.cones.terms(R)
    M_g = gravity_moment(R, config.m_rho, config.gravity)
    parts = [cast(FloatArray, A)[..., None], e_RA, sc.reshape(sc.shape[:-2] + (-1,)), M_g]
    batch = np.broadcast_shapes(*(p.shape[:-1] for p in parts))
    return np.concatenate([np.broadcast_to(p, batch + p.shape[-1:]) for p in parts], axis=-1)


def approach_rate(ops: Ops, c0: Value, c1: Value, c2: Value, w0: Value, w1: Value,
                  w2: Value) -> Value:
    """How fast the sensor's angle to a cone's axis is closing (rad/s; negative when it opens;
    an ``elementwise`` formula), from the cone's (R^T v_i) x r = (c0, c1, c2) (``ConeSet.terms``)
    and Omega: with s_i = cos(phi_i), d/dt s_i = -Omega . ((R^T v_i) x r) and
    sin(phi_i) = |(R^T v_i) x r|.
    """
    sin_phi = ops.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    return -(c0 * w0 + c1 * w1 + c2 * w2) / ops.maximum(sin_phi, 1e-9)


def approach_rates(sc: FloatArray, Omega: FloatArray) -> FloatArray:
    """``approach_rate`` of every cone, from ``ConeSet.terms`` (s_i, (R^T v_i) x r) and Omega."""
    return cast(FloatArray, approach_rate(ARRAYS, sc[..., 1], sc[..., 2], sc[..., 3],
                                          Omega[..., None, 0], Omega[..., None, 1],
                                          Omega[..., None, 2]))


WIDEN_GAP_SHARE = 0.5     # the widening takes at most this share of the gap to a cone's barrier


def widening(ops: Ops, s: Value, rate: Value, blind: Value, widening_max: float,
             theta_b: Optional[Value]) -> Value:
    """How much wider (rad) a cone's barrier is for a loop blind for ``blind`` seconds (an
    ``elementwise`` formula): what the sensor travels towards the cone in that time at its
    approach rate (``approach_rate``), at most widening_max and, given the barrier's half-angle
    theta_b, at most WIDEN_GAP_SHARE of the sensor's gap to it (s: the cosine of the sensor's
    angle to the axis).
    """
    travel = rate * blind
    if theta_b is not None:
        gap = ops.arccos(ops.minimum(ops.maximum(s, -1.0), 1.0)) - theta_b
        travel = ops.minimum(travel, WIDEN_GAP_SHARE * gap)
    return ops.minimum(ops.maximum(travel, 0.0), widening_max)


def blind_widening(sc: FloatArray, Omega: FloatArray, blind: Scalars, widening_max: float,
                   theta_b: Optional[FloatArray] = None) -> FloatArray:
    """How much wider (rad) the barrier's cones are for a loop blind for ``blind`` seconds (one
    per run of a batch; ``widening`` of every cone): the barrier is evaluated where the sensor is
    heading, but never at or past its edge, where a widened cone suddenly round the sensor would
    kick it with the barrier's strongest field (a 19 N m yaw command in a campaign run).
    """
    return cast(FloatArray, widening(ARRAYS, sc[..., 0], approach_rates(sc, Omega),
                                     np.asarray(blind)[..., None], widening_max, theta_b))


def barrier_at_step(cones: ConeSet, sc: FloatArray, Omega: FloatArray, blind: Scalars,
                    widening_max: float) -> ConeEval:
    """The cones' barrier at the step from their terms sc (``ConeSet.terms``), each widened by
    the blind time (``blind_widening``; none where blind is 0 or no cone is being approached):
    ``ConeSet.evaluate_terms``. One run's few cones (up to FLOATS_CONES) go cone by cone in
    floats, by the same formulas (``barrier_floats``), a batch's in arrays.
    """
    n = len(cones)
    if n and sc.shape[:-2] in ((), (1,)) and n <= FLOATS_CONES and cones.constants_floats:
        ev = barrier_floats(cones, sc, Omega, blind, widening_max)
        if ev is not None:
            return ev
    widened = None
    if n and (blind > 0.0 if isinstance(blind, float) else any_flag(np.asarray(blind) > 0.0)):
        extra = blind_widening(sc, Omega, blind, widening_max, cones.theta_b)
        if extra.max() > 0.0:                  # (else no cone is being approached)
            widened = cones.widened(extra)
    return cones.evaluate_terms(sc, widened)


FLOATS_CONES = 4       # one run's cones up to which the barrier is worked out in floats


def barrier_floats(cones: ConeSet, sc: FloatArray, Omega: FloatArray, blind: Scalars,
                   widening_max: float) -> Optional[ConeEval]:
    """``barrier_at_step`` for one run (sc (n, 4), or a batch of one's (1, n, 4)) in floats, cone
    by cone: the same formulas (``approach_rate``, ``widening``, ``barrier_constants``,
    ``log_barrier``) and so the same bits as the arrays; None where a cone is in its floor band
    (the extension's arrays then).
    """
    lead = sc.shape[:-2]
    rows = (sc if not lead else sc[0]).tolist()
    blind_ = float(blind) if isinstance(blind, float) else float(np.asarray(blind).reshape(-1)[0])
    w0, w1, w2 = (Omega if Omega.ndim == 1 else Omega[0]).tolist()
    B, weight = [], []
    total: List[float] = []          # sum_i weight_i ((R^T v_i) x r), as vecmat sums it
    inv_alpha = 1.0 / cones.alpha
    for (s, c0, c1, c2), theta_b, constants in zip(rows, cones.theta_b_floats,
                                                   cones.constants_floats):
        cos_theta: Value
        g0: Value
        B_offset: Value
        cos_theta, g0, B_offset = constants[:3]
        if blind_ > 0.0:
            extra = widening(FLOATS, s, approach_rate(FLOATS, c0, c1, c2, w0, w1, w2), blind_,
                             widening_max, theta_b)
            if extra > 0.0:
                cos_theta, g0, B_offset = barrier_constants(FLOATS, theta_b + extra,
                                                            cones.floor, cones.alpha)[:3]
        g = cos_theta - s
        if g < g0:
            return None
        b, w = log_barrier(FLOATS, g, B_offset, inv_alpha)
        B.append(b)
        weight.append(w)
        term = [w * c0, w * c1, w * c2]
        total = term if not total else [total[k] + term[k] for k in range(3)]
    shape = lead + (len(B),)
    saturated = np.zeros(shape, dtype=bool)
    return ConeEval(sc[..., 0], np.array(B).reshape(shape), sc[..., 1:],
                    np.array(weight).reshape(shape), saturated, saturated,
                    np.zeros(lead, dtype=bool)[()], e_RB_sum=np.array(total).reshape(lead + (3,)))


class LinearMap:
    """``linear_terms`` as one matrix product, ``L vec(R) + y0``: exact, since the terms are affine
    in R, and built at configuration time (a new set point or configuration) by evaluating
    ``linear_terms`` itself on the basis E_jk, so each formula still lives in one place. The hot
    path then gets A, e_RA, every cone's terms and M_g from one small matrix-vector product
    instead of a dozen numpy calls (docs/speed.md).
    """

    def __init__(self, R_d: FloatArray, config: ControllerConfig) -> None:
        lead = np.broadcast_shapes(R_d.shape[:-2], config.cones.V.shape[:-2])     # the batch
        self.y0 = linear_terms(np.zeros((3, 3)), R_d, config)
        basis = _BASIS.reshape((9,) + (1,) * len(lead) + (3, 3))
        terms = linear_terms(basis, R_d, config) - self.y0
        self.L = np.ascontiguousarray(np.moveaxis(terms, 0, -1))
        self.n_cones = len(config.cones)

    def __call__(self, R: FloatArray) -> FloatArray:
        """The terms y = linear_terms(R, R_d, config), to rounding."""
        return matvec(self.L, R.reshape(R.shape[:-2] + (9,))) + self.y0

    def retargeted(self, R_d: FloatArray, G: FloatArray) -> 'LinearMap':
        """This map for another set point R_d (guidance's next): only A and e_RA, its first four
        rows, depend on the set point, so only they are evaluated again, by ``attractive_error``
        on the same basis (the same bits as a map built anew, at a third of the cost).
        """
        lead = self.y0.shape[:-1]
        new = object.__new__(LinearMap)
        new.n_cones = self.n_cones
        A0, e0 = attractive_error(np.zeros((3, 3)), R_d, G)
        A, e = attractive_error(_BASIS.reshape((9,) + (1,) * len(lead) + (3, 3)), R_d, G)
        at_zero = np.concatenate([np.broadcast_to(A0, lead)[..., None],
                                  np.broadcast_to(e0, lead + (3,))], axis=-1)
        rows = np.concatenate([np.broadcast_to(A, (9,) + lead)[..., None],
                               np.broadcast_to(e, (9,) + lead + (3,))], axis=-1) - at_zero
        new.y0 = self.y0.copy()
        new.y0[..., 0:4] = at_zero
        new.L = self.L.copy()
        new.L[..., 0:4, :] = np.moveaxis(rows, 0, -1)
        return new

