"""Field readers of a message, recorded (rosbags' classes) or live (rclpy's): the same fields.
No import of either, so the nodes and the report share them.
"""


def quaternion(msg):
    """geometry_msgs/Quaternion -> (x, y, z, w)."""
    return (msg.x, msg.y, msg.z, msg.w)


def vector(msg):
    """geometry_msgs/Vector3 -> (x, y, z)."""
    return (msg.x, msg.y, msg.z)
