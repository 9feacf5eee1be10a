"""Safety campaign: ``campaign --runs 1000 --seed 1 --out DIR [--jobs 2] [--replay FILE...]``.

Flies many random manoeuvres of the testbed headless and reports how often the sensor kept out of
the cones. Each run is an ordinary scenario (``config/testbed.yaml`` with its own cones, set point,
errors and seed), flown by ``geoctl_ros.tools.batch`` many at a time; the worst runs are written as
scenario files that ``campaign --replay`` flies again to the same figures and ``scenario`` plots.

The distribution of the manoeuvres is ``geoctl_ros.tools.manoeuvres``'s.

Per run: the closest approach to each cone (after every 1 ms integration step), whether the sensor
touched a cone (a violation), convergence (attitude error below 5 deg at the end), and the time the
allocation was saturated. Writes DIR/runs.csv, DIR/summary.md (the table),
DIR/closest_approach.png, DIR/worst_runs.png and DIR/worst/run_NNNN.yaml.
"""
import argparse
import math
import multiprocessing
import os
import sys
import time

import numpy as np

from geoctl_ros.params import (
    ConfigError,
    load_parameter_file,
)
from geoctl_ros.tools import manoeuvres, plots
from geoctl_ros.tools.batch import run_batch
from geoctl_ros.tools.rosenv import config_dir
from geoctl_ros.tools.scenario import from_sections

BATCH = 300                        # runs flown together (more saves little, costs memory)
CONVERGED_DEG = 5.0                # attitude error at the end below which a run has converged
def _init_worker(counter):
    global _progress
    _progress = counter


def _fly(job):
    """Worker: fly one batch of scenarios (all with the same number of cones)."""
    indices, sections = job
    scenarios = [from_sections(s, 'run_%04d' % i) for i, s in zip(indices, sections)]
    done = [0.0]

    def progress(fraction):
        if _progress is not None:
            with _progress.get_lock():
                _progress.value += (fraction - done[0]) * len(indices)
        done[0] = fraction
    result = run_batch(scenarios, progress)
    return indices, result


def fly(sections_by_index, jobs=2, report=None):
    """Fly every run (index -> sections); {index: (result, position in its batch)}.

    Runs are grouped by number of cones (a batch shares it) and cut into batches of at most BATCH;
    the batches go to `jobs` worker processes. report(runs done, seconds) is called about once a
    second.
    """
    groups = {}
    for i, s in sorted(sections_by_index.items()):
        groups.setdefault(len(s['controller']['cones.names']), []).append(i)
    batches = []
    for members in groups.values():
        k = max(1, math.ceil(len(members) / BATCH))
        for part in np.array_split(np.array(members), k):
            batches.append((list(map(int, part)), [sections_by_index[i] for i in part]))
    batches.sort(key=lambda b: -len(b[0]))
    t0 = time.monotonic()
    out = {}
    if jobs <= 1:
        _init_worker(None)
        for b in batches:
            indices, result = _fly(b)
            out.update({i: (result, p) for p, i in enumerate(indices)})
            if report:
                report(len(out), time.monotonic() - t0)
        return out
    # a fork server, not a fork of the caller: a caller with threads (rclpy's, in a test run)
    # can hold a lock at the moment of a fork, and the forked worker then deadlocks on it
    ctx = multiprocessing.get_context('forkserver')
    counter = ctx.Value('d', 0.0)
    with ctx.Pool(jobs, initializer=_init_worker, initargs=(counter,)) as pool:
        pending = pool.map_async(_fly, batches, chunksize=1)
        while not pending.ready():
            pending.wait(1.0)
            if report:
                report(counter.value, time.monotonic() - t0)
        for indices, result in pending.get():
            out.update({i: (result, p) for p, i in enumerate(indices)})
    if report:
        report(len(out), time.monotonic() - t0)
    return out


# --- figures ------------------------------------------------------------------------------------

def table(rows):
    """Summary figures of the per-run rows (dicts)."""
    margins = np.array([r['closest_deg'] for r in rows])
    violations = sum(r['violated'] for r in rows)
    converged = sum(r['converged'] for r in rows)
    sat = np.array([r['saturated_s'] for r in rows])
    by_latency = {}
    for r in rows:
        by_latency.setdefault(r['latency_ms'], []).append(r['closest_deg'])
    return {
        'runs': len(rows),
        'violations': int(violations),
        'converged (error < %g deg at the end)' % CONVERGED_DEG: int(converged),
        'final attitude error median / p95 [deg]': '%.1f / %.1f' % (
            np.median([r['final_error_deg'] for r in rows]),
            np.percentile([r['final_error_deg'] for r in rows], 95)),
        'closest approach min / p1 / p5 / median [deg]': '%.2f / %.2f / %.2f / %.2f' % (
            margins.min(), np.percentile(margins, 1), np.percentile(margins, 5),
            np.median(margins)),
        'runs with the allocation saturated': int(np.sum(sat > 0)),
        'saturated time p99 / max [s]': '%.2f / %.2f' % (np.percentile(sat, 99), sat.max()),
        'worst closest approach by latency 0-3 / 4-7 / 8-10 ms [deg]': ' / '.join(
            '%.2f' % min(min(by_latency.get(ms, [np.inf])) for ms in band)
            for band in (range(0, 4), range(4, 8), range(8, 11))),
    }


def rows_of(flown):
    rows = []
    for i, (res, p) in sorted(flown.items()):
        rows.append({
            'run': i, 'cones': res.min_margin_deg.shape[1],
            'closest_deg': float(res.min_margin_deg[p].min()),
            'violated': bool(res.violated[p]),
            'final_error_deg': float(res.final_error_deg[p]),
            'converged': bool(res.final_error_deg[p] < CONVERGED_DEG),
            'saturated_s': float(res.saturated_s[p]),
            'max_rate': float(res.max_rate[p]),
            'latency_ms': None,
        })
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(prog='campaign', description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=1000, help='number of manoeuvres (1000)')
    parser.add_argument('--seed', type=int, default=1, help='campaign seed (1)')
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument('--jobs', type=int, default=os.cpu_count() or 1,
                        help='worker processes (default: one per core)')
    parser.add_argument('--duration', type=float, default=20.0, help='seconds per run (20)')
    parser.add_argument('--worst', type=int, default=5, help='worst runs written out (5)')
    parser.add_argument('--disturbance-max', type=float, default=manoeuvres.DISTURBANCE_MAX,
                        help='largest constant disturbance, N m (%g)' % manoeuvres.DISTURBANCE_MAX)
    parser.add_argument('--params-file', default=None,
                        help='the testbed (default: config/testbed.yaml)')
    parser.add_argument('--replay', nargs='+', metavar='FILE',
                        help='fly these scenario files (written by a campaign) instead')
    args = parser.parse_args(argv)
    if args.runs < 1 or args.jobs < 1 or not args.duration > 0:
        parser.error('--runs, --jobs and --duration must be positive')
    try:
        os.makedirs(args.out, exist_ok=True)
    except OSError as e:
        print('campaign: --out %s: %s' % (args.out, e.strerror or e), file=sys.stderr)
        return 2
    try:
        if args.replay:
            sections = {i: load_parameter_file(p) for i, p in enumerate(args.replay)}
        else:
            base = load_parameter_file(args.params_file or os.path.join(config_dir(),
                                                                        'testbed.yaml'))
            sections = {i: manoeuvres.run_sections(base, args.seed, i, args.duration,
                                                   args.disturbance_max)
                        for i in range(args.runs)}
    except ConfigError as e:
        print('campaign: %s' % e, file=sys.stderr)
        return 2
    n = len(sections)
    t0 = time.monotonic()

    tty = sys.stderr.isatty()
    shown = [-1]

    def report(done, seconds):
        percent = 100.0 * done / n
        if tty:
            print('\rcampaign: %5.1f %% of %d runs flown, %.0f s' % (percent, n, seconds),
                  end='', file=sys.stderr, flush=True)
        elif int(percent // 10) > shown[0]:          # a log file: a line every 10 %
            shown[0] = int(percent // 10)
            print('campaign: %5.1f %% of %d runs flown, %.0f s' % (percent, n, seconds),
                  file=sys.stderr, flush=True)
    try:
        flown = fly(sections, args.jobs, report)
    except (ConfigError, ValueError) as e:
        print('\ncampaign: %s' % e, file=sys.stderr)
        return 2
    wall = time.monotonic() - t0
    print('', file=sys.stderr)
    rows = rows_of(flown)
    for r in rows:
        r['latency_ms'] = int(round(1000 * sections[r['run']]['scenario']['latency']))
        constant = sections[r['run']]['sim']['disturbance.constant']
        r['disturbance_Nm'] = float(np.linalg.norm(constant))
    if args.replay:
        for r, path in zip(rows, args.replay):
            print('%s: closest approach %.6f deg, %s, final error %.3f deg, saturated %.2f s'
                  % (path, r['closest_deg'], 'VIOLATED' if r['violated'] else 'kept',
                     r['final_error_deg'], r['saturated_s']))
        return 1 if any(r['violated'] for r in rows) else 0
    with open(os.path.join(args.out, 'runs.csv'), 'w') as f:
        keys = list(rows[0])
        f.write(','.join(keys) + '\n')
        for r in rows:
            f.write(','.join(('%.6f' % r[k]) if isinstance(r[k], float) else str(r[k])
                             for k in keys) + '\n')
    worst = [r['run'] for r in sorted(rows, key=lambda r: r['closest_deg'])[:args.worst]]
    os.makedirs(os.path.join(args.out, 'worst'), exist_ok=True)
    for i in worst:
        manoeuvres.write_scenario_file(sections[i],
                                       os.path.join(args.out, 'worst', 'run_%04d.yaml' % i))
    summary = table(rows)
    summary['wall time [s]'] = '%.1f (%d worker processes)' % (wall, args.jobs)
    sim_seconds = n * args.duration
    summary['simulated / wall time (per worker)'] = '%.0f (%.0f)' % (
        sim_seconds / wall, sim_seconds / wall / args.jobs)
    lines = ['| campaign seed %d | |' % args.seed, '|---|---|']
    lines += ['| %s | %s |' % (k, v) for k, v in summary.items()]
    lines += ['', 'worst runs: ' + ', '.join(
        'run %d (%.2f deg)' % (i, next(r['closest_deg'] for r in rows if r['run'] == i))
        for i in worst)]
    with open(os.path.join(args.out, 'summary.md'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    plots.campaign_figures(rows, flown, sections, args.out, worst)
    print('\n'.join(lines))
    print('wrote %s' % args.out)
    return 1 if summary['violations'] else 0


if __name__ == '__main__':
    sys.exit(main())
