"""The campaign's speed, in one run: the batched loop's real-time factor per core before and
after, the fixed cost of a campaign, and a 10,000-run campaign of 20 s runs.

    ./run shell benchmarks/campaign.py                  # all three (about 4 minutes on 2 cores)
    ./run shell benchmarks/campaign.py --runs 2000      # a shorter campaign
    ./run shell benchmarks/campaign.py --against REV    # "before" is REV's tree (default below)

1. Per core: the batched closed loop (``geoctl_ros.sim.closed_loop.fly``: testbed, rotors, 1 kHz
   integration, 100 Hz control) in one process, on runs of 2 s with two cones, in the batch size
   each tree's campaign uses. "Before" is the tree of BEFORE (the campaign on the standard
   library's process pool, 300 runs a batch), "after" this tree. Each is measured by this file's
   ``--per-core`` mode in a fresh process with that tree first on the path, alternating
   (before, after, before, after); the fastest of each.
2. Fixed cost: ``campaign`` with one 0.1 s run per worker: starting the command and the local
   cluster, imports on the workers, drawing and flying the first batch, writing, shutting down.
3. ``campaign --runs 10000 --duration 20`` on the local cluster (one worker per core): its wall
   time from start to exit, and the command's own figures.

Not a test: nothing here passes or fails. Every process stays on 127.0.0.1.
"""
# (first: numpy as the package's processes have it, where the tree first on PYTHONPATH sets it)
import geoctl_ros  # noqa: F401

# isort: split
import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy

from geoctl_ros.params import load_parameter_file  # (the tree first on PYTHONPATH)

try:                                    # this layout (issue 29) ...
    from geoctl_ros.campaign import manoeuvres
    from geoctl_ros.campaign.runner import BATCH
    from geoctl_ros.sim import scenario
    from geoctl_ros.sim.closed_loop import fly
except ImportError:                     # ... or a "before" tree's
    from geoctl_ros.tools import manoeuvres, scenario
    from geoctl_ros.tools.batch import run_batch as fly
    from geoctl_ros.tools.campaign import BATCH

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
BEFORE = '05267a5'        # the last tree before the campaign went to Dask (issue 21)


def per_core(duration=2.0, cones=2):
    """In this process: (batch size, wall s, real-time factor per core) of the tree on the path."""
    n = BATCH
    base = load_parameter_file(os.path.join(ROOT, 'config', 'testbed.yaml'))
    runs, i = [], 0
    while len(runs) < n:
        sections = manoeuvres.run_sections(base, 1, i, duration)
        if manoeuvres.cone_count(1, i) == cones:
            runs.append(scenario.from_sections(sections, 'run_%d' % i))
        i += 1
    wall = fly(runs).wall_s
    return n, wall, n * duration / wall


def tree_of(rev, tmp):
    os.makedirs(tmp, exist_ok=True)
    archive = subprocess.run(['git', 'archive', rev, 'geoctl_ros', 'config'], cwd=ROOT,
                             capture_output=True, check=True).stdout
    subprocess.run(['tar', '-x', '-C', tmp], input=archive, check=True)
    return tmp


def measure_tree(tree):
    env = dict(os.environ, PYTHONPATH=tree)          # ahead of the editable install
    r = subprocess.run([sys.executable, os.path.abspath(__file__), '--per-core'], env=env,
                       capture_output=True, text=True, check=True)
    n, wall, rtf = r.stdout.split()
    return int(n), float(wall), float(rtf)


def timed_campaign(args, out):
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, '-m', 'geoctl_ros.cli.campaign', '--out', out] + args,
                       capture_output=True, text=True)
    wall = time.monotonic() - t0
    if r.returncode not in (0, 1):
        sys.exit('campaign failed:\n' + r.stderr[-2000:])
    return wall, r.stdout


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--per-core', action='store_true', help=argparse.SUPPRESS)
    parser.add_argument('--against', default=BEFORE, help='"before" tree (%s)' % BEFORE)
    parser.add_argument('--runs', type=int, default=10000)
    parser.add_argument('--duration', type=float, default=20.0)
    parser.add_argument('--rounds', type=int, default=2)
    args = parser.parse_args(argv)
    if args.per_core:
        print('%d %.6f %.3f' % per_core())
        return 0
    print('campaign speed (Python %s, numpy %s, %d cores)'
          % (sys.version.split()[0], numpy.__version__, os.cpu_count()))
    with tempfile.TemporaryDirectory() as tmp:
        trees = {args.against: tree_of(args.against, os.path.join(tmp, 'before')),
                 'this tree': ROOT}
        best = {}
        for _ in range(args.rounds):
            for label, tree in trees.items():
                got = measure_tree(tree)
                if label not in best or got[2] > best[label][2]:
                    best[label] = got
        print('\n1. batched loop, one process, 2 s runs with 2 cones (fastest of %d rounds)'
              % args.rounds)
        print('%-12s %8s %10s %22s' % ('tree', 'batch', 'wall [s]', 'real time x per core'))
        for label, (n, wall, rtf) in best.items():
            print('%-12s %8d %10.2f %22.0f' % (label[:12], n, wall, rtf))
        print('after / before: %.2f' % (best['this tree'][2] / best[args.against][2]))

        workers = os.cpu_count() or 1
        wall, _ = timed_campaign(['--runs', str(workers), '--duration', '0.1', '--worst', '0'],
                                 os.path.join(tmp, 'fixed'))
        print('\n2. fixed cost: a campaign of %d runs of 0.1 s, start to exit: %.1f s'
              % (workers, wall))

        wall, out = timed_campaign(['--runs', str(args.runs), '--duration', str(args.duration)],
                                   os.path.join(tmp, 'campaign'))
        print('\n3. campaign --runs %d --duration %g: %.1f s start to exit (%.0fx real time, '
              '%.0fx per worker)' % (args.runs, args.duration, wall,
                                     args.runs * args.duration / wall,
                                     args.runs * args.duration / wall / workers))
        for line in out.splitlines():
            if re.search(r'runs \||violations|wall time|drawing|simulated|settled', line):
                print('   ' + line)
    return 0


if __name__ == '__main__':
    sys.exit(main())
