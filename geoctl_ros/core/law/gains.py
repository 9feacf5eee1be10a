"""The sufficient condition on the gain c of Prop. 5 (the paper's eq. 40 and the dissertation's
second bound) on the operating domain of Prop. 4: checked at configuration, reported as a warning.
"""
from dataclasses import dataclass
import math

import numpy as np

from geoctl_ros.core.law.controller_config import ControllerConfig
from geoctl_ros.core.law.feasibility import smallest_pair_sum


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
    def c_max(self) -> float:
        return min(self.c_max_paper, self.c_max_dissertation)

    @property
    def ok(self) -> bool:
        return 0.0 < self.c < self.c_max

    def message(self) -> str:
        verdict = 'satisfies' if self.ok else 'VIOLATES'
        return ('c = %.4g %s the sufficient condition of Prop. 5: c < min(%.4g (paper eq. 40, '
                'H = %.4g), %.4g (dissertation)) on the domain Psi < %.3g, every cone at least '
                '%.1f deg clear' % (self.c, verdict, self.c_max_paper, self.H,
                                    self.c_max_dissertation, self.psi_max, self.margin_deg))


def gain_condition(config: ControllerConfig, margin_deg: float = 5.0) -> 'GainCheck':
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


def learning_time(k_R: float, c: float, gain: float, regressor: float) -> float:
    """The time constant (s) with which the adaptive estimate learns a block of Delta near an
    equilibrium: the moment error W Delta_tilde shows as e_R = W Delta_tilde / k_R, which the
    adaptive law's c e_R term integrates back at the rate gain |W|^2, so tau = k_R / (c gain
    |W|^2). regressor: |W| of the block (1 for the constant moment, |g| for m*rho). See
    docs/control-law.md, "Learning the gravity moment".
    """
    return k_R / (c * gain * regressor * regressor)


def learning_gain(k_R: float, c: float, tau: float, regressor: float) -> float:
    """The adaptation gain of a block that learns with time constant tau (``learning_time``'s
    inverse).
    """
    return k_R / (c * tau * regressor * regressor)
