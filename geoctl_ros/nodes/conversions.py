"""Message <-> numpy, in one place."""
import array

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from sensor_msgs.msg import JointState

from geoctl_ros.core.actuation.esc_wire import (
    ROTOR_KEY,
    ArmedState,
    esc_report,
    esc_report_of,
)
from geoctl_ros.core.telemetry.diagnostics import Status, from_values, to_values
from geoctl_ros.mavlink.health import Report as BridgeReport
from geoctl_ros.mavlink.health import from_values as bridge_values

ARMED_NAME = 'geoctl_ros: armed'
SESSION_MAX = 2 ** 32 - 1


def armed_state_msg(state):
    """ArmedState -> the controller's ``~/armed`` message: a diagnostic_msgs/DiagnosticStatus
    (level OK, message 'armed' or 'disarmed') with the key-values ``armed`` ('true' or 'false')
    and ``session`` (the session number, decimal).
    """
    armed = 'true' if state.armed else 'false'
    return DiagnosticStatus(level=DiagnosticStatus.OK, name=ARMED_NAME,
                            message='armed' if state.armed else 'disarmed',
                            values=[KeyValue(key='armed', value=armed),
                                    KeyValue(key='session', value=str(int(state.session)))])


def armed_state_of(msg):
    """The ``~/armed`` message -> ArmedState, or None if it is not one (its key-values are not
    exactly ``armed`` true or false and ``session`` a number of 1 to 2^32 - 1).
    """
    pairs = {kv.key: kv.value for kv in msg.values}
    if set(pairs) != {'armed', 'session'} or pairs['armed'] not in ('true', 'false'):
        return None
    session = pairs['session']
    if not _decimal(session) or not 0 < int(session) <= SESSION_MAX:
        return None
    return ArmedState(pairs['armed'] == 'true', int(session))


ESC_HEALTH_NAME = 'geoctl_ros: esc_health'


def esc_health_msg(command_max, escs, hardware_id=''):
    """The ESC node's ``esc_health``: its ``EscReport`` (core.actuation.esc_wire) as a
    diagnostic_msgs/DiagnosticStatus, level ERROR where an ESC is lost or at fault, else OK.
    """
    report = esc_report(command_max, escs)
    return DiagnosticStatus(
        level=DiagnosticStatus.ERROR if report.failing else DiagnosticStatus.OK,
        name=ESC_HEALTH_NAME, hardware_id=hardware_id, message=report.message,
        values=[KeyValue(key=k, value=v) for k, v in report.values])


def esc_health_of(msg):
    """``esc_health`` -> (command_max, each rotor's health as named), or why it is not one."""
    return esc_report_of((kv.key, kv.value) for kv in msg.values)


def motor_commands_msg(session, rotors):
    """An empty motor_commands message of the controller of session for its rotors (a count): a
    sensor_msgs/JointState whose ``name`` is rotor 1 ... rotor n, whose ``effort`` is to hold
    each rotor's normalised command in [0, 1] (command / ``motor.command_max``: not a force),
    and whose header carries the session number (decimal) as its ``frame_id`` and the time the
    command was made as its ``stamp`` (set at each publish).
    """
    msg = JointState(name=[ROTOR_KEY % (i + 1) for i in range(int(rotors))])
    msg.header.frame_id = str(int(session))
    return msg


def commands_of(msg):
    """The normalised commands a motor_commands message holds, in rotor order."""
    return msg.effort


def session_of(msg):
    """The session number a motor_commands message carries (0: none, or not a number)."""
    text = msg.header.frame_id
    if not _decimal(text):
        return 0
    session = int(text)
    return session if session <= SESSION_MAX else 0


def _decimal(text):
    """Whether text is a whole number of 1 to 10 ASCII digits (a session number's form)."""
    return 0 < len(text) <= 10 and text.isascii() and text.isdigit()


def set_stamp(stamp, seconds):
    """A builtin_interfaces/Time set in place to float seconds (a published message's, reused)."""
    sec = int(seconds // 1)
    stamp.sec, stamp.nanosec = sec, min(int(round((seconds - sec) * 1e9)), 999999999)


def stamp_seconds(stamp):
    """builtin_interfaces/Time -> float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def time_msg(seconds):
    """float seconds -> builtin_interfaces/Time."""
    stamp = Time()
    set_stamp(stamp, seconds)
    return stamp


def set_quaternion(msg, q):
    msg.x, msg.y, msg.z, msg.w = (float(v) for v in q)


def set_vector(msg, v):
    msg.x, msg.y, msg.z = float(v[0]), float(v[1]), float(v[2])


def python_value(value):
    """An rclpy parameter value as plain Python (arrays become lists)."""
    if isinstance(value, array.array):
        return list(value)
    if isinstance(value, (list, tuple)):
        return list(value)
    return value


def refusal_reason(text):
    """A parameter set's refusal (``SetParametersResult.reason``) on one line: the controller's
    ConfigError names each parameter after a heading ('invalid parameters:'), one per line.
    """
    lines = [line.strip() for line in str(text).strip().splitlines()]
    if lines and lines[0] == 'invalid parameters:':
        lines = lines[1:]
    return '; '.join(line for line in lines if line) or 'no reason given'


def level(status_msg):
    """The level of a diagnostic_msgs/DiagnosticStatus as an int (the field is a byte)."""
    raw = status_msg.level
    return raw[0] if isinstance(raw, (bytes, bytearray)) else int(raw)


def status_msg(status, name, hardware_id):
    """A core Status (level, message, typed figures) -> diagnostic_msgs/DiagnosticStatus."""
    values = [KeyValue(key=k, value=v) for k, v in to_values(status.figures)]
    return DiagnosticStatus(level=bytes([status.level]), name=name, hardware_id=hardware_id,
                            message=status.message, values=values)


def status_of(status_msg):
    """diagnostic_msgs/DiagnosticStatus of the controller -> a core Status with typed figures."""
    return Status(level(status_msg), status_msg.message,
                  from_values((kv.key, kv.value) for kv in status_msg.values))


def bridge_report(status_msg):
    """diagnostic_msgs/DiagnosticStatus of the MAVLink bridge -> a typed mavlink.health.Report."""
    figures, _ = bridge_values((kv.key, kv.value) for kv in status_msg.values)
    return BridgeReport(level(status_msg), status_msg.message, figures)


def key_values(status_msg):
    """Any node's diagnostic_msgs/DiagnosticStatus as a dict: level (int), message, name and its
    key/values as text.
    """
    return {'level': level(status_msg), 'message': status_msg.message, 'name': status_msg.name,
            **{kv.key: kv.value for kv in status_msg.values}}
