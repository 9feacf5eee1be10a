"""What the ESC node decides, without rclpy: the last line of defence between the controller and
the motors.

- At start: zero to every ESC, and each must answer (a write and a telemetry read) within
  ``probe_timeout``, or the start stops naming its rotor and address (unless ``ignore`` has it).
- The watchdog: the ESCs get the latest valid ``motor_commands`` while it is younger than
  ``timeout`` (this process's clock), zero otherwise: before the first command, after a malformed
  one (wrong length, not finite, outside [0, 1]; the previous one dropped too), and when they
  stop: a controller that dies or hangs gets its ESCs zero one timeout later, by itself.
- Each cycle writes every ESC (a failed transfer retried ``retries`` times, counted). At stop: 0.
- The motor test: one rotor, refused while the controller is armed or commands, while another
  runs, or beyond ``test_command_max``; an arming or a non-zero command ends it.
"""
from dataclasses import dataclass
from enum import Enum
import threading
import time
from typing import Any, List, Optional, Tuple

import numpy as np

from geoctl_ros.core.actuation.esc_wire import motor_commands_problem
from geoctl_ros.core.telemetry.stats import WindowStats
from geoctl_ros.esc import protocol
from geoctl_ros.esc.bus import BusError
from geoctl_ros.params.param import MOTOR_TEST_DURATION_MAX


class EscStartError(Exception):
    """An ESC did not answer at start-up (the message names its rotor and address)."""


@dataclass
class Test:
    rotor: int                        # 1-based
    command: float
    until: float


class Output(Enum):
    """What a write cycle sends (``EscDriver.targets``)."""

    COMMANDED = 'commanded'        # the controller's fresh command (zero while it is disarmed)
    TEST = 'test'                  # a motor test
    REFUSED = 'refused'            # zero: the last message was malformed
    NONE_YET = 'none yet'          # zero: no command yet
    STALE = 'stale'                # zero: the command is older than the timeout


class EscDriver:
    """The ESCs of config on bus. ``offer`` (commands) and ``start_test`` may be called from any
    thread; ``start``, ``write``, ``read_next`` and ``stop`` from the one that owns the bus.
    """

    def __init__(self, config, bus, clock=time.monotonic):
        self.config, self.bus, self.clock = config, bus, clock
        n = len(config.addresses)
        self.n = n
        self.missing = set()              # rotor indices (0-based) ignored at start-up
        self.command = np.zeros(n)
        self.command_time = None          # receipt time of the valid command in force
        self.received = None              # receipt time not yet written (for the latency)
        self.refusal = None               # why the last message was refused (None: it was not)
        self.refused = 0
        self.test = None
        self.output = np.zeros(n)         # what the last cycle wrote (normalised)
        self.reason = 'no command yet'    # why it wrote that
        self.telemetry = [None] * n
        self.errors = [dict(nack=0, timeout=0, io=0) for _ in range(n)]
        self.last_ok = [None] * n         # time of each ESC's last successful transfer
        self.latency = WindowStats()      # command received -> its last byte on the bus (s)
        self.armed = False                # the followed controller's state (follow)
        self.session = 0
        self.foreign = 0                  # messages refused as not the controller's
        self.foreign_refusal = None
        self.commanding = False           # the last valid command had a rotor above zero
        self._zero = protocol.encode(np.zeros(n), config.command_max, config.resolution)
        self._next_read = 0
        self._lock = threading.Lock()

    # --- start and stop ----------------------------------------------------------------------
    def start(self) -> None:
        """Zero to every ESC, and a read of each; EscStartError if one does not answer within
        probe_timeout and its rotor is not ignored.
        """
        deadline = self.clock() + self.config.probe_timeout
        pending, why = set(range(self.n)), {}
        while True:
            for i in sorted(pending):
                try:
                    self._transfer(i, self._zero[i])
                    self._read(i)
                    pending.discard(i)
                except (BusError, ValueError) as e:
                    why[i] = str(e)
            if not pending or self.clock() >= deadline:
                break
            time.sleep(0.05)
        fatal = [i for i in sorted(pending) if i + 1 not in self.config.ignore]
        if fatal:
            raise EscStartError('; '.join(
                'the ESC of rotor %d at 0x%02x did not answer (%s)'
                % (i + 1, self.config.addresses[i], why[i]) for i in fatal)
                + '; add the rotor to esc.ignore to run without it')
        self.missing = pending

    def stop(self) -> List[int]:
        """Zero to every ESC (each retried); the addresses that could not be written."""
        failed = []
        for i in range(self.n):
            if i not in self.missing and not self._write(i, self._zero[i],
                                                         max(self.config.retries, 2)):
                failed.append(self.config.addresses[i])
        self.output = np.zeros(self.n)
        self.reason = 'stopped'
        return failed

    # --- commands ----------------------------------------------------------------------------
    def follow(self, armed: bool, session: int) -> None:
        """The armed state of the controller this node follows, and its session number (the
        nonzero number it stamps on its motor_commands; 0: no controller heard). Disarmed, every
        ESC gets zero whatever the commands say.
        """
        with self._lock:
            self.armed, self.session = bool(armed), int(session)
            if not self.armed:
                self.command = np.zeros(self.n)

    def offer(self, data: Any, now: Optional[float] = None,
              session: Optional[int] = None) -> Optional[str]:
        """A motor_commands message arrived (its data, and the session number it carries; None:
        not checked); the refusal reason, or None.

        A message from anything but the followed controller's session (a second publisher, a
        recorded flight played back, a controller that restarted without saying so) is refused,
        counted in ``foreign`` and leaves the controller's commands in force: the flight goes on.
        A message the controller sent while disarmed is taken as zero.
        """
        now = self.clock() if now is None else now
        if session is not None and (session == 0 or session != self.session):
            self.foreign += 1
            self.foreign_refusal = ('not from the controller%s (session %d, expected %s)'
                                    % ('' if self.session else ' (none heard yet)', session,
                                       self.session or 'none'))
            return self.foreign_refusal
        problem = motor_commands_problem(data, self.n)
        with self._lock:
            if problem:
                self.refusal, self.command_time = problem, None
                self.refused += 1
                return problem
            # the controller commands the motors (it armed, whether or not its armed state
            # has reached this node yet): that ends a motor test; its zeros while disarmed do not
            self.commanding = any(v > 0.0 for v in data)
            if self.commanding:
                self.test = None
            self.command = (np.array(data, dtype=float) if self.armed else np.zeros(self.n))
            self.command_time = self.received = now
            self.refusal = None
        return None

    def commands_fresh(self, now: Optional[float] = None) -> bool:
        now = self.clock() if now is None else now
        t = self.command_time
        return t is not None and now - t <= self.config.timeout

    def targets(self, now: Optional[float] = None) -> Tuple[np.ndarray, 'Output', str]:
        """(normalised command per rotor, what it is (an Output), why in words) for the next
        write.
        """
        now = self.clock() if now is None else now
        with self._lock:
            test = self.test
            if test is not None and now >= test.until:
                self.test = test = None
            if test is not None:
                out = np.zeros(self.n)
                out[test.rotor - 1] = test.command
                return out, Output.TEST, 'motor test of rotor %d' % test.rotor
            if self.command_time is None:
                if self.refusal:
                    return np.zeros(self.n), Output.REFUSED, 'refused: ' + self.refusal
                return np.zeros(self.n), Output.NONE_YET, 'no command yet'
            if now - self.command_time > self.config.timeout:
                return np.zeros(self.n), Output.STALE, ('commands stale (older than %g s)'
                                                        % self.config.timeout)
            return self.command, Output.COMMANDED, 'commanded'

    def write(self) -> str:
        """One write cycle: every ESC gets its set point; failed transfers are retried and
        counted. Returns why it wrote what it wrote (in words).
        """
        targets, output, why = self.targets()
        with self._lock:
            received, self.received = self.received, None
        encoded = protocol.encode(targets, self.config.command_max, self.config.resolution)
        for i, data in enumerate(encoded):
            if i not in self.missing:
                self._write(i, data, self.config.retries)
        if received is not None and output is Output.COMMANDED:
            self.latency.add(self.clock() - received)
        self.output, self.reason = targets, why
        return why

    def read_next(self) -> Optional[int]:
        """Read the telemetry of the next ESC (round robin); its index, or None if none."""
        live = [i for i in range(self.n) if i not in self.missing]
        if not live:
            return None
        i = live[self._next_read % len(live)]
        self._next_read += 1
        try:
            self._read(i)
        except (BusError, ValueError):
            pass
        return i

    # --- the motor test ----------------------------------------------------------------------
    def start_test(self, rotor: int, command: float, duration: float, armed: bool,
                   now: Optional[float] = None) -> Optional[str]:
        """Start a motor test; the refusal (a sentence) or None."""
        now = self.clock() if now is None else now
        if armed:
            return 'refused: the controller is armed'
        if self.commands_fresh(now) and self.commanding:
            return 'refused: motor_commands are arriving (a controller commands the motors)'
        if not 1 <= rotor <= self.n:
            return 'refused: there is no rotor %d (1 to %d)' % (rotor, self.n)
        if rotor - 1 in self.missing:
            return 'refused: the ESC of rotor %d is missing (esc.ignore)' % rotor
        if not 0.0 <= command <= self.config.test_command_max:
            return 'refused: command %g is outside [0, %g]' % (command,
                                                                self.config.test_command_max)
        if not 0.0 < duration <= MOTOR_TEST_DURATION_MAX:
            return 'refused: duration %g s is outside (0, %g]' % (duration,
                                                                  MOTOR_TEST_DURATION_MAX)
        with self._lock:
            if self.test is not None and now < self.test.until:
                return 'refused: the test of rotor %d runs for %.1f s more' % (
                    self.test.rotor, self.test.until - now)
            self.test = Test(rotor, command, now + duration)
        return None

    def abort_test(self) -> bool:
        """End a running test (the motors get zero, or the commands, at the next cycle); whether
        one was running.
        """
        with self._lock:
            running, self.test = self.test, None
        return running is not None

    # --- the bus -----------------------------------------------------------------------------
    def _write(self, i, data, retries):
        """Write ESC i, retrying a failed transfer up to retries times; whether it went through."""
        for _ in range(1 + retries):
            try:
                self._transfer(i, data)
                return True
            except BusError:
                continue
        return False

    def _transfer(self, i, data):
        try:
            self.bus.write(self.config.addresses[i], data)
        except BusError as e:
            self.errors[i][e.kind] += 1
            raise
        self.last_ok[i] = self.clock()

    def _read(self, i):
        try:
            data = self.bus.read(self.config.addresses[i], protocol.TELEMETRY_BYTES)
        except BusError as e:
            self.errors[i][e.kind] += 1
            raise
        self.last_ok[i] = self.clock()
        self.telemetry[i] = protocol.parse(data)
