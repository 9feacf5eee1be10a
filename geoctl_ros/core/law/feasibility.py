"""Whether a set point can be flown: clear of the cones' barrier bands, and far enough from each
cone that its barrier can hold the largest unmodelled moment near the goal (``setpoint_problem``,
which the controller asks at every set point and reconfiguration, never on the hot path).
"""
import math
from typing import Optional, cast

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.controller_config import ControllerConfig


def smallest_pair_sum(G: FloatArray) -> float:
    """min_{i != j} (g_i + g_j): the least A can grow per (1 - cos) of a rotation's angle,
    A = (1 - cos phi) (tr G - n^T G n) / 2 (the paper's h_1).
    """
    g = np.sort(np.asarray(G, dtype=float))
    return float(g[0] + g[1])


def holding_moment(config: ControllerConfig, cones: ConeSet, R_d: FloatArray) -> FloatArray:
    """Per cone: the largest moment its barrier can oppose near the cone, with the set point R_d.

    The repulsion k_R A e_RB,i is largest in the floor band (and inside, where it keeps the band's
    magnitude): k_R A sin(theta_i) / (alpha g0_i). It is proportional to the attitude error A,
    so it is weakest near the goal: where the sensor meets the (guarded) cone, the body has turned
    at least the set point's clearance c_i from that cone away from R_d, and A is then at least
    (1 - cos c_i) (g_a + g_b) / 2 (g_a, g_b the two smallest weights). An unlearnt moment larger
    than this (a disturbance, an error in the model of gravity, before the adaptive estimate has
    caught up) holds the sensor in the cone: the campaign's creep class (docs/campaigns.md, "Safety
    campaign").
    """
    if not len(cones):
        return np.zeros(0)
    c = np.maximum(np.radians(cones.margins_deg(R_d)) - cones.guard, 0.0)
    A_min = 0.5 * (1.0 - np.cos(c)) * smallest_pair_sum(config.G)
    return config.k_R * A_min * np.sin(cones.theta_b) / (cones.alpha * cones.g0)


def holding_clearance_deg(config: ControllerConfig, cones: ConeSet,
                          moment: float) -> FloatArray:
    """Per cone: the set point's clearance (degrees from the real cone) at which
    ``holding_moment`` equals moment.
    """
    x = (2.0 * moment * cones.alpha * cones.g0
         / (config.k_R * smallest_pair_sum(config.G) * np.sin(cones.theta_b)))
    return cast(FloatArray, np.degrees(np.arccos(np.clip(1.0 - x, -1.0, 1.0)) + cones.guard))


def setpoint_problem(config: ControllerConfig, cones: ConeSet,
                     R_d: FloatArray) -> Optional[str]:
    """Why R_d cannot be a set point with these cones (a sentence), or None if it can."""
    if not np.all(np.isfinite(R_d)):
        return 'setpoint is not finite'
    if not len(cones):
        return None
    margins = cones.margins_deg(R_d)
    floor_deg = cones.band_deg
    i = int(np.argmin(margins))
    if margins[i] < floor_deg:
        where = 'inside' if margins[i] < 0 else 'within %.2f deg of' % floor_deg
        return ('setpoint puts the sensor axis %s cone %r (angle to its axis %.2f deg, '
                'half-angle %.2f deg)' % (where, cones.names[i],
                                          margins[i] + math.degrees(cones.theta[i]),
                                          math.degrees(cones.theta[i])))
    moment = config.unmodelled_moment_max
    if moment > 0.0:
        held = holding_moment(config, cones, R_d)
        i = int(np.argmin(held - moment))
        if held[i] < moment:
            need = holding_clearance_deg(config, cones, moment)[i]
            return ('setpoint is %.2f deg clear of cone %r; against unmodelled_moment_max = '
                    '%.3g N m its barrier holds only %.3g N m near the goal, %.1f deg is '
                    'needed' % (margins[i], cones.names[i], moment, held[i], need))
    return None
