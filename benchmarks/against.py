"""This tree's benchmark figures against a git revision's (``bench.py --against REV``).

One worker process per tree, each measuring with its own ``bench.py`` (so REV must have its
figure groups, ``bench.GROUPS``: every revision since ``--json`` does), asked in turn for one
figure group after the other, A B A B ..., a few seconds each, so that a busy spell of this
shared machine slows both alike; the fastest of each figure over the rounds.
"""
import json
import os
import subprocess
import sys
import tempfile

from bench import GROUPS, HERE, named
import numpy

# A tree's worker for --against: that tree's bench.py, one figure group per request line, the
# result as a JSON line (numpy floats as floats)
SERVE = """import json, sys
sys.path.insert(0, sys.argv[1])
import bench
print(json.dumps(bench.geoctl_ros.__file__), flush=True)
for group in sys.stdin:
    result = getattr(bench, group.strip())()
    print(json.dumps(result, default=float), flush=True)
"""


def against(rev, rounds=3):
    """This tree against git revision `rev`, on this interpreter, `rounds` rounds: prints the
    table.
    """
    root = os.path.dirname(HERE)
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(['git', 'archive', rev, 'geoctl_ros', 'config', 'benchmarks'],
                                 cwd=root, capture_output=True, check=True).stdout
        subprocess.run(['tar', '-x', '-C', tmp], input=archive, check=True)
        trees = {rev: tmp, 'this tree': root}
        workers = {}
        for label, tree in trees.items():
            env = dict(os.environ, PYTHONPATH=tree)   # ahead of the editable install
            workers[label] = subprocess.Popen(
                [sys.executable, '-c', SERVE, os.path.join(tree, 'benchmarks')], env=env,
                cwd=tree, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
            first = workers[label].stdout.readline()          # (its error, if any, on stderr)
            if not first:
                sys.exit('against: the worker of %s did not start' % label)
            ran = json.loads(first)
            assert ran.startswith(tree), 'ran %s, not %s' % (ran, tree)
        best = {label: {} for label in trees}
        try:
            for _ in range(rounds):
                for group in GROUPS:
                    for label, w in workers.items():
                        w.stdin.write(group + '\n')
                        w.stdin.flush()
                        for k, v in named(group, json.loads(w.stdout.readline())).items():
                            best[label][k] = min(v, best[label].get(k, v))
        finally:
            for w in workers.values():
                w.stdin.close()
                w.wait()
    print('%s (Python %s, numpy %s): fastest of %d rounds, the trees in turn for each group, us'
          % (rev, sys.version.split()[0], numpy.__version__, rounds))
    mine, theirs = best['this tree'], best[rev]
    print('%-46s %10s %10s %7s' % ('figure', rev[:10], 'this tree', 'ratio'))
    for k, v in mine.items():
        old = theirs.get(k)
        print('%-46s %10s %10.1f %7s' % (k, '%.1f' % old if old else '-', v,
                                          '%.2f' % (v / old) if old else '-'))
    return 0


if __name__ == '__main__':         # (bench.py --against REV [--rounds N] runs this)
    sys.exit(against(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 3))
