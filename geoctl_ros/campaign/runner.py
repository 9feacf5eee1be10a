"""Safety campaigns and gain studies, flown (the ``campaign`` command: geoctl_ros.cli.campaign).

Each run is an ordinary scenario (``config/testbed.yaml`` with its own cones, set point, errors
and seed), flown by ``geoctl_ros.sim.closed_loop`` many at a time on a Dask cluster
(``geoctl_ros.campaign.cluster``: a local one by default). The distribution of the manoeuvres is
``geoctl_ros.campaign.manoeuvres``'s: run i of a seed draws from its own seed, so ``runs.csv`` is
the same, bit for bit, on one worker or many, in any batch size, here or on a cluster.

Per run: the closest approach to each cone (after every 1 ms integration step), whether the sensor
touched a cone (a violation), convergence (attitude error below 5 deg at the end), the settle time
(the error below 5 deg from then on), the time the allocation was saturated, and the effort
(the integral of the law's |u|). Writes
DIR/runs.csv (every figure exact: Python's shortest repr of each float), DIR/summary.md (the
table), DIR/closest_approach.png, DIR/worst_runs.png and DIR/worst/*.yaml; the worst runs are
flown again for their figure, and the files fly them again (``campaign --replay``, ``scenario``).
With a gain study (``geoctl_ros.campaign.study``) every gain set flies the same runs, and the
campaign also writes DIR/gain_sets.csv, DIR/gain_study.png and DIR/best/gain_set_K.yaml.
"""
import math
import os
import sys
import time

import numpy as np

from geoctl_ros.campaign import cluster, manoeuvres, study
from geoctl_ros.params import ConfigError, load_parameter_file
from geoctl_ros.params.scenario import from_sections, goal_check, turn_off_goal_check
from geoctl_ros.plots import campaign as campaign_plots
from geoctl_ros.sim import closed_loop

BATCH = 1024               # runs flown together at most (docs/campaigns.md, "Campaign speed")
# runs.csv's columns, in order (gain_set only in a gain study)
COLUMNS = ('gain_set', 'run', 'cones', 'closest_deg', 'violated', 'final_error_deg', 'converged',
           'settle_s', 'saturated_s', 'max_rate', 'effort_Nms', 'latency_ms', 'disturbance_Nm',
           'takeover_deg', 'goal_refused')


def plan(groups, workers, batch=BATCH):
    """Batches (lists of run indices) of the groups (lists of run indices that may fly together):
    at most `batch` runs each, and as many in all as fill every worker evenly where that does not
    make them smaller than a quarter of `batch`.
    """
    total = sum(len(g) for g in groups)
    want = math.ceil(total / batch)
    even = math.ceil(want / workers) * workers
    if total / even >= batch / 4:
        want = even
    out = []
    for g in groups:
        k = min(len(g), max(1, math.ceil(len(g) / batch), round(want * len(g) / total)))
        out += [list(map(int, part)) for part in np.array_split(np.array(g), k)]
    return sorted(out, key=len, reverse=True)


def _scenario(sections, name):
    """The run's scenario; a goal its controller still refuses (the set-point check, not the
    law) is flown with the check off, as every refused goal of a study is, and so counted
    (``Manoeuvres.goal_refused``): one run never ends a study.
    """
    try:
        return from_sections(sections, name)
    except ConfigError as e:
        if not (goal_check(sections) and all(p.endswith('setpoint') for p, _ in e.errors)):
            raise
        turn_off_goal_check(sections)
        return from_sections(sections, name)


def fly_batch(job):
    """Worker: fly one batch of runs of one gain set; their figures (arrays, one entry per run).
    job: (base sections, seed, duration, disturbance max, gain set number, gains, run indices,
    how many of its worst runs to keep the series of, the draw's stratum).
    """
    base, seed, duration, disturbance_max, gain_set, gains, indices, worst, stratum = job
    t0 = time.perf_counter()
    draw = manoeuvres.Manoeuvres(base, duration, disturbance_max, stratum)
    sections = [draw.sections(seed, i, gains) for i in indices]
    scenarios = [_scenario(s, 'run_%d' % i) for i, s in zip(indices, sections)]
    options = [s.options for s in scenarios]
    drawn = time.perf_counter() - t0
    res = closed_loop.fly(scenarios, cluster.report_progress, series=worst > 0)
    n = len(indices)
    closest = res.min_margin_deg.min(axis=1)
    kept = [(float(closest[p]), gain_set, indices[p], res.margin_series[:, p].copy(),
             res.sensor_series[:, p].copy(), res.dt)
            for p in np.argsort(closest, kind='stable')[:worst]]
    return {
        'worst': kept,
        'gain_set': np.full(n, gain_set), 'run': np.array(indices),
        'cones': np.full(n, res.min_margin_deg.shape[1]),
        'closest_deg': closest, 'violated': res.violated,
        'final_error_deg': res.final_error_deg,
        'converged': res.final_error_deg < study.CONVERGED_DEG,
        'settle_s': res.settle_s, 'saturated_s': res.saturated_s, 'max_rate': res.max_rate,
        'effort_Nms': res.effort,
        'latency_ms': np.array([int(round(1000 * o.latency)) for o in options]),
        'disturbance_Nm': np.array([float(np.linalg.norm(s.testbed.plant.disturbance.constant))
                                    for s in scenarios]),
        'goal_refused': np.array([draw.goal_refused(s) for s in sections]),
        'takeover_deg': (np.full(n, np.nan) if res.takeover_margin_deg is None
                         else res.takeover_margin_deg.min(axis=1)),
        'draw_s': drawn, 'fly_s': res.wall_s,
    }


def fly(client, base, args, gain_sets, progress=None):
    """Fly every run of every gain set on the cluster; (columns sorted by gain set and run, the
    worst runs' series [(closest approach, gain set, run, margins, sensor directions, dt)],
    whether it was interrupted, (seconds spent drawing the runs, and flying them, on the
    workers)).
    """
    groups = {}
    stratum = getattr(args, 'stratum', 'all')
    for i in range(args.runs):
        groups.setdefault((manoeuvres.cone_count(args.seed, i),
                           manoeuvres.start_of(args.seed, i, stratum)), []).append(i)
    workers = cluster.worker_count(client)
    jobs = []
    for k, gains in enumerate(gain_sets, 1):
        for indices in plan(list(groups.values()), workers, args.batch):
            jobs.append((base, args.seed, args.duration, args.disturbance_max, k, gains, indices,
                         args.worst, getattr(args, 'stratum', 'all')))
    parts, worst = [], []

    def take(i, part):               # keep the figures, and the series of the worst runs only
        worst[:] = sorted(worst + part.pop('worst'), key=lambda w: w[:3])[:args.worst]
        parts.append(part)

    interrupted = False
    try:
        cluster.run_tasks(client, fly_batch, jobs, take, progress,
                          weights=[len(j[6]) for j in jobs])
    except KeyboardInterrupt:
        interrupted = True
    columns = {c: np.concatenate([p[c] for p in parts]) if parts else np.array([])
               for c in COLUMNS}
    order = np.lexsort((columns['run'], columns['gain_set']))
    columns = {c: v[order] for c, v in columns.items()}
    seen = set(zip(columns['gain_set'].tolist(), columns['run'].tolist()))
    assert len(seen) == len(order), 'a run was flown twice'
    return columns, worst, interrupted, (sum(p['draw_s'] for p in parts),
                                         sum(p['fly_s'] for p in parts))


def write_runs(path, columns, with_gain_set):
    """runs.csv: a row per run, floats exact (repr)."""
    keys = [c for c in COLUMNS if with_gain_set or c not in ('gain_set', 'goal_refused')]
    with open(path, 'w') as f:
        f.write(','.join(keys) + '\n')
        for row in zip(*(columns[k].tolist() for k in keys)):
            f.write(','.join(map(repr, row)) + '\n')


def replay(paths):
    """Fly scenario files written by a campaign, each alone; exit code 1 if any entered a cone."""
    violated = False
    for path in paths:
        res = closed_loop.fly([from_sections(load_parameter_file(path), os.path.basename(path))])
        violated |= bool(res.violated[0])
        print('%s: closest approach %r deg, %s, final error %.3f deg, saturated %.2f s'
              % (path, float(res.min_margin_deg[0].min()),
                 'VIOLATED' if res.violated[0] else 'kept', res.final_error_deg[0],
                 res.saturated_s[0]))
    return 1 if violated else 0


def worst_runs(worst, base, args, gain_sets, out_dir):
    """Write the worst runs as scenario files and draw worst_runs.png; their labels."""
    draw = manoeuvres.Manoeuvres(base, args.duration, args.disturbance_max,
                                 getattr(args, 'stratum', 'all'))
    os.makedirs(os.path.join(out_dir, 'worst'), exist_ok=True)
    flown, labels = [], []
    for closest, k, i, margins, sensor, dt in worst:
        sections = draw.sections(args.seed, i, gain_sets[k - 1])
        name = ('set_%d_run_%04d' % (k, i)) if len(gain_sets) > 1 else 'run_%04d' % i
        manoeuvres.write_scenario_file(sections, os.path.join(out_dir, 'worst', name + '.yaml'))
        flown.append((name.replace('_', ' '), margins, sensor, dt,
                      _scenario(sections, name).cones()))
        labels.append('%s (%.2f deg)' % (name.replace('_', ' '), closest))
    if flown:
        campaign_plots.worst_runs_figure(flown, os.path.join(out_dir, 'worst_runs.png'))
    return labels


def write_results(columns, worst, interrupted, timing, base, args, gain_sets):
    """Write runs.csv, summary.md, the worst runs and the figures into args.out; the summary's
    lines and its violation count. timing: wall s, workers, cluster start s, drawing s, flying s.
    """
    wall, workers, started, draw_s, fly_s = timing
    n = len(columns['run'])
    write_runs(os.path.join(args.out, 'runs.csv'), columns, len(gain_sets) > 1)
    if interrupted:
        print('campaign: interrupted: %d of %d runs flown, written to %s'
              % (n, args.runs * len(gain_sets), os.path.join(args.out, 'runs.csv')),
              file=sys.stderr)
    summary = study.summary_table(columns)
    summary['wall time [s]'] = '%.1f on %d workers (cluster start %.1f s before it)' % (
        wall, workers, started)
    summary['drawing / flying the runs [s, all workers]'] = '%.1f / %.1f' % (draw_s, fly_s)
    summary['simulated / wall time (per worker)'] = '%.0f (%.0f)' % (
        n * args.duration / wall, n * args.duration / wall / workers)
    labels = worst_runs(worst, base, args, gain_sets, args.out)
    stratum = getattr(args, 'stratum', 'all')
    lines = ['| campaign seed %d%s%s | |' % (args.seed, '' if stratum == 'all' else ', ' + stratum,
                                           ' (interrupted)' if interrupted else ''),
             '|---|---|']
    lines += ['| %s | %s |' % (k, v) for k, v in summary.items()]
    lines += ['', 'worst runs: ' + ', '.join(labels)]
    if len(gain_sets) > 1:
        lines += [''] + study.write_study(columns, base, gain_sets, args.out, args.best)
    with open(os.path.join(args.out, 'summary.md'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    campaign_plots.closest_approach_figure(columns['closest_deg'],
                                  os.path.join(args.out, 'closest_approach.png'))
    return lines, summary['violations']
