"""What the controller and the nodes that drive its motors (esc_i2c, the sim) exchange, as typed
values: the armed state and session the controller publishes (``ArmedState``), each ESC's health as
the ESC node reports it back (``EscHealth``; ``EscReport``, the key-values of its ``esc_health``,
written by ``esc_report`` and read by ``esc_report_of``; ``EscStatus``, what the controller keeps
of it), and the one check of a motor_commands message that every receiver applies
(``motor_commands_problem``). Both sides import it: the
controller's supervisor (core.supervisor) judges the reports, and esc/ writes them without
importing the supervisor.
"""
from enum import IntEnum
import math
from typing import Iterable, List, NamedTuple, Optional, Sequence, Tuple, Union

from geoctl_ros.core.geometry.so3 import Vector


class ArmedState(NamedTuple):
    """What the controller tells the nodes that drive its motors (esc_i2c): whether it is armed,
    and its session number, the random nonzero 32-bit number it drew at start and stamps on each
    of its motor_commands (their header's ``frame_id``), so commands from anything else (a
    second publisher, a recorded flight played back) are told apart and refused.
    """

    armed: bool
    session: int


class EscHealth(IntEnum):
    """Each ESC's health as the ESC node reports it to the controller (its ``esc_health``)."""

    OK = 0
    IGNORED = 1          # missing at start-up, and in esc.ignore: never written
    LOST = 2             # no successful transfer for a while (esc.health.LOST)
    FAULT = 3            # a self-test error or a failed start, or at esc.temperature_error


ROTOR_KEY = 'rotor %d'            # esc_health's key of each rotor's EscHealth (rotor 1, ...)


class EscReport(NamedTuple):
    """The ESC node's report to the controller (its ``esc_health``, a DiagnosticStatus): whether
    an ESC is lost or at fault (its level ERROR, else OK), its message, and its key-values:
    ``command_max``, then ``rotor 1`` ... ``rotor n`` (each ESC's EscHealth, by name).
    """

    failing: bool
    message: str
    values: Tuple[Tuple[str, str], ...]


def esc_report(command_max: int, escs: Sequence['EscHealth']) -> EscReport:
    """The EscReport of the ESCs' healths (in rotor order) under motor.command_max."""
    bad = ['rotor %d %s' % (i + 1, e.name) for i, e in enumerate(escs)
           if e in (EscHealth.LOST, EscHealth.FAULT)]
    return EscReport(bool(bad), ', '.join(bad) if bad else 'no ESC lost or at fault',
                     (('command_max', str(int(command_max))),)
                     + tuple((ROTOR_KEY % (i + 1), e.name) for i, e in enumerate(escs)))


def esc_report_of(values: Iterable[Tuple[str, str]]) -> Union[Tuple[int, List[str]], str]:
    """An EscReport's key-values -> (command_max, each rotor's health as named, in rotor
    order), or why they are not one (a sentence). The names are judged by the controller
    (``ControlLoop.offer_esc_health``).
    """
    pairs = dict(values)
    text = pairs.pop('command_max', None)
    if text is None:
        return 'no command_max'
    try:
        command_max = int(text)
    except ValueError:
        return 'command_max %r is not a whole number' % text[:20]
    rotors: List[str] = []
    while ROTOR_KEY % (len(rotors) + 1) in pairs:
        rotors.append(pairs.pop(ROTOR_KEY % (len(rotors) + 1)))
    if pairs:
        return 'keys other than command_max and rotor 1 ... rotor %d: %s' % (
            len(rotors), ', '.join(sorted(repr(k[:20]) for k in pairs)[:4]))
    return command_max, rotors


class EscStatus(NamedTuple):
    """The ESC node's last report: its motor.command_max, each ESC's EscHealth, when received."""

    command_max: int
    escs: Tuple['EscHealth', ...]
    receipt: float


def motor_commands_problem(data: Vector, n: int) -> Optional[str]:
    """Why a motor_commands message cannot be actuated (a sentence), or None: it must hold n
    finite values in [0, 1] (the sim and the ESC node refuse it the same way).
    """
    if not len(data) or len(data) != n or not all(math.isfinite(x) for x in data):
        return 'expected %d finite values, got %r' % (n, [round(x, 4) for x in list(data)[:8]])
    if min(data) < 0.0 or max(data) > 1.0:
        return 'values outside [0, 1]'
    return None
