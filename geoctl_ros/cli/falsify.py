"""Falsification: ``falsify --budget 2000 [--optimizers uniform,de] [--requirements safety,settle]
[--latency-max-ms 60] [--seed 1] [--out DIR] [--workers N | --scheduler tcp://HOST:PORT]``.

Each optimizer searches the envelope (``geoctl_ros.falsify.envelope``) for the flight of lowest
robustness under each requirement (``geoctl_ros.falsify.requirements``: the cone kept, and the
attitude settled within 10 s), spending --budget evaluations per search, its batches flown on the
Dask cluster. Uniform random search is the baseline. Writes DIR/summary.md (the lowest robustness
per requirement and optimizer), DIR/evaluations.csv (every evaluation, floats exact),
DIR/robustness.png (the lowest found against the evaluations spent) and, per requirement, the
scenario file of its lowest-robustness flight, DIR/worst_<requirement>.yaml, which
``scenario`` and ``campaign --replay`` fly again to the same bits. Exits 1 when a requirement was
falsified (a flight of negative robustness), 2 on a bad argument or file, 130 when interrupted.
"""
import argparse
import math
import os
import sys
import time

from geoctl_ros.campaign import cluster, manoeuvres
from geoctl_ros.cli import tools
from geoctl_ros.cli.args import (
    add_cluster_arguments,
    cannot_start,
    on_a_cluster,
    positive_seconds,
)
from geoctl_ros.falsify.envelope import OUTSIDE, Envelope, Space
from geoctl_ros.falsify.requirements import REQUIREMENTS
from geoctl_ros.falsify.search import OPTIMIZERS, Search, search
from geoctl_ros.params import ConfigError, load_parameter_file
from geoctl_ros.plots.campaign import falsification_figure
from geoctl_ros.sil.rosenv import config_dir


def _names(text, allowed, what):
    names = [n for n in text.split(',') if n]
    unknown = [n for n in names if n not in allowed]
    if unknown or not names:
        raise argparse.ArgumentTypeError('unknown %s %s (known: %s)'
                                         % (what, ', '.join(unknown) or "''", ', '.join(allowed)))
    return names


def summary_lines(searches, names, budget, env, wall, where):
    """summary.md: the lowest robustness per requirement and optimizer."""
    lines = ['# Falsification: %d evaluations per search, %s' % (budget, where), '',
             'Envelope: latency 0-%g ms, tick jitter 0-%g ms, %d input stalls of 10-40 ms at any '
             'time, %d cones, mass, inertia and centre of mass off by up to %g %%, a constant '
             'disturbance up to %g N m; runs of %g s. Requirements (RTAMT, discrete time, '
             'robustness in deg):' % (env.latency_ms_max, env.jitter_ms_max, env.stalls,
                                       env.cones, 100 * env.model_error, env.disturbance_max,
                                       env.duration), '']
    lines += ['- `%s`: %s: `%s`' % (n, REQUIREMENTS[n].says, REQUIREMENTS[n].formula)
              for n in names]
    lines += ['', '| search (optimizer, requirement minimised) | evaluations | inside the '
              'envelope | ' + ' | '.join('lowest %s' % n for n in names) +
              " | closest approach of all [deg] | runs within the brake's assumptions | their "
              'closest approach [deg] |',
              '|---|---|---|' + '---|' * len(names) + '---|---|---|']
    for s in searches:
        inside = [e for e in s.evaluations if e.inside]
        lows = []
        for n in names:
            e = s.lowest(n)
            lows.append('-' if e is None else '%+.3f' % e.robustness[n])
        closest = min((e.closest_deg for e in inside), default=math.nan)
        assumed = [e.closest_assumed_deg for e in inside if math.isfinite(e.closest_assumed_deg)]
        lines.append('| %s, %s | %d | %d | %s | %+.2f | %d | %s |' % (
            s.optimizer, s.target, len(s.evaluations), len(inside), ' | '.join(lows), closest,
            len(assumed), '%+.2f' % min(assumed) if assumed else '-'))
    lines += ['', "Within the brake's assumptions (the `assumed` requirement's robustness): the "
              "control steps the approach brake's derivation speaks of "
              '(sim.closed_loop.AssumedSeries.covered): from a step whose true state was on the '
              "brake's safe set, every bound held at every step since (the allocation not "
              "saturated nor the lag compensation clipped, the brake's condition met, each hold "
              "within its design, what the brake's model did not know of each approach within "
              'a_u, the measurements within e and e_w). A run counts when it has such a step; its '
              "closest approach is over those steps' holds: below 0 is a counterexample to the "
              'derivation.',
              '', 'wall time %.0f s' % wall]
    return lines


def write_evaluations(path, searches, space, names):
    with open(path, 'w') as f:
        f.write(','.join(['optimizer', 'target', 'evaluation'] + space.names +
                         ['inside', 'closest_deg', 'closest_assumed_deg'] + names) + '\n')
        for s in searches:
            for i, e in enumerate(s.evaluations):
                f.write(','.join([s.optimizer, s.target, str(i)] + [repr(float(v)) for v in e.x]
                                 + [str(e.inside), repr(e.closest_deg),
                                    repr(e.closest_assumed_deg)]
                                 + [repr(e.robustness[n]) for n in names]) + '\n')


@on_a_cluster('falsify')
def main(argv=None):
    parser = argparse.ArgumentParser(prog='falsify', description=__doc__.split('\n\n')[0],
                                     epilog=tools.WHERE)
    parser.add_argument('--budget', type=int, default=2000, help='evaluations per search (2000)')
    parser.add_argument('--optimizers', type=lambda t: _names(t, OPTIMIZERS, 'optimizer'),
                        default=['uniform', 'de'],
                        help='Psi-TaLiRo optimizers, of %s (uniform,de)' % ', '.join(OPTIMIZERS))
    parser.add_argument('--requirements',
                        type=lambda t: _names(t, list(REQUIREMENTS), 'requirement'),
                        default=list(REQUIREMENTS),
                        help='requirements to falsify, of %s (all)' % ', '.join(REQUIREMENTS))
    parser.add_argument('--latency-max-ms', type=float, default=Envelope.latency_ms_max,
                        help='the envelope: measurement latency up to this (60 ms, documented)')
    parser.add_argument('--jitter-max-ms', type=float, default=Envelope.jitter_ms_max,
                        help='the envelope: tick jitter up to this (10 ms)')
    parser.add_argument('--cones', type=int, default=Envelope.cones, help='cones per run (2)')
    parser.add_argument('--duration', type=positive_seconds, default=Envelope.duration,
                        help='seconds per run (12; the settle requirement looks 10 s ahead)')
    parser.add_argument('--seed', type=int, default=1, help="the optimizers' seed (1)")
    parser.add_argument('--out', default=os.path.join('out', 'falsify'),
                        help='output directory (out/falsify)')
    add_cluster_arguments(parser)
    parser.add_argument('--params-file', default=None,
                        help='the testbed and its gains (default: config/testbed.yaml)')
    args = parser.parse_args(argv)
    if min(args.budget, args.workers, args.cones) < 1:
        parser.error('--budget, --workers and --cones must be positive')
    if not (0.0 <= args.latency_max_ms <= 490.0 and 0.0 <= args.jitter_max_ms <= 100.0):
        parser.error('--latency-max-ms must be within 0-490 and --jitter-max-ms within 0-100')
    absent = tools.missing('falsify')   # (psy-taliro and rtamt are imported when it searches)
    if absent:
        print(tools.refusal('falsify', absent), file=sys.stderr)
        return 2
    env = Envelope(latency_ms_max=args.latency_max_ms, jitter_ms_max=args.jitter_max_ms,
                   cones=args.cones, duration=args.duration)
    try:
        os.makedirs(args.out, exist_ok=True)
        base = load_parameter_file(args.params_file or os.path.join(config_dir(), 'testbed.yaml'))
        space = Space(base, env)
    except (ConfigError, OSError) as e:
        return cannot_start('falsify', e, args.out)
    names = args.requirements
    searches = []
    t0 = time.monotonic()
    with cluster.connect(args.scheduler, args.workers) as (client, where):
        print('falsify: %s x %s, %d evaluations each, on %s'
              % (','.join(args.optimizers), ','.join(names), args.budget, where),
              file=sys.stderr, flush=True)
        try:
            for target in names:
                for name in args.optimizers:
                    same = next((s for s in searches if s.optimizer == name == 'uniform'), None)
                    if same is not None:       # its draw does not depend on the requirement
                        s = Search(name, target, same.evaluations)
                    else:
                        s = search(client, space, target, names, name, args.budget, args.seed)
                    searches.append(s)
                    low = s.lowest(target)
                    print('falsify: %s on %s: lowest robustness %s after %d evaluations'
                          % (name, target, '-' if low is None else
                             '%+.3f' % low.robustness[target], len(s.evaluations)),
                          file=sys.stderr, flush=True)
        except KeyboardInterrupt:
            print('falsify: interrupted; nothing written', file=sys.stderr)
            return 130
    wall = time.monotonic() - t0
    lines = summary_lines(searches, names, args.budget, env, wall, where)
    falsified = []
    for n in names:
        worst = min((s.lowest(n) for s in searches if s.lowest(n) is not None),
                    key=lambda e: e.robustness[n], default=None)
        if worst is None:
            continue
        path = os.path.join(args.out, 'worst_%s.yaml' % n)
        manoeuvres.write_scenario_file(
            space.sections(worst.x, 'falsify: the lowest robustness of %r (%+.3f deg)'
                           % (n, worst.robustness[n])), path)
        lines.append('- `%s`: lowest %+.3f deg, closest approach %+.2f deg: `%s`'
                     % (n, worst.robustness[n], worst.closest_deg, path))
        if worst.robustness[n] < 0.0:
            falsified.append(n)
    lines.append('')
    lines.append('falsified: %s' % (', '.join(falsified) or 'none'))
    write_evaluations(os.path.join(args.out, 'evaluations.csv'), searches, space, names)
    falsification_figure(searches, OUTSIDE, os.path.join(args.out, 'robustness.png'))
    with open(os.path.join(args.out, 'summary.md'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    print('wrote %s' % args.out)
    return 1 if falsified else 0


if __name__ == '__main__':
    sys.exit(main())
