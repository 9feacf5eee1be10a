"""The controller node's monitoring topics (what ``ros2 topic echo`` and the recorder see besides
the motor commands): the measured attitude and body rate in the package's frames (the inputs
after their conventions, ``core.sensors.frames``: what the ground station, the view and the records
show), the wrench, e_R, e_Omega, Psi, the estimate, the cone margins and the set point being
flown. Published after the motor command, from one tick's result.
"""
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped, WrenchStamped
from std_msgs.msg import Float64, Float64MultiArray

from geoctl_ros.core.geometry import so3
from geoctl_ros.nodes import qos
from geoctl_ros.nodes.conversions import set_quaternion, set_vector


class Telemetry:
    """The publishers and their reused messages."""

    def __init__(self, node, frame_id, world_frame_id):
        self.node, self.world_frame_id = node, world_frame_id
        pub = node.create_publisher
        self.pub_wrench = pub(WrenchStamped, 'control_wrench', qos.COMMAND)
        self.pub_eR = pub(Vector3Stamped, 'attitude_error', qos.TELEMETRY)
        self.pub_eW = pub(Vector3Stamped, 'angular_velocity_error', qos.TELEMETRY)
        self.pub_psi = pub(Float64, 'configuration_error', qos.TELEMETRY)
        self.pub_dbar = pub(Float64MultiArray, 'disturbance_estimate', qos.TELEMETRY)
        self.pub_margins = pub(Float64MultiArray, 'cone_margins', qos.TELEMETRY)
        self.pub_setpoint = pub(QuaternionStamped, 'active_setpoint', qos.LATCHED)
        self.pub_attitude = pub(QuaternionStamped, 'attitude', qos.TELEMETRY)
        self.pub_rate = pub(Vector3Stamped, 'body_rate', qos.TELEMETRY)
        self.attitude, self.rate = QuaternionStamped(), Vector3Stamped()
        self.attitude.header.frame_id = world_frame_id
        self.rate.header.frame_id = frame_id
        self._published_R_d = None
        self.wrench, self.eR, self.eW = WrenchStamped(), Vector3Stamped(), Vector3Stamped()
        self.psi, self.dbar, self.margins = Float64(), Float64MultiArray(), Float64MultiArray()
        for msg in (self.wrench, self.eR, self.eW):
            msg.header.frame_id = frame_id

    def publish(self, tick):
        """The monitoring topics of a LoopTick (none before the first pose and rate: a rate
        from the poses counts), and the set point when a new one is flown. A topic nobody
        subscribes to is not filled or published (about 8 us a topic, against 0.5 us to ask).
        """
        out = tick.control
        if out is not None:
            stamp = tick.stamp
            R, Omega = tick.measured
            if self.pub_attitude.get_subscription_count():
                self.attitude.header.stamp = stamp
                set_quaternion(self.attitude.quaternion, so3.rot_to_quat(R))
                self.pub_attitude.publish(self.attitude)
            if self.pub_rate.get_subscription_count():
                self.rate.header.stamp = stamp
                set_vector(self.rate.vector, Omega)
                self.pub_rate.publish(self.rate)
            if self.pub_wrench.get_subscription_count():
                w = self.wrench
                w.header.stamp = stamp
                set_vector(w.wrench.torque, out.u)
                set_vector(w.wrench.force, (0.0, 0.0, tick.motors.allocation.collective))
                self.pub_wrench.publish(w)
            for pub, msg, vector in ((self.pub_eR, self.eR, out.e_R),
                                     (self.pub_eW, self.eW, out.e_Omega)):
                if pub.get_subscription_count():
                    msg.header.stamp = stamp
                    set_vector(msg.vector, vector)
                    pub.publish(msg)
            if self.pub_psi.get_subscription_count():
                self.psi.data = float(out.psi)
                self.pub_psi.publish(self.psi)
            if self.pub_dbar.get_subscription_count():
                self.dbar.data = out.delta_bar.tolist()
                self.pub_dbar.publish(self.dbar)
            if self.pub_margins.get_subscription_count():
                self.margins.data = out.margins_deg.tolist()
                self.pub_margins.publish(self.margins)
        R_d = tick.setpoint
        if R_d is not self._published_R_d:      # a new set point (set_setpoint copies)
            self._published_R_d = R_d
            sp = QuaternionStamped()
            sp.header.stamp = self.node.get_clock().now().to_msg()
            sp.header.frame_id = self.world_frame_id
            set_quaternion(sp.quaternion, so3.rot_to_quat(R_d))
            self.pub_setpoint.publish(sp)
