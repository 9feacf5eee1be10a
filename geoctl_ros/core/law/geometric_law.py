"""Lee's geometric controller on SO(3), the baseline: the attractive error, no barrier."""
from typing import Any

import numpy as np


def unconstrained(controller: Any, R: np.ndarray, Omega: np.ndarray, dt: float,
                   adapt: bool) -> tuple:
    """(the terms at R, Lee's geometric moment): the attractive error alone, no barrier."""
    terms = controller.terms(R, Omega)
    return terms, controller.moment(R, Omega, dt, adapt, terms, terms.A[..., 0], terms.e_RA,
                                    barrier=False)


def geometric_law(controller: Any, R: np.ndarray, Omega: np.ndarray, dt: float, adapt: bool,
                  blind: Any, brake: Any) -> Any:
    """Lee's geometric controller on SO(3) with the same gains and no barrier: the attractive
    error alone (the baseline that shows what the barrier buys). The cones are still evaluated,
    so margins and violations are reported.
    """
    return unconstrained(controller, R, Omega, dt, adapt)[1]
