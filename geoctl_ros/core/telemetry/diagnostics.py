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
from typing import Dict, Iterable, List, NamedTuple, Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.telemetry.codec import Codec, Key
from geoctl_ros.core.telemetry.scheduling import Scheduling, scheduling_text, scheduling_value

NAME = 'geoctl_ros: controller'     # the controller's DiagnosticStatus name
# Diagnostics levels (the values of diagnostic_msgs/DiagnosticStatus).
OK, WARN, ERROR = 0, 1, 2
FAILSAFE = 'failsafe'          # how the state of a vehicle that failed safe begins


def state_kind(figures: 'Figures') -> str:
    """The kind of the state a report's figures show, for a table of time in each state:
    'failsafe' for any failsafe (the typed flag), else the state's words up to their first colon
    ('armed', 'disarmed at start-up', ...).
    """
    return FAILSAFE if figures.failsafe else figures.state.split(':')[0]


def failsafe(why: str) -> str:
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


def window(samples: FloatArray) -> Optional['Window']:
    """The Window of an array of samples (seconds), or None when there are none."""
    if not len(samples):
        return None
    return Window(float(samples.mean()), float(samples.std()), float(np.percentile(samples, 99)),
                  float(samples.max()))


def aggregate(windows: Iterable[Optional['Window']]) -> Optional['Window']:
    """Several windows (None ones skipped) as one: mean of the means, RMS of the standard
    deviations, 99th percentile of the windows' p99 and the largest maximum; None when there is
    none.
    """
    rows = np.array([w for w in windows if w is not None], dtype=float)
    if not len(rows):
        return None
    return Window(float(rows[:, 0].mean()), float(np.sqrt((rows[:, 1] ** 2).mean())),
                  float(np.percentile(rows[:, 2], 99)), float(rows[:, 3].max()))


def aggregate_ms(statuses: Iterable['Status'], name: str) -> Optional['Window']:
    """The windows of one Figures field (``loop_period``, ...) over several reports, as one
    (``aggregate``), in milliseconds; None when none has it.
    """
    w = aggregate(getattr(s.figures, name) for s in statuses)
    return None if w is None else Window(*(1e3 * x for x in w))


class Counts(NamedTuple):
    """Samples of an input stream accepted and refused since the start."""

    accepted: int
    refused: int


class Unlearnt(NamedTuple):
    """The acceleration the model and its observer did not know at the rate samples (the
    observer's innovation), against the approach brake's bound a_u (rad/s^2): the largest of
    this window, the bound, and the samples past it in this window and since the take-over.
    """

    largest: float
    bound: float
    over: int
    over_since_takeover: int


class StampTrust(NamedTuple):
    """An input's header stamps over one diagnostics window: whether they give its age at all
    (``age_from_stamps``), and how many were trusted for it (within 10 ms ahead and 0.5 s behind
    this computer's clock) and how many were not (counted ``measurement_delay`` old instead).
    """

    used: bool = True
    trusted: int = 0
    untrusted: int = 0


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
    # capture to receipt by the stamps against this computer's clock, this window (every
    # accepted sample's, trusted or not), and whether the stamps were trusted for the ages
    pose_delay: Optional[Window] = None
    imu_delay: Optional[Window] = None
    pose_stamps: StampTrust = StampTrust()
    imu_stamps: StampTrust = StampTrust()
    pose_gaps: Gaps = Gaps(0, 0.0)
    imu_gaps: Gaps = Gaps(0, 0.0)
    ticks_bridging: int = 0
    ticks: int = 0
    cone_entries: int = 0          # times the sensor entered a cone since arming (latched)
    psi: Optional[float] = None
    min_cone_margin_deg: Optional[float] = None
    motor_commands: Optional[Tuple[int, ...]] = None
    unlearnt: Optional['Unlearnt'] = None   # the acceleration the model did not know (armed)
    # the node's own timing of the window
    loop_period: Optional[Window] = None
    tick_to_command: Optional[Window] = None
    pose_to_command_latency: Optional[Window] = None
    scheduling: Optional[Scheduling] = None   # the node's class (None: not a node's report)

    def with_timing(self, loop_period: Optional['Window'], tick_to_command: Optional['Window'],
                    pose_to_command_latency: Optional['Window'],
                    scheduling: Optional[Scheduling] = None) -> 'Figures':
        return replace(self, loop_period=loop_period, tick_to_command=tick_to_command,
                       pose_to_command_latency=pose_to_command_latency, scheduling=scheduling)


@dataclass(frozen=True)
class Status:
    """A diagnostics report: level (OK, WARN or ERROR), one message, and the figures."""

    level: int
    message: str
    figures: Figures


# --- the formats ----------------------------------------------------------------------------
_WINDOW = re.compile(r'mean (\S+) std (\S+) p99 (\S+) max (\S+)$')
_GAPS = re.compile(r'(\d+) \(longest (\S+) s\)$')


def window_text(w: Optional['Window']) -> str:
    if w is None:
        return 'n/a'
    return 'mean %.3f std %.3f p99 %.3f max %.3f' % tuple(1e3 * x for x in w)


def window_value(text: str) -> Optional['Window']:
    m = _WINDOW.match(text)
    return None if m is None else Window(*(1e-3 * float(x) for x in m.groups()))


def _counts_value(text: str) -> 'Counts':
    accepted, refused = text.split('/')
    return Counts(int(accepted), int(refused))


def _gaps_value(text: str) -> 'Gaps':
    m = _GAPS.match(text)
    if m is None:
        raise ValueError(text)
    return Gaps(int(m.group(1)), float(m.group(2)))


_STAMPS = re.compile(r'(?:trusted|not trusted|partly trusted) \((\d+) of (\d+) this window\)')


def _stamps_text(s: 'StampTrust') -> str:
    """``trusted (50 of 50 this window)``, ``not trusted (0 of 50 this window): measurement_delay
    counted``, ``partly trusted (40 of 50 ...): measurement_delay counted for the rest``, ``none
    this window``, ``not used (age_from_stamps false): measurement_delay counted``.
    """
    if not s.used:
        return 'not used (age_from_stamps false): measurement_delay counted'
    n = s.trusted + s.untrusted
    if not n:
        return 'none this window'
    if not s.untrusted:
        return 'trusted (%d of %d this window)' % (s.trusted, n)
    if not s.trusted:
        return 'not trusted (0 of %d this window): measurement_delay counted' % n
    return ('partly trusted (%d of %d this window): measurement_delay counted for the rest'
            % (s.trusted, n))


def _stamps_value(text: str) -> 'StampTrust':
    if text.startswith('not used'):
        return StampTrust(False)
    if text == 'none this window':
        return StampTrust()
    m = _STAMPS.match(text)
    if m is None:
        raise ValueError(text)
    trusted, n = int(m.group(1)), int(m.group(2))
    return StampTrust(True, trusted, n - trusted)


def _margin_text(margin: Optional[float]) -> str:
    return 'no cones' if margin is None else '%.3f' % margin


def _margin_value(text: str) -> Optional[float]:
    return None if text == 'no cones' else float(text)


_UNLEARNT = re.compile(r'max (\S+) of a_u (\S+); (\d+) samples past it \((\d+) since the '
                       r'take-over\)$')


def _unlearnt_text(u: 'Unlearnt') -> str:
    return 'max %.2f of a_u %.2f; %d samples past it (%d since the take-over)' % u


def _unlearnt_value(text: str) -> Optional['Unlearnt']:
    m = _UNLEARNT.match(text)
    return None if m is None else Unlearnt(float(m.group(1)), float(m.group(2)),
                                           int(m.group(3)), int(m.group(4)))


def _unlearnt_absent(figures: 'Figures') -> bool:
    return figures.unlearnt is None


def _after_first_step(figures: 'Figures') -> bool:
    return figures.psi is None


def _bool(text: str) -> bool:
    return text == 'True'


# The controller's keys, in the order published (the one codec: ``core.telemetry.codec``). psi, the
# cone margin and the motor commands are left out before the first control step.
CODEC = Codec(Figures, {
    'armed': Key('armed', parse=_bool),
    'failsafe': Key('failsafe', parse=_bool),
    'state': Key('state'),
    'pose_age': Key('pose age [s]', '%.4f'.__mod__, float),
    'imu_age': Key('imu age [s]', '%.4f'.__mod__, float),
    'pose_counts': Key('pose accepted/refused', '%d/%d'.__mod__, _counts_value),
    'imu_counts': Key('imu accepted/refused', '%d/%d'.__mod__, _counts_value),
    'pose_age_at_tick': Key('pose age at tick [ms]', window_text, window_value),
    'imu_age_at_tick': Key('imu age at tick [ms]', window_text, window_value),
    'pose_delay': Key('pose capture to receipt [ms]', window_text, window_value),
    'imu_delay': Key('imu capture to receipt [ms]', window_text, window_value),
    'pose_stamps': Key('pose stamps', _stamps_text, _stamps_value),
    'imu_stamps': Key('imu stamps', _stamps_text, _stamps_value),
    'pose_gaps': Key('pose gaps ridden through', '%d (longest %.3f s)'.__mod__, _gaps_value),
    'imu_gaps': Key('imu gaps ridden through', '%d (longest %.3f s)'.__mod__, _gaps_value),
    'ticks_bridging': Key('ticks bridging a gap', parse=int),
    'ticks': Key('ticks', parse=int),
    'cone_entries': Key('cone entries since arming', parse=int),
    'loop_period': Key('loop period [ms]', window_text, window_value),
    'tick_to_command': Key('tick to motor command [ms]', window_text, window_value),
    'pose_to_command_latency': Key('pose-to-command latency [ms]', window_text, window_value),
    'psi': Key('Psi', '%.6g'.__mod__, float, _after_first_step),
    'min_cone_margin_deg': Key('min cone margin [deg]', _margin_text, _margin_value,
                               _after_first_step),
    'motor_commands': Key('motor commands', lambda c: ' '.join(str(x) for x in c),
                          lambda t: tuple(int(x) for x in t.split()), _after_first_step),
    'unlearnt': Key('unlearnt acceleration [rad/s^2]', _unlearnt_text, _unlearnt_value,
                    _unlearnt_absent),
    'scheduling': Key('scheduling', scheduling_text, scheduling_value,
                      lambda f: f.scheduling is None),
})
assert set(CODEC.table) == {f.name for f in fields(Figures)}


def key(name: str) -> str:
    """The published key of a Figures field (for a reader that wants the text itself)."""
    return CODEC.key(name)


def to_values(figures: 'Figures') -> List[Tuple[str, str]]:
    """The figures as (key, text) pairs, in the published order."""
    return CODEC.to_values(figures)


def from_values(pairs: Iterable[Tuple[str, str]]) -> 'Figures':
    """Figures from (key, text) pairs as published (``Codec.from_values``; the other keys are
    dropped).
    """
    pairs = list(pairs)
    # (Figures require no key: never None)
    figures, _ = cast(Tuple[Figures, Dict[str, str]], CODEC.from_values(pairs))
    if not any(k == CODEC.key('failsafe') for k, _ in pairs):   # a record from before the key:
        figures = replace(figures, failsafe=figures.state.startswith(FAILSAFE))   # its words
    return figures
