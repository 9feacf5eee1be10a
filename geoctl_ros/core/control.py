"""Geometric adaptive attitude control on SO(3) with cone constraints (Kulumani, Poole & Lee).

Notation follows the paper and ../shared/design/control-law.md:

    A     = 1/2 tr(G (I - R_d^T R))                        attractive error (eq. 13)
    e_RA  = 1/2 vee(G R_d^T R - R^T R_d G)                  its gradient (eq. 15)
    Psi   = A (1 + sum_i (B_i - 1))                         configuration error, several cones
    e_R   = e_RA (1 + sum_i (B_i - 1)) + A sum_i e_RB,i     its gradient
    e_Omega = Omega - R^T R_d Omega_d                       (= Omega when stabilising)
    u     = -k_R e_R - k_Omega e_Omega + Omega x J Omega - W Delta_bar - M_g
            [+ the tracking feed-forward]
    Delta_bar' = k_Delta W^T (e_Omega + c e_R)                adaptive law (eq. 39)

J is the inertia about the pivot, M_g the gravity moment of the centre of mass offset rho (both
from ``geoctl_ros.core.mechanics``). The tracking feed-forward
-J (Omega x R^T R_d Omega_d - R^T R_d Omega_d') is the standard one of Lee's geometric tracking
controller; the paper's stability proof covers Omega_d = 0 only.

Discrete time: ``step`` computes u from the estimate Delta_bar_k and then advances the estimate by
one explicit Euler step of the adaptive law over dt (the control period). The estimate is frozen
while any cone's barrier is saturated (the sensor within the floor band or inside a cone, where the
paper's assumptions do not hold) and optionally projected onto a ball so that it cannot wind up.

Batches: with a batched ConeSet (one cone set per run) and stacks of set points, attitudes and
rates (a leading batch axis), ``step`` advances every run at once with the same formulas; this is
how the campaign (``geoctl_ros.campaign.runner``) flies a thousand manoeuvres. The gains, weights
and model are shared by the batch. (``x.T`` on a stack of vectors puts the batch axis last, so
``(x.T * a).T`` scales each run's vector by its own scalar and a single vector by a scalar.)
"""
from dataclasses import dataclass, field
import itertools
from typing import NamedTuple

import numpy as np

from geoctl_ros.core import so3
from geoctl_ros.core.cones import ConeSet
from geoctl_ros.core.feasibility import setpoint_problem
from geoctl_ros.core.flags import any_flag
from geoctl_ros.core.mechanics import cog_regressor, first_moment, gravity_moment, pivot_inertia
from geoctl_ros.core.so3 import cross, matvec, transpose, vee

# Disturbance models: name -> number of estimated parameters (the columns of W).
#   constant:      W = I,                     Delta = a constant moment (the paper's case)
#   constant+cog:  W = [I, -hat(R^T g_w)],    Delta = [constant moment; error of m * rho]
DISTURBANCE_MODELS = {'constant': 3, 'constant+cog': 6}


class SetpointRejected(ValueError):
    """A desired attitude the controller refuses (non-finite, or inside or too close to a cone)."""


@dataclass(frozen=True)
class ControllerConfig:
    """Everything the control law needs; built and validated by ``geoctl_ros.params``."""

    k_R: float
    k_Omega: float
    k_Delta: float
    c: float
    G: np.ndarray                    # (3,) diagonal weights g1, g2, g3
    cones: ConeSet
    inertia: np.ndarray              # (3, 3) about the centre of mass, kg m^2
    mass: float                      # kg
    cog_offset: np.ndarray           # pivot -> centre of mass, body frame, m
    gravity: np.ndarray              # world frame, m/s^2
    adaptive: bool = True
    gravity_compensation: bool = True
    disturbance_model: str = 'constant'
    delta_bar_max: float = 0.0       # bound on |constant estimate| (N m); 0 = none
    cog_estimate_max: float = 0.0    # bound on |m rho estimate| (kg m); 0 = none
    unmodelled_moment_max: float = 0.0   # what a set point must be held against (N m); 0 = none
    blind_guard_max: float = 0.0     # rad, the most a blind loop widens a cone's barrier
    law: str = 'paper'               # the control law, a key of LAWS
    cbf_rate: float = 4.0            # 1/s, the cbf law's double pole
    J: np.ndarray = field(init=False, repr=False)        # inertia about the pivot
    m_rho: np.ndarray = field(init=False, repr=False)    # mass times pivot -> centre of mass

    def __post_init__(self):
        object.__setattr__(self, 'J', pivot_inertia(self.inertia, self.mass, self.cog_offset))
        object.__setattr__(self, 'm_rho', first_moment(self.mass, self.cog_offset))

    @property
    def n_params(self):
        """Number of estimated disturbance parameters (length of Delta_bar)."""
        return DISTURBANCE_MODELS[self.disturbance_model]


class ControlOutput(NamedTuple):
    """One control step's results."""

    u: np.ndarray            # control moment about the pivot, body frame, N m
    e_R: np.ndarray
    e_Omega: np.ndarray
    psi: float
    delta_bar: np.ndarray    # estimate used for this u
    violated: bool           # sensor on or inside a cone
    saturated: bool          # some barrier in its floor band (repulsion saturated)
    adapting: bool           # the estimate was advanced this step
    cones: object = None     # the ConeEval the step used
    half_angles_deg: np.ndarray = None
    # (in a batch, each field has the batch axis first: psi, violated, ... one per run)

    @property
    def margins_deg(self):
        """Per cone: angle between the sensor and the cone's axis minus its half-angle, degrees
        (computed when asked: the node publishes the motor commands first).
        """
        return self.cones.margins_deg(self.half_angles_deg)


def attractive_error(R, R_d, G):
    """A (eq. 13) and e_RA (eq. 15) for the diagonal weights G (3,)."""
    RdtR = so3.matmul(transpose(R_d), R)
    A = 0.5 * so3.dot(1.0 - np.diagonal(RdtR, 0, -2, -1), G)
    M = G[:, None] * RdtR            # G R_d^T R; its transpose is R^T R_d G
    return A, 0.5 * vee(M - transpose(M))


def E_matrix(R, R_d, G):
    """E(R, R_d) of eq. (27): d/dt e_RA = E e_Omega."""
    M = (R.T @ R_d) * G[None, :]     # R^T R_d G
    return 0.5 * (np.trace(M) * np.eye(3) - M)


def configuration_error(R, R_d, G, cones):
    """Psi, e_R, A, e_RA and the cone evaluation at R (Prop. 1 generalised to several cones)."""
    A, e_RA = attractive_error(R, R_d, G)
    ev = cones.evaluate(R)
    psi, e_R = with_cones(A[..., None], e_RA, ev)
    return psi, e_R, A, e_RA, ev


def with_cones(A, e_RA, ev):
    """Psi = A (1 + sum_i (B_i - 1)) and e_R = e_RA (1 + sum_i (B_i - 1)) + A sum_i e_RB,i from
    A (with a trailing axis of 1), e_RA and the cones' evaluation.
    """
    scale = (1.0 - ev.B.shape[-1]) + ev.B.sum(axis=-1, keepdims=True)
    return (A * scale)[..., 0], e_RA * scale + A * ev.e_RB_sum


_BASIS = np.eye(9).reshape(9, 3, 3)       # the unit matrices E_jk


def linear_terms(R, R_d, config):
    """The parts of the law that are affine in R, side by side (..., 5 + 4 n): A, e_RA (3), for
    each cone s_i and (R^T v_i) x r (``ConeSet.terms``), and the gravity moment M_g (3).
    """
    A, e_RA = attractive_error(R, R_d, config.G)
    sc = config.cones.terms(R)
    M_g = gravity_moment(R, config.m_rho, config.gravity)
    parts = [A[..., None], e_RA, sc.reshape(sc.shape[:-2] + (-1,)), M_g]
    batch = np.broadcast_shapes(*(p.shape[:-1] for p in parts))
    return np.concatenate([np.broadcast_to(p, batch + p.shape[-1:]) for p in parts], axis=-1)


def approach_rates(sc, Omega):
    """Per cone, how fast the sensor's angle to the cone's axis is closing (rad/s; negative when
    it opens), from ``ConeSet.terms`` (s_i, (R^T v_i) x r) and Omega: with s_i = cos(phi_i),
    d/dt s_i = -Omega . ((R^T v_i) x r) and sin(phi_i) = |(R^T v_i) x r|.
    """
    cross = sc[..., 1:]
    sin_phi = np.sqrt(so3.dot(cross, cross))
    return -so3.dot(cross, Omega[..., None, :]) / np.maximum(sin_phi, 1e-9)


WIDEN_GAP_SHARE = 0.5     # the widening takes at most this share of the gap to a cone's barrier


def blind_widening(sc, Omega, blind, widening_max, theta_b=None):
    """How much wider (rad) the barrier's cones are for a loop blind for ``blind`` seconds (one
    per run of a batch): what the sensor travels towards each cone in that time at its present
    approach rate, at most widening_max and, given the barrier's half-angles theta_b, at most
    WIDEN_GAP_SHARE of the sensor's gap to each: the barrier is evaluated where the sensor is
    heading, but never at or past its edge, where a widened cone suddenly round the sensor would
    kick it with the barrier's strongest field (a 19 N m yaw command in a campaign run).
    """
    travel = approach_rates(sc, Omega) * np.asarray(blind)[..., None]
    if theta_b is not None:
        gap = np.arccos(np.clip(sc[..., 0], -1.0, 1.0)) - theta_b
        travel = np.minimum(travel, WIDEN_GAP_SHARE * gap)
    return np.clip(travel, 0.0, widening_max)


class LinearMap:
    """``linear_terms`` as one matrix product, ``L vec(R) + y0``: exact, since the terms are affine
    in R, and built at configuration time (a new set point or configuration) by evaluating
    ``linear_terms`` itself on the basis E_jk, so each formula still lives in one place. The hot
    path then gets A, e_RA, every cone's terms and M_g from one small matrix-vector product
    instead of a dozen numpy calls (docs/benchmarks.md, "Benchmarks").
    """

    def __init__(self, R_d, config):
        lead = np.broadcast_shapes(R_d.shape[:-2], config.cones.V.shape[:-2])     # the batch
        self.y0 = linear_terms(np.zeros((3, 3)), R_d, config)
        basis = _BASIS.reshape((9,) + (1,) * len(lead) + (3, 3))
        terms = linear_terms(basis, R_d, config) - self.y0
        self.L = np.ascontiguousarray(np.moveaxis(terms, 0, -1))
        self.n_cones = len(config.cones)

    def __call__(self, R):
        """The terms y = linear_terms(R, R_d, config), to rounding."""
        return matvec(self.L, R.reshape(R.shape[:-2] + (9,))) + self.y0


class AttitudeController:
    """The controller's state (estimate, set point) and its pure-math step."""

    def __init__(self, config):
        self._set_config(config)
        self.delta_bar = np.zeros(config.n_params)
        self.R_d = np.eye(3)
        self.Omega_d = np.zeros(3)
        self.dOmega_d = np.zeros(3)
        self._tracking = False      # Omega_d or its derivative nonzero
        self.gain_scale = 1.0       # of the bandwidth (k_R by its square, k_Omega by it), set by
                                    # the tick past the delay bound (core.step.DegradedMode)

    @property
    def R_d(self):
        """The desired attitude (a stack of them for a batch); setting it rebuilds the linear
        map.
        """
        return self._R_d

    @R_d.setter
    def R_d(self, R_d):
        self._R_d = R_d
        self._linear = LinearMap(R_d, self.config)

    # --- configuration-time operations -------------------------------------------------------
    def setpoint_problem(self, R_d, cones=None):
        """Why R_d cannot be a set point (a sentence), or None if it can (with this
        configuration's cones, or the given ones).
        """
        return setpoint_problem(self.config, self.config.cones if cones is None else cones, R_d)

    def set_setpoint(self, R_d, Omega_d=None, dOmega_d=None):
        """Set the desired attitude (and optionally its angular velocity and acceleration, body
        frame of R_d). Raises SetpointRejected with the reason; the old set point then stays.
        """
        R_d = np.asarray(R_d, dtype=float)
        problem = self.setpoint_problem(R_d)
        if problem:
            raise SetpointRejected(problem)
        self.R_d = R_d.copy()
        self.Omega_d = np.zeros(3) if Omega_d is None else np.asarray(Omega_d, dtype=float).copy()
        self.dOmega_d = (np.zeros(3) if dOmega_d is None
                         else np.asarray(dOmega_d, dtype=float).copy())
        self._tracking = bool(self.Omega_d.any() or self.dOmega_d.any())

    def reset_adaptation(self):
        """Zero the disturbance estimate."""
        self.delta_bar[:] = 0.0

    def reconfigure(self, config):
        """Switch to a new configuration, keeping the estimate when its size still fits.

        Raises SetpointRejected (and changes nothing) if the current set point violates the new
        cones.
        """
        problem = self.setpoint_problem(self.R_d, config.cones)
        if problem:
            raise SetpointRejected('current ' + problem)
        if config.n_params != len(self.delta_bar):
            self.delta_bar = np.zeros(config.n_params)
        self._set_config(config)
        self.R_d = self._R_d
        self._project()

    # --- the hot path ----------------------------------------------------------------------------
    def regressor(self, R):
        """W(R, Omega): 3 x n_params (a stack of them for a batch); None for the constant model,
        where W = I.
        """
        if self.config.disturbance_model == 'constant':
            return None
        Y = cog_regressor(R, self.config.gravity)
        return np.concatenate((np.broadcast_to(np.eye(3), Y.shape), Y), axis=-1)

    def step(self, R, Omega, dt, adapt=True, blind=0.0):
        """One control step at attitude R and body angular velocity Omega, by the configured law
        (``config.law``, one of ``LAWS``).

        dt is the time until the next step (the control period); adapt=False holds the estimate
        (e.g. while disarmed). blind: the time (s; one per run of a batch) over which the loop
        cannot see or correct what the vehicle does beyond its nominal period: a law with the
        barrier then acts on each cone widened by how far the sensor travels towards it in that
        time (``blind_widening``).
        """
        return self._law(self, R, Omega, dt, adapt, blind)

    # --- the pieces every law is made of -------------------------------------------------------
    def terms(self, R, Omega, blind=0.0):
        """The step's terms at (R, Omega): ``StepTerms`` (the attractive error, the cones
        evaluated, widened by the blind time when it is given, and the gravity moment).
        """
        cfg = self.config
        y = self._linear(R)                     # A, e_RA, the cones' terms, M_g (linear_terms)
        n = self._linear.n_cones
        sc = y[..., 4:4 + 4 * n].reshape(y.shape[:-1] + (n, 4))
        widened = None
        if n and any_flag(np.asarray(blind) > 0.0):
            extra = blind_widening(sc, Omega, blind, cfg.blind_guard_max, cfg.cones.theta_b)
            if extra.max() > 0.0:                  # (else no cone is being approached)
                widened = cfg.cones.widened(extra)
        ev = cfg.cones.evaluate_terms(sc, widened)
        return StepTerms(y[..., 0:1], y[..., 1:4], ev, y[..., -3:], self.regressor(R))

    def moment(self, R, Omega, dt, adapt, terms, psi, e_R, barrier=True):
        """The geometric law's moment for the configuration error (psi, e_R), with the adaptive
        estimate advanced: ``ControlOutput``. barrier: the error carries the cones' barrier
        (the estimate then freezes where a barrier saturates).
        """
        cfg = self.config
        ev = terms.cones
        e_Omega = Omega
        tracking = self._tracking
        if tracking:
            RtRd = so3.matmul(transpose(R), self.R_d)
            Omega_d = matvec(RtRd, self.Omega_d)
            e_Omega = Omega - Omega_d
        W = terms.W
        delta_bar = self.delta_bar.copy()
        g = self.gain_scale                     # past the delay bound, below 1 (DegradedMode)
        if np.ndim(g):                          # one per run of a batch
            k_R, k_Omega = (cfg.k_R * g * g)[..., None], (cfg.k_Omega * g)[..., None]
        else:
            k_R, k_Omega = cfg.k_R * g * g, cfg.k_Omega * g
        u = cross(Omega, matvec(cfg.J, Omega)) - k_R * e_R - k_Omega * e_Omega
        u -= delta_bar if W is None else matvec(W, delta_bar)
        if tracking:
            u -= matvec(cfg.J, cross(Omega, Omega_d) - matvec(RtRd, self.dOmega_d))
        if cfg.gravity_compensation:
            u -= terms.M_g
        saturated = ev.any_saturated if barrier else np.zeros_like(ev.any_saturated)
        adapting = adapt and cfg.adaptive and ~saturated      # a flag per run
        if adapting is not False and any_flag(adapting):
            v = e_Omega + cfg.c * e_R
            rate = (dt * cfg.k_Delta) * (v if W is None else matvec(transpose(W), v))
            if rate.ndim > 1:                   # a batch: only the runs that adapt
                rate *= adapting[..., None]
            self.delta_bar += rate
            self._project()
        # violated implies saturated (the floor band lies outside every cone)
        violated = (ev.violated.any(axis=-1) if any_flag(ev.any_saturated)
                    else ev.any_saturated)
        return ControlOutput(u, e_R, e_Omega, psi, delta_bar, violated, saturated,
                             adapting, ev, cfg.cones.theta_deg)

    def _project(self):
        """Project each block of the estimate onto its ball (bounds of 0 mean unbounded)."""
        for block, bound in self._balls:
            part = self.delta_bar[..., block]
            n2 = so3.dot(part, part)
            if any_flag(n2 > bound * bound):
                part *= (bound / np.maximum(np.sqrt(n2), bound))[..., None]

    def _set_config(self, config):
        self.config = config
        self._law = LAWS[config.law]
        self.J_inv = np.linalg.inv(config.J)     # the model's, for the prediction too
        self._balls = [(block, bound) for block, bound in ((slice(0, 3), config.delta_bar_max),
                                                           (slice(3, 6), config.cog_estimate_max))
                       if bound > 0.0 and block.start < config.n_params]


class StepTerms(NamedTuple):
    """What a step computes from the attitude before any law's choice (one per run of a batch)."""

    A: np.ndarray        # attractive error A, with a trailing axis of 1
    e_RA: np.ndarray     # its gradient
    cones: object        # ConeEval: the cones at R (widened by the blind time, if any)
    M_g: np.ndarray      # the model's gravity moment
    W: object            # the regressor W(R) (None for the constant model, W = I)


def paper_law(controller, R, Omega, dt, adapt, blind):
    """The paper's law (Kulumani, Poole & Lee): the configuration error carries every cone's
    log barrier, the cones widened by the blind time (docs/safety.md, "Delay").
    """
    terms = controller.terms(R, Omega, blind)
    psi, e_R = with_cones(terms.A, terms.e_RA, terms.cones)
    return controller.moment(R, Omega, dt, adapt, terms, psi, e_R)


def geometric_law(controller, R, Omega, dt, adapt, blind):
    """Lee's geometric controller on SO(3) with the same gains and no barrier: the attractive
    error alone (the baseline that shows what the barrier buys). The cones are still evaluated,
    so margins and violations are reported.
    """
    terms = controller.terms(R, Omega)
    return controller.moment(R, Omega, dt, adapt, terms, terms.A[..., 0], terms.e_RA,
                             barrier=False)


def pointing_cbf(controller, R, Omega, terms, delta_bar):
    """Each cone as a pointing constraint of relative degree 2, as the rows of A u >= beta.

    h_i = cos(theta_i + guard) - (R^T v_i) . r >= 0 (the sensor outside the guarded cone). With
    b_i = R^T v_i and c_i = b_i x r: b_i' = b_i x Omega, so h_i' = c_i . Omega and
    h_i'' = ((b_i x Omega) x r) . Omega + c_i . Omega', Omega' = J^-1 (u + f) with f = M_g +
    W Delta_bar - Omega x J Omega the model's moment besides u. The exponential CBF condition
    h'' + 2 lambda h' + lambda^2 h >= 0 (a double pole at -lambda, ``cbf_rate``) is then linear in
    u: a_i . u >= beta_i with a_i = J^-1 c_i. Returns (A (..., n, 3), beta (..., n), h, h').
    """
    cfg = controller.config
    cones = cfg.cones
    ev = terms.cones
    b = so3.matmul(cones.V, R)                                     # rows R^T v_i
    c = ev.cross
    h = cones.cos_theta - ev.s
    h_dot = so3.dot(c, Omega[..., None, :])
    c_dot = cross(cross(b, Omega[..., None, :]), np.broadcast_to(cones.r, b.shape))
    W = terms.W
    f = (terms.M_g + (delta_bar if W is None else matvec(W, delta_bar))
         - cross(Omega, matvec(cfg.J, Omega)))
    A = so3.matmul(c, controller.J_inv)                            # J symmetric: rows (J^-1 c_i)^T
    lam = cfg.cbf_rate
    beta = -(so3.dot(c_dot, Omega[..., None, :]) + so3.dot(A, f[..., None, :])
             + 2.0 * lam * h_dot + lam * lam * h)
    return A, beta, h, h_dot


_SUBSETS = {}


def _active_sets(n):
    """The nonempty sets of at most 3 of n constraints (a moment has 3 components), as index
    tuples, smallest first.
    """
    if n not in _SUBSETS:
        _SUBSETS[n] = [S for k in (1, 2, 3) for S in itertools.combinations(range(n), k)]
    return _SUBSETS[n]


def closest_admissible(u0, A, beta):
    """The moment closest to u0 with A u >= beta (the QP min |u - u0|^2), exactly, by its active
    set: with none active u0 if it is admissible; else of the sets of at most 3 constraints held
    with equality, u = u0 + A_S^T lambda, (A_S A_S^T) lambda = beta_S - A_S u0, the admissible
    one with lambda >= 0 closest to u0 (one cone: the closed form u0 + max(0, beta - a.u0) a /
    |a|^2). Where no set is admissible (constraints that contradict each other), the most
    violated constraint alone. A batch solves each run on its own.
    """
    tol = 1e-9
    slack = so3.matvec(A, u0) - beta
    ok = np.all(slack >= -tol, axis=-1)
    if np.all(ok):
        return u0
    n = A.shape[-2]
    best, best_cost = np.array(u0, dtype=float, copy=True), np.where(ok, 0.0, np.inf)
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
        cost = np.where(good, so3.dot(u - u0, u - u0), np.inf)
        better = cost < best_cost
        best = np.where(better[..., None], u, best)
        best_cost = np.where(better, cost, best_cost)
    stuck = ~np.isfinite(best_cost)
    if np.any(stuck):                     # the most violated constraint alone
        i = np.argmin(slack, axis=-1)
        a = np.take_along_axis(A, i[..., None, None], axis=-2)[..., 0, :]
        gap = -np.take_along_axis(slack, i[..., None], axis=-1)[..., 0]
        u = u0 + (a.T * (np.maximum(gap, 0.0) / np.maximum(so3.dot(a, a), 1e-12))).T
        best = np.where(stuck[..., None], u, best)
    return best


def cbf_law(controller, R, Omega, dt, adapt, blind):
    """The geometric baseline filtered by a control-barrier-function QP on SO(3): the moment
    closest to Lee's geometric controller's that keeps every cone's pointing constraint
    (``pointing_cbf``) with a double pole at -``cbf_rate``. The estimate adapts as the
    baseline's.
    """
    terms = controller.terms(R, Omega)
    out = controller.moment(R, Omega, dt, adapt, terms, terms.A[..., 0], terms.e_RA,
                            barrier=False)
    if not len(controller.config.cones):
        return out
    # (with the estimate the moment used, before it advanced)
    A, beta, _, _ = pointing_cbf(controller, R, Omega, terms, out.delta_bar)
    return out._replace(u=closest_admissible(out.u, A, beta))


# The control laws, one signature: law(controller, R, Omega, dt, adapt, blind) -> ControlOutput.
# The ``law`` parameter names one; a new law is a function and a row here, not a new loop.
LAWS = {'paper': paper_law, 'geometric': geometric_law, 'cbf': cbf_law}
