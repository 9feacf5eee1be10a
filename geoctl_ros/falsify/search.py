"""Search-based falsification: an optimizer looks for the point of the envelope (``envelope``)
whose flight has the lowest robustness (``requirements``), flying its candidates as batches of
the one closed loop on the Dask cluster.

The optimizers are Psi-TaLiRo's (``staliro.optimizers``): its ``UniformRandom``, the baseline,
which draws the whole budget at once; ``DifferentialEvolution``, scipy's differential evolution as
a Psi-TaLiRo optimizer, whose population is evaluated a generation at a time (``vectorized``), so
it fits the batched closed loop; and its ``DualAnnealing``, which asks for one point at a time
(each a batch of one: about 40 times slower per run; not in the default set).

Every optimizer calls ``Objective.eval_samples`` (or ``eval_sample``): the points inside the
envelope are grouped into batches (runs of a batch share their tick jitter), flown on the
cluster, and monitored; each evaluation is recorded in order with its robustness under every
requirement, so a search that targets one requirement reports the others too.
"""
from dataclasses import dataclass, field
import functools
import math
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from geoctl_ros.campaign.cluster import checked
from geoctl_ros.falsify.envelope import OUTSIDE, Space
from geoctl_ros.falsify.requirements import COVERED, monitors, series_robustness
from geoctl_ros.params.scenario import from_sections, tick_jitter
from geoctl_ros.sim import closed_loop

BATCH = 256              # runs flown together at most
POPULATION = 256         # differential evolution's population (about: a multiple of the
                         # box's dimension, scipy's popsize): a generation flies as a few batches


def fly_batch(job):
    """Worker: fly a batch of scenario sections; per requirement each run's robustness, each
    run's closest approach to a cone after any integration step (deg), and its closest approach
    within the approach brake's assumptions (``closest_assumed_deg``: the robustness of the
    ``assumed`` requirement; inf where the derivation speaks of no step).
    """
    sections, names = job
    scenarios = [from_sections(s, 'falsify') for s in sections]
    flight = closed_loop.fly(scenarios, series=True, assumed=True)
    a = flight.assumed
    assert a is not None and flight.margin_series is not None
    assert flight.error_series is not None
    covered = a.covered()
    signals = {'margin': flight.margin_series, 'error': flight.error_series,
               'closest': np.minimum(a.hold_margin, flight.margin_series),
               'assumed': np.where(covered, COVERED, -COVERED)}
    got = series_robustness(monitors(names, flight.dt), flight.times, signals)
    if 'assumed' in got:        # (no covered step: no evidence, as a point outside the envelope)
        got['assumed'] = np.minimum(got['assumed'], OUTSIDE)
    got['closest_deg'] = flight.min_margin_deg.min(axis=-1)
    got['closest_assumed_deg'] = closest_assumed(signals['closest'], covered)
    return got


def closest_assumed(closest: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """(runs,) each run's closest approach (deg) over the control steps the approach brake's
    derivation speaks of (``covered``: from a safe state, every bound held since), +inf for a
    run with none: a negative value is a counterexample to the derivation.
    """
    return np.where(covered, closest, np.inf).min(axis=0)


@dataclass
class Evaluation:
    """One evaluated point: its coordinates, and its robustness per requirement (``OUTSIDE``
    for each when the point is outside the envelope).
    """

    x: np.ndarray
    robustness: Dict[str, float]
    closest_deg: float
    inside: bool
    closest_assumed_deg: float = math.inf    # within the brake's assumptions (``closest_assumed``)


@dataclass
class Objective:
    """The cost a Psi-TaLiRo optimizer minimises: the robustness of ``target`` of a point's flight
    (``OUTSIDE`` outside the envelope), evaluated on the cluster; every evaluation is kept.
    """

    client: Any
    space: Space
    target: str
    names: Sequence[str]
    evaluations: List[Evaluation] = field(default_factory=list)

    def eval_sample(self, sample) -> float:
        return self.eval_samples([sample])[0]

    def eval_samples(self, samples) -> List[float]:
        xs = [np.asarray(list(s), dtype=float) for s in samples]
        first = len(self.evaluations)
        sections = [self.space.sections(x, 'falsify, evaluation %d' % (first + i))
                    for i, x in enumerate(xs)]
        groups: Dict[float, List[int]] = {}
        for i, s in enumerate(sections):
            if s is not None:
                groups.setdefault(tick_jitter(s), []).append(i)
        jobs, where = [], []
        for members in groups.values():
            for k in range(0, len(members), BATCH):
                part = members[k:k + BATCH]
                jobs.append(([sections[i] for i in part], list(self.names)))
                where.append(part)
        results = self.client.gather(self.client.map(
            functools.partial(checked, fly_batch), jobs, pure=False)) if jobs else []
        got: Dict[int, Evaluation] = {}
        for part, res in zip(where, results):
            for j, i in enumerate(part):
                got[i] = Evaluation(xs[i], {n: float(res[n][j]) for n in self.names},
                                    float(res['closest_deg'][j]), True,
                                    float(res['closest_assumed_deg'][j]))
        for i, x in enumerate(xs):
            self.evaluations.append(got.get(i) or Evaluation(
                x, {n: OUTSIDE for n in self.names}, math.nan, False))
        return [e.robustness[self.target] for e in self.evaluations[first:]]


def differential_evolution():
    """scipy's differential evolution as a Psi-TaLiRo optimizer: a population of about
    POPULATION (latin hypercube), a generation evaluated at once, as many generations as the
    budget holds (the budget is spent in whole generations; none is polished locally).
    """
    from scipy import optimize  # noqa: PLC0415  (development tools: the falsifier's)
    from staliro.optimizers import Optimizer  # noqa: PLC0415

    class DifferentialEvolution(Optimizer):
        def optimize(self, func, params):
            bounds = [b.as_tuple() for b in params.input_bounds]
            popsize = max(1, min(round(POPULATION / len(bounds)), params.budget // len(bounds)))
            generations = max(1, params.budget // (popsize * len(bounds)))

            def costs(X):           # (dimensions, S) -> (S,)
                return np.array(func.eval_samples(list(np.asarray(X).T)))
            optimize.differential_evolution(
                costs, bounds, popsize=popsize, maxiter=generations - 1, vectorized=True,
                updating='deferred', polish=False, tol=0.0, rng=params.seed,
                init='latinhypercube')
            return None
    return DifferentialEvolution()


def optimizer(name: str):
    """The Psi-TaLiRo optimizer called name (``OPTIMIZERS``)."""
    from staliro.optimizers import DualAnnealing, UniformRandom  # noqa: PLC0415
    return {'uniform': UniformRandom, 'de': differential_evolution,
            'annealing': DualAnnealing}[name]()


OPTIMIZERS = ('uniform', 'de', 'annealing')


@dataclass
class Search:
    """One search: an optimizer, the requirement it minimised, its evaluations in order."""

    optimizer: str
    target: str
    evaluations: List[Evaluation]

    def lowest(self, name: str) -> Optional[Evaluation]:
        """The evaluation of lowest robustness under requirement name (None: none inside)."""
        inside = [e for e in self.evaluations if e.inside]
        return min(inside, key=lambda e: e.robustness[name]) if inside else None

    def running_min(self) -> np.ndarray:
        """The lowest robustness of the target found after each evaluation."""
        return np.minimum.accumulate([e.robustness[self.target] for e in self.evaluations])


def search(client, space: Space, target: str, names: Sequence[str], optimizer_name: str,
           budget: int, seed: int) -> Search:
    """Minimise the robustness of requirement target over the envelope with an optimizer."""
    from staliro.optimizers import Optimizer  # noqa: PLC0415
    from staliro.signals import Interval  # noqa: PLC0415
    objective = Objective(client, space, target, names)
    params = Optimizer.Params(seed=seed, budget=budget,
                              input_bounds=[Interval(lo, hi) for _, lo, hi in space.box])
    optimizer(optimizer_name).optimize(objective, params)
    return Search(optimizer_name, target, objective.evaluations[:budget])

