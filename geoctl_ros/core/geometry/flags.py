"""Reductions of per-run flags for code that takes one run or a batch of runs.

A step of one run gives a single numpy bool where a batch gives one flag per run; ``np.all`` and
``np.any`` on a single numpy bool cost about as much as the arithmetic of a whole control step
(8 us against 0.3 us on the development machine), so the hot path uses these.
"""
from typing import Any

import numpy as np


def any_flag(flags: np.ndarray) -> Any:
    """flags.any() for an array of flags; a single numpy bool as it is."""
    return flags if flags.ndim == 0 else flags.any()


def all_flag(flags: np.ndarray) -> Any:
    """flags.all() for an array of flags; a single numpy bool as it is."""
    return flags if flags.ndim == 0 else flags.all()
