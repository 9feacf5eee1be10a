"""The lab's sensors in the sim-in-the-loop: ``./run sensors [--case NAME ...] [--duration 15]
[--out DIR]``.

Each case (``geoctl_ros.sil.sensors.CASES``: NED/FRD, a Y-up frame, an IMU 90 deg off in yaw, a
marker set 10 deg off in tilt, a 0.02 rad/s gyro bias) flies sim and controller as processes
twice: with the controller's defaults (it must refuse to arm naming the mismatch, or, for what
only motion shows, fail safe in flight naming it) and with the matching parameters (calibrated
where that is the fix), which must fly config/testbed.yaml and keep the cone. Prints a table.
"""
import argparse
import os
import sys
import tempfile

from geoctl_ros.cli import tools
from geoctl_ros.sil import sensors
from geoctl_ros.sil.rosenv import config_dir


def main(argv=None):
    parser = argparse.ArgumentParser(prog='sensors', description=__doc__.split('\n\n')[0],
                                     epilog=tools.WHERE)
    parser.add_argument('--case', action='append', choices=sorted(sensors.CASES),
                        help='a case (repeatable; default: all)')
    parser.add_argument('--duration', type=float, default=15.0,
                        help='seconds each armed flight lasts (15)')
    parser.add_argument('--params-file', default=None, help='default: config/testbed.yaml')
    parser.add_argument('--out', default=None, help="folder for the nodes' logs")
    args = parser.parse_args(argv)
    params_file = args.params_file or os.path.join(config_dir(), 'testbed.yaml')
    out = args.out or tempfile.mkdtemp(prefix='sensors-')
    rows = ['| case | parameters | armed | what the controller said | closest approach [deg] '
            '| final error [deg] |', '|---|---|---|---|---|---|']
    ok = True
    for name in args.case or list(sensors.CASES):
        for matching in (False, True):
            print('sensors: %s, %s ...' % (name, 'matching' if matching else 'defaults'),
                  file=sys.stderr, flush=True)
            o = sensors.run_case(name, matching, params_file, out, args.duration)
            said = o.failsafe or o.message
            rows.append('| %s | %s | %s | %s | %s | %s |' % (
                sensors.CASES[name].title, o.parameters, 'yes' if o.armed else 'no',
                said.replace('|', '/'),
                '' if o.min_margin_deg is None else '%+.2f' % o.min_margin_deg,
                '' if o.final_error_deg is None else '%.2f' % o.final_error_deg))
            if matching:
                ok &= (o.armed and o.failsafe is None and o.min_margin_deg is not None
                       and o.min_margin_deg > 0.0)
            else:
                ok &= (not o.armed) or o.failsafe is not None
    print('\n'.join(rows))
    print('logs in %s' % out)
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
