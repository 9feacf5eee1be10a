"""The benchmark's standard cases, each flown by every law, and the laws' steps timed side by side.

The cases are the shipped scenario files of the paper and the testbed (``CASES``); each law flies
each case as the file has it but for ``law``. A flight whose moment is no longer finite (an
unbounded law on the ideal-torque plant) counts as diverged: its figures are NaN and it is a
violation, and the benchmark goes on.
"""
import copy
from dataclasses import dataclass, field
import math
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from geoctl_ros.benchmark.scores import RUN_COLUMNS, run_scores
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.core.law.laws import LAWS
from geoctl_ros.params import controller_setup
from geoctl_ros.sim.closed_loop import fly
from geoctl_ros.sim.scenario import from_sections

# the standard cases (scenario files in config/scenarios), in the tables' order
CASES = ('paper_four_cones_adaptive', 'paper_four_cones_no_adaptation',
         'paper_four_cones_code_variant', 'dissertation_time_varying', 'testbed_yaw90')
# the laws in the tables' order: the paper's, its delay-robust variant, the baseline, the filter
BENCHED = ('paper', 'delay_robust', 'geometric', 'cbf')
DEFAULT_LAW = 'delay_robust'   # the schema's default law: the one the gain sets are compared with
assert set(BENCHED) == set(LAWS)
TIMED_STATES = 300          # states of each flight the steps are timed at


def with_law(sections: dict, law: str) -> dict:
    """A copy of a scenario file's sections with the controller's law set."""
    out = copy.deepcopy(sections)
    out.setdefault('controller', {})['law'] = law
    return out


@dataclass
class CaseFlight:
    """One case flown by one law: what the tables and figures need of it."""

    case: str
    law: str
    title: str
    controller: dict                   # its resolved controller parameters
    cones: Any                         # its ConeSet
    diverged: str = ''                 # why the flight stopped, '' when it did not
    scores: Dict[str, Any] = field(default_factory=dict)     # RUN_COLUMNS
    margins: np.ndarray = field(default_factory=lambda: np.array([]))   # at each control step
    sensor: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))   # direction, world
    dt: float = 0.0
    states: List[tuple] = field(default_factory=list)   # (R, Omega) the steps are timed at


def fly_case(job: Tuple[str, str, dict, Optional[float]]) -> CaseFlight:
    """Worker: fly one case (name, law, the scenario file's sections, the simulated seconds or
    None for the file's) with its law; the run's
    figures, its series (margin and sensor direction at each control step), the states the steps
    are timed at, and what the figures need of the scenario.
    """
    name, law, sections, duration = job
    scenario = from_sections(with_law(sections, law), name)
    out = CaseFlight(name, law, scenario.options.title, scenario.controller, scenario.cones())
    try:
        flight = fly([scenario], series=True, history=True, duration=duration)
    except FloatingPointError as e:
        out.diverged = str(e)
        out.scores = dict({k: math.nan for k in RUN_COLUMNS}, violated=True)
        return out
    assert flight.history is not None and flight.margin_series is not None
    assert flight.sensor_series is not None
    a = flight.history.arrays
    picked = np.linspace(0, len(flight.times) - 1, min(TIMED_STATES, len(flight.times)))
    states = [(so3.quat_to_rot(a['q'][k, 0]), a['w'][k, 0].copy()) for k in picked.astype(int)]
    out.scores = {k: v[0].item() for k, v in run_scores(flight).items()}
    out.margins = flight.margin_series[:, 0].copy()
    out.sensor = flight.sensor_series[:, 0].astype(float)
    out.dt, out.states = flight.dt, states
    return out


def step_times(controller_values: dict, laws: Sequence[str], states: List[tuple],
               rounds: int = 3) -> Dict[str, np.ndarray]:
    """Each law's control step (``AttitudeController.step``) timed at the states, microseconds
    per call: side by side, in rounds that take the laws in turn, each state once a round, so that
    a busy machine slows every law alike. controller_values: resolved controller parameters.
    """
    controllers = {}
    for law in laws:
        setup = controller_setup(dict(controller_values, law=law))
        controllers[law] = AttitudeController(setup.config)
        controllers[law].R_d = setup.setpoint
    dt = 1.0 / setup.loop.rate_hz
    order = tuple(laws)
    times: Dict[str, list] = {law: [] for law in order}
    clock = time.perf_counter_ns
    for r in range(rounds):
        for law in order[r % len(order):] + order[:r % len(order)]:
            step = controllers[law].step
            took = times[law]
            for R, Omega in states:
                t0 = clock()
                step(R, Omega, dt)
                took.append(clock() - t0)
    return {law: np.asarray(t, dtype=float) / 1000.0 for law, t in times.items()}
