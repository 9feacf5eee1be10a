"""What a MAVLink message asks of the controller, as typed actions (``Vehicle.handle`` returns
them; the bridge carries them out), and the helpers that read a message's fields safely.
"""
import math
from typing import NamedTuple

from pymavlink.dialects.v20 import common


# What an incoming message asks of the bridge (``Vehicle.handle``): typed, dispatched by type.
class Send(NamedTuple):
    """Send this message to the ground station."""

    message: object


class Arm(NamedTuple):
    """Arm (on) or disarm the controller, then answer the COMMAND_LONG command."""

    on: bool
    command: int


class SetParameter(NamedTuple):
    """Set the controller's ROS parameter name to a PARAM_SET value (table index)."""

    name: str
    value: float
    index: int


class Say(NamedTuple):
    """Tell the ground station text in STATUSTEXT, in chunks of 50 characters when longer;
    limited: at most mavlink.statustext_rate_hz (what a flood of bad messages would repeat).
    """

    text: str
    severity: str = 'MAV_SEVERITY_WARNING'
    limited: bool = False


class SetAttitude(NamedTuple):
    """Fly this set point (the ground station's SET_ATTITUDE_TARGET, in the package's frames:
    the quaternion (x, y, z, w) of ENU <- FLU) through the controller's ``setpoint`` parameter.
    """

    q: tuple


class MotorTest(NamedTuple):
    """Spin rotor (1-based) at a normalised command for seconds through the ESC node."""

    rotor: int
    command: float
    seconds: float
    mav_command: int


class Ignored(NamedTuple):
    """Nothing to do (the message is not for this system, or names nothing it has)."""

    why: str


MESSAGE_ID_MAX = (1 << 24) - 1      # MAVLink 2 message ids are 24 bits
MOTORS_MAX = 32                     # a motor test's instance number (ACTUATOR_OUTPUT_STATUS: 32)


def whole(x, lo, hi):
    """x (a command's float parameter) as a whole number in [lo, hi], or None: NaN, inf and
    fractions are not (int() of NaN or inf raises, which ended the bridge).
    """
    if not (math.isfinite(x) and lo <= x <= hi and x == math.floor(x)):
        return None
    return int(x)


def shown(x):
    return '%g' % x


def m_const(name):
    """A constant of the common dialect by name (MAV_TYPE_HEXAROTOR, ...)."""
    return getattr(common, name)

