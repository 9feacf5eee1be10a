"""The ESC node's health as typed values, and the one place that spells its diagnostics keys:
``report`` judges a driver's state, ``to_values`` formats its figures for a DiagnosticStatus and
``from_values`` reads them back (as the tests do); the keys are a table of the one codec
(``core.telemetry.codec``).

Levels: ERROR for an ESC that has not answered for ``LOST`` s (or a failed start, a self-test
error, ``esc.temperature_error``); WARN for I2C errors in the last window (retried), an ESC
limiting, ``esc.temperature_warn``, a missing ESC that ``esc.ignore`` lets the node run without, or
commands refused in the window; OK otherwise.
"""
from dataclasses import dataclass
import math
from typing import Iterable, List, NamedTuple, Optional, Tuple, cast

from geoctl_ros.core.actuation.esc_wire import EscHealth
from geoctl_ros.core.telemetry.codec import Codec, Key
from geoctl_ros.core.telemetry.diagnostics import Window, window, window_text, window_value
from geoctl_ros.core.telemetry.scheduling import Scheduling, scheduling_text, scheduling_value
from geoctl_ros.esc import protocol
from geoctl_ros.esc.driver import EscDriver

NAME = 'geoctl_ros: esc_i2c'
LOST = 0.5                        # s without a successful transfer: the ESC is lost



def esc_health(driver: EscDriver, now: float, temperature_error: float) -> Tuple[EscHealth, ...]:
    """Per rotor, the EscHealth of the driver's ESCs at now."""
    out = []
    for i in range(len(driver.config.addresses)):
        ok_time, tel = driver.last_ok[i], driver.telemetry[i]
        if i in driver.missing:
            out.append(EscHealth.IGNORED)
        elif ok_time is not None and now - ok_time > LOST:
            out.append(EscHealth.LOST)
        elif tel is not None and (protocol.state_problem(tel.state)[0] == protocol.ERROR
                                  or tel.temperature >= temperature_error):
            out.append(EscHealth.FAULT)
        else:
            out.append(EscHealth.OK)
    return tuple(out)


@dataclass(frozen=True)
class EscFigures:
    """What the node's diagnostics carry: why it writes what it writes, the set points
    (normalised), the commands refused and I2C errors so far, the command-to-bus latency of the
    window, the motor test, per ESC a line of its own, and the node's scheduling class.
    """

    output: str = ''
    set_points: Tuple[float, ...] = ()
    refused: int = 0
    i2c_errors: int = 0
    latency: Optional[Window] = None
    motor_test: str = ''
    escs: Tuple[str, ...] = ()
    scheduling: Optional[Scheduling] = None


class EscReport(NamedTuple):
    """One diagnostics status of the ESC node: level, message and figures."""

    level: int
    message: str
    figures: EscFigures


# The ESC node's keys, in the order published (the one codec: ``core.telemetry.codec``).
CODEC = Codec(EscFigures, {
    'output': Key('output'),
    'set_points': Key('set points', lambda x: ' '.join('%.4f' % v for v in x),
                      lambda t: tuple(float(v) for v in t.split())),
    'refused': Key('commands refused', parse=int),
    'i2c_errors': Key('i2c errors', parse=int),
    'latency': Key('command to last byte [ms]', window_text, window_value),
    'motor_test': Key('motor test'),
    'escs': Key('esc ', expand=True, numbered=True),
    'scheduling': Key('scheduling', scheduling_text, scheduling_value,
                      lambda f: f.scheduling is None),
})


def _esc_line(address, tel, errors, missing, age):
    if missing:
        return '0x%02x: missing (ignored)' % address
    err = sum(errors.values())
    where = '0x%02x' % address
    if tel is None:
        return '%s: no telemetry, %d errors' % (where, err)
    _, state = protocol.state_problem(tel.state)
    current = 'n/a' if math.isnan(tel.current) else '%.1f A' % tel.current
    lost = '' if age is None or age <= LOST else ', no answer for %.1f s' % age
    return '%s: %s, %s, %.0f C, %d errors%s' % (where, current, state, tel.temperature, err,
                                                lost)


def report(driver: EscDriver, now: float, temperature_warn: float, temperature_error: float,
           errors_before: int = 0, refused_before: int = 0,
           scheduling: Optional[Scheduling] = None) -> EscReport:
    """The EscReport of the driver at now; errors_before and refused_before are the totals at the
    last report (what is new since is judged); scheduling: the node's class.
    """
    cfg = driver.config
    problems, level = [], protocol.OK
    escs = []
    total_errors = sum(sum(e.values()) for e in driver.errors)
    for i, address in enumerate(cfg.addresses):
        missing = i in driver.missing
        ok_time = driver.last_ok[i]
        age = None if ok_time is None else now - ok_time
        tel = driver.telemetry[i]
        escs.append(_esc_line(address, tel, driver.errors[i], missing, age))
        if missing:
            problems.append((protocol.WARN, 'ESC %d (0x%02x) missing, ignored' % (i + 1, address)))
            continue
        if age is not None and age > LOST:
            problems.append((protocol.ERROR, 'ESC %d (0x%02x) does not answer' % (i + 1, address)))
        if tel is not None:
            lvl, what = protocol.state_problem(tel.state)
            if lvl != protocol.OK:
                problems.append((lvl, 'ESC %d (0x%02x) %s' % (i + 1, address, what)))
            if tel.temperature >= temperature_error:
                problems.append((protocol.ERROR, 'ESC %d at %.0f C' % (i + 1, tel.temperature)))
            elif tel.temperature >= temperature_warn:
                problems.append((protocol.WARN, 'ESC %d at %.0f C' % (i + 1, tel.temperature)))
    if total_errors > errors_before:
        problems.append((protocol.WARN,
                         '%d I2C errors (retried)' % (total_errors - errors_before)))
    if driver.refused > refused_before:
        problems.append((protocol.WARN, 'motor_commands refused: %s' % driver.refusal
                         if driver.refusal else 'motor_commands refused'))
    if problems:
        level = max(lvl for lvl, _ in problems)
        message = '; '.join(what for lvl, what in problems if lvl == level)
    else:
        message = 'ESCs %s' % driver.reason
    test = driver.test
    return EscReport(level, message, EscFigures(
        driver.reason, tuple(float(x) for x in driver.output), driver.refused, total_errors,
        window(driver.latency.samples()),
        'rotor %d at %g' % (test.rotor, test.command) if test else 'none', tuple(escs),
        scheduling))


def to_values(figures: EscFigures) -> List[Tuple[str, str]]:
    """The diagnostics key/value pairs of the ESC node's figures."""
    return CODEC.to_values(figures)


def from_values(pairs: Iterable[Tuple[str, str]]) -> EscFigures:
    """The ESC node's figures from a status's key/value pairs (others' keys are dropped)."""
    return cast(EscFigures, CODEC.from_values(pairs)[0])   # (they require no key: never None)
