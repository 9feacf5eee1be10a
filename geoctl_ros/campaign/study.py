"""A campaign's figures, and gain studies: ``campaign --grid k_R=0.3,0.4,0.5 --grid alpha=4,8``.

A grid is the product of the values given per controller parameter: each gain set is the testbed's
controller with those values over it, and every gain set flies the same manoeuvres (the runs of
the campaign's seed). A gain set the controller would refuse (the schema's checks, and the
cross-checks of ``controller_setup``: a set point or scheduled one its barrier cannot hold, ...)
is refused before anything flies, with the reason.

Every gain set flies every run: a goal that a gain set's controller would refuse (its barrier
cannot hold ``unmodelled_moment_max`` there) is flown with that check off and counted as refused.

Per gain set: violations, the closest approach's 1st percentile, the share of runs that converge
(attitude error below CONVERGED_DEG, 5 deg, at the end), the median settle time (from when the
error stays below it; a run that has not settled counts as never), and the mean time with the
allocation saturated. The non-dominated gain sets (no other set with no more violations has both
more margin and an earlier settle time) are written out as parameter files the controller
accepts.
"""
import itertools
import math
import os

import numpy as np
import yaml

from geoctl_ros.campaign.manoeuvres import LATENCY_MS_MAX
from geoctl_ros.params import (
    BY_NAME,
    CONTROLLER,
    ConfigError,
    controller_setup,
    node_overrides,
    resolve,
    write_parameter_file,
)
from geoctl_ros.plots import campaign as campaign_plots
from geoctl_ros.sim.closed_loop import SETTLE_WITHIN_S
from geoctl_ros.sim.closed_loop import SETTLED_DEG as CONVERGED_DEG

# what a gain set may not change: what each run draws for itself
# the summary's bands of measurement latency (ms, inclusive): thirds of the campaign's draw
_THIRD = (LATENCY_MS_MAX + 1) // 3
LATENCY_BANDS_MS = ((0, _THIRD - 1), (_THIRD, 2 * _THIRD - 1), (2 * _THIRD, LATENCY_MS_MAX))
PER_RUN = ('setpoint', 'setpoint_schedule.times', 'setpoint_schedule.quaternions', 'cones.names')


def parse_grid(specs):
    """['k_R=0.3,0.4', 'alpha=8'] -> [{'k_R': 0.3, 'alpha': 8}, ...] (the product, in order).
    ConfigError for a parameter that is not the controller's, or that each run sets itself.
    """
    axes, errors = [], []
    for spec in specs:
        name, sep, values = spec.partition('=')
        name = name.strip()
        p = BY_NAME.get(name)
        if not sep or not values.strip():
            errors.append((spec, 'expected NAME=VALUE[,VALUE...]'))
        elif p is None or CONTROLLER not in p.nodes:
            errors.append((name, 'not a controller parameter'))
        elif name in PER_RUN or name.startswith('cones.'):
            errors.append((name, 'each run of a campaign sets it'))
        elif name in (a for a, _ in axes):
            errors.append((name, 'given twice'))
        else:
            parsed = [yaml.safe_load(v) for v in values.split(',')]
            if p.type == 'double':      # alpha=4 on a command line means 4.0
                parsed = [float(v) if type(v) is int else v for v in parsed]
            axes.append((name, parsed))
    if errors:
        raise ConfigError(errors)
    names = [a for a, _ in axes]
    return [dict(zip(names, combo)) for combo in itertools.product(*(v for _, v in axes))]


def label(gains):
    return ' '.join('%s=%s' % kv for kv in gains.items()) or "the testbed's gains"


def check_gain_sets(base, gain_sets):
    """ConfigError naming every gain set that the controller would refuse on this testbed, with
    the reason (resolve's checks, then controller_setup's).
    """
    errors = []
    for k, gains in enumerate(gain_sets, 1):
        try:
            controller_setup(resolve(CONTROLLER, dict(node_overrides(base, CONTROLLER), **gains)))
        except ConfigError as e:
            errors.append(('gain set %d (%s)' % (k, label(gains)), str(e)))
    if errors:
        raise ConfigError(errors)


def parameter_file(base, gains):
    """The testbed's parameter file (sections) with the gains put over its controller's."""
    out = {node: dict(flat) for node, flat in base.items()}
    out.setdefault('controller', {}).update(gains)
    return out


# --- figures ------------------------------------------------------------------------------------

def percentile(x, q):
    """The q-th percentile of x, NaN for no samples."""
    return float(np.percentile(x, q)) if len(x) else math.nan


def set_figures(columns):
    """Per-gain-set figures (a dict) of a campaign's columns (arrays, one entry per run)."""
    settle = np.where(np.isnan(columns['settle_s']), np.inf, columns['settle_s'])
    return {
        'runs': len(settle),
        'violations': int(np.sum(columns['violated'])),
        'closest_p1_deg': percentile(columns['closest_deg'], 1),
        'converged_share': float(np.mean(columns['converged'])) if len(settle) else math.nan,
        'settle_median_s': float(np.median(settle)) if len(settle) else math.nan,
        'saturated_mean_s': float(np.mean(columns['saturated_s'])) if len(settle) else math.nan,
        'goals_refused': int(np.sum(columns['goal_refused'])),
    }


def non_dominated(figures):
    """Indices of the gain sets on the front: among those with the fewest violations, the ones no
    other beats in both closest approach (p1, larger) and settle time (median, smaller).
    """
    fewest = min(f['violations'] for f in figures)
    pool = [k for k, f in enumerate(figures) if f['violations'] == fewest]
    front = []
    for k in pool:
        a = figures[k]
        if not any(figures[j]['closest_p1_deg'] >= a['closest_p1_deg']
                   and figures[j]['settle_median_s'] <= a['settle_median_s']
                   and (figures[j]['closest_p1_deg'], figures[j]['settle_median_s'])
                   != (a['closest_p1_deg'], a['settle_median_s'])
                   for j in pool):
            front.append(k)
    return front


def _seconds(x):
    return '%.2f' % x if np.isfinite(x) else 'not settled'


def summary_table(columns):
    """The campaign's figures over all its runs (name -> value)."""
    margins = columns['closest_deg']
    sat = columns['saturated_s']
    final = columns['final_error_deg']
    settled = columns['settle_s'][~np.isnan(columns['settle_s'])]
    late = np.where(np.isnan(columns['settle_s']), np.inf, columns['settle_s'])
    table = {
        'runs': len(margins),
        'violations': int(np.sum(columns['violated'])),
        'converged (error < %g deg at the end)' % CONVERGED_DEG: int(np.sum(columns['converged'])),
        'settled (error < %g deg to the end): runs, median time [s]' % CONVERGED_DEG:
            '%d, %s' % (len(settled), '%.1f' % np.median(settled) if len(settled) else '-'),
        'settled within %g s: share; time to settle median / p95 over all runs [s]' % (
            SETTLE_WITHIN_S): '%.1f %%; %s / %s' % (
            100.0 * np.mean(late <= SETTLE_WITHIN_S), _seconds(np.median(late)),
            _seconds(np.percentile(late, 95))),
        'final attitude error median / p95 [deg]': '%.1f / %.1f' % (
            np.median(final), np.percentile(final, 95)),
        'closest approach min / p1 / p5 / median [deg]': '%.2f / %.2f / %.2f / %.2f' % (
            margins.min(), np.percentile(margins, 1), np.percentile(margins, 5),
            np.median(margins)),
        'runs with the allocation saturated': int(np.sum(sat > 0)),
        'saturated time p99 / max [s]': '%.2f / %.2f' % (np.percentile(sat, 99), sat.max()),
    }
    takeover = columns.get('takeover_deg')
    if takeover is not None and np.any(takeover < 0.0):
        refused = takeover < 0.0
        table['armings refused (the take-over check: its predicted closest approach below 0); '
              'violations among the armings accepted'] = '%d (predicted %.2f deg at worst); %d' % (
            int(refused.sum()), float(takeover.min()),
            int(np.sum(columns['violated'] & ~refused)))
    bands = []
    for band in LATENCY_BANDS_MS:
        picked = margins[(columns['latency_ms'] >= band[0]) & (columns['latency_ms'] <= band[1])]
        bands.append('%.2f' % picked.min() if len(picked) else '-')
    table['worst closest approach by latency %s ms [deg]' % ' / '.join(
        '%d-%d' % band for band in LATENCY_BANDS_MS)] = ' / '.join(bands)
    return table


def write_study(columns, base, gain_sets, out_dir, best):
    """gain_sets.csv, gain_study.png and best/gain_set_K.yaml (the non-dominated sets, at most
    `best`, by closest approach); the summary's lines.
    """
    figures = []
    for k in range(1, len(gain_sets) + 1):
        mine = columns['gain_set'] == k
        figures.append(set_figures({c: v[mine] for c, v in columns.items()}))
    front = non_dominated(figures)
    keys = list(figures[0])
    names = list(dict.fromkeys(n for g in gain_sets for n in g))
    with open(os.path.join(out_dir, 'gain_sets.csv'), 'w') as f:
        f.write(','.join(['gain_set'] + names + keys + ['non_dominated']) + '\n')
        for k, (gains, fig) in enumerate(zip(gain_sets, figures), 1):
            f.write(','.join([str(k)] + [repr(gains.get(n)) for n in names]
                             + [repr(fig[c]) for c in keys] + [str(k - 1 in front)]) + '\n')
    campaign_plots.gain_study_figure(figures, [label(g) for g in gain_sets], front,
                            os.path.join(out_dir, 'gain_study.png'))
    os.makedirs(os.path.join(out_dir, 'best'), exist_ok=True)
    chosen = sorted(front, key=lambda k: -figures[k]['closest_p1_deg'])[:best]
    for k in chosen:
        write_parameter_file(parameter_file(base, gain_sets[k]),
                             os.path.join(out_dir, 'best', 'gain_set_%d.yaml' % (k + 1)),
                             'gain set %d of a gain study (%s): written by `campaign --grid`'
                             % (k + 1, label(gain_sets[k])))
    lines = ['| gain set | runs | violations | closest p1 [deg] | converged | settle median [s] '
             '| saturated mean [s] | goals it refuses |', '|---|---|---|---|---|---|---|---|']
    for k, (gains, fig) in enumerate(zip(gain_sets, figures)):
        lines.append('| %d: %s%s | %d | %d | %.2f | %.0f %% | %s | %.3f | %d |' % (
            k + 1, label(gains), ' (front)' if k in front else '', fig['runs'],
            fig['violations'], fig['closest_p1_deg'], 100 * fig['converged_share'],
            '%.1f' % fig['settle_median_s'] if math.isfinite(fig['settle_median_s'])
            else 'not settled', fig['saturated_mean_s'], fig['goals_refused']))
    lines += ['', 'best gain sets written: ' + ', '.join(
        'best/gain_set_%d.yaml' % (k + 1) for k in chosen)]
    return lines
