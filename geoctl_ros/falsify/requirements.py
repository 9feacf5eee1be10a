"""The requirements a falsification attacks, in signal temporal logic, monitored with RTAMT.

Each is a formula over the flight's signals sampled at every control step:
- ``margin``: the sensor's angle to the nearest cone's surface (deg; negative inside a cone);
- ``error``: the attitude error to the goal (deg; the true attitude).

Its robustness on a trace (RTAMT's discrete-time semantics) is a number in degrees: positive when
the trace satisfies it, by how much it could be disturbed and still do; negative when it is
violated, by how much. A falsifier looks for a trace of negative robustness.
"""
from dataclasses import dataclass
from typing import Dict, Iterable, Sequence

import numpy as np

SETTLE_DEG = 5.0          # the settle requirement's error bound (deg)
SETTLE_WITHIN_S = 10.0    # and its deadline (s from arming)


@dataclass(frozen=True)
class Requirement:
    """A requirement: its name, its STL formula (RTAMT's syntax) and what it says."""

    name: str
    formula: str
    says: str


REQUIREMENTS = {
    'safety': Requirement('safety', 'always (margin >= 0)',
                          'always, the sensor stays outside every cone'),
    'settle': Requirement(
        'settle', 'eventually[0:%g](always(error <= %g))' % (SETTLE_WITHIN_S, SETTLE_DEG),
        'within %g s, and always after, the attitude error stays under %g deg'
        % (SETTLE_WITHIN_S, SETTLE_DEG)),
}


class Monitor:
    """RTAMT's offline monitor of one requirement, parsed once, for traces of period ``dt``."""

    def __init__(self, requirement: Requirement, dt: float):
        import rtamt  # noqa: PLC0415  (a development tool: the falsifier's, not the vehicle's)
        self.requirement = requirement
        spec = rtamt.StlDiscreteTimeSpecification()
        spec.declare_var('margin', 'float')
        spec.declare_var('error', 'float')
        spec.spec = requirement.formula
        spec.set_sampling_period(dt, 's', 0.1)
        spec.parse()
        self._spec = spec

    def robustness(self, times: Iterable[float], margin: Iterable[float],
                   error: Iterable[float]) -> float:
        """The robustness of the trace (deg) at its start."""
        got = self._spec.evaluate({'time': [float(t) for t in times],
                                   'margin': [float(m) for m in margin],
                                   'error': [float(e) for e in error]})
        return float(got[0][1])


def monitors(names: Sequence[str], dt: float) -> Dict[str, Monitor]:
    """A monitor per named requirement (``REQUIREMENTS``' keys)."""
    return {name: Monitor(REQUIREMENTS[name], dt) for name in names}


def series_robustness(mons: Dict[str, Monitor], times: np.ndarray, margin: np.ndarray,
                      error: np.ndarray) -> Dict[str, np.ndarray]:
    """Per requirement, each run's robustness: margin and error (steps, runs) of a batch."""
    runs = margin.shape[1]
    return {name: np.array([m.robustness(times, margin[:, j], error[:, j]) for j in range(runs)])
            for name, m in mons.items()}
