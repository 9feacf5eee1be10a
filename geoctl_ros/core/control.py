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
how the campaign (``geoctl_ros.tools.campaign``) flies a thousand manoeuvres. The gains, weights
and model are shared by the batch. (``x.T`` on a stack of vectors puts the batch axis last, so
``(x.T * a).T`` scales each run's vector by its own scalar and a single vector by a scalar.)
"""
from dataclasses import dataclass, field
import math
from typing import NamedTuple

import numpy as np

from geoctl_ros.core import so3
from geoctl_ros.core.cones import ConeSet
from geoctl_ros.core.flags import any_flag
from geoctl_ros.core.mechanics import cog_regressor, first_moment, gravity_moment, pivot_inertia
from geoctl_ros.core.so3 import cross, matvec, transpose, vee

# Disturbance models: name -> number of estimated parameters (the columns of W).
#   constant:      W = I,                     Delta = a constant moment (the paper's case)
#   constant+cog:  W = [I, -hat(R^T g_w)],    Delta = [constant moment; error of m * rho]
DISTURBANCE_MODELS = {'constant': 3, 'constant+cog': 6}
PREDICT_SLOW_S = 0.25     # s, what delay compensation counts as the model's slow error


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
    RdtR = transpose(R_d) @ R
    A = 0.5 * ((1.0 - np.diagonal(RdtR, 0, -2, -1)) @ G)
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


class LinearMap:
    """``linear_terms`` as one matrix product, ``L vec(R) + y0``: exact, since the terms are affine
    in R, and built at configuration time (a new set point or configuration) by evaluating
    ``linear_terms`` itself on the basis E_jk, so each formula still lives in one place. The hot
    path then gets A, e_RA, every cone's terms and M_g from one small matrix-vector product
    instead of a dozen numpy calls (README, "Benchmarks").
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


def smallest_pair_sum(G):
    """min_{i != j} (g_i + g_j): the least A can grow per (1 - cos) of a rotation's angle,
    A = (1 - cos phi) (tr G - n^T G n) / 2 (the paper's h_1).
    """
    g = np.sort(np.asarray(G, dtype=float))
    return float(g[0] + g[1])


def holding_moment(config, cones, R_d):
    """Per cone: the largest moment its barrier can oppose near the cone, with the set point R_d.

    The repulsion k_R A e_RB,i is largest in the floor band (and inside, where it keeps the band's
    magnitude): k_R A sin(theta_i) / (alpha g0_i). It is proportional to the attitude error A,
    so it is weakest near the goal: where the sensor meets the (guarded) cone, the body has turned
    at least the set point's clearance c_i from that cone away from R_d, and A is then at least
    (1 - cos c_i) (g_a + g_b) / 2 (g_a, g_b the two smallest weights). An unlearnt moment larger
    than this (a disturbance, an error in the model of gravity, before the adaptive estimate has
    caught up) holds the sensor in the cone: the campaign's creep class (README, "Safety
    campaign").
    """
    if not len(cones):
        return np.zeros(0)
    c = np.maximum(np.radians(cones.margins_deg(R_d)) - cones.guard, 0.0)
    A_min = 0.5 * (1.0 - np.cos(c)) * smallest_pair_sum(config.G)
    return config.k_R * A_min * np.sin(cones.theta_b) / (cones.alpha * cones.g0)


def holding_clearance_deg(config, cones, moment):
    """Per cone: the set point's clearance (degrees from the real cone) at which
    ``holding_moment`` equals moment.
    """
    x = (2.0 * moment * cones.alpha * cones.g0
         / (config.k_R * smallest_pair_sum(config.G) * np.sin(cones.theta_b)))
    return np.degrees(np.arccos(np.clip(1.0 - x, -1.0, 1.0)) + cones.guard)


class AttitudeController:
    """The controller's state (estimate, set point) and its pure-math step."""

    def __init__(self, config):
        self._set_config(config)
        self._acc_slow = 0.0              # slow part of the model's acceleration (see predict)
        self.delta_bar = np.zeros(config.n_params)
        self.R_d = np.eye(3)
        self.Omega_d = np.zeros(3)
        self.dOmega_d = np.zeros(3)
        self._tracking = False      # Omega_d or its derivative nonzero

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
        """Why R_d cannot be a set point (a sentence), or None if it can."""
        cones = self.config.cones if cones is None else cones
        if not np.all(np.isfinite(R_d)):
            return 'setpoint is not finite'
        if not len(cones):
            return None
        margins = cones.margins_deg(R_d)
        floor_deg = math.degrees(cones.floor + cones.guard)    # the barrier's band, guard included
        i = int(np.argmin(margins))
        if margins[i] < floor_deg:
            where = 'inside' if margins[i] < 0 else 'within %.2f deg of' % floor_deg
            return ('setpoint puts the sensor axis %s cone %r (angle to its axis %.2f deg, '
                    'half-angle %.2f deg)' % (where, cones.names[i],
                                              margins[i] + math.degrees(cones.theta[i]),
                                              math.degrees(cones.theta[i])))
        moment = self.config.unmodelled_moment_max
        if moment > 0.0:
            held = holding_moment(self.config, cones, R_d)
            i = int(np.argmin(held - moment))
            if held[i] < moment:
                need = holding_clearance_deg(self.config, cones, moment)[i]
                return ('setpoint is %.2f deg clear of cone %r; against unmodelled_moment_max = '
                        '%.3g N m its barrier holds only %.3g N m near the goal, %.1f deg is '
                        'needed' % (margins[i], cones.names[i], moment, held[i], need))
        return None

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
    def predict(self, R, Omega, age_R, age_Omega, moment, dt):
        """Delay compensation: the attitude and rate at the control tick from measurements age_R
        and age_Omega seconds old (scalars, or one per run of a batch), given the moment the rotors
        produce (the last allocation's). Ages of 0 return the measurements unchanged.

        The angular acceleration is the model's, J^-1 (moment + M_g(R) + W Delta_bar - Omega x J
        Omega) (Delta_bar standing for the disturbance it estimates), less its own slow part
        (low-pass, time constant PREDICT_SLOW_S; dt is the time since the last call), held over the
        age: Omega <- Omega + age_Omega Omega', R <- R exp(hat(Omega + age_R Omega' / 2) age_R).
        The slow part is what the model gets wrong at rest: there the true acceleration is zero
        while the model's is J^-1 times the moment not yet learnt (k_R e_R of the steady error);
        predicting with it would soften the attitude loop (the demo's final error went from 5.5 to
        15 deg). The fast part, which the delay turns into lost damping, is kept. A measurement 10
        ms old on the testbed, with its 40 ms motor lag, otherwise costs the rate loop most of its
        phase margin (README, "Safety campaign").
        """
        cfg = self.config
        W = self.regressor(R)
        acc = matvec(self._J_inv, moment + gravity_moment(R, cfg.m_rho, cfg.gravity)
                     + (self.delta_bar if W is None else matvec(W, self.delta_bar))
                     - cross(Omega, matvec(cfg.J, Omega)))
        self._acc_slow = self._acc_slow + (acc - self._acc_slow) * (dt / (PREDICT_SLOW_S + dt))
        acc = acc - self._acc_slow
        acc_R = (acc.T * age_R).T
        Omega_now = Omega + (acc.T * age_Omega).T
        return R @ so3.exp(((Omega + 0.5 * acc_R).T * age_R).T), Omega_now

    def regressor(self, R):
        """W(R, Omega): 3 x n_params (a stack of them for a batch); None for the constant model,
        where W = I.
        """
        if self.config.disturbance_model == 'constant':
            return None
        Y = cog_regressor(R, self.config.gravity)
        return np.concatenate((np.broadcast_to(np.eye(3), Y.shape), Y), axis=-1)

    def step(self, R, Omega, dt, adapt=True):
        """One control step at attitude R and body angular velocity Omega.

        dt is the time until the next step (the control period); adapt=False holds the estimate
        (e.g. while disarmed).
        """
        cfg = self.config
        y = self._linear(R)                     # A, e_RA, the cones' terms, M_g (linear_terms)
        A, e_RA = y[..., 0:1], y[..., 1:4]
        n = self._linear.n_cones
        ev = cfg.cones.evaluate_terms(y[..., 4:4 + 4 * n].reshape(y.shape[:-1] + (n, 4)))
        psi, e_R = with_cones(A, e_RA, ev)
        e_Omega = Omega
        tracking = self._tracking
        if tracking:
            RtRd = transpose(R) @ self.R_d
            Omega_d = matvec(RtRd, self.Omega_d)
            e_Omega = Omega - Omega_d
        W = self.regressor(R)
        delta_bar = self.delta_bar.copy()
        u = cross(Omega, matvec(cfg.J, Omega)) - cfg.k_R * e_R - cfg.k_Omega * e_Omega
        u -= delta_bar if W is None else matvec(W, delta_bar)
        if tracking:
            u -= matvec(cfg.J, cross(Omega, Omega_d) - matvec(RtRd, self.dOmega_d))
        if cfg.gravity_compensation:
            u -= y[..., -3:]
        saturated = ev.any_saturated
        adapting = adapt and cfg.adaptive and ~saturated      # a flag per run
        if adapting is not False and any_flag(adapting):
            v = e_Omega + cfg.c * e_R
            rate = (dt * cfg.k_Delta) * (v if W is None else matvec(transpose(W), v))
            if rate.ndim > 1:                   # a batch: only the runs that adapt
                rate *= adapting[..., None]
            self.delta_bar += rate
            self._project()
        # violated implies saturated (the floor band lies outside every cone)
        violated = ev.violated.any(axis=-1) if any_flag(saturated) else saturated
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
        self._J_inv = np.linalg.inv(config.J)
        self._balls = [(block, bound) for block, bound in ((slice(0, 3), config.delta_bar_max),
                                                           (slice(3, 6), config.cog_estimate_max))
                       if bound > 0.0 and block.start < config.n_params]


@dataclass
class GainCheck:
    """The upper bounds on c of Prop. 5 on an operating domain, and whether c respects them."""

    c: float
    c_max_paper: float          # 4 k_R k_Omega / (k_Omega^2 + 4 k_R lambda_M H), eq. (40)
    c_max_dissertation: float   # sqrt(2 lambda_m k_R n_1 / lambda_M^2)
    H: float
    psi_max: float
    margin_deg: float

    @property
    def c_max(self):
        return min(self.c_max_paper, self.c_max_dissertation)

    @property
    def ok(self):
        return 0.0 < self.c < self.c_max

    def message(self):
        verdict = 'satisfies' if self.ok else 'VIOLATES'
        return ('c = %.4g %s the sufficient condition of Prop. 5: c < min(%.4g (paper eq. 40, '
                'H = %.4g), %.4g (dissertation)) on the domain Psi < %.3g, every cone at least '
                '%.1f deg clear' % (self.c, verdict, self.c_max_paper, self.H,
                                    self.c_max_dissertation, self.psi_max, self.margin_deg))


def gain_condition(config, margin_deg=5.0):
    """Evaluate the bound on c of Prop. 5 (eq. 40 with "4k - R" read as 4 k_R, and the
    dissertation's second bound) on the domain D of Prop. 4.

    D is taken as Psi < psi with psi = h_1 (the largest the proposition allows) and every cone at
    least margin_deg clear (beta_i = cos(theta_i + margin)). The bounds of Prop. 4 are summed over
    the cones. The condition is sufficient, not necessary: a violation is a warning.
    """
    g = np.asarray(config.G, dtype=float)
    pairs = [(0, 1), (1, 2), (2, 0)]
    h1 = smallest_pair_sum(g)
    # |e_RA|^2 <= A / b1. The paper's Prop. 1 (v) prints b1 = h1 / (h2 + h3) with the minima of
    # (g_i - g_j)^2 and (g_i + g_j)^2; that is not a bound (for G = diag(0.9, 1.1, 1.0), sampled
    # |e_RA|^2 / A reaches 2.099 > 1/b1 = 1.905). With the maxima, as the dissertation's n1, it is.
    b1 = n1 = h1 / (max((g[i] - g[j]) ** 2 for i, j in pairs)
                    + max((g[i] + g[j]) ** 2 for i, j in pairs))
    psi = h1
    c_A = c_B = psi
    E_bound = float(g.sum()) / math.sqrt(2.0)
    eRA_bound = math.sqrt(psi / b1)
    cones = config.cones
    eRB_sum = F_sum = 0.0
    for theta in cones.theta_b:
        beta = math.cos(theta + math.radians(margin_deg))
        d = beta - math.cos(theta)
        # |e_RB| = sin(angle) / (alpha (cos theta - cos angle)); on the domain (angle >= theta +
        # margin) it is largest at angle = theta + margin, so sin(theta + margin), not sin(theta)
        eRB_sum += math.sin(theta + math.radians(margin_deg)) / (config.cones.alpha * -d)
        F_sum += (((beta ** 2 + 1.0) * d ** 2 + 1.0 + beta ** 2 * (beta ** 2 - 2.0))
                  / (cones.alpha ** 2 * d ** 4))
    H = c_B * E_bound + 2.0 * eRA_bound * eRB_sum + c_A * F_sum
    eig = np.linalg.eigvalsh(config.J)
    lam_m, lam_M = float(eig[0]), float(eig[-1])
    c_paper = (4.0 * config.k_R * config.k_Omega
               / (config.k_Omega ** 2 + 4.0 * config.k_R * lam_M * H))
    c_diss = math.sqrt(2.0 * lam_m * config.k_R * n1 / lam_M ** 2)
    return GainCheck(c=config.c, c_max_paper=c_paper, c_max_dissertation=c_diss, H=H,
                     psi_max=psi, margin_deg=margin_deg)
