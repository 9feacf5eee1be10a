"""Headless closed loop: ``scenario CONFIG.yaml --out DIR [--duration S]``.

A scenario file is a ROS 2 parameter file with ``/**`` (shared), ``controller:``, ``sim:`` and
optionally ``scenario:`` sections; the parameters are those of ``geoctl_ros.params``. The
controller runs at ``rate_hz`` with a zero-order hold on its moment; the simulator integrates at
``integration_rate_hz`` (an integer multiple). Writes DIR/summary.json, DIR/history.csv (one row
per control step) and PNG plots like the paper's figures (with matplotlib, the extra ``tools``).

``scenario.latency`` delays the measurements: at each control step the controller sees the
simulated state of ``latency`` seconds before (noise added to that state), as a motion-capture
and IMU chain with that delay would deliver it; ``scenario.stalls`` hold samples back for a
while (the controller flies on its last one, older by the stall). ``scenario.tick_jitter`` makes
the control steps late, as a busy machine's timer does: each command is held until the next step
comes.
"""
import argparse
import os
import sys

from geoctl_ros import numpy_rounding_problem, plots
from geoctl_ros.cli.args import positive_seconds
from geoctl_ros.core.law.gains import gain_condition
from geoctl_ros.params import ConfigError, controller_config
from geoctl_ros.records import scenario as scenario_files
from geoctl_ros.sim.scenario import load, run


def _output_problem(out_dir):
    """Why out_dir cannot take the results (a short phrase), or None; creates it."""
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as e:
        return 'cannot be created (%s)' % (e.strerror or e)
    if not os.access(out_dir, os.W_OK):
        return 'is not writable'
    return None


def main(argv=None):
    parser = argparse.ArgumentParser(prog='scenario', description=__doc__.split('\n\n')[0])
    parser.add_argument('config', help='scenario file (ROS 2 parameter YAML)')
    parser.add_argument('--out', required=True, help='output directory')
    parser.add_argument('--duration', type=positive_seconds,
                        help="simulated seconds (default: the file's)")
    parser.add_argument('--no-plots', action='store_true', help='skip the PNG figures')
    args = parser.parse_args(argv)
    try:
        scenario = load(args.config)
    except ConfigError as e:
        if len(e.errors) == 1 and e.errors[0][0] == str(args.config):
            print('scenario: %s: %s' % e.errors[0], file=sys.stderr)      # the file itself
        else:
            print('scenario: %s: %s' % (args.config, e), file=sys.stderr)
        return 2
    problem = _output_problem(args.out)
    if problem:
        print('scenario: --out %s: %s' % (args.out, problem), file=sys.stderr)
        return 2
    check = gain_condition(controller_config(scenario.controller))
    if not check.ok:
        print('warning: ' + check.message(), file=sys.stderr)
    rounding = numpy_rounding_problem()       # (a NPY_DISABLE_CPU_FEATURES set otherwise)
    if rounding:
        print('warning: ' + rounding, file=sys.stderr)
    result = run(scenario, args.duration)
    try:
        scenario_files.write(result, args.out,
                             plots=not args.no_plots and plots.available('scenario'))
    except OSError as e:
        print('scenario: --out %s: %s' % (args.out, e.strerror or e), file=sys.stderr)
        return 2
    s = result.summary
    print('%s: %d steps in %.2f s wall; final attitude error %.3g deg, Psi %.3g, settle %s s; '
          'constraint %s' % (scenario.name, s['control_steps'], s['wall_time_s'],
                             s['final_attitude_error_deg'], s['final_psi'], s['settle_time_s'],
                             'VIOLATED' if s['constraint_violated'] else 'kept'))
    for n, a in s['min_cone_angle_deg'].items():
        print('  cone %-12s min angle %7.2f deg (half-angle %.1f)' % (
            n, a, s['cone_half_angle_deg'][n]))
    print('  wrote %s' % args.out)
    return 0


if __name__ == '__main__':
    sys.exit(main())
