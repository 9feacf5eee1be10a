"""What the controller and the nodes that drive its motors (esc_i2c, the sim) exchange, as typed
values: the armed state and session the controller publishes (``ArmedState``), each ESC's health as
the ESC node reports it back (``EscHealth``, ``EscStatus``), and the one check of a motor_commands
message that every receiver applies (``motor_commands_problem``). Both sides import it: the
controller's supervisor (core.supervisor) judges the reports, and esc/ writes them without
importing the supervisor.
"""
from enum import IntEnum
import math
from typing import NamedTuple, Optional, Tuple

from geoctl_ros.core.geometry.so3 import Vector


class ArmedState(NamedTuple):
    """What the controller tells the nodes that drive its motors (esc_i2c): whether it is armed,
    and its session number, the random nonzero 32-bit number it drew at start and stamps on each
    of its motor_commands (their ``layout.data_offset``), so commands from anything else (a
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
