"""The package's topics as a recording sees them: name, type and the QoS their publisher offers
(the recorder's subscriptions, the ``record.topics`` parameter's choices, the bag reader).

A topic is chosen by its package name; the recorder hears it, and writes it, under its real name
once its remaps apply (``record --ros-args -r pose:=/vicon/hexrotor/pose`` records the driver's
topic as ``/vicon/hexrotor/pose``), and keeps which package name each real one stands for in the
bag (``RECORDED_NAMES``), for ``report``.
"""
from typing import NamedTuple


class Topic(NamedTuple):
    """A recorded topic: its name (absolute), type and the QoS its publisher offers."""

    name: str
    type: str
    reliable: bool
    transient_local: bool = False
    depth: int = 1


# The package's topics, as the nodes publish them at the root namespace (qos.py's profiles).
TOPICS = (
    Topic('/pose', 'geometry_msgs/msg/PoseStamped', False, depth=5),
    Topic('/imu', 'sensor_msgs/msg/Imu', False, depth=5),
    Topic('/attitude', 'geometry_msgs/msg/QuaternionStamped', False),
    Topic('/body_rate', 'geometry_msgs/msg/Vector3Stamped', False),
    Topic('/motor_commands', 'sensor_msgs/msg/JointState', True),
    Topic('/control_wrench', 'geometry_msgs/msg/WrenchStamped', True),
    Topic('/attitude_error', 'geometry_msgs/msg/Vector3Stamped', False),
    Topic('/angular_velocity_error', 'geometry_msgs/msg/Vector3Stamped', False),
    Topic('/configuration_error', 'std_msgs/msg/Float64', False),
    Topic('/disturbance_estimate', 'std_msgs/msg/Float64MultiArray', False),
    Topic('/cone_margins', 'std_msgs/msg/Float64MultiArray', False),
    Topic('/active_setpoint', 'geometry_msgs/msg/QuaternionStamped', True, True),
    Topic('/attitude_setpoint', 'geometry_msgs/msg/QuaternionStamped', True, depth=10),
    Topic('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', True, depth=10),
    Topic('/sim/true_pose', 'geometry_msgs/msg/PoseStamped', False),
    Topic('/view/markers', 'visualization_msgs/msg/MarkerArray', False),
)
BY_NAME = {t.name: t for t in TOPICS}
# Written by the recorder itself, not heard on DDS: the controller's cone and sensor parameters
# (a YAML mapping), so that a bag cut short still knows its cones.
CONTROLLER_PARAMETERS = Topic('/record/controller_parameters', 'std_msgs/msg/String', True, True)
# Written by the recorder at the start: the real names of the topics it heard under another
# name than the package's (a YAML mapping, package name -> real name; empty when none was
# remapped).
RECORDED_NAMES = Topic('/record/topic_names', 'std_msgs/msg/String', True, True)
