"""The benchmark of the control laws: ``benchmark --out DIR [--runs N] [--workers N |
--scheduler tcp://HOST:PORT] [--cases NAME,...]``.

Flies every law (paper, delay_robust, geometric, cbf) on the standard cases and on N random
manoeuvres of the campaign, on a Dask cluster (a local one on 127.0.0.1 by default), and writes
the tables (Markdown and CSV) and the figures (``geoctl_ros.benchmark.run`` says which).
"""
import argparse
import os
import sys

from geoctl_ros.benchmark import cases
from geoctl_ros.benchmark.run import GAIN_SETS, benchmark, gain_set
from geoctl_ros.campaign import cluster, runner
from geoctl_ros.cli import tools
from geoctl_ros.cli.args import (
    add_cluster_arguments,
    cannot_start,
    on_a_cluster,
    positive_seconds,
)
from geoctl_ros.cli.campaign import progress_printer
from geoctl_ros.params import ConfigError, load_parameter_file
from geoctl_ros.sil.rosenv import config_dir


@on_a_cluster('benchmark')
def main(argv=None):
    parser = argparse.ArgumentParser(prog='benchmark', description=__doc__.split('\n\n')[0],
                                     epilog=tools.WHERE)
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument('--runs', type=int, default=1000,
                        help='random manoeuvres, each flown by every law (1000; 0: none)')
    parser.add_argument('--seed', type=int, default=1, help='campaign seed of the random runs (1)')
    parser.add_argument('--duration', type=positive_seconds, default=20.0,
                        help='seconds per random run (20)')
    parser.add_argument('--case-duration', type=positive_seconds, default=None,
                        help="simulated seconds of each standard case (default: its file's)")
    parser.add_argument('--cases', default=','.join(cases.CASES),
                        help='standard cases to fly (default: all: %s)' % ','.join(cases.CASES))
    add_cluster_arguments(parser)
    parser.add_argument('--batch', type=int, default=runner.BATCH,
                        help='random runs flown together at most (%d)' % runner.BATCH)
    args = parser.parse_args(argv)
    if args.runs < 0 or args.workers < 1 or args.batch < 1:
        parser.error('--runs must be at least 0, and --workers and --batch positive')
    names = [c for c in args.cases.split(',') if c]
    unknown = sorted(set(names) - set(cases.CASES))
    if unknown or not names:
        parser.error('--cases: %s (known: %s)' % (', '.join(unknown) or 'none given',
                                                  ', '.join(cases.CASES)))
    try:
        os.makedirs(args.out, exist_ok=True)
        config = config_dir()
        sections = {n: load_parameter_file(os.path.join(config, 'scenarios', n + '.yaml'))
                    for n in names}
        base = load_parameter_file(os.path.join(config, 'testbed.yaml'))
        args.gain_sets = {name: gain_set(f and os.path.join(config, 'scenarios', f))
                          for name, f in GAIN_SETS.items()}
    except (ConfigError, OSError) as e:
        return cannot_start('benchmark', e, args.out)

    def say(line):
        print(line, file=sys.stderr, flush=True)

    total = args.runs * (len(cases.BENCHED) + sum(1 for g in args.gain_sets.values() if g))
    with cluster.connect(args.scheduler, args.workers) as (client, where):
        say('benchmark: %d laws on %d cases and %d random runs, on %s'
            % (len(cases.BENCHED), len(names), args.runs, where))
        try:
            lines = benchmark(client, sections, base, args, say,
                              progress_printer(total, 'benchmark') if total else None)
        except KeyboardInterrupt:
            say('\nbenchmark: interrupted; nothing written')
            return 130
    print('\n'.join(lines))
    print('wrote %s' % args.out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
