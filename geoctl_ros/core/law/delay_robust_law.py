"""The delay-robust law (the default): the paper's, each cone's barrier widened by the blind
time, with the approach brake.
"""
from typing import Any

import numpy as np

from geoctl_ros.core.law.brake import braked
from geoctl_ros.core.law.paper_law import barrier_step


def delay_robust_law(controller: Any, R: np.ndarray, Omega: np.ndarray, dt: float, adapt: bool,
                     blind: Any, brake: Any) -> Any:
    """The paper's law made robust to delay (the safety envelope; the default): each cone's
    barrier widened by what the sensor travels towards it over the blind time, up to
    ``blind_guard_max_deg`` (docs/safety.md, "Delay"), and the approach brake
    (``core.law.brake.braked``: every cone's sampled-data condition, within the rotors'
    limits; brake: its inputs of the tick, or None). With fresh inputs on time and the brake off
    it is the paper's.
    """
    out = barrier_step(controller, R, Omega, dt, adapt, blind)[1]
    if brake is None or not out.cones.s.shape[-1]:
        return out
    cfg = controller.config
    b = braked(controller.brake, cfg.cones, controller.J_inv, cfg.moment_limits, brake, out.u)
    return out._replace(u=b.u, braking=b.braking, brake_unmet=b.unmet)
