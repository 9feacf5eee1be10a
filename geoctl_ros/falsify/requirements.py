"""The requirements a falsification attacks, in signal temporal logic, monitored with RTAMT.

Each is a formula over the flight's signals sampled at every control step:
- ``margin``: the sensor's angle to the nearest cone's surface at the step (deg; negative inside
  a cone);
- ``error``: the attitude error to the goal (deg; the true attitude);
- ``closest``: the closest approach to any cone over the step's hold (deg);
- ``assumed``: whether the approach brake's derivation speaks of the step (+COVERED where it
  does, -COVERED where it does not: ``sim.closed_loop.AssumedSeries.covered``).

Its robustness on a trace (RTAMT's discrete-time semantics) is a number in degrees: positive when
the trace satisfies it, by how much it could be disturbed and still do; negative when it is
violated, by how much. A falsifier looks for a trace of negative robustness. The robustness of
``assumed`` is the closest approach over the steps the derivation speaks of (COVERED where there
are none): it attacks the claim itself.
"""
from dataclasses import dataclass
from typing import Any, Dict, Sequence

import numpy as np

SETTLE_DEG = 5.0          # the settle requirement's error bound (deg)
SETTLE_WITHIN_S = 10.0    # and its deadline (s from the take-over)
COVERED = 1.0e6           # the assumed signal's magnitude (deg: beyond any margin)
SIGNALS = ('margin', 'error', 'closest', 'assumed')


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
    'assumed': Requirement(
        'assumed', 'always ((assumed >= 0) -> (closest >= 0))',
        "within the approach brake's assumptions, the sensor stays outside every cone (the "
        "derivation's claim)"),
}


class Monitor:
    """RTAMT's offline monitor of one requirement, parsed once, for traces of period ``dt``."""

    def __init__(self, requirement: Requirement, dt: float):
        import rtamt  # noqa: PLC0415  (a development tool: the falsifier's, not the vehicle's)
        self.requirement = requirement
        spec = rtamt.StlDiscreteTimeSpecification()
        for name in SIGNALS:
            spec.declare_var(name, 'float')
        spec.spec = requirement.formula
        spec.set_sampling_period(dt, 's', 0.1)
        spec.parse()
        self._spec = spec

    def robustness(self, times: Any, signals: Dict[str, np.ndarray]) -> float:
        """The robustness of the trace (deg) at its start; signals: each of ``SIGNALS`` per
        step.
        """
        trace = {'time': [float(t) for t in times]}
        trace.update({name: [float(v) for v in signals[name]] for name in SIGNALS})
        return float(self._spec.evaluate(trace)[0][1])


def monitors(names: Sequence[str], dt: float) -> Dict[str, Monitor]:
    """A monitor per named requirement (``REQUIREMENTS``' keys)."""
    return {name: Monitor(REQUIREMENTS[name], dt) for name in names}


def series_robustness(mons: Dict[str, Monitor], times: np.ndarray,
                      signals: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
    """Per requirement, each run's robustness: signals (``SIGNALS``, each (steps, runs)) of a
    batch.
    """
    runs = next(iter(signals.values())).shape[1]
    return {name: np.array([m.robustness(times, {k: v[:, j] for k, v in signals.items()})
                            for j in range(runs)])
            for name, m in mons.items()}
