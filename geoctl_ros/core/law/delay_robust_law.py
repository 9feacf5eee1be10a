"""The delay-robust law (the default): the paper's, each cone's barrier widened by the blind
time, with the approach brake.
"""
from typing import Any

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.paper_law import barrier_step


def delay_robust_law(controller: Any, R: np.ndarray, Omega: np.ndarray, dt: float, adapt: bool,
                     blind: Any) -> Any:
    """The paper's law made robust to delay (the safety envelope; the default): each cone's
    barrier widened by what the sensor travels towards it over the blind time, up to
    ``blind_guard_max_deg`` (docs/safety.md, "Delay"), and the approach brake
    (``core.law.brake``: no cone approached faster than the derived sampled-data margin allows).
    With fresh inputs on time and the brake off it is the paper's.
    """
    terms, out = barrier_step(controller, R, Omega, dt, adapt, blind)
    brake = controller.brake
    if brake is not None and out.cones.s.shape[-1]:
        cones = controller.config.cones
        extra = brake.moment(controller.config.J, so3.vecmat(cones.V, R[..., None, :, :]),
                             out.cones.s, out.cones.cross, cones.theta, cones.r, Omega,
                             controller.model_acceleration(R, Omega, out.u, out.delta_bar,
                                                            terms.M_g, terms.W),
                             blind, dt)
        if extra is not None:
            out = out._replace(u=out.u + extra)
    return out
