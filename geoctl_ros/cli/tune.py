"""Gain tuning: ``tune --trials 40 [--runs 320] [--seed 7] [--out DIR] [--params-file FILE]
[--k-R LO HI] [--k-Omega LO HI] ... [--workers N | --scheduler tcp://HOST:PORT]``.

Optuna searches the controller's gains on the campaign's random manoeuvres, with all of the
campaign's draw, and on docs/safety.md's latency rows, on the Dask cluster
(``geoctl_ros.campaign.tune`` says what a trial flies and what it must keep), all on the airframe
of --params-file (config/testbed.yaml by default): the latency rows are testbed_yaw90's gains,
cone and manoeuvre flown on that file's body, rotors and motors. Each coordinate of the search
has its range as an option (--k-R, --k-Omega, --c-share, --cog-learning-s, --moment-learning-s,
--guidance-lookahead-deg; defaults ``geoctl_ros.campaign.tune.SPACE``). The best feasible
sets by settle p95 (--best) are then checked on manoeuvres of another seed (--check-runs of
--check-seed) and on the whole latency table; the first that passes is the tuning's result.
Writes DIR/trials.csv (a row per trial, floats exact), DIR/pareto.png, DIR/summary.md, the checked
sets as parameter files DIR/best/gain_set_K.yaml and the chosen one as DIR/best.yaml (the
testbed's file with the gains put over it: load it in place of config/testbed.yaml, or copy its
gains). The same --seed gives the same trials and the same chosen set.
"""
import argparse
import os
import sys
import time

import numpy as np

from geoctl_ros.campaign import cluster, study, tune
from geoctl_ros.cli import tools
from geoctl_ros.cli.args import (
    add_cluster_arguments,
    cannot_start,
    on_a_cluster,
    positive_seconds,
)
from geoctl_ros.params import (
    CONTROLLER,
    ConfigError,
    load_parameter_file,
    node_overrides,
    resolve,
    write_parameter_file,
)
from geoctl_ros.params.build import controller_config, gain_set
from geoctl_ros.plots.campaign import tuning_figure
from geoctl_ros.sil.rosenv import config_dir

# what each coordinate of the search is (its option's help)
_MEANING = {'k_R': 'k_R', 'k_Omega': 'k_Omega', 'c_share': 'c as a share of k_R / k_Omega',
            'cog_learning_s': "m*rho's learning time constant (s)",
            'moment_learning_s': "a constant moment's learning time constant (s)",
            'guidance_lookahead_deg': "guidance's lookahead (deg)"}


def _line(number, gains, got):
    return ('trial %3d: settle p50 %.2f s, p95 %.2f s, settled %.0f %%, violations %d, closest '
            'min %.2f p1 %.2f deg, latency rows %.2f deg%s | %s'
            % (number, got.settle_p50_s, got.settle_p95_s, 100 * got.settled_share,
               got.violations, got.closest_min_deg, got.closest_p1_deg,
               min(got.latency_margins_deg),
               '' if got.feasible else ' (infeasible)',
               ' '.join('%s=%.4g' % kv for kv in gains.items())))


@on_a_cluster('tune')
def main(argv=None):
    parser = argparse.ArgumentParser(prog='tune', description=__doc__.split('\n\n')[0],
                                     epilog=tools.WHERE)
    parser.add_argument('--trials', type=int, default=40, help='gain sets tried (40)')
    parser.add_argument('--runs', type=int, default=320,
                        help='random manoeuvres each gain set flies (320)')
    parser.add_argument('--seed', type=int, default=7,
                        help="the campaign's seed and the sampler's (7)")
    parser.add_argument('--duration', type=positive_seconds, default=4.0,
                        help='seconds per manoeuvre (4)')
    parser.add_argument('--latency-duration', type=positive_seconds, default=10.0,
                        help='seconds per latency row (10)')
    parser.add_argument('--best', type=int, default=6,
                        help='the best feasible gain sets checked, in turn until one passes (6)')
    parser.add_argument('--check-runs', type=int, default=400,
                        help='held-out manoeuvres each of those flies (400)')
    parser.add_argument('--check-seed', type=int, default=None,
                        help="the held-out manoeuvres' campaign seed (the tuning's + 1000)")
    parser.add_argument('--out', default=os.path.join('out', 'tune'),
                        help='output directory (out/tune)')
    add_cluster_arguments(parser)
    parser.add_argument('--params-file', default=None,
                        help='the testbed: its airframe and its gains, trial 0 '
                             '(default: config/testbed.yaml)')
    for name, (lo, hi, log) in tune.SPACE.items():
        parser.add_argument('--' + name.replace('_', '-'), dest=name, type=float, nargs=2,
                            metavar=('LO', 'HI'), default=[lo, hi],
                            help='the range of %s searched%s (%g %g)'
                                 % (_MEANING[name], ', on a log scale' if log else '', lo, hi))
    args = parser.parse_args(argv)
    if min(args.trials, args.runs, args.workers, args.best, args.check_runs) < 1:
        parser.error('--trials, --runs, --workers, --best and --check-runs must be positive')
    if args.check_seed is None:
        args.check_seed = args.seed + 1000
    absent = tools.missing('tune')      # (optuna is imported when the study starts)
    if absent:
        print(tools.refusal('tune', absent), file=sys.stderr)
        return 2
    latency_path = os.path.join(config_dir(), 'scenarios', 'testbed_yaw90.yaml')
    params_file = args.params_file or os.path.join(config_dir(), 'testbed.yaml')
    try:
        os.makedirs(os.path.join(args.out, 'best'), exist_ok=True)
        base = load_parameter_file(params_file)
        nominal = resolve(CONTROLLER, node_overrides(base, CONTROLLER))
        airframe = tune.airframe_of(base)
        tune.airframe_of(tune.latency_file(latency_path, base))    # (the rows configure there)
    except (ConfigError, OSError) as e:
        return cannot_start('tune', e, args.out)
    start = gain_set(nominal).overrides()
    gravity = float(np.linalg.norm(controller_config(nominal).gravity))
    space = {name: (*getattr(args, name), log) for name, (_, _, log) in tune.SPACE.items()}
    problems = tune.space_problems(space, gravity)
    if problems:
        parser.error('; '.join('%s: %s' % ('--' + name.replace('_', '-') if name in space
                                           else name, reason) for name, reason in problems))
    targs = tune.TuneArgs(args.runs, args.seed, args.duration, latency_path,
                          args.latency_duration, gravity=gravity, space=space)
    t0 = time.monotonic()
    with cluster.connect(args.scheduler, args.workers) as (client, where):
        print('tune: %d trials of %d manoeuvres (seed %d) on %s\ntune: the airframe of %s: %s'
              % (args.trials, args.runs, args.seed, where, params_file, airframe.describe()),
              file=sys.stderr, flush=True)
        try:
            _, done = tune.tune(client, base, targs, args.trials, args.seed,
                                lambda *t: print(_line(*t), file=sys.stderr, flush=True),
                                start)
        except KeyboardInterrupt:
            print('tune: interrupted; nothing written', file=sys.stderr)
            return 130
        front = tune.pareto(done)
        candidates = tune.ranked(done)[:args.best]
        held_out = tune.TuneArgs(args.check_runs, args.check_seed, args.duration, latency_path,
                                 args.latency_duration, gravity=targs.gravity)
        checked = tune.check(client, base, held_out, candidates)
    wall = time.monotonic() - t0
    tune.write_trials(os.path.join(args.out, 'trials.csv'), done)
    tuning_figure(done, front, os.path.join(args.out, 'pareto.png'))
    chosen = next((k for k, (_, passed) in enumerate(checked, 1) if passed), None)
    lines = ['# Tuning: %d trials, %d manoeuvres of %g s each (campaign seed %d), %.0f s'
             % (args.trials, args.runs, args.duration, args.seed, wall), '',
             'The airframe of `%s` (the runs and the latency rows fly it): %s.'
             % (params_file, airframe.describe()),
             'The search space: %s.' % ', '.join(
                 '%s %g-%g%s' % (name, lo, hi, ' (log)' if log else '')
                 for name, (lo, hi, log) in space.items()), '',
             '%d feasible (%s <= 0). The best by settle p95, each checked in turn on %d other '
             'manoeuvres (seed %d) and the whole latency table until one passes (no violation, '
             'closest p1 and every latency row at least %g deg, every run at least %g deg):'
             % (sum(d[2].feasible for d in done), ', '.join(tune.CONSTRAINTS), args.check_runs,
                args.check_seed, tune.CHECK_FLOOR_DEG, tune.CHECK_MIN_DEG), '',
             '| set | trial | settle p50 / p95 [s] | closest min / p1 [deg] | held out: '
             'violations, closest min / p1 [deg], settle p95 [s] | latency table, closest [deg] '
             '| passed | gains |',
             '|---|---|---|---|---|---|---|---|']
    for k, ((number, gains, got), (check, passed)) in enumerate(zip(candidates, checked), 1):
        lines.append('| %d | %d | %.2f / %.2f | %.2f / %.2f | %d, %.2f / %.2f, %.2f | %s | %s | '
                     '%s |' % (
            k, number, got.settle_p50_s, got.settle_p95_s, got.closest_min_deg,
            got.closest_p1_deg, check.violations, check.closest_min_deg, check.closest_p1_deg,
            check.settle_p95_s,
            ' '.join('%.2f' % m for m in check.latency_margins_deg),
            'yes' + (' (chosen)' if k == chosen else '') if passed else 'no',
            ' '.join('%s=%.4g' % kv for kv in gains.items())))
        comment = ('Written by `tune` (trial %d of seed %d): settle p50 %.2f s, p95 %.2f s over '
                   '%d manoeuvres; held out (seed %d, %d manoeuvres): %d violations, closest p1 '
                   '%.2f deg; latency table closest %.2f deg.'
                   % (number, args.seed, got.settle_p50_s, got.settle_p95_s, got.runs,
                      args.check_seed, check.runs, check.violations, check.closest_p1_deg,
                      min(check.latency_margins_deg)))
        write_parameter_file(study.parameter_file(base, gains),
                             os.path.join(args.out, tune.best_file_name(k)), comment)
        if k == chosen:
            write_parameter_file(study.parameter_file(base, gains),
                                 os.path.join(args.out, 'best.yaml'), comment)
    if chosen is None:
        lines.append('(no set passed: try more trials, or look at trials.csv)')
    lines += ['', 'latency rows (testbed_yaw90 on the airframe; latency, jitter) [ms]: ' +
              ' '.join('(%.0f, %.0f)' % (1e3 * a, 1e3 * b) for a, b in tune.LATENCY_ROWS)]
    with open(os.path.join(args.out, 'summary.md'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    print('wrote %s' % args.out)
    return 0 if chosen is not None else 1


if __name__ == '__main__':
    sys.exit(main())
