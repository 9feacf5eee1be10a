"""Input checks and the arming supervisor: the controller node's safety logic, ROS-free.

Rules (docs/safety-behaviour.md says the same to users):

- A measurement is refused, with its reason, if it is not finite, if its quaternion is not a unit
  quaternion (|q| off by more than 1e-3; within that it is normalised), if its angular velocity is
  beyond ``max_angular_velocity``, or if its stamp is not newer than the last accepted one.
- A stream is fresh while its last accepted sample arrived (receipt time, on the node's clock)
  less than its timeout ago. Receipt time is used because the motion-capture host's clock need not
  agree with the onboard one; stamps are used only for ordering.
- A stale stream is not yet lost: up to its ride-through limit (``pose_ride_through``,
  ``imu_ride_through``) the control loop bridges the gap (``geoctl_ros.core.supervisor.loop``:
  attitude propagated with the gyro, rates from successive poses) and reports it. Past the limit
  the stream is lost.
- Arming is refused unless pose and angular velocity are both fresh. While armed, if either is
  lost the supervisor disarms (failsafe) and says why. Motor commands are zero unless armed.

The values exchanged with the nodes that drive the motors (ArmedState, EscHealth, EscStatus and
the motor_commands check) are ``geoctl_ros.core.actuation.esc_wire``'s, which esc/ imports
without the supervisor; ``esc_problem`` here is the controller's judgement of the ESC node's
report.
"""
from dataclasses import dataclass
import math
import secrets
from typing import Iterable, List, Optional, Sequence, Tuple, cast

import numpy as np

from geoctl_ros.core.actuation.esc_wire import EscHealth as EscHealth
from geoctl_ros.core.actuation.esc_wire import EscStatus as EscStatus
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.quaternions import quaternion_problem
from geoctl_ros.core.geometry.so3 import FloatArray, Vector
from geoctl_ros.core.telemetry.diagnostics import StampTrust, failsafe
from geoctl_ros.core.telemetry.stats import WindowStats

SPECIFIC_FORCE_MAX = 2000.0     # m/s^2: beyond any IMU's range (about 200 g)


def attitude_of(q: Vector) -> Tuple[Optional[FloatArray], Optional[str]]:
    """(R, None) for an acceptable attitude quaternion q (x, y, z, w), else (None, why): what
    the bridge and the view take from a pose or a set point.
    """
    problem = quaternion_problem(q)
    return (None, problem) if problem else (so3.quat_to_rot(q), None)


def specific_force_problem(f: Optional[Vector]) -> Optional[str]:
    """Why an IMU's specific force cannot be used, or None (None: the IMU gave none)."""
    if f is None:
        return None
    if len(f) != 3 or not all(math.isfinite(v) for v in f):
        return 'specific force must be 3 finite values, got %r' % (list(f)[:6],)
    largest = max(abs(v) for v in f)
    if largest > SPECIFIC_FORCE_MAX:
        return 'specific force %.3g m/s^2 beyond %g' % (largest, SPECIFIC_FORCE_MAX)
    return None


def angular_velocity_problem(w: Vector, limit: float) -> Optional[str]:
    """Why w is not an acceptable angular velocity, or None."""
    if not all(math.isfinite(v) for v in w):
        return 'angular velocity is not finite'
    n = math.sqrt(sum(v * v for v in w))
    if n > limit:
        return 'angular velocity %.1f rad/s is above max_angular_velocity %.1f' % (n, limit)
    return None


STAMP_AHEAD_TOLERANCE = 0.01   # s: a stamp this far ahead of this computer's clock is taken as now
STAMP_AGE_MAX = 0.5            # s: a stamp older than this at receipt is not believed for the age
REANCHOR_AFTER = 3             # consecutive good samples refused as not newer: the clock stepped


class Stream:
    """Freshness, ordering, ages and refusal counts of one input stream.

    timeout: older than this (by receipt), the stream is stale. ride_through: older than this, it
    is lost (0: lost as soon as it is stale).

    Ordering: a sample whose stamp is not newer than the last accepted one is refused, unless
    REANCHOR_AFTER such samples in a row were otherwise good: the stream's clock stepped back (or
    one sample's stamp was an outlier ahead), and the stream re-anchors on the new stamps rather
    than staying refused until a restart.

    Age: each sample's delay from capture to receipt is its stamp against this computer's clock
    (``delay``, when the caller gives it, ``age_from_stamps`` is on and it lies within
    -STAMP_AHEAD_TOLERANCE..STAMP_AGE_MAX: the stamp is trusted), else the configured
    ``fallback_delay`` (measurement_delay; a stamp outside those bounds is from a clock that is
    not this one's, counted in ``untrusted_stamps``). At a tick the input's age is that delay plus
    the time since receipt. Over each diagnostics window the stream keeps every accepted sample's
    delay by its stamp, trusted or not (``delays``), and how many stamps were trusted and not
    (``stamps``): what /diagnostics shows of the chain's latency and of the clocks.
    """

    def __init__(self, name: str, timeout: float, ride_through: float = 0.0,
                 fallback_delay: float = 0.0, age_from_stamps: bool = True) -> None:
        self.name = name
        self.timeout = timeout
        self.ride_through = ride_through
        self.fallback_delay = fallback_delay
        self.age_from_stamps = age_from_stamps
        self.last_stamp = -math.inf
        self.last_receipt: Optional[float] = None
        self.last_delay = 0.0           # capture to receipt of the last accepted sample (s)
        self.accepted = 0
        self.refused = 0
        self.untrusted_stamps = 0       # samples whose stamp did not give their delay
        self.delays = WindowStats()     # this window: every accepted sample's delay by its stamp
        self._trusted = self._untrusted = 0     # this window: stamps trusted for the age, not
        self.reanchored = 0             # times the stream's clock was found to have stepped
        self._not_newer = 0             # good samples refused as not newer, in a row
        self.recent_refusals: List[str] = []   # distinct reasons since take_refusals(), at most 5

    def offer(self, stamp: float, receipt: float, problem: Optional[str] = None,
              delay: Optional[float] = None) -> Optional[str]:
        """Record a sample; returns None if accepted, else the reason it was refused. delay: its
        stamp against this computer's clock at receipt (s), or None if unknown.
        """
        if problem is None and stamp <= self.last_stamp:
            self._not_newer += 1
            if self._not_newer < REANCHOR_AFTER:
                problem = 'stamp %.6f is not newer than the last accepted %.6f' % (
                    stamp, self.last_stamp)
            else:
                self.reanchored += 1
        if problem is not None:
            self.refused += 1
            if problem not in self.recent_refusals and len(self.recent_refusals) < 5:
                self.recent_refusals.append(problem)
            return problem
        self._not_newer = 0
        self.last_stamp = stamp
        self.last_receipt = receipt
        if delay is not None:
            self.delays.add(delay)
        if (self.age_from_stamps and delay is not None
                and -STAMP_AHEAD_TOLERANCE <= delay <= STAMP_AGE_MAX):
            self.last_delay = max(delay, 0.0)
            self._trusted += 1
        else:
            self.last_delay = self.fallback_delay
            if self.age_from_stamps and delay is not None:
                self.untrusted_stamps += 1
                self._untrusted += 1
        self.accepted += 1
        return None

    def stamps(self) -> StampTrust:
        """This window's stamps: used for the age or not, how many trusted and how many not."""
        return StampTrust(self.age_from_stamps, self._trusted, self._untrusted)

    def stamp_note(self) -> Optional[str]:
        """A sentence when stamps of this window were not trusted for the age, else None."""
        if not self._untrusted:
            return None
        d = self.delays.samples()
        return ('%s stamps not trusted: %d of %d this window are more than %.0f ms ahead of this '
                "computer's clock or more than %.0f ms behind it (capture to receipt %.1f to "
                '%.1f ms): each counted measurement_delay %.1f ms old (synchronise the clocks, '
                'docs/safety.md, "Delay")' % (
                    self.name, self._untrusted, self._trusted + self._untrusted,
                    1e3 * STAMP_AHEAD_TOLERANCE, 1e3 * STAMP_AGE_MAX, 1e3 * float(d.min()),
                    1e3 * float(d.max()), 1e3 * self.fallback_delay))

    def end_window(self) -> None:
        """Start a new diagnostics window of delays and stamp counts."""
        self.delays.reset()
        self._trusted = self._untrusted = 0

    def capture_age(self, now: float) -> float:
        """How old the last accepted sample's content is at now (s): its delay from capture to
        receipt plus the time since receipt.
        """
        return self.last_delay + max(now - cast(float, self.last_receipt), 0.0)

    def take_refusals(self) -> List[str]:
        """The distinct refusal reasons since the last call (and forget them)."""
        out, self.recent_refusals = self.recent_refusals, []
        return out

    def age(self, now: float) -> float:
        return math.inf if self.last_receipt is None else now - self.last_receipt

    def fresh(self, now: float) -> bool:
        return self.age(now) < self.timeout

    @property
    def limit(self) -> float:
        """Age at which the stream is lost: the ride-through limit, or the timeout without one."""
        return max(self.ride_through, self.timeout)

    def staleness(self, now: float) -> Optional[str]:
        """A sentence if the stream is stale, else None."""
        if self.last_receipt is None:
            return 'no %s received yet' % self.name
        if not self.fresh(now):
            return '%s stale (last %.3f s ago, timeout %.3f s)' % (self.name, self.age(now),
                                                                 self.timeout)
        return None

    def loss(self, now: float) -> Optional[str]:
        """A sentence if the stream is lost (older than its limit, or never received), else
        None.
        """
        if self.last_receipt is None:
            return 'no %s received yet' % self.name
        if self.age(now) >= self.limit:
            return '%s lost (last %.3f s ago, %s %.3f s)' % (
                self.name, self.age(now),
                'ride-through limit' if self.ride_through > self.timeout else 'timeout',
                self.limit)
        return None


ESC_SILENT_S = 1.5       # s without a report from an ESC node that has reported: it is gone


def esc_problem(status: Optional[EscStatus], now: float, command_max: int) -> Optional[str]:
    """Why the ESCs cannot carry a flight (a sentence), or None: none reported (no ESC node:
    nothing to judge), the node silent for ESC_SILENT_S, a command scale that is not the
    controller's command_max, or an ESC lost or at fault.
    """
    if status is None:
        return None
    if now - status.receipt > ESC_SILENT_S:
        return 'esc_i2c silent for %.1f s' % (now - status.receipt)
    if status.command_max != command_max:
        return ("esc_i2c's motor.command_max %d is not the controller's %d"
                % (status.command_max, command_max))
    bad = ['ESC of rotor %d %s' % (i + 1, h.name.lower()) for i, h in enumerate(status.escs)
           if h in (EscHealth.LOST, EscHealth.FAULT)]
    return '; '.join(bad) or None


def new_session() -> int:
    """A controller's session number: random, nonzero, 32 bits."""
    return secrets.randbelow(2 ** 32 - 1) + 1


@dataclass
class ArmResult:
    ok: bool
    message: str


class Supervisor:
    """Armed/disarmed state with its reasons; decides whether the motors may turn."""

    def __init__(self, streams: Sequence[Stream]) -> None:
        self.streams = streams
        self.armed = False
        self.armed_since: Optional[float] = None
        self.reason = 'disarmed at start-up'
        self.failed = False          # disarmed by a failsafe (reason says why)

    def input_problem(self, now: float) -> Optional[str]:
        """Why the inputs are not fresh enough to arm (the first stale stream), or None."""
        return next(filter(None, (s.staleness(now) for s in self.streams)), None)

    def input_loss(self, now: float) -> Optional[str]:
        """Why the inputs can no longer carry a flight (the first lost stream), or None."""
        return next(filter(None, (s.loss(now) for s in self.streams)), None)

    def arm(self, now: float, extra_problem: Optional[str] = None) -> ArmResult:
        """Try to arm; refused (with the reason) unless every input is fresh."""
        problem = extra_problem or self.input_problem(now)
        if problem:
            return ArmResult(False, 'arming refused: ' + problem)
        if not self.armed:
            self.armed, self.armed_since = True, now
        self.reason, self.failed = 'armed', False
        return ArmResult(True, 'armed')

    def disarm(self, reason: str = 'disarm requested', failed: bool = False) -> ArmResult:
        """Disarm; failed: by a failsafe (reason then reads 'failsafe: why')."""
        self.armed, self.armed_since = False, None
        self.reason, self.failed = reason, failed
        return ArmResult(True, 'disarmed')

    def check(self, now: float) -> bool:
        """Called every control tick: disarm if an input is lost. True if the motors may run."""
        if self.armed:
            problem = self.input_loss(now)
            if problem:
                self.disarm(failsafe(problem), failed=True)
        return self.armed


class SetpointSchedule:
    """Set points at times (s) after arming, held until the next; empty means none."""

    def __init__(self, times: Vector, rotations: Iterable[FloatArray]) -> None:
        self.times = np.asarray(times, dtype=float)
        self.rotations = list(rotations)

    def __len__(self) -> int:
        return len(self.times)

    def index_at(self, t: float) -> int:
        """Index of the set point in force t seconds after arming (-1 before the first)."""
        return int(np.searchsorted(self.times, t, side='right')) - 1

    def due(self, t: float, current: int) -> int:
        """The index of the set point that takes over t seconds after arming, if it is not
        ``current`` (the one in force; -1: none yet), else -1: the one rule the node's loop and
        the closed loop switch by.
        """
        i = self.index_at(t) if len(self.times) else -1
        return i if i != current else -1
