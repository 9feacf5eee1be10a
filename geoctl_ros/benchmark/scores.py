"""The benchmark's figures: per run from a flight, and per law over a set of runs.

A run's figures (``run_scores``): whether the sensor entered a cone, the closest approach (after
every integration step), the time from which the attitude error stays under 5 deg, the final error,
the control effort (the integral of the law's |u|), the peak measured rate and the time the
allocation was saturated. A law's row over a set of runs (``law_row``): the violations, the closest
approach (its minimum, and its 1st percentile over the runs; over one run, over its control
steps), and the medians of the rest, with the step's time.
"""
import math
from typing import Dict, List, Optional, Sequence

import numpy as np

from geoctl_ros.campaign.study import percentile
from geoctl_ros.sim.closed_loop import SETTLE_WITHIN_S, SETTLED_DEG, Flight

# a run's figures (the campaign's runs.csv's names)
RUN_COLUMNS = ('violated', 'closest_deg', 'settle_s', 'final_error_deg', 'effort_Nms', 'max_rate',
               'saturated_s')

# a law's row: (key, heading, format)
ROW = (
    ('law', 'law', '%s'),
    ('runs', 'runs', '%d'),
    ('violations', 'violations', '%d'),
    ('closest_min_deg', 'closest min [deg]', '%+.2f'),
    ('closest_p1_deg', 'closest p1 [deg]', '%+.2f'),
    ('settled', 'settled (< %g deg)' % SETTLED_DEG, '%d'),
    ('settled_in_time', 'settled within %g s' % SETTLE_WITHIN_S, '%d'),
    ('settle_s', 'time to %g deg, median [s]' % SETTLED_DEG, '%.2f'),
    ('settle_p95_s', 'time to %g deg, p95 [s]' % SETTLED_DEG, '%.2f'),
    ('final_error_deg', 'final error, median [deg]', '%.2f'),
    ('effort_Nms', 'effort, median [N m s]', '%.3f'),
    ('max_rate', 'peak rate, median [rad/s]', '%.2f'),
    ('saturated_s', 'saturated, median [s]', '%.2f'),
    ('step_p50_us', 'step p50 [us]', '%.0f'),
    ('step_p99_us', 'step p99 [us]', '%.0f'),
)


def run_scores(flight: Flight) -> Dict[str, np.ndarray]:
    """Each run's figures (RUN_COLUMNS: arrays, one entry per run) of a flight."""
    return {
        'violated': flight.violated,
        'closest_deg': flight.min_margin_deg.min(axis=-1),
        'settle_s': flight.settle_s,
        'final_error_deg': flight.final_error_deg,
        'effort_Nms': flight.effort,
        'max_rate': flight.max_rate,
        'saturated_s': flight.saturated_s,
    }


def _median(x: np.ndarray) -> float:
    return float(np.median(x)) if len(x) else math.nan


def law_row(law: str, columns: Dict[str, np.ndarray], step_us: Optional[Sequence[float]] = None,
            margins: Optional[np.ndarray] = None) -> dict:
    """A law's row (ROW's keys) over its runs (columns: RUN_COLUMNS' arrays). The closest
    approach's p1 is over the runs, or with margins (one run's margin at each control step) over
    those. The time to 5 deg's median and p95 are over every run, one that never settled counting
    as infinitely late ('-' when that is where the percentile falls).
    step_us: the law's step times, microseconds.
    """
    closest = np.asarray(columns['closest_deg'], dtype=float)
    settle = np.asarray(columns['settle_s'], dtype=float)
    settled = settle[~np.isnan(settle)]
    late = np.where(np.isnan(settle), np.inf, settle)
    p1_of = closest if margins is None else np.asarray(margins, dtype=float)
    steps = np.asarray(step_us if step_us is not None else [], dtype=float)
    return {
        'law': law, 'runs': len(closest),
        'violations': int(np.sum(columns['violated'])),
        'closest_min_deg': float(closest.min()) if len(closest) else math.nan,
        'closest_p1_deg': percentile(p1_of, 1),
        'settled': len(settled),
        'settled_in_time': int(np.sum(settled <= SETTLE_WITHIN_S)),
        'settle_s': _median(late),
        'settle_p95_s': float(np.percentile(late, 95)) if len(late) else math.nan,
        'final_error_deg': _median(columns['final_error_deg']),
        'effort_Nms': _median(columns['effort_Nms']),
        'max_rate': _median(columns['max_rate']),
        'saturated_s': _median(columns['saturated_s']),
        'step_p50_us': percentile(steps, 50), 'step_p99_us': percentile(steps, 99),
    }


def markdown(rows: List[dict]) -> List[str]:
    """The rows as a Markdown table ('-' for a figure that is not a number)."""
    lines = ['| %s |' % ' | '.join(h for _, h, _ in ROW),
             '|%s|' % '|'.join('---' for _ in ROW)]
    for row in rows:
        cells = []
        for key, _, fmt in ROW:
            value = row[key]
            nan = isinstance(value, float) and not math.isfinite(value)
            cells.append('-' if nan else fmt % value)
        lines.append('| %s |' % ' | '.join(cells))
    return lines


def csv_lines(rows: List[dict], first: Sequence[str] = ()) -> List[str]:
    """The rows as CSV (a header, then one line per row; floats exact, NaN as 'nan'); first: the
    names of leading columns the rows also hold (the case's name).
    """
    keys = list(first) + [k for k, _, _ in ROW]
    return [','.join(keys)] + [','.join(repr(r[k]) if isinstance(r[k], float) else str(r[k])
                                        for k in keys) for r in rows]
