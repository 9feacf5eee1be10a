"""The controller's diagnostics as typed values, and the one table of their keys.

``ControlLoop.status`` reports a :class:`Status` (level, message and typed :class:`Figures`); the
controller node adds its timing windows and publishes ``to_values(figures)`` as the key/values of
its DiagnosticStatus; whoever reads /diagnostics (the MAVLink bridge, the tools, the tests) gets
the figures back with ``from_values``. A key, its format and its parsing are written here only:
renaming a key changes this file and nothing else.

ROS-free: the nodes turn a DiagnosticStatus message into (level, message, pairs) and back.
"""
from dataclasses import dataclass, fields, replace
import math
import re
from typing import NamedTuple, Optional

import numpy as np

NAME = 'geoctl_ros: controller'     # the controller's DiagnosticStatus name
# Diagnostics levels (the values of diagnostic_msgs/DiagnosticStatus).
OK, WARN, ERROR = 0, 1, 2
FAILSAFE = 'failsafe'          # how the state of a vehicle that failed safe begins


def state_kind(figures):
    """The kind of the state a report's figures show, for a table of time in each state:
    'failsafe' for any failsafe (the typed flag), else the state's words up to their first colon
    ('armed', 'disarmed at start-up', ...).
    """
    return FAILSAFE if figures.failsafe else figures.state.split(':')[0]


def failsafe(why):
    """The state (and disarm reason) of a vehicle that failed safe because of why."""
    return '%s: %s' % (FAILSAFE, why)


class Window(NamedTuple):
    """Mean, standard deviation, 99th percentile and maximum of a quantity over one diagnostics
    window, in seconds (shown in milliseconds).
    """

    mean: float
    std: float
    p99: float
    max: float


def window(samples):
    """The Window of an array of samples (seconds), or None when there are none."""
    if not len(samples):
        return None
    return Window(float(samples.mean()), float(samples.std()), float(np.percentile(samples, 99)),
                  float(samples.max()))


def aggregate(windows):
    """Several windows (None ones skipped) as one: mean of the means, RMS of the standard
    deviations, 99th percentile of the windows' p99 and the largest maximum; None when there is
    none.
    """
    rows = np.array([w for w in windows if w is not None], dtype=float)
    if not len(rows):
        return None
    return Window(float(rows[:, 0].mean()), float(np.sqrt((rows[:, 1] ** 2).mean())),
                  float(np.percentile(rows[:, 2], 99)), float(rows[:, 3].max()))


def aggregate_ms(statuses, name):
    """The windows of one Figures field (``loop_period``, ...) over several reports, as one
    (``aggregate``), in milliseconds; None when none has it.
    """
    w = aggregate(getattr(s.figures, name) for s in statuses)
    return None if w is None else Window(*(1e3 * x for x in w))


class Counts(NamedTuple):
    """Samples of an input stream accepted and refused since the start."""

    accepted: int
    refused: int


class Gaps(NamedTuple):
    """Gaps of an input stream ridden through since the start, and the longest (s)."""

    ridden: int        # gaps ridden through
    longest: float


@dataclass(frozen=True)
class Figures:
    """What the controller's diagnostics carry besides level and message.

    The ages are those of the newest accepted sample at the moment of the report (inf before the
    first); the windows and tick counts are of the current diagnostics window. psi, the cone
    margin and the motor commands are None before the first control step; the margin is also None
    when there are no cones.
    """

    armed: bool = False
    failsafe: bool = False         # disarmed by a failsafe (until someone arms it again)
    state: str = ''                # the supervisor's state, in words
    pose_age: float = math.inf
    imu_age: float = math.inf
    pose_counts: Counts = Counts(0, 0)
    imu_counts: Counts = Counts(0, 0)
    pose_age_at_tick: Optional[Window] = None
    imu_age_at_tick: Optional[Window] = None
    pose_gaps: Gaps = Gaps(0, 0.0)
    imu_gaps: Gaps = Gaps(0, 0.0)
    ticks_bridging: int = 0
    ticks: int = 0
    cone_entries: int = 0          # times the sensor entered a cone since arming (latched)
    psi: Optional[float] = None
    min_cone_margin_deg: Optional[float] = None
    motor_commands: Optional[tuple] = None
    # the node's own timing of the window
    loop_period: Optional[Window] = None
    tick_to_command: Optional[Window] = None
    pose_to_command_latency: Optional[Window] = None

    def with_timing(self, loop_period, tick_to_command, pose_to_command_latency):
        return replace(self, loop_period=loop_period, tick_to_command=tick_to_command,
                       pose_to_command_latency=pose_to_command_latency)


@dataclass(frozen=True)
class Status:
    """A diagnostics report: level (OK, WARN or ERROR), one message, and the figures."""

    level: int
    message: str
    figures: Figures


# --- the formats ----------------------------------------------------------------------------
_WINDOW = re.compile(r'mean (\S+) std (\S+) p99 (\S+) max (\S+)$')
_GAPS = re.compile(r'(\d+) \(longest (\S+) s\)$')


def _window_text(w):
    if w is None:
        return 'n/a'
    return 'mean %.3f std %.3f p99 %.3f max %.3f' % tuple(1e3 * x for x in w)


def _window_value(text):
    m = _WINDOW.match(text)
    return None if m is None else Window(*(1e-3 * float(x) for x in m.groups()))


def _counts_value(text):
    accepted, refused = text.split('/')
    return Counts(int(accepted), int(refused))


def _gaps_value(text):
    m = _GAPS.match(text)
    return Gaps(int(m.group(1)), float(m.group(2)))


def _margin_text(margin):
    return 'no cones' if margin is None else '%.3f' % margin


def _margin_value(text):
    return None if text == 'no cones' else float(text)


# field -> (key, to text, from text); the order is the order published. The last four are left
# out of a report when they are None (psi and the commands before the first control step).
KEYS = {
    'armed': ('armed', str, lambda t: t == 'True'),
    'failsafe': ('failsafe', str, lambda t: t == 'True'),
    'state': ('state', str, str),
    'pose_age': ('pose age [s]', '%.4f'.__mod__, float),
    'imu_age': ('imu age [s]', '%.4f'.__mod__, float),
    'pose_counts': ('pose accepted/refused', '%d/%d'.__mod__, _counts_value),
    'imu_counts': ('imu accepted/refused', '%d/%d'.__mod__, _counts_value),
    'pose_age_at_tick': ('pose age at tick [ms]', _window_text, _window_value),
    'imu_age_at_tick': ('imu age at tick [ms]', _window_text, _window_value),
    'pose_gaps': ('pose gaps ridden through', '%d (longest %.3f s)'.__mod__, _gaps_value),
    'imu_gaps': ('imu gaps ridden through', '%d (longest %.3f s)'.__mod__, _gaps_value),
    'ticks_bridging': ('ticks bridging a gap', str, int),
    'ticks': ('ticks', str, int),
    'cone_entries': ('cone entries since arming', str, int),
    'loop_period': ('loop period [ms]', _window_text, _window_value),
    'tick_to_command': ('tick to motor command [ms]', _window_text, _window_value),
    'pose_to_command_latency': ('pose-to-command latency [ms]', _window_text, _window_value),
    'psi': ('Psi', '%.6g'.__mod__, float),
    'min_cone_margin_deg': ('min cone margin [deg]', _margin_text, _margin_value),
    'motor_commands': ('motor commands', lambda c: ' '.join(str(x) for x in c),
                       lambda t: tuple(int(x) for x in t.split())),
}
_AFTER_FIRST_STEP = ('psi', 'min_cone_margin_deg', 'motor_commands')
_BY_KEY = {key: (name, parse) for name, (key, _, parse) in KEYS.items()}
assert set(KEYS) == {f.name for f in fields(Figures)}


def key(name):
    """The published key of a Figures field (for a reader that wants the text itself)."""
    return KEYS[name][0]


def to_values(figures):
    """The figures as (key, text) pairs, in the published order (psi, the cone margin and the
    motor commands from the first control step on).
    """
    pairs = []
    for name, (k, text, _) in KEYS.items():
        if name in _AFTER_FIRST_STEP and figures.psi is None:
            continue
        pairs.append((k, text(getattr(figures, name))))
    return pairs


def from_values(pairs):
    """Figures from (key, text) pairs as published. Keys this version does not know are ignored,
    and a value that does not parse is left at its default, so a reader never fails on a report.
    """
    found = {}
    for k, text in pairs:
        entry = _BY_KEY.get(k)
        if entry is None:
            continue
        name, parse = entry
        try:
            found[name] = parse(text)
        except (ValueError, AttributeError):
            pass
    if 'failsafe' not in found:     # a record from before the key: its state's words say it
        found['failsafe'] = str(found.get('state', '')).startswith(FAILSAFE)
    return Figures(**found)
