"""A recorded flight as the paper's figures and a summary: ``report BAG [--out DIR]``.

BAG is any rosbag2 bag of this package's topics (MCAP or sqlite3; from ``record`` or from
``ros2 bag record``; one whose writer was killed too). The cones come from the bag (``record``
writes the controller's in it) or from ``--params-file``. The sensor's path and the closest
approach come from the sim's true attitude (``/sim/true_pose``) where the bag has it, otherwise
from the controller's measured one (``/attitude``, in the package's frames whatever the sensors'
conventions), otherwise from ``/pose`` (records from before ``/attitude``).

Writes ``summary.json``, ``summary.md``, ``flight.png`` and ``sensor_path.png`` to DIR (default:
BAG/report) and prints the Markdown summary. Topics the bag lacks are named, and what can be
drawn without them is drawn. What is not a readable bag ends with one line and exit code 2. The
figures need matplotlib (the extra ``tools``): without it one line says they are skipped.
"""
import argparse
import json
import os
import sys

from geoctl_ros import plots
from geoctl_ros.params import ConfigError
from geoctl_ros.records import report


def main(argv=None):
    parser = argparse.ArgumentParser(prog='report', description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', help='a rosbag2 bag folder (MCAP or sqlite3)')
    parser.add_argument('--out', default=None, help='output folder (default: BAG/report)')
    parser.add_argument('--params-file', default=None,
                        help="the controller's parameter file, for the cones (default: the "
                             "ones record stored in the bag)")
    parser.add_argument('--compare', metavar='SCENARIO.yaml', default=None,
                        help="also fly this scenario file headless from the record's attitude "
                             'at arming, through its set points, and lay the two side by side '
                             '(compare.png; the summary gets the headless closest approach)')
    parser.add_argument('--no-plots', action='store_true', help='skip the PNG figures')
    args = parser.parse_args(argv)
    try:
        f = report.load_flight(args.bag, args.params_file)
        out = args.out or os.path.join(args.bag, 'report')
        os.makedirs(out, exist_ok=True)
    except (ValueError, ConfigError, OSError) as e:
        print('report: %s' % str(e).replace('\n', ' '), file=sys.stderr)
        return 2
    s = report.summary(f)
    headless = None
    if args.compare:
        try:
            headless, t_arm = report.fly_headless(f, args.compare)
        except (ValueError, ConfigError, OSError) as e:
            print('report: --compare: %s' % str(e).replace('\n', ' '), file=sys.stderr)
            return 2
        s['headless'] = {'scenario': args.compare, 'armed_at_s': t_arm,
                         'closest_approach_deg': headless.summary['min_cone_angle_deg'],
                         'final_attitude_error_deg':
                             headless.summary['final_attitude_error_deg']}
    text = report.markdown(args.bag, s)
    with open(os.path.join(out, 'summary.json'), 'w') as fh:
        json.dump(s, fh, indent=2)
        fh.write('\n')
    with open(os.path.join(out, 'summary.md'), 'w') as fh:
        fh.write(text)
    if not args.no_plots and plots.available('report'):
        from geoctl_ros.plots import flight as flight_plots  # noqa: PLC0415  (matplotlib)
        flight_plots.flight_figures(f, out)
        if headless is not None:
            flight_plots.compare_figure(f, headless, t_arm, out)
    print(text + 'wrote %s' % out)
    if f.missing:
        print('report: the bag has no %s' % ', '.join(f.missing), file=sys.stderr)
    if f.cones is None:
        print('report: no cones (the bag has none stored: give --params-file)', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())

