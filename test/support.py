"""Test support (not installed): a monitor that also plays the motion capture, the IMU, an
operator's set points and a rival controller.
"""
import math

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseStamped, QuaternionStamped
import numpy as np
from sensor_msgs.msg import Imu, JointState

from geoctl_ros.core.actuation.esc_wire import ArmedState
from geoctl_ros.core.geometry import so3
from geoctl_ros.nodes import qos
from geoctl_ros.nodes.conversions import (
    armed_state_msg,
    motor_commands_msg,
    set_quaternion,
    set_vector,
)
from geoctl_ros.sil.processes import Monitor

GRAVITY_REACTION = np.array([0.0, 0.0, 9.81])     # m/s^2: what an IMU at rest reads, level


class FakeInputs(Monitor):
    """Monitor plus fake inputs."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.pub_pose = self.create_publisher(PoseStamped, 'pose', qos.SENSOR)
        self.pub_imu = self.create_publisher(Imu, 'imu', qos.SENSOR)
        self.pub_setpoint = self.create_publisher(QuaternionStamped, 'attitude_setpoint',
                                                  qos.EVENT)
        self.fed = 0          # pose and imu pairs fed so far
        self.feed_force_axes = np.eye(3)     # the fed IMU's axes against the body's

    def feed(self, q=(0.0, 0.0, 0.0, 1.0), w=(0.0, 0.0, 0.0), rate_hz=100.0):
        """Publish pose and imu at rate_hz with fresh stamps until stop_feed(); q and w can be
        changed on the fly through self.feed_q / self.feed_w.
        """
        self.feed_q, self.feed_w = tuple(q), tuple(w)
        self._feed_timer = self.create_timer(1.0 / rate_hz, self._feed_tick)

    def _feed_tick(self):
        stamp = self.get_clock().now().to_msg()
        self.publish_pose(self.feed_q, stamp)
        self.publish_imu(self.feed_w, stamp, self.feed_q, self.feed_force_axes)
        self.fed += 1

    def stop_feed(self):
        self.destroy_timer(self._feed_timer)

    def publish_pose(self, q, stamp=None):
        msg = PoseStamped()
        msg.header.stamp = stamp or self.get_clock().now().to_msg()
        set_quaternion(msg.pose.orientation, q)
        self.pub_pose.publish(msg)

    def publish_imu(self, w, stamp=None, q=(0.0, 0.0, 0.0, 1.0), force_axes=np.eye(3)):
        """An IMU sample: angular velocity w, and the specific force of a vehicle at rest at
        attitude q (the reaction to gravity, R^T [0, 0, 9.81]) in force_axes (body to IMU).
        """
        msg = Imu()
        msg.header.stamp = stamp or self.get_clock().now().to_msg()
        set_vector(msg.angular_velocity, w)
        set_vector(msg.linear_acceleration, force_axes @ so3.quat_to_rot(q).T @ GRAVITY_REACTION)
        self.pub_imu.publish(msg)

    def publish_attitude(self, q):
        """The controller's measured attitude (what the bridge and the view show)."""
        if getattr(self, 'pub_attitude', None) is None:
            self.pub_attitude = self.create_publisher(QuaternionStamped, 'attitude',
                                                      qos.TELEMETRY)
        msg = QuaternionStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        set_quaternion(msg.quaternion, q)
        self.pub_attitude.publish(msg)

    def publish_setpoint(self, q):
        msg = QuaternionStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        set_quaternion(msg.quaternion, q)
        self.pub_setpoint.publish(msg)

    def publish_commands(self, data, session=0):
        """Publish on motor_commands as a plain publisher (session 0: the values alone, as a
        hand-typed command), or as the controller of session (created on first use: while it
        exists, the real controller refuses to arm).
        """
        if getattr(self, 'pub_commands', None) is None:
            self.pub_commands = self.create_publisher(JointState, 'motor_commands',
                                                      qos.COMMAND)
        msg = motor_commands_msg(session, len(data)) if session else JointState()
        msg.effort = [float(x) for x in data]
        self.pub_commands.publish(msg)

    def stop_commands(self):
        """Remove the motor_commands publisher (the real controller may arm again)."""
        if getattr(self, 'pub_commands', None) is not None:
            self.destroy_publisher(self.pub_commands)
            self.pub_commands = None

    def act_as_controller(self, armed, session):
        """Publish the typed armed state a controller of session publishes (~/armed)."""
        if getattr(self, 'pub_armed', None) is None:
            self.pub_armed = self.create_publisher(DiagnosticStatus, '/controller/armed',
                                                   qos.LATCHED)
        self.pub_armed.publish(armed_state_msg(ArmedState(armed, session)))



def past_bounds(p):
    """The values a numeric schema parameter p must refuse, each with a label: NaN, +-inf,
    +-1e30 and just past each of its bounds (for an array, in its first element, the rest its
    default). Integers get the integers just past their bounds; the non-integers are refused as
    the wrong type.
    """
    if p.type.startswith('integer'):
        scalars = [('lo - 1', p.lo - 1), ('hi + 1', p.hi + 1)]
    else:
        scalars = [('lo - eps', p.lo - 1e-6 * max(1.0, abs(p.lo))),
                   ('hi + eps', p.hi + 1e-6 * max(1.0, abs(p.hi)))]
    scalars += [('nan', math.nan), ('inf', math.inf), ('-inf', -math.inf), ('1e30', 1e30),
                ('-1e30', -1e30)]
    if not p.type.endswith('_array'):
        return scalars
    base = list(p.default) if p.default else [0.0 if p.type == 'double_array' else 0]
    return [(label, [v] + base[1:]) for label, v in scalars]
