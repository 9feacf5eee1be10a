"""Geometric adaptive attitude control on SO(3) with cone constraints (Kulumani, Poole & Lee).

Notation follows the paper and ../shared/design/control-law.md:

    A     = 1/2 tr(G (I - R_d^T R))                        attractive error (eq. 13)
    e_RA  = 1/2 vee(G R_d^T R - R^T R_d G)                  its gradient (eq. 15)
    Psi   = A (1 + sum_i (B_i - 1))                         configuration error, several cones
    e_R   = e_RA (1 + sum_i (B_i - 1)) + A sum_i e_RB,i     its gradient
    e_Omega = Omega - R^T R_d Omega_d                       (= Omega when stabilising)
    u     = -k_R e_R - k_Omega e_Omega + Omega x J Omega - W Delta_bar - M_g
            [+ the tracking feed-forward]
    Delta_bar' = Gamma W^T (e_Omega + c e_R)                  adaptive law (eq. 39)

Gamma is the adaptation gain: k_Delta for the constant moment (the paper's scalar) and, with the
constant+cog model, k_Delta_cog for the m*rho block, whose regressor -hat(R^T g_w) is |g| (about
10) times larger: one scalar for both would learn m*rho some 100 times faster than the moment
(docs/control-law.md, "Gravity moment"). A positive diagonal Gamma leaves Prop. 5's argument as
it is, with 1/2 Delta_tilde^T Gamma^-1 Delta_tilde in the Lyapunov function.

J is the inertia about the pivot, M_g the gravity moment of the centre of mass offset rho (both
from ``geoctl_ros.core.law.mechanics``). The tracking feed-forward
-J (Omega x R^T R_d Omega_d - R^T R_d Omega_d') is the standard one of Lee's geometric tracking
controller; the paper's stability proof covers Omega_d = 0 only.

Discrete time: ``step`` computes u from the estimate Delta_bar_k and then advances the estimate by
one explicit Euler step of the adaptive law over dt (the control period): the stage ``adapted``, a
pure function of the estimate and the step's output (the control tick runs it as a stage of its
own). The estimate is frozen
while any cone's barrier is saturated (the sensor within the floor band or inside a cone, where the
paper's assumptions do not hold) and optionally projected onto a ball so that it cannot wind up.

Batches: with a batched ConeSet (one cone set per run) and stacks of set points, attitudes and
rates (a leading batch axis), ``step`` advances every run at once with the same formulas; this is
how the campaign (``geoctl_ros.campaign.runner``) flies a thousand manoeuvres. The gains, weights
and model are shared by the batch. (``x.T`` on a stack of vectors puts the batch axis last, so
``(x.T * a).T`` scales each run's vector by its own scalar and a single vector by a scalar.)
"""
import math
from typing import NamedTuple, Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.flags import any_flag
from geoctl_ros.core.geometry.so3 import BoolArray, FloatArray, Scalars, cross, matvec, transpose
from geoctl_ros.core.law.brake import ApproachBrake, BrakeInputs
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.configuration_error import LinearMap, barrier_at_step, with_cones
from geoctl_ros.core.law.controller_config import DISTURBANCE_MODELS, ControllerConfig
from geoctl_ros.core.law.dynamics import Dynamics, ModelParts
from geoctl_ros.core.law.feasibility import setpoint_problem
from geoctl_ros.core.law.guidance import Guidance
from geoctl_ros.core.law.laws import LAWS
from geoctl_ros.core.law.step_types import ControlOutput, LawModel, StepTerms

__all__ = ['DISTURBANCE_MODELS', 'AttitudeController', 'ControlOutput', 'ControllerConfig',
           'SetpointRejected', 'StepTerms']

class SetpointRejected(ValueError):
    """A desired attitude the controller refuses (non-finite, or inside or too close to a cone)."""


class AttitudeController:
    """The controller's state (estimate, set point) and its pure-math step."""

    def __init__(self, config: ControllerConfig) -> None:
        self._set_config(config)
        self.delta_bar = np.zeros(config.n_params)
        self.R_d = np.eye(3)
        self.Omega_d = np.zeros(3)
        self.dOmega_d = np.zeros(3)
        self._tracking = False      # Omega_d or its derivative nonzero

    @property
    def R_d(self) -> FloatArray:
        """The desired attitude (a stack of them for a batch); setting it rebuilds the linear
        map.
        """
        return self._R_d

    @R_d.setter
    def R_d(self, R_d: FloatArray) -> None:
        self._R_d = R_d
        self._linear = LinearMap(R_d, self.config)
        self._carrot: Optional[FloatArray] = None
        if self.guidance is not None:
            self.guidance.reset()

    def replan(self) -> None:
        """Plan guidance's way to R_d again from the attitude of the next step (at arming)."""
        if self.guidance is not None:
            self.guidance.reset()
            self._linear = LinearMap(self._R_d, self.config)
            self._carrot = None

    # --- configuration-time operations -------------------------------------------------------
    def setpoint_problem(self, R_d: FloatArray, cones: Optional[ConeSet] = None) -> Optional[str]:
        """Why R_d cannot be a set point (a sentence), or None if it can (with this
        configuration's cones, or the given ones).
        """
        return setpoint_problem(self.config, self.config.cones if cones is None else cones, R_d)

    def set_setpoint(self, R_d: FloatArray, Omega_d: Optional[FloatArray] = None,
                     dOmega_d: Optional[FloatArray] = None) -> None:
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

    def reset_adaptation(self) -> None:
        """Zero the disturbance estimate."""
        self.delta_bar = np.zeros(self.delta_bar.shape)

    def reconfigure(self, config: ControllerConfig) -> None:
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
        self.delta_bar = projected(self.delta_bar.copy(), self._adaptation.balls)

    # --- the hot path ----------------------------------------------------------------------------
    @property
    def dynamics(self) -> Dynamics:
        """The model's dynamics with the estimate in force (``core.law.dynamics``)."""
        return Dynamics(self.config, self.J_inv, self.delta_bar, self.model_parts)

    def regressor(self, R: FloatArray) -> Optional[FloatArray]:
        """W(R): ``Dynamics.regressor``."""
        return self.dynamics.regressor(R)

    def gravity_moment(self, R: FloatArray) -> FloatArray:
        """The model's gravity moment at R (about the pivot, body frame)."""
        return self.dynamics.gravity_moment(R)

    def feedforward(self, R: FloatArray) -> FloatArray:
        """The moment that holds the model at rest at R: -(M_g(R) + W Delta_bar) (the law's
        feed-forward; the rotors spool up to it while the vehicle is held).
        """
        W = self.regressor(R)
        held = self.delta_bar if W is None else matvec(W, self.delta_bar)
        if self.config.gravity_compensation:
            held = held + self.gravity_moment(R)
        return -held

    def step(self, R: FloatArray, Omega: FloatArray, dt: float, adapt: bool = True,
             blind: Scalars = 0.0, brake: Optional[BrakeInputs] = None, guide: bool = True,
             gain_scale: Scalars = 1.0) -> ControlOutput:
        """One control step of a controller used alone: the law's stage (``control``, with the
        same arguments) and then the estimate's (``adapt``), as the control tick runs them.
        """
        out = self.control(R, Omega, adapt, blind, brake, guide, gain_scale)
        self.adapt(out, dt)
        return out

    def control(self, R: FloatArray, Omega: FloatArray, adapt: bool = True,
                blind: Scalars = 0.0, brake: Optional[BrakeInputs] = None, guide: bool = True,
                gain_scale: Scalars = 1.0) -> ControlOutput:
        """The law's stage at attitude R and body angular velocity Omega, by the configured law
        (``config.law``, one of ``LAWS``): its configuration error (``terms``, with the cones'
        barrier or without), the geometric moment with the estimate in force (``moment``), and
        the law's filter of the moment, if it has one (a pure function of the step's terms and
        the model: ``core.law.step_types.Law``). The estimate does not move here (``adapt``).

        adapt=False: the estimate is to hold this step (e.g. while disarmed; ``out.adapting``).
        blind: the time (s; one per run of a batch) over which the loop cannot see or correct
        what the vehicle does beyond its nominal period: a law with the barrier then acts on
        each cone widened by how far the sensor travels towards it in that time
        (``blind_widening``). brake: the approach brake's inputs of the tick
        (``core.law.brake.BrakeInputs``), or None (no brake this step: disarmed, spooling).
        guide: move guidance's set point (not while the rotors spool up: it is planned at the
        take-over). gain_scale: of the bandwidth (k_R by its square, k_Omega by it; one per run
        of a batch), below 1 past the delay bound
        (``core.supervisor.control_tick.Degraded``).
        """
        if guide and self.guidance is not None and not self._tracking:
            self._follow(R)
        law = self._law
        terms = self.terms(R, Omega, blind if law.widened else 0.0)
        if law.barrier:
            psi, e_R = with_cones(terms.A, terms.e_RA, terms.cones)
        else:
            psi, e_R = terms.A[..., 0], terms.e_RA
        out = self.moment(R, Omega, adapt, terms, psi, e_R, law.barrier, gain_scale)
        if law.filter is None:
            return out
        return law.filter(out, terms, R, Omega, self.law_model,
                          brake if self.brake is not None else None)

    def _follow(self, R: FloatArray) -> None:
        """Move the law's set point along guidance's path (``core.law.guidance``): its linear map
        is rebuilt only when the set point moves. (By the set point itself, not its index on the
        path: a path planned again can put another set point at the same index.)
        """
        guidance = self.guidance
        assert guidance is not None
        carrot = guidance.carrot(R, self._R_d, self.config.cones)
        # (one run's compared as floats: a tenth of array_equal's cost; the same equality)
        same = (self._carrot is not None
                and (carrot.tolist() == self._carrot.tolist() if carrot.ndim == 2
                     else np.array_equal(carrot, self._carrot)))
        if not same:
            self._linear = self._linear.retargeted(carrot, self.config.G)
            self._carrot = carrot.copy()

    # --- the pieces every law is made of -------------------------------------------------------
    def terms(self, R: FloatArray, Omega: FloatArray, blind: Scalars = 0.0) -> StepTerms:
        """The step's terms at (R, Omega): ``StepTerms`` (the attractive error, the cones
        evaluated, widened by the blind time when it is given, and the gravity moment).
        """
        cfg = self.config
        y = self._linear(R)                     # A, e_RA, the cones' terms, M_g (linear_terms)
        n = self._linear.n_cones
        sc = y[..., 4:4 + 4 * n].reshape(y.shape[:-1] + (n, 4))
        ev = barrier_at_step(cfg.cones, sc, Omega, blind, cfg.blind_guard_max)
        return StepTerms(y[..., 0:1], y[..., 1:4], ev, y[..., -3:], self.regressor(R))

    def moment(self, R: FloatArray, Omega: FloatArray, adapt: bool, terms: StepTerms,
               psi: Scalars, e_R: FloatArray, barrier: bool = True,
               gain_scale: Scalars = 1.0) -> ControlOutput:
        """The geometric law's moment for the configuration error (psi, e_R) with the estimate in
        force, and whether the estimate adapts this step (``adapting``, per run: adapt, and no
        barrier saturated where the error carries the barrier): ``ControlOutput``. gain_scale:
        as ``step``'s. The estimate itself moves in ``adapt``.
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
        delta_bar = self.delta_bar          # (never changed in place: ``adapted`` makes anew)
        g = gain_scale                          # past the delay bound, below 1 (Degraded)
        k_R: Scalars
        k_Omega: Scalars
        if np.ndim(g):                          # one per run of a batch
            k_R, k_Omega = (cast(FloatArray, cfg.k_R * g * g)[..., None],
                            cast(FloatArray, cfg.k_Omega * g)[..., None])
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
        # violated implies saturated (the floor band lies outside every cone)
        violated = (ev.violated.any(axis=-1) if any_flag(ev.any_saturated)
                    else ev.any_saturated)
        return ControlOutput(u, e_R, e_Omega, psi, delta_bar, violated, saturated,
                             adapting, ev, cfg.cones.theta_deg, W=W)

    def adapt(self, out: ControlOutput, dt: float) -> None:
        """The adaptive law's stage: the estimate after a step's output (``adapted``)."""
        self.delta_bar = adapted(self.delta_bar, out, dt, self._adaptation)

    def _set_config(self, config: ControllerConfig) -> None:
        self.config = config
        g = math.sqrt(so3.dot(config.gravity, config.gravity))
        self.guidance = (Guidance(config.guidance_lookahead, config.guidance_clearance,
                                  -config.gravity / g, config.tilt_max)
                         if config.guidance_lookahead > 0.0 else None)
        self._law = LAWS[config.law]
        # (the brake needs the rotors' limits: a configuration built without them has none)
        self.brake = ApproachBrake.of(config) if config.moment_limits is not None else None
        self.J_inv = so3.inverse3(config.J)      # the model's, for the prediction too
        self.model_parts = ModelParts.of(config, self.J_inv)
        self.law_model = LawModel(config, self.J_inv, self.brake)     # what a law's filter knows
        self._adaptation = Adaptation.of(config)


class Adaptation(NamedTuple):
    """What the adaptive law's stage knows of the configuration: k_Delta, c, Gamma's diagonal
    (k_Delta for the constant moment, k_Delta_cog for the m*rho block) and the estimate's balls
    ((its block, its bound) for each block bounded).
    """

    k_Delta: float
    c: float
    gamma: FloatArray
    balls: Tuple[Tuple[slice, float], ...]

    @classmethod
    def of(cls, config: ControllerConfig) -> 'Adaptation':
        gamma = np.array([config.k_Delta] * 3 + [config.k_Delta_cog] * 3)[:config.n_params]
        balls = tuple((block, bound) for block, bound in (
            (slice(0, 3), config.delta_bar_max), (slice(3, 6), config.cog_estimate_max))
            if bound > 0.0 and block.start < config.n_params)
        return cls(config.k_Delta, config.c, gamma, balls)


def adapted(delta_bar: FloatArray, out: ControlOutput, dt: float,
            adaptation: Adaptation) -> FloatArray:
    """The adaptive law's step (eq. 39), explicit Euler over dt: Delta_bar + dt Gamma W^T
    (e_Omega + c e_R) for the runs that adapt (``out.adapting``; W the step's regressor,
    ``out.W``, None for the constant model), then projected onto its balls (``projected``). A
    new array: the estimate a step used (``out.delta_bar``) stays as it was.
    """
    adapting = out.adapting
    if adapting is False or not any_flag(adapting):
        return delta_bar
    v = out.e_Omega + adaptation.c * out.e_R
    W = out.W
    rate = (dt * adaptation.k_Delta) * v if W is None else dt * (
        adaptation.gamma * matvec(transpose(W), v))
    if rate.ndim > 1:                       # a batch: only the runs that adapt
        rate *= cast(BoolArray, adapting)[..., None]
    return projected(delta_bar + rate, adaptation.balls)


def projected(delta_bar: FloatArray, balls: Tuple[Tuple[slice, float], ...]) -> FloatArray:
    """Each block of the estimate projected onto its ball (``Adaptation.balls``), in place of
    delta_bar (a new array, or one the caller owns).
    """
    for block, bound in balls:
        part = delta_bar[..., block]
        n2 = so3.dot(part, part)
        if any_flag(n2 > bound * bound):
            part *= (bound / np.maximum(np.sqrt(n2), bound))[..., None]
    return delta_bar
