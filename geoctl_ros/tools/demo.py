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
import json
import math
import os
import sys
import time

import numpy as np
import rclpy

from geoctl_ros.core import so3
from geoctl_ros.core.diagnostics import aggregate_ms
from geoctl_ros.esc.virtual import VirtualEscBus
from geoctl_ros.nodes.recorder import default_path
from geoctl_ros.params import (
    CONTROLLER,
    ESC,
    cone_set,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.tools import plots, scenario
from geoctl_ros.tools.processes import Monitor, NodeProcess
from geoctl_ros.tools.rosenv import config_dir, use_node_env

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
    rows = []
    for path in sorted(glob.glob(os.path.join(config_dir(), 'scenarios', '*.yaml'))):
        name = os.path.splitext(os.path.basename(path))[0]
        result = scenario.run(scenario.load(path))
        scenario.write(result, os.path.join(out, name))
        rows.append(table_row(result.summary))
        print('%-34s done (%s)' % (name, os.path.join(out, name)), file=sys.stderr)
    print(TABLE_HEAD)
    print('\n'.join(rows))
    return 0


def _diag_stats(diags, name):
    """The controller's windows of one diagnostics figure (a Figures field) as one, ms."""
    w = aggregate_ms(diags, name)
    return None if w is None else {k + '_ms': v for k, v in w._asdict().items()}


def fly(params_file, out, duration, monitor_factory=None, mavlink=None, record=True,
        esc=False):
    """Run sim + controller as processes, arm, fly duration seconds; returns the summary. With
    record, ``record`` writes the flight to a bag under out/records (its path in the summary).
    With esc, the ``esc_i2c`` node writes the commands to a virtual ESC bus (out/esc_bus) that
    the sim reads instead of ``motor_commands``: the flight goes through the ESCs' byte encoding
    and the node's watchdog, and the summary says what the ESCs were told after the disarm.
    """
    use_node_env()
    values = resolve(CONTROLLER, node_overrides(load_parameter_file(params_file), CONTROLLER))
    setup = controller_setup(values)
    cones = cone_set(values)
    final_setpoint = (setup.schedule.rotations[-1] if len(setup.schedule) else setup.setpoint)
    os.makedirs(out, exist_ok=True)
    bus_args = ()
    if esc:
        bus_path = os.path.abspath(os.path.join(out, 'esc_bus'))
        if os.path.exists(bus_path):
            os.unlink(bus_path)
        bus_args = ('-p', 'esc.virtual_bus:=' + bus_path)
    procs = [NodeProcess('sim', params_file, bus_args, log_dir=out),
             NodeProcess('controller', params_file, log_dir=out)]
    if esc:             # first in the list: stopped (zero to every ESC) before the sim goes
        procs.insert(0, NodeProcess('esc_i2c', params_file,
                                    bus_args + ('-p', 'esc.probe_timeout:=20.0'), log_dir=out))
    if mavlink:        # a ground station on this machine can watch the flight
        procs.append(NodeProcess('mavlink_bridge', None, ('-p', 'mavlink.url:=' + mavlink),
                                 log_dir=out))
    bag_path = os.path.join(out, default_path()) if record else None
    if record:
        recorder = NodeProcess('record', None, ('-p', 'record.path:=' + bag_path), log_dir=out)
        procs.append(recorder)
    rclpy.init()
    mon = (monitor_factory or Monitor)()
    try:
        if record:          # from the first true pose on: the flight is recorded whole
            mon.wait_for(lambda: 'first message on /sim/true_pose' in recorder.output()
                         or recorder.proc.poll() is not None, 30.0, 'the recorder')
        reply = mon.arm_when_ready(30.0)
        if not reply.success:
            raise RuntimeError(reply.message)
        t_arm = time.monotonic()
        print('armed; flying %.0f s ...' % duration, file=sys.stderr)
        mon.spin_for(duration)
        t_end = time.monotonic()
        mon.arm(False)
        mon.spin_for(0.5)
        after_disarm = mon.last('motors')
        if esc:             # what the ESCs were told last, from the bus itself
            bus = VirtualEscBus(bus_path, resolve(ESC, {})['esc.addresses'])
            after_disarm = [data[0] for data, _ in bus.setpoints()]
            bus.close()
    finally:
        mon.destroy_node()
        rclpy.try_shutdown()
        codes = [p.stop() for p in procs]

    flight = [(t - t_arm, v[1]) for t, v in mon.log['true_pose'] if t_arm <= t <= t_end]
    t = np.array([x[0] for x in flight])
    Rs = [so3.quat_to_rot(q) for _, q in flight]
    angles = np.array([cones.angles_deg(R) for R in Rs]).reshape(len(Rs), len(cones))
    err = np.array([math.degrees(so3.angle(final_setpoint.T @ R)) for R in Rs])
    diags = [d for tt, d in mon.log['diagnostics'] if t_arm + 1.0 <= tt <= t_end]
    cmd_times = np.array([tt for tt, _ in mon.log['motors'] if t_arm <= tt <= t_end])
    gaps = np.diff(cmd_times) * 1e3 if len(cmd_times) > 1 else np.array([0.0])
    commands = np.array([c for tt, c in mon.log['motors'] if t_arm <= tt <= t_end])
    psi = [(tt - t_arm, v) for tt, v in mon.log['psi'] if t_arm <= tt <= t_end]
    summary = {
        'params_file': str(params_file),
        'flight_s': duration,
        'min_cone_angle_deg': {n: float(angles[:, i].min()) for i, n in enumerate(cones.names)},
        'cone_half_angle_deg': {n: float(math.degrees(th)) for n, th in zip(cones.names,
                                                                            cones.theta)},
        'min_cone_margin_deg': float((angles - np.degrees(cones.theta)).min()) if len(cones)
        else None,
        'final_attitude_error_deg': float(err[-1]),
        'loop_period': _diag_stats(diags, 'loop_period'),
        'step_compute': _diag_stats(diags, 'tick_to_command'),
        'pose_to_command_latency': _diag_stats(diags, 'pose_to_command_latency'),
        'commands_seen_by_subscriber': {'count': int(len(cmd_times)),
                                        'rate_hz': float(1e3 / gaps.mean()),
                                        'gap_std_ms': float(gaps.std()),
                                        'gap_max_ms': float(gaps.max())},
        'commands_zero_after_disarm': bool(after_disarm is not None and not any(after_disarm)),
        'node_exit_codes': codes,
        'record': bag_path,
        'through': 'virtual ESC bus' if esc else 'motor_commands',
    }
    with open(os.path.join(out, 'sil_summary.json'), 'w') as f:
        json.dump(summary, f, indent=2)
        f.write('\n')
    plots.sil_figure(out, t, angles, cones, err, psi, cmd_times - t_arm, commands)
    return summary


def main(argv=None):
    parser = argparse.ArgumentParser(prog='demo', description=__doc__.split('\n\n')[0])
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
    s = fly(params_file, args.out, args.duration, mavlink=args.mavlink,
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
          % (sub['rate_hz'], sub['gap_std_ms'], sub['gap_max_ms']))
    print('  commands after disarm  %s%s' % ('all zero' if s['commands_zero_after_disarm']
                                            else 'NOT ZERO', ' (at the ESCs)' if args.esc else ''))
    print('  wrote %s/sil_summary.json, %s/sil.png' % (args.out, args.out))
    if s['record']:
        print('  recorded the flight   %s (./run report %s)' % (s['record'], s['record']))
    ok = (s['min_cone_margin_deg'] is None or s['min_cone_margin_deg'] > 0) and \
        s['commands_zero_after_disarm']
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
