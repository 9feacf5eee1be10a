"""The approach brake: every cone's margin kept for the loop as it runs, sampled, held and delayed
(docs/safety.md, "The approach brake").

The loop. At a tick the controller has measurements T_b old (their age from capture); it
predicts the state at the tick by its model and the moments already commanded, then commands a
moment that is held for the hold h, and the lagged rotors, compensated (``core.actuation.
motors.Mixer``), reach it at the end of the hold. The moment in force during the hold moves
monotonically from the one the rotors make at the tick to the one commanded.

One cone, in one axis. Let g = phi - theta be the sensor's gap to the cone (its angle to the
axis less the half-angle), w = -dg/dt its approach rate, and D the deceleration of w that the
moment in force gives by the brake's model (``deceleration``: D = n . J^-1 (M + f) - kin, n the
cone's opening direction, f the model's moment besides the rotors' (gravity, the estimate, the
gyroscopic term, the observed model error), kin the approach's kinematic term). Then
dw/dt = -D + d with |d| <= a_u: a_u bounds what the model, frozen at the tick, does not know
over a hold. Bounds (numbers from the parameters; docs/safety.md has the testbed's):
- e, e_w: the attitude's and the gyro's measurement errors (3 standard deviations);
- a_u: the unknown acceleration (``cbf_moment_bound`` over the smallest pivot inertia);
- a_b: the deceleration the rotors can always make along any opening direction, gravity at the
  joint's tilt limit counted (``brake_authority``, from the rotors' moment polytope).
The prediction is off by at most dw = e_w + e |Omega| + a_u T_b in w and dg = e + (e_w +
e |Omega|) T_b + a_u T_b^2 / 2 in g, so the brake takes the worst state in that box:
w0 = w + dw, G0 = g - dg.

The backup. From any tick, the full brake (the rotors asked for a_b) keeps the sensor out if
the peak of its travel towards the cone is at most the gap: over the first hold the
deceleration is at least min(D_s, a_b) (D_s: the rotors' at the tick), then a_b, against a_u
throughout. Its margin Phi = G0 - peak is >= 0 on the safe set.

The condition. A command whose deceleration at the end of its hold is D keeps the state safe at
the next tick if the travel over its hold (deceleration at least min(D_s, D)), one more hold at
the backup's min(D, a_b), and the backup's a_b after, peaks within G0 (``least_deceleration``:
the least such D, in closed form; ``peak_travel`` the travel). By induction the true state stays
in the safe set at every tick, and the sensor out of the cone between them: where no command
meets the condition the backup itself does. A state past the curve (Phi < 0: at take-over
after a fall, after the bounds broke, or inside a cone) is brought back at the rate k_b
(``approach_brake_rate``): the travel after the hold must peak within G0 - (1 - k_b h) Phi, so
the deceleration asked grows with the depth and pushes an entry back out.

Several cones are joined: each condition is a row on the moment, (J^-1 n_i) . u >= beta_i, and
the law's moment, where it breaks one, is replaced by the closest moment that meets every row
within the rotors' polytope (``core.law.cbf_law.closest_admissible``); where none exists, by the
polytope's vertex that decelerates the unmet cones most.

Assumptions (what "derived" covers): the bounds above hold over every hold (judged per step by
``covered``), the allocation is not saturated and the lag compensation not clipped (so the
rotors reach each command at the end of its hold), each command is held no longer than its
designed hold, and the state is safe (Phi >= 0) at the start.
"""
from dataclasses import dataclass
import math
from typing import Any, NamedTuple, Optional

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.projection import TOL, project, slack_of

SIGMAS = 3.0      # the measurement errors are bounded at this many standard deviations
NET_SHARE_MIN = 0.25   # the backup must out-brake a_u by at least this share of a_b


@dataclass(frozen=True)
class ApproachBrake:
    """The brake's bounds and recovery rate (see the module)."""

    rate: float             # 1/s, k_b: how fast a state past the curve is brought back
    authority: float        # rad/s^2, a_b: the deceleration the rotors can always make
    unmodelled: float       # rad/s^2, a_u: what the model does not know over a hold
    measurement: float      # rad, e: the attitude measurement's error
    rate_error: float = 0.0  # rad/s, e_w: the gyro's error

    @classmethod
    def of(cls, config: Any) -> Optional['ApproachBrake']:
        """The brake of a ControllerConfig, or None when it is off."""
        return cls.bounds_of(config) if config.approach_brake_rate > 0.0 else None

    @classmethod
    def bounds_of(cls, config: Any) -> 'ApproachBrake':
        """The brake's bounds of a ControllerConfig, whether or not its law brakes (what a
        flight is judged against: ``covered``).
        """
        return cls(config.approach_brake_rate, config.brake_acceleration,
                   unmodelled_acceleration(config.cbf_moment_bound, config.J),
                   SIGMAS * config.attitude_noise, SIGMAS * config.gyro_noise)

    def uncertainty(self, T_b: Any, spin: Any) -> tuple:
        """(dg, dw): how far the predicted gap (rad) and approach rate (rad/s) can be from the
        truth, with measurements T_b old (s) and |Omega| = spin (rad/s): the measurement
        errors, and a_u acting over T_b.
        """
        e_w = self.rate_error + self.measurement * spin
        return (self.measurement + e_w * T_b + 0.5 * self.unmodelled * T_b * T_b,
                e_w + self.unmodelled * T_b)


def unmodelled_acceleration(moment_bound: float, J: np.ndarray) -> float:
    """a_u: the largest angular acceleration (rad/s^2) an unlearnt moment of moment_bound (N m)
    gives, over the smallest principal inertia of J.
    """
    return moment_bound / so3.symmetric_eigenvalues(J)[0]


def peak_travel(v: Any, alpha: Any, T: Any, b: Any) -> Any:
    """The farthest (rad) the sensor travels towards the cone from now, at approach rate v, with
    the approach accelerating at alpha for T, then decelerating at b > 0 for ever (0 if it never
    approaches). Floats or arrays alike.
    """
    w_T = v + alpha * T
    x_T = (v + 0.5 * alpha * T) * T
    turn = (v > 0.0) & (w_T < 0.0)                     # it stops within the phase
    inside = np.where(turn, v * v / (2.0 * np.maximum(-alpha, 1e-12)), 0.0)
    after = x_T + np.maximum(w_T, 0.0) ** 2 / (2.0 * b)
    return np.maximum(np.maximum(inside, after), 0.0)


def largest_acceleration(v: Any, T: Any, b: Any, budget: Any) -> Any:
    """The largest alpha with ``peak_travel(v, alpha, T, b)`` <= budget (-inf where none: a
    budget below 0, or an approach already too fast for any stop within it). In closed form:
    where the approach still closes at the end of the phase, the peak is
    v T + alpha T^2 / 2 + (v + alpha T)^2 / (2 b), whose largest root in y = alpha T is
    (-(2 v + b T) + sqrt(b (b T^2 - 4 v T + 8 budget))) / 2; where it stops within the phase,
    v^2 / (2 (-alpha)) = budget.
    """
    disc = b * (b * T * T - 4.0 * v * T + 8.0 * budget)
    y = 0.5 * (np.sqrt(np.maximum(disc, 0.0)) - (2.0 * v + b * T))
    root = (disc >= 0.0) & (v + y >= 0.0)
    stop = np.where((v > 0.0) & (budget > 0.0), -v * v / (2.0 * np.maximum(budget, 1e-300)),
                    -np.inf)
    return np.where(budget < 0.0, -np.inf, np.where(root, y / T, stop))


def committed_travel(w0: Any, D_s: Any, D: Any, brake: ApproachBrake, authority: Any,
                     hold: float) -> Any:
    """The peak travel (rad) of the worst case from a tick: the approach w0 (rad/s), the rotors
    at D_s, a command of deceleration D reached at the end of its hold, then the backup
    (``authority``, a_b): the hold at min(D_s, D), one more at min(D, a_b), then a_b, each
    against a_u.
    """
    a, b = brake.unmodelled, authority - brake.unmodelled
    a0 = a - np.minimum(D_s, D)
    x1 = (w0 + 0.5 * a0 * hold) * hold
    w1 = w0 + a0 * hold
    within = peak_travel(w0, a0, hold, np.inf)                      # the hold itself
    return np.maximum(within, x1 + peak_travel(w1, a - np.minimum(D, authority), hold, b))


class BrakeRows(NamedTuple):
    """The brake's condition for every cone at a tick, as rows on the moment u:
    A u >= beta (``A`` (..., cones, 3), ``beta`` (..., cones)); ``margin``: each cone's Phi
    (rad; < 0 past the curve); ``unmet``: where no deceleration meets it (beta is then +inf).
    """

    A: np.ndarray
    beta: np.ndarray
    margin: np.ndarray
    unmet: np.ndarray


class BrakeInputs(NamedTuple):
    """What the brake needs of a tick besides the law's moment (one per run of a batch where
    arrays): the state predicted at the tick (R, Omega: not the lead the law flies on), the
    measurements' age T_b (s), the hold the command is designed for (s), the moment the rotors
    make at the tick (about the pivot, N m) and the model's moment besides the rotors' there
    (f: gravity, the estimate, the gyroscopic term, the observed error; N m), and its gravity
    moment alone (N m).
    """

    R: np.ndarray
    Omega: np.ndarray
    age: Any
    hold: float
    rotors: np.ndarray
    f: np.ndarray
    gravity: np.ndarray


def opening(cones: Any, R: np.ndarray, Omega: np.ndarray) -> tuple:
    """Per cone at (R, Omega): (gap (rad, phi - theta), n (the opening direction, body, unit),
    w (the approach rate, rad/s), kin (the approach's kinematic term, rad/s^2)): with
    b = R^T v, c = b x r, n = c / |c|, w = -n . Omega, and dw/dt = kin - n . Omega' where
    kin = -(dn/dt) . Omega = ((b . Omega)(r . Omega) - s (|Omega|^2 - w^2)) / |c|
    (dc/dt = s Omega - b (r . Omega), n . b = 0; dot products only).
    """
    sc = cones.terms(R)
    s, c = sc[..., 0], sc[..., 1:]
    inv = 1.0 / np.maximum(np.sqrt(so3.dot(c, c)), 1e-9)
    n = c * inv[..., None]
    Om = Omega[..., None, :]
    w = -so3.dot(n, Om)
    b = so3.vecmat(cones.V, R[..., None, :, :])           # R^T v_i
    spin = so3.dot(Omega, Omega)[..., None]
    kin = (so3.dot(b, Om) * so3.dot(cones.r, Omega)[..., None] - s * (spin - w * w)) * inv
    gap = np.arccos(np.clip(s, -1.0, 1.0)) - cones.theta
    return gap, n, w, kin


class BrakeTerms(NamedTuple):
    """The brake's view of every cone at a tick (arrays (..., cones)): the gap (rad), the
    opening direction n (body, unit; (..., cones, 3)), the approach rate w (rad/s) and its
    kinematic term kin (rad/s^2), the rows A = (J^-1 n)^T
    (..., cones, 3) that give the rotors' part of the deceleration (A u), the model's other
    part n . J^-1 f, the rotors' deceleration now D_s, the backup's authority here (rad/s^2),
    and where that is too weak for the derivation (``NET_SHARE_MIN``).
    """

    gap: np.ndarray
    n: np.ndarray
    w: np.ndarray
    kin: np.ndarray
    A: np.ndarray
    f_along: np.ndarray
    D_s: np.ndarray
    authority: np.ndarray
    weak: np.ndarray

    def model_rate_change(self, moment: np.ndarray) -> np.ndarray:
        """dw/dt by the brake's model, frozen at the tick, under the rotors' moment."""
        return self.kin - so3.dot(self.A, moment[..., None, :]) - self.f_along


def brake_terms(brake: ApproachBrake, cones: Any, J_inv: np.ndarray,
                x: BrakeInputs) -> BrakeTerms:
    """``BrakeTerms`` at the tick of x (see the module)."""
    gap, n, w, kin = opening(cones, x.R, x.Omega)
    A = so3.matmul(n, J_inv)                             # J symmetric: rows (J^-1 n_i)^T
    f_along = so3.dot(A, x.f[..., None, :])              # n . J^-1 f
    # the backup's authority here: a_b, less what of the model's other terms (the estimate,
    # the gyroscopic term, the observed error: a_b counts gravity) and of the kinematic term
    # works against it now
    authority = brake.authority + np.minimum(
        f_along - so3.dot(A, x.gravity[..., None, :]) - kin, 0.0)
    # the backup must out-brake a_u by a share of a_b at least: where the model's other terms
    # leave less (a model error past the bounds, learnt by the observer), the derivation does
    # not hold (``weak``), and the brake takes that share all the same
    floor = brake.unmodelled + NET_SHARE_MIN * brake.authority
    weak = authority < floor
    authority = np.maximum(authority, floor)
    D_s = so3.dot(A, x.rotors[..., None, :]) + f_along - kin
    return BrakeTerms(gap, n, w, kin, A, f_along, D_s, authority, weak)


def rows(brake: ApproachBrake, cones: Any, J_inv: np.ndarray, x: BrakeInputs) -> BrakeRows:
    """The brake's condition at a tick for every cone (``BrakeRows``; see the module)."""
    t = brake_terms(brake, cones, J_inv, x)
    spin = np.sqrt(so3.dot(x.Omega, x.Omega))[..., None]
    age = np.asarray(x.age, dtype=float)[..., None] if np.ndim(x.age) else x.age
    D, margin = least_deceleration(brake, t.gap, t.w, t.D_s, age, spin, t.authority, x.hold)
    return BrakeRows(t.A, D - t.f_along + t.kin, margin, ~np.isfinite(D))


def backup_margin(brake: ApproachBrake, gap: Any, w: Any, D_s: Any, authority: Any,
                  hold: float) -> Any:
    """Phi (rad): the gap left when the backup (the rotors asked for a_b, ``authority``) stops
    an approach w (rad/s) with the rotors at D_s now (taken at most a_b): >= 0 on the safe set.
    """
    Ds = np.minimum(D_s, authority)
    return gap - committed_travel(w, Ds, authority, brake, authority, hold)


def least_deceleration(brake: ApproachBrake, gap: Any, w: Any, D_s: Any, age: Any,
                       spin: Any, authority: Any, hold: float) -> tuple:
    """(D, Phi) per cone: the least deceleration D (rad/s^2) the command must reach at the end of
    its hold for the condition (+inf where none can), and the backup's margin Phi (rad) now.

    The worst state (w0, G0) of the uncertainty box; the rotors' deceleration now taken at most
    a_b (D_s' = min(D_s, a_b): a conservative start). Where Phi >= 0, the peak of
    ``committed_travel`` must be within G0: if even D <= D_s' does (both holds at D, one phase
    of 2 h), D is ``largest_acceleration``'s; else the first hold is at D_s' and the second
    carries D. Past the curve (Phi < 0), the travel after the first hold must peak within
    G0 - (1 - gamma) Phi, gamma = min(1, k_b h), asking at least D_s'.
    """
    dg, dw = brake.uncertainty(age, spin)
    G0, w0 = gap - dg, w + dw
    a = brake.unmodelled
    b = authority - a
    Ds = np.minimum(D_s, authority)
    margin = backup_margin(brake, G0, w0, D_s, authority, hold)
    both = a - largest_acceleration(w0, 2.0 * hold, b, G0)            # D <= D_s'
    a0 = a - Ds
    x1 = (w0 + 0.5 * a0 * hold) * hold
    w1 = w0 + a0 * hold
    gamma = min(1.0, brake.rate * hold)
    budget = np.where(margin >= 0.0, G0, G0 - (1.0 - gamma) * margin) - x1
    second = np.maximum(a - largest_acceleration(w1, hold, b, budget), Ds)
    D = np.where((margin >= 0.0) & (both <= Ds), both, second)
    return D, margin


def brake_authority(vertices: np.ndarray, J_inv: np.ndarray, m_rho: np.ndarray,
                    gravity: np.ndarray, tilt_max: float, r: np.ndarray,
                    directions: int = 720) -> float:
    """a_b (rad/s^2): the least, over the opening directions n (every unit n perpendicular to
    the sensor axis r: a cone is opened by turning r), of the deceleration along n that the
    rotors' moment polytope (its vertices) gives, less the gravity moment working against it at
    any attitude within tilt_max (rad) of upright: min over n of [max over vertices of
    (J^-1 n) . u - max over the tilts of -(J^-1 n) . M_g]. With c = J^-1 n, -c . (m rho x g_b)
    = g_b . (m rho x c), and gravity in the body frame g_b ranges over the cap of half-angle
    tilt_max round -e3 (|g_b| = g): its most is g |k| cos(max(0, angle(k, -e3) - tilt_max)) for
    k = m rho x c. The directions are sampled finely; the support and the cap are exact.
    """
    r = np.asarray(r, dtype=float)
    e1 = np.cross(r, np.eye(3)[int(np.argmin(np.abs(r)))])
    e1 /= math.sqrt(so3.dot(e1, e1))
    e2 = np.cross(r, e1)
    t = np.linspace(0.0, 2.0 * math.pi, directions, endpoint=False)
    n = np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2            # (N, 3)
    c = so3.matvec(J_inv, n)                                          # J^-1 n
    support = so3.dot(c[:, None, :], vertices[None, :, :]).max(axis=1)
    g = math.sqrt(so3.dot(gravity, gravity))
    k = so3.cross(np.broadcast_to(m_rho, c.shape), c)
    size = np.sqrt(so3.dot(k, k))
    down = -k[:, 2] / np.maximum(size, 1e-300)                         # cos angle(k, -e3)
    off = np.maximum(np.arccos(np.clip(down, -1.0, 1.0)) - tilt_max, 0.0)
    worst = np.maximum(g * size * np.cos(np.minimum(off, math.pi)), 0.0)
    return float((support - worst).min())


def covered(ok: np.ndarray, safe: np.ndarray, lead: int) -> np.ndarray:
    """(steps, runs) bool: whether the derivation speaks of each control step: some step j at
    or before it had a safe state (``safe``: Phi >= 0 of the true state, every cone) and the
    bounds held (``ok``) at every step from ``lead`` steps before j (the measurements j used)
    up to it. Per step and run (arrays (steps, runs)).
    """
    steps = ok.shape[0]
    broken = np.concatenate([np.zeros((1,) + ok.shape[1:]), np.cumsum(~ok, axis=0)])
    k = np.arange(steps)
    lead_ok = (broken[k + 1] - broken[np.maximum(k - lead, 0)]) == 0
    out = np.zeros(ok.shape, dtype=bool)
    prev = np.zeros(ok.shape[1:], dtype=bool)
    for i in range(steps):
        prev = ok[i] & (prev | (safe[i] & lead_ok[i]))
        out[i] = prev
    return out


class Braked(NamedTuple):
    """The brake stage's result: the moment, and per run whether the brake changed the law's
    (``braking``) and whether no moment within the rotors' limits met its condition, so that
    the polytope's most decelerating vertex was taken instead (``unmet``).
    """

    u: np.ndarray
    braking: Any
    unmet: Any


def braked(brake: ApproachBrake, cones: Any, J_inv: np.ndarray, polytope: Any,
           x: BrakeInputs, u: np.ndarray, extra: Optional[tuple] = None) -> Braked:
    """The brake stage: u (the law's moment; one per run of a batch) where it meets every cone's
    condition (``rows``), else the closest moment that meets them all within the rotors'
    ``polytope`` (``core.law.projection.project``); where none does, the polytope's vertex that
    decelerates the unmet cones most. extra: more rows (A, beta) the moment must meet with the
    brake's (the cbf law's pointing constraints), or None.
    """
    r = rows(brake, cones, J_inv, x)
    A, beta = r.A, r.beta
    if extra is not None:
        A = np.concatenate((extra[0], A), axis=-2)
        beta = np.concatenate((extra[1], beta), axis=-1)
    slack = np.where(np.isinf(beta), -np.inf, slack_of(A, u, np.where(np.isinf(beta), 0.0, beta)))
    need = np.any(slack < -TOL, axis=-1)
    if extra is not None:                  # (a filter keeps the rotors' limits too)
        need = need | np.any(slack_of(polytope.A, u, polytope.beta) < -TOL, axis=-1)
    unmet_any = np.any(r.unmet, axis=-1)
    if not np.any(need):
        return Braked(u, need, unmet_any)
    out = np.array(u, dtype=float, copy=True)
    unmet = np.array(unmet_any, copy=True)
    for i in zip(*np.nonzero(need)) if out.ndim > 1 else [()]:
        A_i = np.concatenate((A[i], polytope.A))
        beta_i = np.concatenate((np.where(np.isinf(beta[i]), _reach(polytope, A[i]), beta[i]),
                                 polytope.beta))
        v, ok = project(u[i], A_i, beta_i)
        if not ok:
            v = _compromise(u[i], A_i, beta_i, len(beta[i]))
            unmet[i] = True
        out[i] = v
    return Braked(out, need, unmet)


def _reach(polytope: Any, A: np.ndarray) -> np.ndarray:
    """Per row, the most A_i u any moment of the polytope gives (its support along A_i)."""
    return so3.dot(A[:, None, :], polytope.vertices[None, :, :]).max(axis=-1)


def _compromise(u: np.ndarray, A: np.ndarray, beta: np.ndarray, rows_: int,
                iterations: int = 30) -> np.ndarray:
    """Where the first ``rows_`` rows (the cones') cannot all be met within the rest (the
    rotors' polytope): the moment closest to u that meets them all relaxed by the least common
    amount e (rad/s^2 of deceleration: A_i u >= beta_i - e), found by bisection on e, so that no
    cone is given up for another (two cones' rows conflict where the sensor runs fast down a
    narrow corridor between them).
    """
    soft = np.zeros(len(beta))
    soft[:rows_] = 1.0
    # (at e = max beta_i the zero moment meets every relaxed row, and the polytope holds it)
    lo, hi = 0.0, max(float(np.max(beta[:rows_])), 0.0) + 1.0
    best = None
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        v, ok = project(u, A, beta - mid * soft)
        if ok:
            hi, best = mid, v
        else:
            lo = mid
    if best is None:
        best, _ = project(u, A[rows_:], beta[rows_:])
    return best
