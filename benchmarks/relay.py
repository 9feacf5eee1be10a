"""A bare relay node, the floor of input-to-command latency (issue 10): it subscribes to ``imu`` as
the controller does (same QoS, same executor) and publishes a motor_commands message of six
rotors (the controller's type, ``nodes.conversions.motor_commands_msg``) on
``relay/motor_commands`` (the controller's command QoS) for each sample, carrying the sample's
stamp, with no work in between. Started by ``latency.py``; not part of the package.
"""
import sys

from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState

from geoctl_ros.nodes import qos
from geoctl_ros.nodes.conversions import motor_commands_msg
from geoctl_ros.nodes.runtime import spin


class Relay(Node):
    def __init__(self):
        super().__init__('relay')
        self.pub = self.create_publisher(JointState, 'relay/motor_commands', qos.COMMAND)
        self.msg = motor_commands_msg(1, 6)
        self.create_subscription(Imu, 'imu', self._on_imu, qos.SENSOR)

    def _on_imu(self, msg):
        self.msg.header.stamp = msg.header.stamp
        self.msg.effort = [0.0] * 6
        self.pub.publish(self.msg)


if __name__ == '__main__':
    sys.exit(spin(Relay, 'relay'))
