"""The ESC node's health as typed values, and the one place that spells its diagnostics keys:
``report`` judges a driver's state, ``to_values`` formats it for a DiagnosticStatus and
``from_values`` reads one back (as the tests do).

Levels: ERROR for an ESC that has not answered for ``LOST`` s (or a failed start, a self-test
error, ``esc.temperature_error``); WARN for I2C errors in the last window (retried), an ESC
limiting, ``esc.temperature_warn``, a missing ESC that ``esc.ignore`` lets the node run without, or
commands refused in the window; OK otherwise.
"""
from dataclasses import dataclass
import math
from typing import Optional, Tuple

from geoctl_ros.core.diagnostics import Window, window
from geoctl_ros.core.safety import EscHealth
from geoctl_ros.esc import protocol

NAME = 'geoctl_ros: esc_i2c'
LOST = 0.5                        # s without a successful transfer: the ESC is lost

_OUTPUT = 'output'
_SET_POINTS = 'set points'
_REFUSED = 'commands refused'
_ERRORS = 'i2c errors'
_LATENCY = 'command to last byte [ms]'
_TEST = 'motor test'
_ESC = 'esc %d'                   # % rotor number


def esc_health(driver, now, temperature_error):
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
class EscReport:
    """What the node reports: why it writes what it writes, the set points (normalised), the
    commands refused and I2C errors so far, the command-to-bus latency of the window, and per ESC
    a line of its own.
    """

    level: int
    message: str
    output: str
    set_points: Tuple[float, ...]
    refused: int
    i2c_errors: int
    latency: Optional[Window]
    motor_test: str
    escs: Tuple[str, ...]


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


def report(driver, now, temperature_warn, temperature_error, errors_before=0, refused_before=0):
    """The EscReport of the driver at now; errors_before and refused_before are the totals at the
    last report (what is new since is judged).
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
    return EscReport(level, message, driver.reason, tuple(float(x) for x in driver.output),
                     driver.refused, total_errors, window(driver.latency.samples()),
                     'rotor %d at %g' % (test.rotor, test.command) if test else 'none',
                     tuple(escs))


def _window_text(w):
    if w is None:
        return 'n/a'
    return 'mean %.3f p99 %.3f max %.3f' % (1e3 * w.mean, 1e3 * w.p99, 1e3 * w.max)


def to_values(r):
    """The diagnostics key/values (str -> str) of an EscReport."""
    values = {_OUTPUT: r.output,
              _SET_POINTS: ' '.join('%.4f' % x for x in r.set_points),
              _REFUSED: str(r.refused), _ERRORS: str(r.i2c_errors),
              _LATENCY: _window_text(r.latency), _TEST: r.motor_test}
    for k, line in enumerate(r.escs, 1):
        values[_ESC % k] = line
    return values


def from_values(pairs):
    """(output, set points, commands refused, I2C errors, latency p99 and max in s or None, motor
    test, ESC lines) from a status's key/values.
    """
    v = dict(pairs)
    lat = v.get(_LATENCY, 'n/a').split()
    return (v.get(_OUTPUT, ''), tuple(float(x) for x in v.get(_SET_POINTS, '').split()),
            int(v.get(_REFUSED, 0)), int(v.get(_ERRORS, 0)),
            None if lat[0] == 'n/a' else (1e-3 * float(lat[3]), 1e-3 * float(lat[5])),
            v.get(_TEST, ''), tuple(v[k] for k in sorted(v) if k.startswith('esc ')))
