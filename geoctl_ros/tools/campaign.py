"""Safety campaign: ``campaign --runs 1000 --seed 1 --out DIR [--jobs 2] [--replay FILE...]``.

Flies many random manoeuvres of the testbed headless and reports how often the sensor kept out of
the cones. Each run is an ordinary scenario (``config/testbed.yaml`` with its own cones, set point,
errors and seed), flown by ``geoctl_ros.tools.batch`` many at a time; the worst runs are written as
scenario files that ``campaign --replay`` flies again to the same figures and ``scenario`` plots.

The distribution (run i of seed S draws from numpy's default_rng([S, i]), so a run does not depend
on how many others there are):

- cones: 1-4 (uniform), half-angles uniform in 10-35 deg, axes at a uniform azimuth and an
  elevation uniform within +-20 deg of the horizon (where a body-fixed sensor of a testbed on a
  joint can point), every two cones at least 10 deg apart (edge to edge), so there is always a way
  round;
- the manoeuvre: the sensor starts 5-30 deg outside the first cone (uniform, at a uniform azimuth
  round its axis) and its goal is 5-30 deg outside the same cone on the far side (azimuth 150-210
  deg away), so the straight way crosses the cone and the controller must go round; start and goal
  are at least 5 deg clear of every cone, and the goal is one the controller accepts with
  ``unmodelled_moment_max`` set to what the errors below can add up to (``unmodelled_moment``,
  0.40 N m for the testbed; redrawn otherwise). About the sensor axis, start and goal attitudes
  are the most upright ones turned by up to +-15 deg, and the body's z axis is within 40 deg of
  vertical (the joint's range; redrawn otherwise);
- the testbed (``config/testbed.yaml``): its gains, rotors, thrust curve, 40 ms motor lag and
  saturation, motion-capture (0.1 deg) and gyro (0.005 rad/s) noise, 100 Hz control, 1 kHz
  integration, 20 s;
- per run: measurement latency 0-10 ms (whole ms, uniform); a constant disturbance of uniform
  direction and magnitude up to 0.05 N m (``--disturbance-max``; with the gravity moment of the
  errors below the estimate sees at most 0.40 N m, within its bound delta_bar_max = 1 N m); the
  true mass off by up to +-20 %; the true inertia's mass distribution stretched by up to +-20 %
  along each body axis (second moment E = tr(J)/2 I - J -> S E S, S = diag(sqrt(f)), f uniform
  0.8-1.2; J = tr(E) I - E stays a physical inertia); the true centre-of-mass offset scaled by
  0.8-1.2.

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

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import yaml

from geoctl_ros.core import so3
from geoctl_ros.core.control import AttitudeController
from geoctl_ros.params import (
    CONTROLLER,
    SIM,
    ConfigError,
    cone_set,
    controller_config,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.tools.batch import run_batch
from geoctl_ros.tools.rosenv import config_dir
from geoctl_ros.tools.scenario import from_sections

CONVERGED_DEG = 5.0                # attitude error at the end below which a run has converged
CLEAR_DEG = 5.0                    # start and goal at least this far outside every cone
GAP_DEG = 10.0                     # edge-to-edge distance between two cones, at least
BATCH = 300                        # runs flown together (more saves little, costs memory)
UP = np.array([0.0, 0.0, 1.0])
TILT_DEG = 40.0                    # the body's z axis within this of vertical at start and goal
TWIST_DEG = 15.0                   # turn about the sensor axis from the most upright attitude
CONE_ELEVATION_DEG = 20.0          # cone axes within this of the horizon
DISTURBANCE_MAX = 0.05             # N m, largest constant disturbance (see the README)
MODEL_ERROR = 0.2                  # true mass, inertia stretch and centre of mass within +-20 %


def _unit(v):
    return v / np.linalg.norm(v)


def _direction(axis, angle, azimuth):
    """The unit vector at angle from axis, at azimuth round it."""
    e1 = _unit(np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))]))
    e2 = np.cross(axis, e1)
    return (math.cos(angle) * axis
            + math.sin(angle) * (math.cos(azimuth) * e1 + math.sin(azimuth) * e2))


def _aligning(r, d):
    """The rotation by the shortest arc that takes r to d (unit vectors, not opposite)."""
    axis = np.cross(r, d)
    return so3.exp(axis / max(np.linalg.norm(axis), 1e-12)
                   * math.atan2(np.linalg.norm(axis), float(r @ d)))


def _angle_deg(a, b):
    return math.degrees(math.acos(min(1.0, max(-1.0, float(a @ b)))))


def _elevation_deg(d):
    return math.degrees(math.asin(max(-1.0, min(1.0, float(d[2])))))


def _attitude(rng, r, d):
    """An attitude with the sensor axis r pointing along d and the body as upright as it can be
    (then turned about d by up to +-TWIST_DEG); None if that leaves the body tilted more than
    TILT_DEG (the joint's range).
    """
    base = _aligning(r, d)
    twists = np.radians(np.arange(-180.0, 180.0, 2.0))
    ups = so3.exp(d * twists[:, None]) @ (base @ UP)            # body z for each twist
    twist = twists[int(np.argmax(ups[:, 2]))] + math.radians(rng.uniform(-TWIST_DEG, TWIST_DEG))
    R = so3.exp(d * twist) @ base
    return R if _angle_deg(R @ UP, UP) <= TILT_DEG else None


def draw_manoeuvre(seed, index, sensor_axis, goal_ok=None):
    """The random part of run index of campaign seed: a dict of per-run values. goal_ok(cones,
    R_d) (cones as [(axis, half-angle deg)]), if given, must accept the goal (else redrawn).
    """
    rng = np.random.default_rng([seed, index])
    r = _unit(np.asarray(sensor_axis, dtype=float))
    while True:
        n = int(rng.integers(1, 5))
        theta = rng.uniform(10.0, 35.0, n)
        axes = [_direction(UP, math.radians(90.0 - rng.uniform(-CONE_ELEVATION_DEG,
                                                                CONE_ELEVATION_DEG)),
                           rng.uniform(0.0, 2.0 * math.pi)) for _ in range(n)]
        if any(_angle_deg(axes[i], axes[j]) < theta[i] + theta[j] + GAP_DEG
               for i in range(n) for j in range(i)):
            continue
        v0, th0 = axes[0], math.radians(theta[0])
        azimuth = rng.uniform(0.0, 2.0 * math.pi)
        d0 = _direction(v0, th0 + math.radians(rng.uniform(5.0, 30.0)), azimuth)
        d1 = _direction(v0, th0 + math.radians(rng.uniform(5.0, 30.0)),
                        azimuth + math.pi + math.radians(rng.uniform(-30.0, 30.0)))
        if any(_angle_deg(d, v) < t + CLEAR_DEG for d in (d0, d1) for v, t in zip(axes, theta)):
            continue
        arc = [_unit((1.0 - s) * d0 + s * d1) for s in np.linspace(0.0, 1.0, 41)]
        if min(_angle_deg(p, v0) for p in arc) >= theta[0]:
            continue                                    # the straight way misses the cone
        R0, R_d = _attitude(rng, r, d0), _attitude(rng, r, d1)
        if R0 is not None and R_d is not None and (
                goal_ok is None or goal_ok(list(zip(axes, theta)), R_d)):
            break
    direction = _unit(rng.normal(size=3))
    return {
        'cones': [(list(map(float, v)), float(t)) for v, t in zip(axes, theta)],
        'R0': R0, 'R_d': R_d,
        'latency_ms': int(rng.integers(0, 11)),
        'disturbance': direction * rng.uniform(0.0, 1.0),      # times --disturbance-max
        'mass_factor': rng.uniform(1.0 - MODEL_ERROR, 1.0 + MODEL_ERROR),
        'inertia_factors': rng.uniform(1.0 - MODEL_ERROR, 1.0 + MODEL_ERROR, 3),
        'cog_factor': rng.uniform(1.0 - MODEL_ERROR, 1.0 + MODEL_ERROR),
        'noise_seed': int(rng.integers(0, 2 ** 31)),
    }


def _floats(a):
    return [float(x) for x in np.ravel(a)]


def unmodelled_moment(nominal_sim, disturbance_max=DISTURBANCE_MAX):
    """The most the campaign's runs ask the controller to hold before learning it (N m): the
    largest disturbance plus the gravity moment of the largest error in m rho (mass and
    centre-of-mass height each off by 20 %: 1.2^2 - 1 = 44 %) at the largest tilt at the goal.
    """
    m_rho = nominal_sim['mass'] * float(np.linalg.norm(nominal_sim['cog_offset']))
    return float(disturbance_max + ((1.0 + MODEL_ERROR) ** 2 - 1.0) * m_rho
                 * float(np.linalg.norm(nominal_sim['gravity']))
                 * math.sin(math.radians(TILT_DEG)))


def run_sections(base, seed, index, duration=20.0, disturbance_max=DISTURBANCE_MAX):
    """The scenario file's sections ({'/**' or node: flat parameters}) of run index."""
    nominal_c = resolve(CONTROLLER, node_overrides(base, CONTROLLER))
    nominal_s = resolve(SIM, node_overrides(base, SIM))
    unmodelled = unmodelled_moment(nominal_s, disturbance_max)
    probe = AttitudeController(controller_config(dict(nominal_c,
                                                      unmodelled_moment_max=unmodelled)))

    def goal_ok(cones, R_d):                    # the controller's own set-point check
        values = dict(nominal_c, **{'cones.names': ['c%d' % i for i in range(len(cones))]})
        for i, (axis, half_angle) in enumerate(cones):
            values['cones.c%d.axis' % i] = axis
            values['cones.c%d.half_angle_deg' % i] = half_angle
        return probe.setpoint_problem(R_d, cone_set(values)) is None

    m = draw_manoeuvre(seed, index, nominal_c['sensor_axis'], goal_ok)
    controller = {k: v for k, v in base.get('controller', {}).items()
                  if not k.startswith(('cones.', 'setpoint'))}
    controller['unmodelled_moment_max'] = unmodelled
    names = ['c%d' % (i + 1) for i in range(len(m['cones']))]
    controller['cones.names'] = names
    for name, (axis, half_angle) in zip(names, m['cones']):
        controller['cones.%s.axis' % name] = axis
        controller['cones.%s.half_angle_deg' % name] = half_angle
    controller['setpoint'] = _floats(so3.rot_to_quat(m['R_d']))
    S = np.diag(np.sqrt(m['inertia_factors']))
    J = nominal_s['inertia'].reshape(3, 3)
    E = S @ (0.5 * np.trace(J) * np.eye(3) - J) @ S            # second moment of the mass
    rho = nominal_s['cog_offset']
    sim = dict(base.get('sim', {}))
    sim.update({
        'initial_attitude': _floats(so3.rot_to_quat(m['R0'])),
        'mass': float(nominal_s['mass'] * m['mass_factor']),
        'inertia': _floats(np.trace(E) * np.eye(3) - E),
        'cog_offset': _floats(rho * m['cog_factor']),
        'disturbance.constant': _floats(m['disturbance'] * disturbance_max),
        'noise.seed': m['noise_seed'],
    })
    return {
        '/**': dict(base.get('/**', {})), 'controller': controller, 'sim': sim,
        'scenario': {'title': 'campaign seed %d, run %d' % (seed, index),
                     'duration': float(duration), 'latency': m['latency_ms'] / 1000.0},
    }


def write_scenario_file(sections, path):
    """Write sections as a ROS 2 parameter file (nested keys, floats exact)."""
    doc = {}
    for node, flat in sections.items():
        tree = {}
        for key, value in flat.items():
            *parents, leaf = key.split('.')
            d = tree
            for p in parents:
                d = d.setdefault(p, {})
            d[leaf] = value.tolist() if isinstance(value, np.ndarray) else value
        doc[node] = {'ros__parameters': tree}
    with open(path, 'w') as f:
        f.write('# Written by `campaign`; fly it again with `campaign --replay %s` or '
                '`scenario %s '
                '--out DIR`.\n' % (os.path.basename(path), os.path.basename(path)))
        yaml.safe_dump(doc, f, sort_keys=False, default_flow_style=None, width=100)


# --- flying -----------------------------------------------------------------------------------

_progress = None        # shared counter of simulated run-steps (set in each worker)


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


def figures(rows, flown, sections_by_index, out_dir, worst):
    """closest_approach.png (histogram) and worst_runs.png (margins in time, sensor paths)."""
    matplotlib.use('Agg')
    margins = np.array([r['closest_deg'] for r in rows])
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.hist(margins, bins=40, color='tab:blue', alpha=0.8)
    ax.axvline(0.0, color='tab:red', lw=1.5, label='cone boundary')
    ax.set(xlabel='closest approach to a cone [deg] (negative: inside)', ylabel='runs',
           title='%d manoeuvres: closest approach of the sensor to any cone' % len(rows))
    ax.legend()
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, 'closest_approach.png'), dpi=110)
    plt.close(fig)

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    for i in worst:
        res, p = flown[i]
        t = np.arange(res.margin_series.shape[0]) * res.dt
        a1.plot(t, res.margin_series[:, p], lw=1, label='run %d' % i)
    a1.axhline(0.0, color='k', lw=0.8)
    a1.set(xlabel='t [s]', ylabel='cone margin [deg]', title='the %d worst runs' % len(worst))
    a1.legend(fontsize=7)
    a1.grid(True, alpha=0.3)
    i = worst[0]
    res, p = flown[i]
    path = res.sensor_series[:, p].astype(float)
    _sky(a2, path, sections_by_index[i]['controller'], 'run %d: sensor path' % i)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, 'worst_runs.png'), dpi=110)
    plt.close(fig)


def _sky(ax, path, controller, title):
    """The sensor's world direction in azimuth / elevation, with the cones' boundaries."""
    def az_el(d):
        d = np.atleast_2d(d)
        return (np.degrees(np.arctan2(d[:, 1], d[:, 0])),
                np.degrees(np.arcsin(np.clip(d[:, 2], -1, 1))))
    for name in controller['cones.names']:
        v = _unit(np.asarray(controller['cones.%s.axis' % name], dtype=float))
        th = math.radians(controller['cones.%s.half_angle_deg' % name])
        ring = np.array([_direction(v, th, a) for a in np.linspace(0, 2 * math.pi, 181)])
        az, el = az_el(ring)
        ax.plot(az, el, '.', ms=1.5, color='tab:red')
    az, el = az_el(path)
    ax.plot(az, el, '.', ms=1.5, color='tab:blue')
    ax.plot(az[0], el[0], 'o', color='tab:green', label='start')
    ax.plot(az[-1], el[-1], 's', color='k', label='end')
    ax.set(xlabel='azimuth [deg]', ylabel='elevation [deg]', title=title, xlim=(-180, 180),
           ylim=(-90, 90))
    ax.legend(fontsize=7)
    ax.grid(True, alpha=0.3)


def main(argv=None):
    parser = argparse.ArgumentParser(prog='campaign', description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=1000, help='number of manoeuvres (1000)')
    parser.add_argument('--seed', type=int, default=1, help='campaign seed (1)')
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument('--jobs', type=int, default=os.cpu_count() or 1,
                        help='worker processes (default: one per core)')
    parser.add_argument('--duration', type=float, default=20.0, help='seconds per run (20)')
    parser.add_argument('--worst', type=int, default=5, help='worst runs written out (5)')
    parser.add_argument('--disturbance-max', type=float, default=DISTURBANCE_MAX,
                        help='largest constant disturbance, N m (%g)' % DISTURBANCE_MAX)
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
            sections = {i: run_sections(base, args.seed, i, args.duration, args.disturbance_max)
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
        write_scenario_file(sections[i], os.path.join(args.out, 'worst', 'run_%04d.yaml' % i))
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
    figures(rows, flown, sections, args.out, worst)
    print('\n'.join(lines))
    print('wrote %s' % args.out)
    return 1 if summary['violations'] else 0


if __name__ == '__main__':
    sys.exit(main())
