"""``./run fuzz``: hostile input at every boundary (``geoctl_ros.fuzz.boundaries``)."""
import argparse
import sys

import numpy as np

from geoctl_ros.cli import tools
from geoctl_ros.fuzz import boundaries


def main(argv=None):
    parser = argparse.ArgumentParser(prog='fuzz', description=boundaries.__doc__.split('\n\n')[0],
                                     epilog=tools.WHERE)
    parser.add_argument('--examples', type=int, default=10_000, help='inputs per boundary')
    parser.add_argument('--boundary', action='append', choices=sorted(boundaries.BOUNDARIES),
                        help='only these (default: all)')
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args(argv)
    if args.examples < 1:
        parser.error('--examples must be positive')
    print('fuzz: Python %s, numpy %s, %d examples per boundary, seed %d'
          % (sys.version.split()[0], np.__version__, args.examples, args.seed), flush=True)
    crashes = 0
    try:
        for name in args.boundary or list(boundaries.BOUNDARIES):
            tally = boundaries.BOUNDARIES[name](args.examples, args.seed)
            crashes += tally.crash is not None
            print(tally.line(), flush=True)
    finally:
        boundaries.close_nodes()
    return 1 if crashes else 0


if __name__ == '__main__':
    sys.exit(main())

