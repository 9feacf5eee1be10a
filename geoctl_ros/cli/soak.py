"""Load and fault runs over real DDS: does the lab's own workflow ever drop the testbed?

    ./run soak                                   # every case, 60 s each, prints a table
    ./run soak --case monitoring --duration 600  # the README's monitoring commands for 10 min
    ./run soak --transport rmw-default ...       # the same with the rmw's default transports

The cases, the loads and faults, and what is measured: ``geoctl_ros.sil.soak``.
"""
import argparse
import json
import os
import sys
import tempfile

from geoctl_ros.cli import tools
from geoctl_ros.sil import measures, soak
from geoctl_ros.sil.rosenv import config_dir


def main(argv=None):
    parser = argparse.ArgumentParser(prog='soak', description=__doc__.split('\n\n')[0],
                                     epilog=tools.WHERE)
    parser.add_argument('--case', action='append', choices=sorted(soak.CASES),
                        help='a case to run (repeatable; default: all)')
    parser.add_argument('--duration', type=float, default=60.0, help='seconds per case (60)')
    parser.add_argument('--transport', choices=('profile', 'rmw-default'), default='profile',
                        help='the nodes on the loopback profile (default) or the rmw defaults')
    parser.add_argument('--params-file', default=None, help='default: config/testbed.yaml')
    parser.add_argument('--prefix', default='',
                        help="run sim and controller under this command, as ros2 run --prefix "
                             "(e.g. 'nice -n -10'; docs/interface.md, \"Scheduling\")")
    parser.add_argument('--out', default=None, help='folder for logs and soak.json')
    args = parser.parse_args(argv)
    params_file = args.params_file or os.path.join(config_dir(), 'testbed.yaml')
    out = args.out or tempfile.mkdtemp(prefix='soak-')
    names = args.case or list(soak.CASES)
    results = soak.run_cases(names, args.duration, params_file, out, args.transport,
                        args.prefix.split(),
                        progress=lambda m: print(m, file=sys.stderr, flush=True))
    with open(os.path.join(out, 'soak.json'), 'w') as f:
        json.dump({'transport': args.transport, 'results': results}, f, indent=2)
    print('transport: %s, %s%s' % (args.transport, os.path.basename(params_file),
                                    ', nodes under ' + args.prefix if args.prefix else ''))
    print(measures.TABLE_HEAD)
    for label, f in results.items():
        print(measures.table_row(label, f))
    print('logs and soak.json in %s' % out)
    return 0


if __name__ == '__main__':
    sys.exit(main())

