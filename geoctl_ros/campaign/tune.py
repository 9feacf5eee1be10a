"""Gain tuning: Optuna searches the controller's gains on the campaign's random manoeuvres.

Each trial is a gain set (``SPACE``: the feedback gains, the adaptation, guidance's lookahead),
flown over the same ``runs`` manoeuvres of campaign seed ``seed`` with all of the campaign's draw
(latency and stalls, model errors, noise, the motors' lag; ``geoctl_ros.campaign.manoeuvres``) and
over the latency rows of docs/safety.md (``LATENCY_ROWS``: config/scenarios/testbed_yaw90.yaml
with its measurements that old and its steps that late), all on the Dask cluster.

- **Objectives** (both minimised): the settle time's median and 95th percentile over the runs
  (the time from which the attitude error stays under 5 deg; a run that never settles counts as
  ``UNSETTLED_FACTOR`` times the run's duration).
- **Constraints** (Optuna's: feasible when every value is <= 0): no violation in the runs, the
  closest approach at least ``CLOSEST_FLOOR_DEG``, the rotors saturated at most
  ``SATURATED_SHARE_MAX`` of the time on average (their authority), and every latency row clear
  of the cone.

The sampler is Optuna's TPE (multivariate) with ``seed``, and a trial's figures are a pure
function of its gains and the campaign seed (``runs.csv`` is the same on any cluster), so a
tuning run again with the same seeds proposes and finds the same gain sets.
"""
from dataclasses import dataclass
import math
import os
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from geoctl_ros.campaign import runner, study
from geoctl_ros.params import load_parameter_file
from geoctl_ros.sim import closed_loop
from geoctl_ros.sim.scenario import from_sections

# name: (low, high, log scale); everything else is the testbed's
SPACE = {
    'k_R': (0.3, 3.0, True),
    'k_Omega': (0.15, 1.5, True),
    'c': (0.1, 5.0, True),
    'k_Delta': (0.005, 0.5, True),
    'k_Delta_cog': (0.0005, 0.05, True),
    'guidance_lookahead_deg': (10.0, 45.0, False),
}
CLOSEST_FLOOR_DEG = 2.0        # the closest approach of any run, at least
SATURATED_SHARE_MAX = 0.02     # the rotors saturated at most this share of the time, on average
UNSETTLED_FACTOR = 2.0         # a run that never settles counts as this many durations
# docs/safety.md's latency table: (latency s, tick jitter s) of testbed_yaw90
LATENCY_ROWS = ((0.0, 0.0), (0.02, 0.0), (0.05, 0.0), (0.05, 0.01), (0.08, 0.02), (0.1, 0.02),
                (0.1, 0.05), (0.15, 0.05))
TRIAL_LATENCY_ROWS = ((0.05, 0.01), (0.1, 0.05), (0.15, 0.05))    # the hardest, in every trial
CONSTRAINTS = ('violations', 'closest below the floor [deg]', 'saturated share over the limit',
               'latency rows into the cone')


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
    saturated_share: float
    latency_margins_deg: List[float]   # closest approach of each latency row

    def constraints(self) -> List[float]:
        """Optuna's constraint values, feasible when all are <= 0 (in CONSTRAINTS' order)."""
        return [float(self.violations), CLOSEST_FLOOR_DEG - self.closest_min_deg,
                self.saturated_share - SATURATED_SHARE_MAX,
                float(sum(m <= 0.0 for m in self.latency_margins_deg))]

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
        saturated_share=float(np.mean(columns['saturated_s'])) / duration,
        latency_margins_deg=[float(m) for m in latency_margins])


def latency_row(job):
    """Worker: testbed_yaw90 with the gains, its inputs ``latency`` old and its steps up to
    ``jitter`` late, flown for ``duration`` s; its closest approach to the cone (deg).
    """
    path, gains, latency, jitter, duration = job
    sections = study.parameter_file(load_parameter_file(path), gains)
    sections.setdefault('scenario', {}).update(latency=float(latency), tick_jitter=float(jitter),
                                               duration=float(duration))
    flight = closed_loop.fly([from_sections(sections, 'latency')])
    return float(flight.min_margin_deg.min())


def latency_margins(client, path, gains, rows, duration):
    """The closest approach of each latency row, flown on the cluster."""
    jobs = [(path, gains, lat, jit, duration) for lat, jit in rows]
    return client.gather(client.map(latency_row, jobs, pure=False))


def suggest(trial) -> Dict[str, Any]:
    """The trial's gain set from SPACE (floats, as the schema wants them)."""
    return {name: float(trial.suggest_float(name, lo, hi, log=log))
            for name, (lo, hi, log) in SPACE.items()}


@dataclass
class TuneArgs:
    """What a tuning flies (the campaign runner's arguments, and the latency rows')."""

    runs: int
    seed: int
    duration: float
    latency_path: str
    latency_duration: float
    batch: int = runner.BATCH
    disturbance_max: float = 0.05
    worst: int = 0


def evaluate(client, base, args: TuneArgs, gains, rows=TRIAL_LATENCY_ROWS) -> TrialFigures:
    """Fly one gain set: the campaign's runs and the latency rows; its TrialFigures."""
    columns, _, interrupted, _ = runner.fly(client, base, args, [gains])
    if interrupted:
        raise KeyboardInterrupt
    margins = latency_margins(client, args.latency_path, gains, rows, args.latency_duration)
    return figures(columns, args.duration, margins)


def tune(client, base, args: TuneArgs, trials: int, sampler_seed: int,
         report=None, start: Optional[Dict[str, float]] = None):
    """Run the study; (the Optuna study, [(trial number, gains, TrialFigures)]). start: a gain set
    tried first (the testbed's own, so the study knows where it stands).
    """
    import optuna                    # (imported here: only the tuner needs it)
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = optuna.samplers.TPESampler(
        seed=sampler_seed, multivariate=True, n_startup_trials=min(10, max(1, trials // 4)))
    optuna_study = optuna.create_study(directions=['minimize', 'minimize'], sampler=sampler)
    if start:
        optuna_study.enqueue_trial({k: v for k, v in start.items() if k in SPACE},
                                   skip_if_exists=True)
    done = []
    for _ in range(trials):
        trial = optuna_study.ask()
        gains = suggest(trial)
        got = evaluate(client, base, args, gains)
        for name, value in zip(CONSTRAINTS, got.constraints()):
            trial.set_constraint(name, value)        # (feasible: every value <= 0)
        optuna_study.tell(trial, [got.settle_p50_s, got.settle_p95_s])
        done.append((trial.number, gains, got))
        if report is not None:
            report(trial.number, gains, got)
    return optuna_study, done


def pareto(done):
    """The feasible trials no other feasible trial beats in both settle figures, by p50."""
    feasible = [d for d in done if d[2].feasible]
    front = [d for d in feasible
             if not any((o[2].settle_p50_s <= d[2].settle_p50_s and
                         o[2].settle_p95_s <= d[2].settle_p95_s and
                         (o[2].settle_p50_s, o[2].settle_p95_s) !=
                         (d[2].settle_p50_s, d[2].settle_p95_s)) for o in feasible)]
    return sorted(front, key=lambda d: (d[2].settle_p95_s, d[2].settle_p50_s, d[0]))


TRIAL_COLUMNS = ('trial',) + tuple(SPACE) + (
    'runs', 'violations', 'closest_min_deg', 'closest_p1_deg', 'settled_share', 'settle_p50_s',
    'settle_p95_s', 'saturated_share', 'latency_min_margin_deg', 'feasible')


def trial_row(number, gains, got: TrialFigures) -> list:
    """A row of trials.csv (TRIAL_COLUMNS)."""
    return ([number] + [gains[k] for k in SPACE] +
            [got.runs, got.violations, got.closest_min_deg, got.closest_p1_deg,
             got.settled_share, got.settle_p50_s, got.settle_p95_s, got.saturated_share,
             min(got.latency_margins_deg) if got.latency_margins_deg else math.nan,
             got.feasible])


def write_trials(path, done):
    """trials.csv: a row per trial, floats exact (repr)."""
    with open(path, 'w') as f:
        f.write(','.join(TRIAL_COLUMNS) + '\n')
        for number, gains, got in done:
            f.write(','.join(map(repr, trial_row(number, gains, got))) + '\n')


def best_file_name(k: int) -> str:
    return os.path.join('best', 'gain_set_%d.yaml' % k)
