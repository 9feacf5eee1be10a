"""The main job (``./run demo``): every shipped scenario through the headless runner.

Writes each run's summary.json, history.csv and figures to OUT/<scenario>/ (default ./out) and
prints the table of results that the README shows.
"""
import argparse
import glob
import os
import sys

from geoctl_ros import scenario

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TABLE_HEAD = ('| scenario | min angle to each cone (half-angle), deg | final attitude error, deg '
              '| final Psi | settle time (Psi < 1e-3), s | final Delta_bar | wall time, s |\n'
              '|---|---|---|---|---|---|---|')


def table_row(summary):
    """One README table row of a run's summary."""
    cones = ', '.join('%s %.1f (%g)' % (n, a, summary['cone_half_angle_deg'][n])
                      for n, a in summary['min_cone_angle_deg'].items()) or '-'
    settle = '-' if summary['settle_time_s'] is None else '%.1f' % summary['settle_time_s']
    dbar = '[%s]' % ', '.join('%.3f' % v for v in summary['final_disturbance_estimate'])
    return '| `%s` | %s | %.2g | %.2g | %s | %s | %.1f |' % (
        summary['scenario'], cones, summary['final_attitude_error_deg'], summary['final_psi'],
        settle, dbar, summary['wall_time_s'])


def scenario_files():
    """The shipped scenario files, from the source tree or the installed share directory."""
    here = os.path.join(ROOT, 'config', 'scenarios')
    if not os.path.isdir(here):
        from ament_index_python.packages import get_package_share_directory
        here = os.path.join(get_package_share_directory('geoctl_ros'), 'config', 'scenarios')
    return sorted(glob.glob(os.path.join(here, '*.yaml')))


def main(argv=None):
    parser = argparse.ArgumentParser(prog='demo', description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', default='out', help='output folder (default: ./out)')
    args = parser.parse_args(argv)
    rows = []
    for path in scenario_files():
        name = os.path.splitext(os.path.basename(path))[0]
        result = scenario.run(scenario.load(path))
        scenario.write(result, os.path.join(args.out, name))
        rows.append(table_row(result.summary))
        print('%-34s done (%s)' % (name, os.path.join(args.out, name)), file=sys.stderr)
    print(TABLE_HEAD)
    print('\n'.join(rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())
