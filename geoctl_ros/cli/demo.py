"""The main job (``./run demo``): the testbed flown in the loop over real DDS.

Starts the ``sim`` and ``controller`` nodes as two processes with ``config/testbed.yaml`` (as
``ros2 run ... --ros-args --params-file`` would), waits for them, arms the controller through its
``~/arm`` service, records the topics while the 90 deg yaw round the cone plays, disarms, and
prints a summary: the closest approach to each cone (from the simulator's true attitude), the final
error, the control loop's rate and jitter and its input-to-command latency (from the controller's
diagnostics), and what a subscriber sees of the command stream. Writes OUT/sil_summary.json,
OUT/sil.png and the two nodes' logs. Discovery stays on loopback in a DDS domain of its own.

``./run demo --headless`` instead runs every shipped scenario through the headless runner and
prints the results table of docs/scenarios.md.
"""
import argparse
import glob
import os
import sys

from geoctl_ros import plots
from geoctl_ros.cli import tools
from geoctl_ros.records import scenario as scenario_files
from geoctl_ros.sil import flight
from geoctl_ros.sil.rosenv import config_dir
from geoctl_ros.sim import scenario

TABLE_HEAD = ('| scenario | min angle to each cone (half-angle), deg | final attitude error, deg '
              '| final Psi | settle time (Psi < 1e-3), s | final Delta_bar | wall time, s |\n'
              '|---|---|---|---|---|---|---|')


def table_row(summary):
    """One results-table row (docs/scenarios.md) of a run's summary."""
    cones = ', '.join('%s %.1f (%g)' % (n, a, summary['cone_half_angle_deg'][n])
                      for n, a in summary['min_cone_angle_deg'].items()) or '-'
    settle = '-' if summary['settle_time_s'] is None else '%.1f' % summary['settle_time_s']
    dbar = '[%s]' % ', '.join('%.3f' % v for v in summary['final_disturbance_estimate'])
    return '| `%s` | %s | %.2g | %.2g | %s | %s | %.1f |' % (
        summary['scenario'], cones, summary['final_attitude_error_deg'], summary['final_psi'],
        settle, dbar, summary['wall_time_s'])


def headless(out):
    rows, figures = [], plots.available('demo')
    for path in sorted(glob.glob(os.path.join(config_dir(), 'scenarios', '*.yaml'))):
        name = os.path.splitext(os.path.basename(path))[0]
        result = scenario.run(scenario.load(path))
        scenario_files.write(result, os.path.join(out, name), plots=figures)
        rows.append(table_row(result.summary))
        print('%-34s done (%s)' % (name, os.path.join(out, name)), file=sys.stderr)
    print(TABLE_HEAD)
    print('\n'.join(rows))
    return 0


def main(argv=None):
    parser = argparse.ArgumentParser(prog='demo', description=__doc__.split('\n\n')[0],
                                     epilog=tools.WHERE)
    parser.add_argument('--out', default='out', help='output folder (default: ./out)')
    parser.add_argument('--headless', action='store_true',
                        help='run every shipped scenario headless and print the results table')
    parser.add_argument('--params-file', default=None,
                        help='parameter file for both nodes (default: config/testbed.yaml)')
    parser.add_argument('--duration', type=float, default=25.0, help='seconds to fly (25)')
    parser.add_argument('--no-record', action='store_true',
                        help='do not record the flight (default: a bag under OUT/records)')
    parser.add_argument('--mavlink', metavar='URL', nargs='?', const='udpout:127.0.0.1:14550',
                        help='also run the MAVLink bridge to a ground station on this machine '
                             '(default URL udpout:127.0.0.1:14550, where QGroundControl listens)')
    parser.add_argument('--esc', action='store_true',
                        help="fly through the esc_i2c node and a virtual ESC bus (the ESCs' "
                             'byte encoding and watchdog) instead of motor_commands to the sim')
    args = parser.parse_args(argv)
    if args.headless:
        return headless(args.out)
    params_file = args.params_file or os.path.join(config_dir(), 'testbed.yaml')
    if args.mavlink and args.mavlink.split(':')[1:2] not in (['127.0.0.1'], ['localhost']) \
            and args.mavlink.startswith(('udp', 'tcp')):
        parser.error('--mavlink: the demo talks to this machine only (127.0.0.1)')
    s = flight.fly(params_file, args.out, args.duration, mavlink=args.mavlink,
            record=not args.no_record, esc=args.esc)
    lp, lat, sub = s['loop_period'], s['pose_to_command_latency'], s['commands_seen_by_subscriber']
    print('sim-in-the-loop: %s, %.0f s armed, commands through %s'
          % (os.path.basename(params_file), s['flight_s'], s['through']))
    for n, a in s['min_cone_angle_deg'].items():
        print('  cone %-10s closest %.2f deg (half-angle %.1f): margin %.2f deg'
              % (n, a, s['cone_half_angle_deg'][n], a - s['cone_half_angle_deg'][n]))
    print('  final attitude error   %.2f deg' % s['final_attitude_error_deg'])
    if lp:
        print('  control loop           %.2f Hz, period std %.3f ms, max %.2f ms'
              % (1e3 / lp['mean_ms'], lp['std_ms'], lp['max_ms']))
    if s['step_compute']:
        print('  tick to motor command  mean %.3f ms, max %.3f ms'
              % (s['step_compute']['mean_ms'], s['step_compute']['max_ms']))
    if lat:
        print('  pose-to-command        mean %.2f ms, max %.2f ms (pose receipt to publish)'
              % (lat['mean_ms'], lat['max_ms']))
    print('  commands at subscriber %.1f Hz, gap std %.2f ms, max %.1f ms'
          % (sub['frequency_hz'], sub['gap_std_ms'], sub['gap_max_ms']))
    print('  commands after disarm  %s%s' % ('all zero' if s['commands_zero_after_disarm']
                                            else 'NOT ZERO', ' (at the ESCs)' if args.esc else ''))
    print('  wrote %s/sil_summary.json%s' % (
        args.out, ', %s/sil.png' % args.out if os.path.isfile(os.path.join(args.out, 'sil.png'))
        else ''))
    if s['record']:
        print('  recorded the flight   %s (./run report %s)' % (s['record'], s['record']))
    ok = (s['min_cone_margin_deg'] is None or s['min_cone_margin_deg'] > 0) and \
        s['commands_zero_after_disarm']
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
