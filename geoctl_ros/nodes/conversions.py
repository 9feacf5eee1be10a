"""Message <-> numpy, in one place."""
import array

from builtin_interfaces.msg import Time


def stamp_seconds(stamp):
    """builtin_interfaces/Time -> float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def time_msg(seconds):
    """float seconds -> builtin_interfaces/Time."""
    sec = int(seconds // 1)
    return Time(sec=sec, nanosec=min(int(round((seconds - sec) * 1e9)), 999999999))


def quaternion(msg):
    """geometry_msgs/Quaternion -> (x, y, z, w)."""
    return (msg.x, msg.y, msg.z, msg.w)


def set_quaternion(msg, q):
    msg.x, msg.y, msg.z, msg.w = (float(v) for v in q)


def vector(msg):
    """geometry_msgs/Vector3 -> (x, y, z)."""
    return (msg.x, msg.y, msg.z)


def set_vector(msg, v):
    msg.x, msg.y, msg.z = float(v[0]), float(v[1]), float(v[2])


def python_value(value):
    """An rclpy parameter value as plain Python (arrays become lists)."""
    if isinstance(value, array.array):
        return list(value)
    if isinstance(value, (list, tuple)):
        return list(value)
    return value
