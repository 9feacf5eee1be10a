"""Load and fault runs over real DDS: does the lab's own workflow ever drop the testbed?

    ./run soak                                   # every case, 60 s each, prints a table
    ./run soak --case monitoring --duration 600  # the README's monitoring commands for 10 min
    ./run soak --transport rmw-default ...       # the same with the rmw's default transports

Each case flies the sim-in-the-loop (``sim`` and ``controller`` processes on
``config/testbed.yaml``, armed) while loads run beside it or
faults are injected into its inputs, and measures what matters for a vehicle on a joint:

- failsafes (each one is counted, then the controller is re-armed, as an operator would; the
  set-point schedule plays from each arming and then holds R_d),
- input age at the controller's ticks (p99 of its 0.5 s diagnostics windows, and max),
- the gap between motor commands at a subscriber (p99, max) and the control loop period (p99,
  max), and the sensor's closest approach to the cone (from the sim's true attitude).

Loads (other people's processes, in a plain ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` shell):
``cli`` the README's monitoring commands with the real ``ros2`` command in a loop (topic echo,
topic hz, param dump and get on both nodes, service call, service list); ``churn`` a ROS process
joining every second and leaving after 0.5-1.5 s, one in three killed with SIGKILL; ``params``
an rclpy client reading every parameter of both nodes every 0.5 s; ``cpu`` one busy process
per core; ``record`` the flight recorder and the live 3D view, on the nodes' loopback profile
(what recording costs the flight). Faults, through a relay between the sim and the controller:
inputs delayed by 0-10 ms, duplicated, reordered, held back and released in bursts, poses or IMU
missing for a while; and the sim process paused with SIGSTOP/SIGCONT (both inputs missing).

``--transport profile`` (default) runs the nodes on the shipped loopback profile
(``geoctl_ros.sil.rosenv``), ``rmw-default`` on the rmw's defaults (shared memory + UDP,
LOCALHOST): the "before" of docs/interface.md's table. Everything stays on 127.0.0.1.
"""
import argparse
import json
import os
import sys
import tempfile

from geoctl_ros.sil import measures, soak
from geoctl_ros.sil.rosenv import config_dir


def main(argv=None):
    parser = argparse.ArgumentParser(prog='soak', description=__doc__.split('\n\n')[0])
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

