"""Statistics of a quantity over a fixed reporting window (the diagnostics period), ROS-free.

``add`` is called on the hot path (one store into a preallocated array); the figures are
computed only when the window is reported. A window holds at most ``capacity`` samples; beyond
that the newest overwrite the oldest (the count still counts every sample), so a window that
overflows reports its most recent samples.
"""
import re

import numpy as np

_SUMMARY = re.compile(r'mean ([\d.]+) std ([\d.]+) p99 ([\d.]+) max ([\d.]+)')


class WindowStats:
    """Mean, standard deviation, 99th percentile and maximum of the samples since ``reset``."""

    def __init__(self, capacity=2048):
        self._x = np.empty(capacity)
        self.n = 0

    def add(self, x):
        self._x[self.n % len(self._x)] = x
        self.n += 1

    def reset(self):
        self.n = 0

    def samples(self):
        return self._x[:min(self.n, len(self._x))]

    def figures(self):
        """dict(mean, std, p99, max, n), or None for an empty window."""
        x = self.samples()
        if not len(x):
            return None
        return {'mean': float(x.mean()), 'std': float(x.std()),
                'p99': float(np.percentile(x, 99)), 'max': float(x.max()), 'n': self.n}

    def summary(self, scale=1e3):
        """'mean M std S p99 P max X' (scaled, e.g. s -> ms), or 'n/a'."""
        f = self.figures()
        if f is None:
            return 'n/a'
        return 'mean %.3f std %.3f p99 %.3f max %.3f' % (f['mean'] * scale, f['std'] * scale,
                                                         f['p99'] * scale, f['max'] * scale)


def aggregate(summaries):
    """Several windows' ``summary`` strings (unparsable ones skipped) as one dict: mean of the
    means, RMS of the standard deviations, 99th percentile of the windows' p99, maximum; None when
    none parse."""
    rows = [tuple(float(x) for x in m.groups()) for m in map(_SUMMARY.match, summaries) if m]
    if not rows:
        return None
    a = np.array(rows)
    return {'mean': float(a[:, 0].mean()), 'std': float(np.sqrt((a[:, 1] ** 2).mean())),
            'p99': float(np.percentile(a[:, 2], 99)), 'max': float(a[:, 3].max())}
