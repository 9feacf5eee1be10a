"""The gain condition of Prop. 5: the bound of eq. 40 by hand, the bounds where sampled, and the
check's report.
"""
import math

from control_support import (
    config,
    four_cones,
    rng,
)
import numpy as np
import pytest

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.configuration_error import (
    attractive_error,
)
from geoctl_ros.core.law.gains import gain_condition

# on the vehicle's stack too, but for the four long closed-loop flights: the scenario and campaign
# tests and the sim-in-the-loop flight fly the same loop there
odroid = pytest.mark.odroid


@odroid
def test_gain_bound_of_eq_40_matches_a_hand_computation():
    """One cone, theta 30 deg, margin 5 deg, alpha 8, G = diag(0.9, 1.1, 1.0), by hand:
    h1 = 1.9; b1 = 1.9 / (0.2^2 + 2.1^2) = 0.42697; Psi <= 1.9;
    |E| <= 3 / sqrt(2) = 2.1213; |e_RA| <= sqrt(1.9 / 0.42697) = 2.1095;
    beta = cos 35 = 0.81915, d = beta - cos 30 = -0.046880;
    |e_RB| <= sin 35 / (8 * 0.046880) = 1.5294;
    |F| <= ((beta^2 + 1) d^2 + 1 + beta^2 (beta^2 - 2)) / (alpha^2 d^4) = 0.11190 / 3.0909e-4 =
    362.0; H = 1.9 * 2.1213 + 2 * 2.1095 * 1.5294 + 1.9 * 362.0 = 698.3.
    """
    cones = ConeSet([1, 0, 0], [[0.0, 0.0, -1.0]], np.radians([30.0]), 8.0, np.radians(0.25))
    cfg = config(cones, k_R=0.4, k_Omega=0.7, c=0.1)
    check = gain_condition(cfg, margin_deg=5.0)
    assert check.H == pytest.approx(698.3, rel=2e-3)
    lam = np.linalg.eigvalsh(cfg.J)
    assert check.c_max_paper == pytest.approx(
        4 * 0.4 * 0.7 / (0.7 ** 2 + 4 * 0.4 * lam[-1] * 698.3), rel=2e-3)


@odroid
def test_the_gain_check_bounds_hold_where_sampled():
    """|e_RA|^2 <= A / b1 (the b1 the check uses) and |e_RB| <= its bound on the domain, at
    random attitudes: the bounds of Prop. 1 and 4 are bounds.
    """
    G = np.array([0.9, 1.1, 1.0])
    b1 = 1.9 / (0.2 ** 2 + 2.1 ** 2)
    theta, margin, alpha = math.radians(30.0), math.radians(5.0), 8.0
    cones = ConeSet([1, 0, 0], [[0.0, 0.0, -1.0]], [theta], alpha, math.radians(0.25))
    bound_eRB = math.sin(theta + margin) / (alpha * (math.cos(theta) - math.cos(theta + margin)))
    worst_A, worst_B = 0.0, 0.0
    for _ in range(4000):
        R = so3.exp(rng.normal(size=3) * 2.0)
        A, e_RA = attractive_error(R, np.eye(3), G)
        if A > 1e-6:
            worst_A = max(worst_A, float(e_RA @ e_RA) / A)
        if cones.margins_deg(R)[0] >= math.degrees(margin):
            worst_B = max(worst_B, float(np.linalg.norm(cones.evaluate(R).e_RB[0])))
    assert 1.905 < worst_A <= 1.0 / b1       # beyond the paper's min form, within the max form
    assert 0.5 * bound_eRB < worst_B <= bound_eRB


@odroid
def test_gain_check_reports_numbers():
    check = gain_condition(config(four_cones(), c=1e-4))
    assert check.ok and check.c_max > 1e-4 and check.H > 0
    bad = gain_condition(config(four_cones(), c=100.0))
    assert not bad.ok
    assert 'VIOLATES' in bad.message() and '%.4g' % bad.c_max_paper in bad.message()
