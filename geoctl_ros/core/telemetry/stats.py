"""Statistics of a quantity over a fixed reporting window (the diagnostics period), ROS-free.

``add`` is called on the hot path (one store into a preallocated array); the figures are
computed only when the window is reported. A window holds at most ``capacity`` samples; beyond
that the newest overwrite the oldest (the count still counts every sample), so a window that
overflows reports its most recent samples.
"""
from typing import Optional, Sequence

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.telemetry.diagnostics import Window, window


class WindowStats:
    """Mean, standard deviation, 99th percentile and maximum of the samples since ``reset``."""

    def __init__(self, capacity: int = 2048) -> None:
        self._x = np.empty(capacity)
        self.n = 0

    def add(self, x: float) -> None:
        self._x[self.n % len(self._x)] = x
        self.n += 1

    def reset(self) -> None:
        self.n = 0

    def samples(self) -> FloatArray:
        return self._x[:min(self.n, len(self._x))]

    def window(self) -> Optional[Window]:
        """The diagnostics Window of the samples (mean, std, p99, max), or None for none."""
        return window(self.samples())


SETTLE_PSI = 1e-3          # Psi below this counts as settled (the runner's and report's summary)


def settle_time(t: Sequence[float], psi: Sequence[float],
                threshold: float = SETTLE_PSI) -> Optional[float]:
    """The time from which Psi stays below threshold: t[0] when it always was, None when it is
    not below at the end (t and psi: samples in time order).
    """
    above = np.nonzero(np.asarray(psi) >= threshold)[0]
    if not len(above):
        return float(t[0])
    if above[-1] + 1 < len(psi):
        return float(t[above[-1] + 1])
    return None
