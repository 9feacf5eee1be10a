"""The testbed: a rigid body turning about a spherical joint, with gravity and a disturbance.

Equations of motion about the pivot (body frame):

    J_p Omega' + Omega x J_p Omega = tau + M_g(R) + Delta(t),     R' = R hat(Omega)

with J_p the inertia about the pivot, M_g the gravity moment of the centre of mass offset rho
(``geoctl_ros.core.law.mechanics``), tau the actuation moment (held constant over a step) and
Delta(t) the disturbance: constant + amplitude * [sin wt, cos wt, (sin wt + cos wt) / 2]
(elementwise; the dissertation's time-varying case).

Integrator: RKMK4, the classical fourth-order Runge-Kutta method applied in the Lie algebra
(Runge-Kutta-Munthe-Kaas). Over a step R(t) = R_n exp(hat(xi(t))) with xi' = dexp^{-1}_{-xi}(Omega)
= Omega + 1/2 xi x Omega + 1/12 xi x (xi x Omega) (truncated where it no longer affects fourth
order), so R_{n+1} = R_n exp(hat(xi_{n+1})) is a rotation to machine precision at every step, with
no re-orthonormalisation. Global error is O(h^4) (halving the step divides it by 16): a body
tumbling at 3.7 rad/s for 10 s ends 2e-12 rad from the reference at the default 1 kHz (3e-11 rad at
500 Hz), and its kinetic energy drifts by 1e-15 (see test_plant.py).

A batch of testbeds (one per run of a campaign) is one Plant whose configuration and state carry a
leading batch axis (inertia (batch, 3, 3), mass (batch,), R (batch, 3, 3), ...); ``step`` advances
them all with the same formulas.
"""

import math
from typing import Tuple

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import cross, cross_floats, matvec, matvec_floats, vecmat
from geoctl_ros.core.law.mechanics import body_gravity_moment

STOP_HZ = 25.0        # the joint's stops: a contact of this natural frequency
STOP_DAMPING = 0.7    # and damping ratio, about the pivot's mean principal inertia


class Plant:
    """State (t, R, Omega) of the testbed and its integrator."""

    def __init__(self, config, R0=None, Omega0=None):
        self.config = config
        self.J = config.J
        self.J_inv = so3.inverse3(self.J)
        self.t = 0.0
        self.R = np.eye(3) if R0 is None else np.array(R0, dtype=float)
        self.Omega = np.zeros(3) if Omega0 is None else np.array(Omega0, dtype=float)
        self.held = False              # held still (by hand: it neither moves nor integrates)
        # the stops (none at a tilt limit of pi): a spring-damper on the tilt past the limit
        self.stops = config.tilt_max < math.pi - 1e-9
        omega = 2.0 * math.pi * STOP_HZ
        J_mean = (self.J[..., 0, 0] + self.J[..., 1, 1] + self.J[..., 2, 2]) / 3.0
        self._stop = (omega * omega * J_mean, 2.0 * STOP_DAMPING * omega * J_mean)
        # |g| up_b . e3 above this: within the stops by a margin far above rounding (no
        # testbed of a batch there needs its stop worked out)
        g = math.sqrt(so3.dot(config.gravity, config.gravity))
        self._clear = (g * math.cos(min(config.tilt_max, math.pi)) + 1e-6 * g if self.stops
                       else -math.inf)
        # one testbed: its constants as floats for _step_one, once
        self._floats = None if self.R.ndim != 2 else (
            self.J.tolist(), self.J_inv.tolist(), config.m_rho.tolist(), config.gravity.tolist(),
            float(self._stop[0]), float(self._stop[1]))

    def angular_acceleration(self, t: float, g_b: np.ndarray, Omega: np.ndarray,
                             tau: np.ndarray) -> np.ndarray:
        """Omega' with gravity g_b = R^T g_w in the body frame (all the attitude it needs)."""
        c = self.config
        gyroscopic = cross(Omega, matvec(self.J, Omega))
        moment = tau + body_gravity_moment(c.m_rho, g_b) + c.disturbance(t) - gyroscopic
        if self.stops and not np.all(-g_b[..., 2] > self._clear):
            # (a testbed within its stops is not touched: its moment as it is)
            beyond, stop = self.stop_moment(g_b, Omega)
            moment = np.where(beyond[..., None], moment + stop, moment)
        return matvec(self.J_inv, moment)

    def stop_moment(self, g_b: np.ndarray, Omega: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """(Whether the body's z axis is tilted beta past the limit from upright, the stops'
        moment (body frame)): there a push K (beta - limit) + C dbeta/dt (never a pull) about
        k = e3 x up_b / |e3 x up_b| (up_b = -g_b / |g|, cos beta = up_b . e3), the axis that
        rights it (dbeta/dt = -Omega . k); 0 within the limit.
        """
        K, C = self._stop
        g = math.sqrt(so3.dot(self.config.gravity, self.config.gravity))
        ux, uy, uz = -g_b[..., 0] / g, -g_b[..., 1] / g, -g_b[..., 2] / g
        sin_b = np.sqrt(ux * ux + uy * uy)
        beta = np.arctan2(sin_b, uz)
        inv = 1.0 / np.maximum(sin_b, 1e-12)
        kx, ky = -uy * inv, ux * inv
        push = np.maximum(K * (beta - self.config.tilt_max)
                          - C * (Omega[..., 0] * kx + Omega[..., 1] * ky), 0.0)
        beyond = beta > self.config.tilt_max
        push = np.where(beyond, push, 0.0)
        return beyond, np.stack([push * kx, push * ky, 0.0 * push], axis=-1)

    def step(self, tau: np.ndarray, h: float) -> None:
        """Advance by h seconds with the actuation moment tau held constant (RKMK4).

        The stages need the attitude only through gravity in the body frame: at R0 exp(hat(xi))
        that is exp(-hat(xi)) R0^T g_w, so the stages rotate a vector; only the step's end forms
        its rotation matrix. One testbed (not a batch) steps in floats (``_step_one``).
        """
        if self.held:
            self.Omega = np.zeros_like(self.Omega)
            self.t += h
            return
        if self._floats is not None:
            _step_one(self, tau, h)
            return
        t, R0, W0 = self.t, self.R, self.Omega
        acc = self.angular_acceleration
        g0 = vecmat(self.config.gravity, R0)                     # R0^T g_w
        # stage 1 (xi = 0)
        k1x, k1w = W0, acc(t, g0, W0, tau)
        # stage 2
        xi = 0.5 * h * k1x
        W = W0 + 0.5 * h * k1w
        k2x, k2w = _dexpinv(xi, W), acc(t + 0.5 * h, so3.exp_apply(-xi, g0), W, tau)
        # stage 3
        xi = 0.5 * h * k2x
        W = W0 + 0.5 * h * k2w
        k3x, k3w = _dexpinv(xi, W), acc(t + 0.5 * h, so3.exp_apply(-xi, g0), W, tau)
        # stage 4
        xi = h * k3x
        W = W0 + h * k3w
        k4x, k4w = _dexpinv(xi, W), acc(t + h, so3.exp_apply(-xi, g0), W, tau)
        self.R = so3.matmul(R0, so3.exp((h / 6.0) * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)))
        self.Omega = W0 + (h / 6.0) * (k1w + 2.0 * k2w + 2.0 * k3w + k4w)
        self.t = t + h

    def kinetic_energy(self) -> float:
        return 0.5 * float(self.Omega @ self.J @ self.Omega)

    def angular_momentum_world(self) -> np.ndarray:
        return self.R @ (self.J @ self.Omega)


def _dexpinv(xi, w):
    """xi' for R = R_n exp(hat(xi)) and body rate w (R' = R hat(w)): dexp^{-1}_{-xi}(w), truncated
    after the terms RKMK4 needs. (The sign of the commutator term is that of the body-frame,
    left-trivialised kinematics; the other sign silently gives a second-order method.)
    """
    xw = cross(xi, w)
    return w + 0.5 * xw + cross(xi, xw) / 12.0


def _step_one(plant: Plant, tau: np.ndarray, h: float) -> None:
    """``Plant.step`` for one testbed, in floats: every operation a batch's arrays do, on the
    same operands in the same order (so3's float paths: sums left to right, the same cross
    products and Rodrigues coefficients), so a run alone steps to the same bits as in a batch,
    about four times faster than through 3-vector arrays.
    """
    J, J_inv, m_rho, g, K, C = plant._floats
    t, R0 = plant.t, plant.R.tolist()
    W0, tau_ = plant.Omega.tolist(), np.asarray(tau, dtype=float).tolist()
    disturbance = plant.config.disturbance
    stops, limit = plant.stops, plant.config.tilt_max
    g_norm = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])

    def _acc(t, g_b, W):                # Plant.angular_acceleration
        gyroscopic = cross_floats(W, matvec_floats(J, W))
        bgm = cross_floats(m_rho, g_b)
        d = disturbance(t).tolist()
        m = [tau_[i] + bgm[i] + d[i] - gyroscopic[i] for i in range(3)]
        if stops:                       # Plant.stop_moment
            ux, uy, uz = -g_b[0] / g_norm, -g_b[1] / g_norm, -g_b[2] / g_norm
            sin_b = math.sqrt(ux * ux + uy * uy)
            beta = float(np.arctan2(sin_b, uz))
            inv = 1.0 / max(sin_b, 1e-12)
            kx, ky = -uy * inv, ux * inv
            if beta > limit:            # (within the stops: the moment as it is)
                push = max(K * (beta - limit) - C * (W[0] * kx + W[1] * ky), 0.0)
                m = [m[0] + push * kx, m[1] + push * ky, m[2] + 0.0 * push]
        return matvec_floats(J_inv, m)

    g0 = [R0[0][j] * g[0] + R0[1][j] * g[1] + R0[2][j] * g[2] for j in range(3)]   # R0^T g_w
    half = 0.5 * h
    k1x, k1w = W0, _acc(t, g0, W0)
    xi = [half * v for v in k1x]
    W = _ahead(W0, half, k1w)
    k2x, k2w = _xi_rate(xi, W), _acc(t + 0.5 * h, _rotate_back(xi, g0), W)
    xi = [half * v for v in k2x]
    W = _ahead(W0, half, k2w)
    k3x, k3w = _xi_rate(xi, W), _acc(t + 0.5 * h, _rotate_back(xi, g0), W)
    xi = [h * v for v in k3x]
    W = _ahead(W0, h, k3w)
    k4x, k4w = _xi_rate(xi, W), _acc(t + h, _rotate_back(xi, g0), W)
    sixth = h / 6.0
    xi = [sixth * (k1x[i] + 2.0 * k2x[i] + 2.0 * k3x[i] + k4x[i]) for i in range(3)]
    plant.R = so3.matmul(plant.R, so3.exp(np.array(xi)))
    plant.Omega = np.array([W0[i] + sixth * (k1w[i] + 2.0 * k2w[i] + 2.0 * k3w[i] + k4w[i])
                            for i in range(3)])
    plant.t = t + h


# _step_one's pieces, in floats (lists of 3)
def _xi_rate(xi, w):                    # _dexpinv
    xw = cross_floats(xi, w)
    xxw = cross_floats(xi, xw)
    return [w[i] + 0.5 * xw[i] + xxw[i] / 12.0 for i in range(3)]


def _rotate_back(xi, v):                # so3.exp_apply(-xi, v)
    w = [-xi[0], -xi[1], -xi[2]]
    a, b = so3.rodrigues_ab(*w)
    wv = cross_floats(w, v)
    wwv = cross_floats(w, wv)
    return [v[i] + a * wv[i] + b * wwv[i] for i in range(3)]


def _ahead(base, f, k):                 # base + f k
    return [base[0] + f * k[0], base[1] + f * k[1], base[2] + f * k[2]]
