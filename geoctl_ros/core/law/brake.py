"""The approach brake: the barrier's sampled-data margin, derived, and enforced on the sensor's
approach rate to each cone (docs/safety.md, "The approach brake").

A command is computed from measurements the blind time T_b old and then held for the control
period h: for T = T_b + h the loop cannot act on what the sensor does. Let phi_i be the sensor's
angle to cone i's axis, theta_i the cone's half-angle, w_i = -d phi_i / dt its approach rate
(``errors.approach_rates``). With the bounds
- e: the attitude measurement's error, 3 standard deviations (``attitude_noise_deg``);
- a_u: the angular acceleration the model does not know, the unlearnt moment over the smallest
  pivot inertia (``cbf_moment_bound`` / J_min);
- a_b: the angular acceleration the rotors can spare to brake (``brake_acceleration``),
the sensor closes on the cone by at most w T + 1/2 a_u T^2 before the loop acts, and by
w^2 / (2 a_b) more while it brakes. So it stays out of the cone when

    phi_i - theta_i - e - 1/2 a_u T^2 >= w T + w^2 / (2 a_b),

that is when w is at most the allowed rate w_max = a_b (sqrt(T^2 + 2 G / a_b) - T), with G the
left-hand side (at least 0). The brake keeps every approach under that curve as a control barrier
function of its own: with h_i = w_max(G_i) - w_i it asks that dh_i/dt >= -k_b h_i
(``approach_brake_rate``) for any unlearnt acceleration within a_u. Since dG/dt = -w, that is

    dw_i/dt <= -(dw_max/dG) w_i + k_b h_i,   dw_max/dG = a_b / (w_max + a_b T),

and where the law's own moment (the model's acceleration under it, its closing part included)
would break it by the worst a_u, the brake adds the least deceleration along the cone's opening
direction that meets it. Then h_i >= 0 holds once it holds: the approach never outruns the
curve, which stops the sensor e outside the cone. On the curve the deceleration asked is at most
a_b (plus a_u, plus whatever of the law's own moment closes on the cone).

Assumptions (what the derivation covers): the rotors make the moments commanded (the allocation is
not saturated, and the rotors have spooled up after arming), what the prediction does not model
is an acceleration within a_u, the attitude measurement's error is within e, and h_i >= 0 at the
start (an approach already faster than the curve is taken back to it at the rate k_b, not at
once). The condition is kept in continuous time on the predicted state; the blind time and the
hold enter through T in w_max, not through the condition. The falsifier judges the first three
per control step (``assumptions_held``).
What it does not cover (the fall while the rotors spool up, a saturated allocation, model errors
past a_u, an approach past the curve at arming) is measured by the campaign and attacked by the
falsifier.
"""
from dataclasses import dataclass
import math
from typing import Any, Optional

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.flags import any_flag

SIGMAS = 3.0      # the measurement error is bounded at this many standard deviations
ASSUMED_WINDOW_S = 0.3   # s, how long before a moment the bounds must have held for the
                         # derivation to speak of it: the longest blind time searched (150 ms of
                         # latency, a 40 ms stall), a hold (10 ms), and braking from 3.3 rad/s at
                         # a_b (83 ms)


@dataclass(frozen=True)
class ApproachBrake:
    """The brake's bounds and rate (see the module)."""

    rate: float             # 1/s, k_b
    acceleration: float     # rad/s^2, a_b
    unmodelled: float       # rad/s^2, a_u
    measurement: float      # rad, e

    @classmethod
    def of(cls, config: Any) -> Optional['ApproachBrake']:
        """The brake of a ControllerConfig, or None when it is off."""
        return cls.bounds_of(config) if config.approach_brake_rate > 0.0 else None

    @classmethod
    def bounds_of(cls, config: Any) -> 'ApproachBrake':
        """The brake's bounds of a ControllerConfig, whether or not its law brakes (what a
        flight is judged against: ``assumptions_held``).
        """
        j_min = so3.symmetric_eigenvalues(config.J)[0]
        return cls(config.approach_brake_rate, config.brake_acceleration,
                   config.cbf_moment_bound / j_min, SIGMAS * config.attitude_noise)

    def allowed_rate(self, gap: Any, T: Any) -> Any:
        """w_max (rad/s): the fastest approach that the margin gap (rad, phi - theta) allows
        with the loop blind for T (s).
        """
        G = np.maximum(gap - self.measurement - 0.5 * self.unmodelled * T * T, 0.0)
        return self.acceleration * (np.sqrt(T * T + 2.0 * G / self.acceleration) - T)

    def moment(self, J: np.ndarray, b: np.ndarray, s: np.ndarray, cross: np.ndarray,
               theta: np.ndarray, r: np.ndarray, Omega: np.ndarray, acc: np.ndarray, blind: Any,
               hold: float) -> Optional[np.ndarray]:
        """The brake's moment (body frame, N m; one per run of a batch), or None where no cone
        needs it. b: each cone's axis in the body frame (R^T v_i); s, cross: ``ConeSet.terms``
        (cos phi_i and (R^T v_i) x r per cone); theta: the cones' half-angles (rad); r: the
        sensor axis (body); acc: the model's angular acceleration under the law's moment (rad/s^2,
        the brake's own left out); blind: T_b (s; a float or one per run); hold: h (s).

        With h_i = w_max(G_i) - w_i, it asks that the model's dh_i/dt, less what the unlearnt
        acceleration can take away (a_u), be at least -k_b h_i: along each cone's opening
        direction n_i = cross_i / |cross_i| it adds the least deceleration d_i that makes

            dw_i/dt (the law's) - d_i + a_u <= -(dw_max/dG) w_i + k_b h_i,

        with dw_i/dt = -(dn_i/dt) . Omega - n_i . acc and dw_max/dG = a_b / (w_max + a_b T).
        """
        inv, w, kinematic, w_max, slope = self.condition(b, s, cross, theta, r, Omega, blind,
                                                         hold)
        w_dot = kinematic - so3.dot(cross, acc[..., None, :]) * inv
        need = w_dot + self.unmodelled + slope * w - self.rate * (w_max - w)
        if not any_flag(need > 0.0):                # (the usual case)
            return None
        # at most the law's own closing acceleration, a_u and a_b: what the derivation takes the
        # rotors to spare (asking more only saturates the allocation, and takes authority from
        # the barrier)
        decel = np.clip(need, 0.0, np.maximum(w_dot, 0.0) + self.unmodelled + self.acceleration)
        return so3.matvec(J, so3.vecmat(decel * inv, cross))

    def condition(self, b: np.ndarray, s: np.ndarray, cross: np.ndarray, theta: np.ndarray,
                  r: np.ndarray, Omega: np.ndarray, blind: Any, hold: float) -> tuple:
        """The terms of the brake's condition per cone, dw_i/dt + a_u <= -(dw_max/dG) w_i +
        k_b (w_max - w_i) with dw_i/dt = kinematic_i - n_i . Omega' (Omega' the angular
        acceleration, n_i = cross_i / |cross_i| the opening direction): (1 / |cross_i|, w,
        kinematic, w_max, dw_max/dG) (arguments as ``moment``'s).

        kinematic = -(dn_i/dt) . Omega: with c = b x r, dc/dt = (b x Omega) x r = s Omega -
        b (r . Omega) and n . b = 0, it is -(s (|Omega|^2 - w^2) - (b . Omega)(r . Omega)) /
        |c| (dot products only).
        """
        inv = 1.0 / np.maximum(np.sqrt(so3.dot(cross, cross)), 1e-9)
        Om = Omega[..., None, :]
        w = -so3.dot(cross, Om) * inv
        T = (np.asarray(blind, dtype=float)[..., None] if np.ndim(blind) else blind) + hold
        gap = np.arccos(np.clip(s, -1.0, 1.0)) - theta
        w_max = self.allowed_rate(gap, T)
        slope = self.acceleration / np.maximum(w_max + self.acceleration * T, 1e-9)
        spin = so3.dot(Omega, Omega)[..., None]
        kinematic = (so3.dot(b, Om) * so3.dot(r, Omega)[..., None] - s * (spin - w * w)) * inv
        return inv, w, kinematic, w_max, slope

    def rows(self, J_inv: np.ndarray, f: np.ndarray, b: np.ndarray, s: np.ndarray,
             cross: np.ndarray, theta: np.ndarray, r: np.ndarray, Omega: np.ndarray, blind: Any,
             hold: float) -> tuple:
        """The brake's condition as constraints on the moment u, A u >= beta (one row per
        cone), for a law that solves for u (the cbf law's QP): with Omega' = J^-1 (u + f), f the
        model's moment besides u, the condition is n_i . J^-1 u >= kinematic_i - n_i . J^-1 f +
        a_u + (dw_max/dG) w_i - k_b (w_max - w_i). Returns (A (..., cones, 3), beta (..., cones)).
        """
        inv, w, kinematic, w_max, slope = self.condition(b, s, cross, theta, r, Omega, blind,
                                                         hold)
        A = so3.matmul(cross * inv[..., None], J_inv)   # J symmetric: rows (J^-1 n_i)^T
        beta = (kinematic - so3.dot(A, f[..., None, :]) + self.unmodelled + slope * w
                - self.rate * (w_max - w))
        return A, beta


def braking_distance(brake: ApproachBrake, w: float, T: float) -> float:
    """How far (rad) the sensor closes on a cone from approach rate w, the loop blind for T,
    under the bounds: w T + 1/2 a_u T^2 + w^2 / (2 a_b) (the derivation's left-hand side less
    e; its inverse is ``allowed_rate``).
    """
    return w * T + 0.5 * brake.unmodelled * T * T + w * w / (2.0 * brake.acceleration)



def assumptions_held(brake: ApproachBrake, unlearnt: np.ndarray, measurement: np.ndarray,
                     saturated: np.ndarray, dt: float, spooled_s: float) -> np.ndarray:
    """(steps, runs) bool: whether the derivation speaks of each control step of a flight: its
    bounds held at every step of the ``ASSUMED_WINDOW_S`` up to it, and the rotors had spooled
    up (``spooled_s`` after the arming at step 0) by the window's start. Per step and run
    (arrays (steps, runs)): unlearnt, the acceleration the model did not know (rad/s^2, within
    a_u); measurement, the attitude measurement's error (rad, within e); saturated, the
    allocation saturated (it must not be: the rotors make the moments commanded).
    """
    ok = (~saturated) & (unlearnt <= brake.unmodelled) & (measurement <= brake.measurement)
    steps = ok.shape[0]
    window = int(math.ceil(ASSUMED_WINDOW_S / dt - 1e-9))
    first = window + int(math.ceil(spooled_s / dt - 1e-9))     # the first step judged
    broken = np.concatenate([np.zeros((1,) + ok.shape[1:]), np.cumsum(~ok, axis=0)])
    k = np.arange(steps)
    in_window = broken[k + 1] - broken[np.maximum(k - window, 0)]
    return (in_window == 0) & (k >= first)[:, None]
