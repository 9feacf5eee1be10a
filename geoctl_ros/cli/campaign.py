"""Safety campaigns and gain studies:
``campaign --runs 1000 --seed 1 --out DIR [--workers N | --scheduler tcp://HOST:PORT]
[--grid NAME=V1,V2,...]... [--replay FILE...]``.

Flies many random manoeuvres of the testbed headless and reports how often the sensor kept out of
the cones (``geoctl_ros.campaign.runner`` says what each run is and what is written).
"""
import argparse
import os
import sys
import time

from geoctl_ros.campaign import cluster, manoeuvres, runner, study
from geoctl_ros.cli import tools
from geoctl_ros.cli.args import (
    add_cluster_arguments,
    cannot_start,
    on_a_cluster,
    positive_seconds,
)
from geoctl_ros.params import ConfigError, load_parameter_file
from geoctl_ros.sil.rosenv import config_dir


def progress_printer(total, prog='campaign'):
    tty = sys.stderr.isatty()
    shown = [-1]

    def report(done, seconds):
        percent = 100.0 * done / total
        line = '%s: %5.1f %% of %d runs flown, %.0f s' % (prog, percent, total, seconds)
        if tty:
            print('\r' + line, end='', file=sys.stderr, flush=True)
        elif int(percent // 10) > shown[0]:          # a log file: a line every 10 %
            shown[0] = int(percent // 10)
            print(line, file=sys.stderr, flush=True)
    return report


@on_a_cluster('campaign')
def main(argv=None):
    parser = argparse.ArgumentParser(prog='campaign', description=__doc__.split('\n\n')[0],
                                     epilog=tools.WHERE)
    parser.add_argument('--runs', type=int, default=1000, help='number of manoeuvres (1000)')
    parser.add_argument('--seed', type=int, default=1, help='campaign seed (1)')
    parser.add_argument('--stratum', choices=sorted(manoeuvres.STRATA), default='all',
                        help="the part of the draw: all (the campaign's), near-cone (starts "
                        '5-11 deg from a cone, 30-60 ms of latency: its hardest part), or arming '
                        "(armed 2.25-5 deg from a cone, half resting on the joint's stops, half "
                        'held: the take-over check refuses some; the summary counts them)')
    parser.add_argument('--out', required=True, help='output directory')
    add_cluster_arguments(parser, '--jobs')
    parser.add_argument('--dashboard', action='store_true',
                        help='local cluster: serve the Dask dashboard on 127.0.0.1:8787')
    parser.add_argument('--batch', type=int, default=runner.BATCH,
                        help='runs flown together at most (%d)' % runner.BATCH)
    parser.add_argument('--grid', action='append', default=[], metavar='NAME=V1,V2,...',
                        help='a gain study: fly every run with each combination of these '
                             'controller parameters')
    parser.add_argument('--duration', type=positive_seconds, default=20.0,
                        help='seconds per run (20)')
    parser.add_argument('--worst', type=int, default=5, help='worst runs written out (5)')
    parser.add_argument('--best', type=int, default=3,
                        help='gain study: non-dominated gain sets written out, at most (3)')
    parser.add_argument('--disturbance-max', type=float, default=manoeuvres.DISTURBANCE_MAX,
                        help='largest constant disturbance, N m (%g)' % manoeuvres.DISTURBANCE_MAX)
    parser.add_argument('--params-file', default=None,
                        help='the testbed (default: config/testbed.yaml)')
    parser.add_argument('--replay', nargs='+', metavar='FILE',
                        help='fly these scenario files (written by a campaign) instead')
    args = parser.parse_args(argv)
    if args.runs < 1 or args.workers < 1 or args.batch < 1:
        parser.error('--runs, --workers and --batch must be positive')
    try:
        if args.replay:
            return runner.replay(args.replay)
        os.makedirs(args.out, exist_ok=True)
        base = load_parameter_file(args.params_file or os.path.join(config_dir(), 'testbed.yaml'))
        gain_sets = study.parse_grid(args.grid) if args.grid else [{}]
        study.check_gain_sets(base, gain_sets)
    except (ConfigError, OSError) as e:
        return cannot_start('campaign', e, args.out)
    total = args.runs * len(gain_sets)
    t0 = time.monotonic()
    with cluster.connect(args.scheduler, args.workers, args.dashboard) as (client, where):
        started = time.monotonic() - t0
        print('campaign: %d runs on %s (started in %.1f s)' % (total, where, started),
              file=sys.stderr, flush=True)
        t1 = time.monotonic()
        try:
            columns, worst, interrupted, (draw_s, fly_s) = runner.fly(
                client, base, args, gain_sets, progress_printer(total))
        except (ConfigError, ValueError) as e:          # a run the batch cannot fly
            print('\ncampaign: %s' % e, file=sys.stderr)
            return 2
        workers = cluster.worker_count(client)
    wall = time.monotonic() - t1
    print('', file=sys.stderr)
    n = len(columns['run'])
    if not n:
        print('campaign: interrupted before any run was flown; nothing written', file=sys.stderr)
        return 130
    lines, violations = runner.write_results(columns, worst, interrupted,
                                              (wall, workers, started, draw_s, fly_s), base, args,
                                              gain_sets)
    print('\n'.join(lines))
    print('wrote %s' % args.out)
    if interrupted:
        return 130
    return 1 if violations else 0


if __name__ == '__main__':
    sys.exit(main())

