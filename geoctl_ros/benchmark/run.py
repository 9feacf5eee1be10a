"""The benchmark of the control laws (the ``benchmark`` command: geoctl_ros.cli.benchmark).

Every law of ``geoctl_ros.core.law.laws`` flies the standard cases (``cases.CASES``: the paper's
four cones with and without adaptation, the authors' code variant, the dissertation's time-varying
disturbance, the testbed's 90 deg yaw with rotors) and the same random manoeuvres of the campaign
(``geoctl_ros.campaign.manoeuvres``: noise, model errors, latency, input stalls), all on a Dask
cluster. The laws' steps are then timed side by side in this process, at states of the cases'
flights. Writes into the output folder:

- benchmark.md: a table per case, one over the random runs and one overall (every run);
- cases.csv, random.csv, overall.csv: the same rows (floats exact);
- random_runs.csv: every random run's figures, per law;
- CASE.png: per case, every law's sensor path with the cones, and its margins in time;
- random_closest.png: the random runs' closest approach per law;
- gain_sets.csv and a table in benchmark.md: the default law over the random runs with each gain
  set (``GAIN_SETS``: the testbed's tuned gains, and the paper's experiment's).
"""
import os
import time
from types import SimpleNamespace
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from geoctl_ros.benchmark import cases
from geoctl_ros.benchmark.scores import RUN_COLUMNS, csv_lines, law_row, markdown
from geoctl_ros.campaign import cluster, manoeuvres, runner, tune
from geoctl_ros.params import CONTROLLER, load_parameter_file, node_overrides, resolve
from geoctl_ros.plots import benchmark as plots

# The gain sets the default law flies the random runs with: name -> the scenario file (under
# config/scenarios) whose gains go over config/testbed.yaml's; None: the testbed's own
GAIN_SETS = {"the testbed's (config/testbed.yaml)": None,
             "the experiment's (testbed_experiment.yaml)": 'testbed_experiment.yaml'}
GAIN_KEYS = tune.GAINS + ('disturbance_model',)


def gain_set(path: Optional[str]) -> dict:
    """The gains (GAIN_KEYS) of a scenario file, its defaults included; {} for None."""
    if path is None:
        return {}
    values = resolve(CONTROLLER, node_overrides(load_parameter_file(path), CONTROLLER))
    return {k: values[k] for k in GAIN_KEYS}


def fly_cases(client, sections: Dict[str, dict], say: Callable[[str], None],
              duration: Optional[float] = None) -> List[cases.CaseFlight]:
    """Fly every standard case (sections: {name: the scenario file's sections}) with every law
    on the cluster, for duration simulated seconds (None: the files'); the flights
    (``cases.fly_case``'s), in the tables' order.
    """
    jobs = [(name, law, sections[name], duration) for name in sections for law in cases.BENCHED]
    flown: Dict[int, dict] = {}

    def take(i, out):
        flown[i] = out
        say('benchmark: %s, %s: closest %+.2f deg%s' % (
            out.case, out.law, out.scores['closest_deg'], ' (diverged)' if out.diverged else ''))

    cluster.run_tasks(client, cases.fly_case, jobs, take)
    return [flown[i] for i in range(len(jobs))]


def fly_random(client, base: dict, runs: int, seed: int, duration: float, batch: int,
               progress: Optional[Callable] = None, gain_sets: Optional[Dict[str, dict]] = None
               ) -> Tuple[Dict[str, Dict[str, np.ndarray]], Dict[str, Dict[str, np.ndarray]]]:
    """Fly the campaign's random runs 0..runs-1 of seed with every law, and with the default law
    under each of gain_sets ({name: gains}; the testbed's own, {}, is the default law's row), on
    the cluster (the same manoeuvres for each); ({law: {column: array over the runs}}, {gain set
    name: the same}).
    """
    args = SimpleNamespace(runs=runs, seed=seed, duration=duration, batch=batch,
                           disturbance_max=manoeuvres.DISTURBANCE_MAX, worst=0)
    sets = [{'law': law} for law in cases.BENCHED]
    extra = {name: gains for name, gains in (gain_sets or {}).items() if gains}
    sets += [dict(gains, law=cases.DEFAULT_LAW) for gains in extra.values()]
    columns, _, interrupted, _ = runner.fly(client, base, args, sets, progress)
    if interrupted:
        raise KeyboardInterrupt

    def of(k):
        return {c: v[columns['gain_set'] == k + 1] for c, v in columns.items()}
    by_law = {law: of(k) for k, law in enumerate(cases.BENCHED)}
    by_set = {}
    for name, gains in (gain_sets or {}).items():
        by_set[name] = (by_law[cases.DEFAULT_LAW] if not gains
                        else of(len(cases.BENCHED) + list(extra).index(name)))
    return by_law, by_set


def time_steps(flights: List[cases.CaseFlight],
               rounds: int = 3) -> Dict[str, Dict[str, np.ndarray]]:
    """Each case's laws timed side by side at the states of all its laws' flights; {case: {law:
    microseconds per step}}.
    """
    out = {}
    for name in dict.fromkeys(f.case for f in flights):
        mine = [f for f in flights if f.case == name]
        states = [s for f in mine for s in f.states]
        out[name] = cases.step_times(mine[0].controller, cases.BENCHED, states, rounds)
    return out


def tables(flights, random, timed):
    """The rows: ({case: [row per law]}, [row per law over the random runs], [row per law over
    every run]). The random runs' step times are the testbed case's (its controller), or those
    of all cases pooled when it was not flown.
    """
    per_case: Dict[str, List[dict]] = {}
    for f in flights:
        one = {c: np.array([f.scores[c]]) for c in RUN_COLUMNS}
        row = law_row(f.law, one, timed[f.case][f.law], f.margins)
        per_case.setdefault(f.case, []).append(dict(row, case=f.case))
    pooled = {law: np.concatenate([t[law] for t in timed.values()]) for law in cases.BENCHED}
    random_steps = timed.get('testbed_yaw90', pooled)
    random_rows, overall = [], []
    for law in cases.BENCHED:
        mine = [f for f in flights if f.law == law]
        columns = {c: np.array([f.scores[c] for f in mine], dtype=float) for c in RUN_COLUMNS}
        if random:
            random_rows.append(law_row(law, random[law], random_steps[law]))
            columns = {c: np.concatenate([columns[c], np.asarray(random[law][c], dtype=float)])
                       for c in RUN_COLUMNS}
        overall.append(law_row(law, columns, pooled[law]))
    return per_case, random_rows, overall


def write(out_dir, flights, random, timed, titles, notes, by_set=None):
    """benchmark.md, the CSV files and the figures; benchmark.md's lines."""
    per_case, random_rows, overall = tables(flights, random, timed)
    set_rows = [law_row(name, columns) for name, columns in (by_set or {}).items()]
    lines = ['# Benchmark of the control laws', ''] + notes
    for name, rows in per_case.items():
        lines += ['', '## %s: %s' % (name, titles[name]), ''] + markdown(rows)
        lines += ['', '![%s](%s.png)' % (name, name)]
        mine = [f for f in flights if f.case == name]
        plots.case_figure(titles[name], mine[0].cones,
                          [(f.law, f.margins, f.sensor, f.dt) for f in mine],
                          os.path.join(out_dir, name + '.png'))
    if random_rows:
        n = random_rows[0]['runs']
        lines += ['', '## %d random manoeuvres (each flown by every law)' % n, '']
        lines += markdown(random_rows) + ['', '![random](random_closest.png)']
        plots.closest_figure({law: random[law]['closest_deg'] for law in cases.BENCHED},
                             os.path.join(out_dir, 'random_closest.png'))
        with open(os.path.join(out_dir, 'random_runs.csv'), 'w') as f:
            keys = ['run'] + list(RUN_COLUMNS) + ['latency_ms', 'disturbance_Nm']
            f.write('law,' + ','.join(keys) + '\n')
            for law in cases.BENCHED:
                for row in zip(*(random[law][k].tolist() for k in keys)):
                    f.write(law + ',' + ','.join(map(repr, row)) + '\n')
    if set_rows:
        lines += ['', '## Gain sets: the default law (%s) over the same random manoeuvres'
                  % cases.DEFAULT_LAW, '']
        lines += [line.replace('| law |', '| gain set |', 1) for line in markdown(set_rows)]
    lines += ['', '## Overall (every run: the standard cases and the random ones)', '']
    lines += markdown(overall)
    files = {'cases.csv': csv_lines([r for rows in per_case.values() for r in rows], ['case']),
             'random.csv': csv_lines(random_rows), 'overall.csv': csv_lines(overall)}
    if set_rows:
        files['gain_sets.csv'] = csv_lines(set_rows)
    for name, text in files.items():
        with open(os.path.join(out_dir, name), 'w') as f:
            f.write('\n'.join(text) + '\n')
    with open(os.path.join(out_dir, 'benchmark.md'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    return lines


def benchmark(client, case_sections, base, args, say, progress=None):
    """Fly, time and write the benchmark (args: runs, seed, duration, case_duration, batch,
    out); its lines.
    """
    t0 = time.monotonic()
    flights = fly_cases(client, case_sections, say, args.case_duration)
    t1 = time.monotonic()
    random, by_set = (fly_random(client, base, args.runs, args.seed, args.duration, args.batch,
                                 progress, args.gain_sets) if args.runs else ({}, {}))
    t2 = time.monotonic()
    timed = time_steps(flights)
    workers = cluster.worker_count(client)
    shortened = ('' if args.case_duration is None else
                 ' The standard cases were cut to their first %g s.' % args.case_duration)
    notes = ['Laws: %s. The standard cases flown in %.0f s and %d random runs (campaign seed %d, '
             "%g s each) with every law in %.0f s, on %d workers. Each case's laws were then "
             'timed side by side in this process (`AttitudeController.step`), in %d rounds at the '
             'states of all its flights (%d per flight).'
             % (', '.join(cases.BENCHED), t1 - t0, args.runs, args.seed, args.duration,
                t2 - t1, workers, 3, cases.TIMED_STATES) + shortened]
    titles = {f.case: f.title for f in flights}
    return write(args.out, flights, random, timed, titles, notes, by_set)
