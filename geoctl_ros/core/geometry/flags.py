"""Reductions of per-run flags for code that takes one run or a batch of runs.

A step of one run gives a single numpy bool where a batch gives one flag per run; ``np.all`` and
``np.any`` on a single numpy bool cost about as much as the arithmetic of a whole control step
(8 us against 0.3 us on the development machine), so the hot path uses these.
"""
from typing import Union

import numpy as np

from geoctl_ros.core.geometry.so3 import BoolArray

Flags = Union[np.bool_, BoolArray]      # one run's flag (a numpy bool), or one per run


def any_flag(flags: Flags) -> Flags:
    """flags.any() for an array of flags; a single numpy bool as it is."""
    return flags if flags.ndim == 0 else flags.any()


def all_flag(flags: Flags) -> Flags:
    """flags.all() for an array of flags; a single numpy bool as it is."""
    return flags if flags.ndim == 0 else flags.all()
