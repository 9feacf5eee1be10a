"""What a soak run measures (``geoctl_ros.sil.soak``): failsafes, input ages, command gaps, loop
periods and the closest approach, from the monitor's log; and the table row of a case.
"""
import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.telemetry.diagnostics import WARN, aggregate_ms
from geoctl_ros.params import CONTROLLER, cone_set, load_parameter_file, node_overrides, resolve


def windows(diags, name):
    """(p99 over the windows' p99, max) of a windowed figure of the controller's diagnostics
    (a Figures field), ms.
    """
    w = aggregate_ms(diags, name)
    return (float('nan'), float('nan')) if w is None else (w.p99, w.max)


def cones_of(params_file):
    return cone_set(resolve(CONTROLLER, node_overrides(load_parameter_file(params_file),
                                                       CONTROLLER)))


def command_gaps(times, t0, t1):
    """(p99, max) of the gaps between command receipts within [t0, t1], ms."""
    t = times[(times >= t0) & (times <= t1)]
    if len(t) < 2:
        return float('nan'), float('nan')
    gaps = np.diff(t) * 1e3
    return float(np.percentile(gaps, 99)), float(gaps.max())


def figures(mon, t0, t1, cones, armed=None):
    """The figures of the flight between t0 and t1 (monotonic, as the monitor's log); the closest
    approach from armed (its arming) on when given.
    """
    diags = [d for t, d in mon.log['diagnostics'] if t0 <= t <= t1]
    failed = [d.figures.failsafe for d in diags]
    failsafes = sum(1 for a, b in zip([False] + failed, failed) if b and not a)
    since = t0 if armed is None else armed
    poses = [q for t, (_, q) in mon.log['true_pose'] if since <= t <= t1]
    margins = ([float(np.min(cones.margins_deg(so3.quat_to_rot(q)))) for q in poses]
               if len(cones) else [np.nan])
    last = diags[-1].figures if diags else None
    out = {
        'seconds': t1 - t0,
        'failsafes': failsafes,
        'warn windows': sum(1 for d in diags if d.level == WARN),
        'pose age p99/max [ms]': windows(diags, 'pose_age_at_tick'),
        'imu age p99/max [ms]': windows(diags, 'imu_age_at_tick'),
        'loop period p99/max [ms]': windows(diags, 'loop_period'),
        'pose to command p99/max [ms]': windows(diags, 'pose_to_command_latency'),
        'closest approach [deg]': min(margins) if margins else float('nan'),
        'gaps ridden (pose, imu)': (('-', '-') if last is None else
                                    (last.pose_gaps.ridden, last.imu_gaps.ridden)),
    }
    return out


TABLE_HEAD = ('| case | s | failsafes | pose age p99 / max, ms | imu age p99 / max, ms | '
              'command gap p99 / max, ms | loop period p99 / max, ms | '
              'pose to command p99 / max, ms | min cone margin, deg |\n'
              '|---|---|---|---|---|---|---|---|---|')


def table_row(name, f):
    def pair(p):
        return '%.1f / %.1f' % p
    return '| %s | %.0f | %d | %s | %s | %s | %s | %s | %.1f |' % (
        name, f['seconds'], f['failsafes'], pair(f['pose age p99/max [ms]']),
        pair(f['imu age p99/max [ms]']), pair(f['command gap p99/max [ms]']),
        pair(f['loop period p99/max [ms]']), pair(f['pose to command p99/max [ms]']),
        f['closest approach [deg]'])

