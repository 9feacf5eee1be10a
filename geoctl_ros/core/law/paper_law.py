"""The paper's law as published (Kulumani, Poole & Lee), and its barrier step, which the
delay-robust law shares: the configuration error carries every cone's log barrier.
"""
from typing import Any

import numpy as np

from geoctl_ros.core.law.configuration_error import with_cones


def barrier_step(controller: Any, R: np.ndarray, Omega: np.ndarray, dt: float, adapt: bool,
                 blind: Any) -> Any:
    """The paper's configuration error with every cone's log barrier, each cone widened by the
    blind time (none when blind is 0): (the step's terms, its ControlOutput).
    """
    terms = controller.terms(R, Omega, blind)
    psi, e_R = with_cones(terms.A, terms.e_RA, terms.cones)
    return terms, controller.moment(R, Omega, dt, adapt, terms, psi, e_R)


def paper_law(controller: Any, R: np.ndarray, Omega: np.ndarray, dt: float, adapt: bool,
              blind: Any, brake: Any) -> Any:
    """The paper's law as published (Kulumani, Poole & Lee): the configuration error carries every
    cone's log barrier, on the cones as configured (never blind, no brake).
    """
    return barrier_step(controller, R, Omega, dt, adapt, 0.0)[1]
