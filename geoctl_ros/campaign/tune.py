"""Gain tuning: Optuna searches the controller's gains on the campaign's random manoeuvres.

Each trial is a gain set: a point of the search space (the feedback gains, the adaptation's
weight c as a share of k_R / k_Omega, the time constants with which the estimate learns m*rho and
a constant moment, guidance's lookahead), which ``controller_gains`` turns into the controller's
parameters. The space's ranges are ``tune``'s options, ``SPACE`` by default; ``space_problems``
refuses a space with a gain set the controller would not take.
It flies the same ``runs`` manoeuvres of campaign seed ``seed`` with all of the campaign's draw
(latency and stalls, model errors, noise, the motors' lag; ``geoctl_ros.campaign.manoeuvres``),
and the hardest rows of docs/safety.md's latency table (``TRIAL_LATENCY_ROWS``:
config/scenarios/testbed_yaw90.yaml flown on the tuned file's airframe, ``latency_file``, with its
measurements that old and its steps that late), all on the Dask cluster. The approach brake's
bounds are those the airframe gives (``airframe_of``: ``controller_setup`` computes a_b from the
rotors' polytope where ``brake_acceleration`` is 0, and a_u from the inertia).

- **Objectives** (both minimised): the settle time's median and 95th percentile over the runs
  (the time from which the attitude error stays under 5 deg; a run that never settles counts as
  ``UNSETTLED_FACTOR`` times the run's duration).
- **Constraints** (Optuna's: feasible when every value is <= 0): no violation in the runs, the
  closest approach's 1st percentile at least ``CLOSEST_FLOOR_DEG``, at most
  ``SATURATED_RUNS_MAX`` of the runs with the rotors saturated for longer than ``SATURATED_RUN_S``
  (their authority: a mean over the runs let a set through that saturated 41 % of a 10,000-run
  campaign's runs and went into the cone in 5), at most ``SATURATING_RUNS_MAX`` of the runs with
  the rotors saturated at all (where they saturate, the moment the prediction assumes is not made:
  a set that saturated in 20 % of a 10,000-run campaign's runs rang against the rotors' limits
  with 60 ms of latency and went 10 deg into a cone), and every latency row at least
  ``CLOSEST_FLOOR_DEG`` clear of the cone too.

The sampler is Optuna's TPE (multivariate) with ``seed``, and a trial's figures are a pure
function of its gains and the campaign seed (``runs.csv`` is the same on any cluster), so a
tuning run again with the same seeds proposes and finds the same gain sets.
"""
from dataclasses import dataclass, field
import functools
import itertools
import math
import os
from typing import Any, Dict, List, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from geoctl_ros.campaign import cluster, manoeuvres, runner, study
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.brake import ApproachBrake
from geoctl_ros.core.law.gains import learning_gain, learning_time
from geoctl_ros.params import (
    CONTROLLER,
    ConfigError,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.params.build import GainSet, gain_set
from geoctl_ros.params.scenario import on_airframe
from geoctl_ros.sim import closed_loop
from geoctl_ros.sim.scenario import from_sections

# The search's coordinates, name: (low, high, log scale), the defaults of ``tune``'s options
# (``--k-R LO HI``, ...). The adaptation is searched by what it
# does rather than by its raw gains: c as a share of k_R / k_Omega (at 1, e_Omega + c e_R vanishes
# along the loop's own slow decay, so the estimate learns from what the model misses, not from the
# manoeuvre itself), and each block's learning time constant (``core.law.gains.learning_time``),
# m*rho's within a few seconds (docs/control-law.md, "Learning the gravity moment").
SPACE = {
    'k_R': (0.5, 3.0, True),
    'k_Omega': (0.15, 1.5, True),
    'c_share': (0.25, 1.5, False),
    'cog_learning_s': (0.5, 3.0, True),
    'moment_learning_s': (2.0, 30.0, True),
    'guidance_lookahead_deg': (10.0, 45.0, False),
}
# the controller's parameters a trial sets (over the testbed's file)
GAINS = GainSet.names()
Space = Dict[str, Tuple[float, float, bool]]     # SPACE's shape: name: (low, high, log scale)


class SearchPoint(NamedTuple):
    """A point of the search space (SPACE's coordinates)."""

    k_R: float
    k_Omega: float
    c_share: float
    cog_learning_s: float
    moment_learning_s: float
    guidance_lookahead_deg: float
# the closest approach's 1st percentile over the runs, and every latency row's, at least: half a
# degree over the 2 deg that the gains must keep on other draws (the benchmark's 1,000 runs of
# another seed), for what a tuning's few hundred runs do not show
CLOSEST_FLOOR_DEG = 2.5
SATURATED_RUN_S = 0.1          # a run whose rotors saturate longer than this (s) in all
SATURATED_RUNS_MAX = 0.01      # may be at most this share of the runs
# the share of the runs whose rotors saturate at all, at most: of four gain sets checked on the
# 10,000-run campaign (seed 1), the three that saturated in 20-41 % of its runs entered a cone 4
# or 5 times, and the one at 4.5 % never (docs/campaigns.md, "Gain tuning")
SATURATING_RUNS_MAX = 0.10
UNSETTLED_FACTOR = 2.0         # a run that never settles counts as this many durations
# docs/safety.md's latency table: (latency s, tick jitter s) of testbed_yaw90
LATENCY_ROWS = ((0.0, 0.0), (0.02, 0.0), (0.05, 0.0), (0.05, 0.01), (0.08, 0.02), (0.1, 0.02),
                (0.1, 0.05), (0.15, 0.05))
TRIAL_LATENCY_ROWS = ((0.05, 0.01), (0.1, 0.05), (0.15, 0.05))    # the hardest, in every trial
CONSTRAINTS = ('violations', 'closest p1 below the floor [deg]',
               'share of runs saturated over the limit', 'latency rows below the floor [deg]',
               'share of runs saturating over the limit')
TRIALS_AT_ONCE = 2      # trials asked and flown together (a constant: the same on any cluster)


def controller_gains(point: SearchPoint, gravity: float) -> Dict[str, float]:
    """The controller's parameters (GAINS) of a point of SPACE; gravity: |g| (m/s^2)."""
    k_R, k_Omega = point.k_R, point.k_Omega
    c = point.c_share * k_R / k_Omega
    return GainSet(k_R, k_Omega, c, learning_gain(k_R, c, point.moment_learning_s, 1.0),
                   learning_gain(k_R, c, point.cog_learning_s, gravity),
                   point.guidance_lookahead_deg).overrides()


def search_point(gains: Dict[str, float], gravity: float) -> SearchPoint:
    """The point of SPACE of the controller's parameters (``controller_gains``' inverse)."""
    g = gain_set(gains)
    return SearchPoint(g.k_R, g.k_Omega, g.c * g.k_Omega / g.k_R,
                       learning_time(g.k_R, g.c, g.k_Delta_cog, gravity),
                       learning_time(g.k_R, g.c, g.k_Delta, 1.0), g.guidance_lookahead_deg)


@dataclass
class TrialFigures:
    """What one gain set did: over the runs, and over the latency rows."""

    runs: int
    violations: int
    closest_min_deg: float
    closest_p1_deg: float
    settled_share: float           # settled within the run
    settle_p50_s: float            # (unsettled runs count as UNSETTLED_FACTOR durations)
    settle_p95_s: float
    saturated_runs: float         # the share of the runs saturated longer than SATURATED_RUN_S
    saturating_runs: float        # the share of the runs saturated at all
    latency_margins_deg: List[float]   # closest approach of each latency row

    def constraints(self) -> List[float]:
        """Optuna's constraint values, feasible when all are <= 0 (in CONSTRAINTS' order)."""
        return [float(self.violations), CLOSEST_FLOOR_DEG - self.closest_p1_deg,
                self.saturated_runs - SATURATED_RUNS_MAX,
                CLOSEST_FLOOR_DEG - min(self.latency_margins_deg, default=math.inf),
                self.saturating_runs - SATURATING_RUNS_MAX]

    @property
    def feasible(self) -> bool:
        return all(v <= 0.0 for v in self.constraints())


def figures(columns: Dict[str, np.ndarray], duration: float,
            latency_margins: Sequence[float]) -> TrialFigures:
    """TrialFigures of one gain set's campaign columns (``runner.fly``) and latency rows."""
    settle = np.where(np.isnan(columns['settle_s']), UNSETTLED_FACTOR * duration,
                      columns['settle_s'])
    return TrialFigures(
        runs=len(settle), violations=int(np.sum(columns['violated'])),
        closest_min_deg=float(np.min(columns['closest_deg'])),
        closest_p1_deg=study.percentile(columns['closest_deg'], 1),
        settled_share=float(np.mean(~np.isnan(columns['settle_s']))),
        settle_p50_s=float(np.median(settle)), settle_p95_s=float(np.percentile(settle, 95)),
        saturated_runs=float(np.mean(columns['saturated_s'] > SATURATED_RUN_S)),
        saturating_runs=float(np.mean(columns['saturated_s'] > 0.0)),
        latency_margins_deg=[float(m) for m in latency_margins])


def space_problems(space: Space, gravity: float) -> List[Tuple[str, str]]:
    """Why the controller would refuse some gain set of a search space, as (coordinate or 'the
    search space', reason) pairs ([] when it takes all): a range that is not low < high (and
    low > 0 on a log scale), or a corner of the box whose gains (``controller_gains``) the schema
    refuses. Each gain is monotonic in each coordinate, so the corners hold its extremes.
    """
    errors = []
    for name, (lo, hi, log) in space.items():
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi and (lo > 0.0 or not log)):
            errors.append((name, '%g-%g is no range (low < high%s)'
                           % (lo, hi, ', low > 0: a log scale' if log else '')))
    if errors:
        return errors
    for corner in itertools.product(*((lo, hi) for lo, hi, _ in space.values())):
        point = SearchPoint(*corner)
        try:
            resolve(CONTROLLER, controller_gains(point, gravity))
        except ConfigError as e:
            return [('the search space', 'its corner %s gives %s' % (
                ' '.join('%s=%g' % kv for kv in point._asdict().items()),
                '; '.join('%s: %s' % err for err in e.errors)))]
    return errors


class Airframe(NamedTuple):
    """What a tuning flies on, as its controller's model has it."""

    mass: float                   # kg
    pivot_inertia: Tuple[float, float, float]   # kg m^2, principal, about the pivot, ascending
    brake: ApproachBrake          # the approach brake's bounds it gives

    def describe(self) -> str:
        return ('mass %.3g kg, principal inertias about the pivot %s kg m^2; the approach '
                "brake's a_b %.1f rad/s^2, a_u %.2f rad/s^2"
                % (self.mass, ' / '.join('%.4f' % j for j in self.pivot_inertia),
                   self.brake.authority, self.brake.unmodelled))


def airframe_of(sections: dict) -> Airframe:
    """The Airframe of a parameter file's controller, as ``controller_setup`` builds it: the
    brake's bounds are ``ApproachBrake.bounds_of`` its configuration (a_b from
    ``core.law.brake.brake_authority`` where ``brake_acceleration`` is 0, a_u from the inertia).
    Raises ConfigError where the file does not configure a controller.
    """
    config = controller_setup(resolve(CONTROLLER, node_overrides(sections, CONTROLLER))).config
    return Airframe(float(config.mass), so3.symmetric_eigenvalues(config.J),
                    ApproachBrake.bounds_of(config))


def latency_file(path: str, base: dict) -> dict:
    """The latency rows' scenario file (sections) flown on the airframe of the tuned file's
    (``geoctl_ros.params.scenario.on_airframe``): its gains, cones and set points, base's body,
    rotors and motors.
    """
    return on_airframe(load_parameter_file(path), base)


def latency_row(job):
    """Worker: the latency rows' file (sections: ``latency_file``, the gains put over it), its
    inputs ``latency`` old and its steps up to ``jitter`` late, flown for ``duration`` s; its
    closest approach to the cone (deg).
    """
    sections, latency, jitter, duration = job
    sections = {node: dict(flat) for node, flat in sections.items()}
    sections.setdefault('scenario', {}).update(latency=float(latency), tick_jitter=float(jitter),
                                               duration=float(duration))
    flight = closed_loop.fly([from_sections(sections, 'latency')])
    return float(flight.min_margin_deg.min())


@dataclass
class TuneArgs:
    """What a tuning flies (the campaign runner's arguments, and the latency rows')."""

    runs: int
    seed: int
    duration: float
    latency_path: str              # the latency rows' file (flown on the tuned file's airframe)
    latency_duration: float
    gravity: float = 9.81          # |g| of the testbed (m/s^2)
    space: Space = field(default_factory=lambda: dict(SPACE))   # the search's ranges
    batch: int = runner.BATCH
    disturbance_max: float = manoeuvres.DISTURBANCE_MAX
    worst: int = 0


def evaluate(client, base, args: TuneArgs, gain_sets, rows=TRIAL_LATENCY_ROWS):
    """Fly gain sets together on the cluster: the campaign's runs and the latency rows of each;
    their TrialFigures, in order.
    """
    columns, _, interrupted, _ = runner.fly(client, base, args, gain_sets)
    if interrupted:
        raise KeyboardInterrupt
    flown = latency_file(args.latency_path, base)
    jobs = [(study.parameter_file(flown, gains), lat, jit, args.latency_duration)
            for gains in gain_sets for lat, jit in rows]
    margins = client.gather(client.map(functools.partial(cluster.checked, latency_row), jobs,
                                       pure=False))
    n = len(rows)
    return [figures({c: v[columns['gain_set'] == k + 1] for c, v in columns.items()},
                    args.duration, margins[k * n:(k + 1) * n]) for k in range(len(gain_sets))]


def suggest(trial, gravity: float, space: Space = SPACE) -> Dict[str, Any]:
    """The trial's gain set (GAINS, floats as the schema wants them) from its point of the
    search space.
    """
    return controller_gains(SearchPoint(*(float(trial.suggest_float(name, lo, hi, log=log))
                                          for name, (lo, hi, log) in space.items())), gravity)


def tune(client, base, args: TuneArgs, trials: int, sampler_seed: int,
         report=None, start: Optional[Dict[str, float]] = None):
    """Run the study; (the Optuna study, [(trial number, gains, TrialFigures)]). start: a gain set
    (GAINS) tried first where it lies in the search space (args.space; the testbed's own, so that
    the study knows where it stands). TRIALS_AT_ONCE trials are asked, flown together and told at
    a time.
    """
    import optuna  # noqa: PLC0415  (here: only the tuner needs it, on a development machine)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = optuna.samplers.TPESampler(
        seed=sampler_seed, multivariate=True, n_startup_trials=min(10, max(1, trials // 4)))
    optuna_study = optuna.create_study(directions=['minimize', 'minimize'], sampler=sampler)
    if start:
        point = search_point(start, args.gravity)
        if all(lo <= x <= hi for x, (lo, hi, _) in zip(point, args.space.values())):
            optuna_study.enqueue_trial(point._asdict(), skip_if_exists=True)
    done: list = []
    while len(done) < trials:
        asked = [optuna_study.ask() for _ in range(min(TRIALS_AT_ONCE, trials - len(done)))]
        gain_sets = [suggest(t, args.gravity, args.space) for t in asked]
        for trial, gains, got in zip(asked, gain_sets, evaluate(client, base, args, gain_sets)):
            for name, value in zip(CONSTRAINTS, got.constraints()):
                trial.set_constraint(name, value)        # (feasible: every value <= 0)
            optuna_study.tell(trial, [got.settle_p50_s, got.settle_p95_s])
            done.append((trial.number, gains, got))
            if report is not None:
                report(trial.number, gains, got)
    return optuna_study, done


def ranked(done):
    """The feasible trials, best first: by settle p95, then p50, then trial number."""
    feasible = [d for d in done if d[2].feasible]
    return sorted(feasible, key=lambda d: (d[2].settle_p95_s, d[2].settle_p50_s, d[0]))


CHECK_FLOOR_DEG = 2.0     # the held-out check: the floor of closest p1 and of the latency rows
CHECK_MIN_DEG = 1.0       # and of every held-out run's closest approach


def check(client, base, args: TuneArgs, candidates):
    """The held-out check of candidate gain sets ([(trial, gains, TrialFigures)]), in turn until
    one passes: each flies args' runs (another seed's than the tuning's) and the whole latency
    table; [(TrialFigures, passed)] of those flown, passed when no run entered a cone, the
    closest approach's p1 and every latency row are at least CHECK_FLOOR_DEG, and every run's
    at least CHECK_MIN_DEG (the tuning's sets sit at the edge of its own floor: a held-out run
    that comes nearer than that is one the tuning's draw did not show).
    """
    out = []
    for _, gains, _ in candidates:
        got = evaluate(client, base, args, [gains], LATENCY_ROWS)[0]
        passed = (got.violations == 0 and got.closest_p1_deg >= CHECK_FLOOR_DEG and
                  got.closest_min_deg >= CHECK_MIN_DEG and
                  min(got.latency_margins_deg) >= CHECK_FLOOR_DEG)
        out.append((got, passed))
        if passed:
            break
    return out


def pareto(done):
    """The feasible trials no other feasible trial beats in both settle figures, by p95."""
    feasible = [d for d in done if d[2].feasible]
    front = [d for d in feasible
             if not any((o[2].settle_p50_s <= d[2].settle_p50_s and
                         o[2].settle_p95_s <= d[2].settle_p95_s and
                         (o[2].settle_p50_s, o[2].settle_p95_s) !=
                         (d[2].settle_p50_s, d[2].settle_p95_s)) for o in feasible)]
    return sorted(front, key=lambda d: (d[2].settle_p95_s, d[2].settle_p50_s, d[0]))


TRIAL_COLUMNS = ('trial',) + GAINS + (
    'runs', 'violations', 'closest_min_deg', 'closest_p1_deg', 'settled_share', 'settle_p50_s',
    'settle_p95_s', 'saturated_runs', 'latency_min_margin_deg', 'saturating_runs', 'feasible')


def trial_row(number, gains, got: TrialFigures) -> list:
    """A row of trials.csv (TRIAL_COLUMNS)."""
    return ([number] + [gains[k] for k in GAINS] +
            [got.runs, got.violations, got.closest_min_deg, got.closest_p1_deg,
             got.settled_share, got.settle_p50_s, got.settle_p95_s, got.saturated_runs,
             min(got.latency_margins_deg) if got.latency_margins_deg else math.nan,
             got.saturating_runs, got.feasible])


def write_trials(path, done):
    """trials.csv: a row per trial, floats exact (repr)."""
    with open(path, 'w') as f:
        f.write(','.join(TRIAL_COLUMNS) + '\n')
        for number, gains, got in done:
            f.write(','.join(map(repr, trial_row(number, gains, got))) + '\n')


def best_file_name(k: int) -> str:
    return os.path.join('best', 'gain_set_%d.yaml' % k)
