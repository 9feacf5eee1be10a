"""A flight controller on a MAVLink link of its own as the testbed's IMU (the MAVLink bridge's
``mavlink.autopilot_url``): its HIGHRES_IMU (FRD) is republished on ``imu`` (FLU), at the rate
asked of it with MAV_CMD_SET_MESSAGE_INTERVAL after its first heartbeat.
"""
import time

from sensor_msgs.msg import Imu

from geoctl_ros.mavlink import frames
from geoctl_ros.mavlink.actions import m_const
from geoctl_ros.mavlink.health import NO_AUTOPILOT_HEARTBEAT
from geoctl_ros.mavlink.link import Link
from geoctl_ros.nodes import qos
from geoctl_ros.nodes.conversions import set_vector

HEARTBEAT_TIMEOUT = 3.0        # s without the autopilot's heartbeat: "no autopilot heartbeat"


class AutopilotImu:
    def __init__(self, node, url, sysid, rate_hz, mav):
        """node: the ROS node that publishes ``imu``; mav: a MAVLink encoder of this system (for
        the rate request).
        """
        self.link = Link(url, sysid, m_const('MAV_COMP_ID_ONBOARD_COMPUTER'))
        self._pub = node.create_publisher(Imu, 'imu', qos.SENSOR)
        self._clock = node.get_clock()
        self._mav = mav
        self._rate_hz = rate_hz
        self._requested = False
        self.heartbeat = None          # time.monotonic() of its last heartbeat
        self.messages = 0              # HIGHRES_IMU republished

    def pump(self):
        """Read what the autopilot sent: ask for the IMU rate once, republish every sample."""
        for msg in self.link.receive():
            kind = msg.get_type()
            if kind == 'HEARTBEAT':
                self.heartbeat = time.monotonic()
                if not self._requested:
                    self.link.send(self._mav.command_long_encode(
                        msg.get_srcSystem(), msg.get_srcComponent(),
                        m_const('MAV_CMD_SET_MESSAGE_INTERVAL'), 0,
                        m_const('MAVLINK_MSG_ID_HIGHRES_IMU'), 1e6 / self._rate_hz,
                        0, 0, 0, 0, 0))
                    self._requested = True
            elif kind == 'HIGHRES_IMU':
                out = Imu()
                out.header.stamp = self._clock.now().to_msg()
                out.header.frame_id = 'base_link'
                out.orientation_covariance[0] = -1.0
                set_vector(out.angular_velocity,
                           frames.body_vector((msg.xgyro, msg.ygyro, msg.zgyro)))
                set_vector(out.linear_acceleration,
                           frames.body_vector((msg.xacc, msg.yacc, msg.zacc)))
                self._pub.publish(out)
                self.messages += 1

    def health(self, now):
        """(heartbeat age in s or None, HIGHRES_IMU republished, a warning or None) at now
        (time.monotonic()).
        """
        age = None if self.heartbeat is None else now - self.heartbeat
        lost = age is None or age > HEARTBEAT_TIMEOUT
        return age, self.messages, NO_AUTOPILOT_HEARTBEAT if lost else None

    def close(self):
        self.link.close()
