"""The QoS of every topic this package publishes or reads, in one place.

- SENSOR: pose and imu, as motion-capture and IMU drivers publish them (best effort): a late
  sample is worth nothing, a retransmission would only delay the next one.
- COMMAND: motor_commands and control_wrench (what the sim actuates in torque mode): reliable,
  depth 1, so the newest command is delivered and no queue of old ones builds up.
- TELEMETRY: the 100-200 Hz monitoring topics (errors, Psi, estimate, cone margins, the sim's true
  pose): best effort, depth 1. A slow or dropped monitor never holds a publisher up. Subscribe with
  TELEMETRY too: a reliable subscriber would not connect to them. ``ros2 topic echo`` adapts.
- EVENT: set points and /diagnostics: reliable, depth 10, nothing lost.
- LATCHED: state that changes rarely (the active set point): reliable, depth 1, transient local,
  so a node that starts later still gets the current value.
"""
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

SENSOR = qos_profile_sensor_data
COMMAND = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
TELEMETRY = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
EVENT = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
