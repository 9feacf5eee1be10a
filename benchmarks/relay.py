"""A bare relay node, the floor of input-to-command latency (issue 10): it subscribes to ``imu`` as
the controller does (same QoS, same executor) and publishes a Float64MultiArray of six values on
``relay/motor_commands`` (the controller's command QoS) for each sample, carrying the sample's
stamp, with no work in between. Started by ``latency.py``; not part of the package.
"""
import sys

from rclpy.node import Node
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray

from geoctl_ros.nodes import qos
from geoctl_ros.nodes.runtime import spin


class Relay(Node):
    def __init__(self):
        super().__init__('relay')
        self.pub = self.create_publisher(Float64MultiArray, 'relay/motor_commands', qos.COMMAND)
        self.msg = Float64MultiArray(data=[0.0] * 6)
        self.create_subscription(Imu, 'imu', self._on_imu, qos.SENSOR)

    def _on_imu(self, msg):
        self.msg.data = [msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec] + [0.0] * 5
        self.pub.publish(self.msg)


if __name__ == '__main__':
    sys.exit(spin(Relay, 'relay'))
