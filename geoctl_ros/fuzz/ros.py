"""The ``parameters`` and ``messages`` boundaries: hostile parameter values through the controller
node's own ``set_parameters`` and MAVLink PARAM_SET; hostile messages into the callbacks of real
rclpy nodes (controller, sim, view, bridge) in this process, on the loopback profile.
"""
import math
import os
import time

from diagnostic_msgs.msg import KeyValue
from geometry_msgs.msg import PoseStamped
from hypothesis import strategies as st
import numpy as np
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import Imu

from geoctl_ros.fuzz.hostile import (
    HOSTILE_FLOATS,
    NOW,
    Tally,
    finite_fields,
    hostile_float,
    run_property,
)
from geoctl_ros.mavlink.params import TABLE, to_ros
from geoctl_ros.nodes.calibrate import Listener as CalibrationListener
from geoctl_ros.nodes.controller import ControllerNode
from geoctl_ros.nodes.conversions import set_quaternion, set_vector, time_msg
from geoctl_ros.nodes.mavlink_bridge import MavlinkBridge
from geoctl_ros.nodes.sim import SimNode
from geoctl_ros.nodes.view import View
from geoctl_ros.params import CONTROLLER, schema_for
from geoctl_ros.sil.rosenv import config_dir, node_env


# --- ROS nodes (parameters, messages) ----------------------------------------------------------
class _Nodes:
    """The controller, sim, view and bridge as rclpy nodes of this process (never spun: their
    callbacks are called as the executor would), on the testbed's parameters.
    """

    def __init__(self):
        os.environ.update(node_env())
        self.rclpy = rclpy
        testbed = os.path.join(config_dir(), 'testbed.yaml')
        rclpy.init(args=['--ros-args', '--params-file', testbed, '--log-level', 'fatal'])
        self.controller = ControllerNode()
        self.sim = SimNode()
        self.view = View()
        self.bridge = MavlinkBridge()
        self.calibrate = CalibrationListener()
        self.nodes = (self.controller, self.sim, self.view, self.bridge, self.calibrate)

    def callbacks(self, topic):
        out = []
        for node in self.nodes:
            for sub in node.subscriptions:
                if sub.topic_name.rstrip('/').split('/')[-1] == topic:
                    out.append((sub.msg_type, sub.callback))
        return out

    def close(self):
        for node in self.nodes:
            if hasattr(node, 'link'):
                node.link.close()
            node.destroy_node()
        self.rclpy.try_shutdown()


_NODES = None


def nodes():
    """The nodes of this process (made on first use, and rclpy initialised with them)."""
    global _NODES
    if _NODES is None:
        _NODES = _Nodes()
    return _NODES


def close_nodes():
    """Destroy the nodes and shut rclpy down, if they were made."""
    global _NODES
    if _NODES is not None:
        _NODES.close()
        _NODES = None


ROS_VALUES = st.one_of(
    st.booleans(), st.integers(-2 ** 63, 2 ** 63 - 1), hostile_float(), st.text(max_size=20),
    st.lists(hostile_float(), max_size=12), st.lists(st.integers(-2 ** 63, 2 ** 63 - 1),
                                                     max_size=6),
    st.lists(st.booleans(), max_size=4), st.lists(st.text(max_size=5), max_size=4))


def fuzz_parameters(examples, seed):
    n = nodes()
    node = n.controller
    names = [p.name for p in schema_for(CONTROLLER)] + ['cones.obstacle.axis',
                                                       'cones.obstacle.half_angle_deg']
    by_name = {p.name: p for p in schema_for(CONTROLLER)}
    strategy = st.one_of(
        st.tuples(st.just('ros'), st.sampled_from(names), ROS_VALUES),
        st.tuples(st.just('mavlink'), st.sampled_from([ros for ros, _, _ in TABLE]),
                  st.one_of(st.sampled_from(HOSTILE_FLOATS),
                            st.floats(width=32))))

    def check(case):
        path, name, value = case
        before = node.get_parameter(name).value if node.has_parameter(name) else None
        if path == 'mavlink':
            try:
                value = to_ros(name, value)
            except (ValueError, OverflowError) as e:       # what the bridge answers
                return 'not a %s: %s' % (name, e)
        try:
            param = Parameter(name, value=value)
        except (TypeError, ValueError) as e:      # not a ROS parameter value: no client sends it
            return 'not a parameter value: %s' % e
        result = node.set_parameters([param])[0]
        after = node.get_parameter(name).value if node.has_parameter(name) else None
        if not result.successful:
            if _differs(before, after):
                raise AssertionError('refused, yet %s changed from %r to %r'
                                     % (name, before, after))
            return result.reason or ''
        p = by_name.get(name)
        if p is not None and p.lo is not None:
            for x in np.atleast_1d(np.asarray(after, dtype=float)):
                if not (math.isfinite(x) and p.lo <= x <= p.hi):
                    raise AssertionError('%s accepted %r outside [%g, %g]' % (name, after, p.lo,
                                                                              p.hi))
        if before is not None:     # put it back: every example starts from the testbed's
            node.set_parameters([Parameter(name, value=before)])
        return None
    return run_property(Tally('parameters'), strategy, check, examples, seed)


def _differs(a, b):
    try:
        return not (a == b or (np.asarray(a) == np.asarray(b)).all())
    except Exception:
        return a is not b


@st.composite
def stamps(draw):
    now = NOW
    sec = draw(st.one_of(st.sampled_from((0, 1, now - 1000, now, now + 1, now + 10 ** 6,
                                          2 ** 31 - 1, -2 ** 31)),
                         st.integers(-2 ** 31, 2 ** 31 - 1)))
    return sec, draw(st.integers(0, 2 ** 32 - 1))


QUATERNIONS = st.one_of(st.tuples(*[hostile_float()] * 4),
                        st.sampled_from(((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0),
                                         (1e-310, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.01))))


VECTORS = st.tuples(*[hostile_float()] * 3)


ARRAYS = st.lists(hostile_float(), max_size=12)


EVENTS = st.lists(st.one_of(
    st.tuples(st.just('pose'), stamps(), QUATERNIONS),
    st.tuples(st.just('active_setpoint'), stamps(), QUATERNIONS),
    st.tuples(st.just('attitude_setpoint'), stamps(), QUATERNIONS),
    st.tuples(st.just('imu'), stamps(), st.tuples(VECTORS, VECTORS, st.booleans())),
    st.tuples(st.just('control_wrench'), stamps(), VECTORS),
    st.tuples(st.sampled_from(('cone_margins', 'disturbance_estimate')), st.none(), ARRAYS),
    st.tuples(st.just('motor_commands'), stamps(), st.tuples(     # (the session's text, values)
        st.one_of(st.integers(0, 2 ** 33).map(str), st.text(max_size=12)), ARRAYS)),
    st.tuples(st.just('configuration_error'), st.none(), hostile_float()),
    st.tuples(st.just('armed'), st.none(), st.lists(st.tuples(   # (key-values)
        st.sampled_from(('armed', 'session', 'other')),
        st.one_of(st.sampled_from(('true', 'false', '0', '1', '4294967295', '4294967296', '')),
                  st.text(max_size=12))), max_size=4)),
    st.tuples(st.just('esc_health'), st.none(), st.lists(st.tuples(
        st.sampled_from(('command_max', 'rotor 1', 'rotor 2', 'rotor 6', 'rotor 7', 'other')),
        st.one_of(st.sampled_from(('OK', 'IGNORED', 'LOST', 'FAULT', '240', '255', '-1', '')),
                  st.text(max_size=12))), max_size=8))),
    min_size=1, max_size=6)


def _message(msg_type, topic, stamp, payload):
    msg = msg_type()
    if stamp is not None and hasattr(msg, 'header'):
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
    if topic == 'pose':
        set_quaternion(msg.pose.orientation, payload)
    elif topic in ('active_setpoint', 'attitude_setpoint'):
        set_quaternion(msg.quaternion, payload)
    elif topic == 'imu':          # (angular velocity, specific force, "no specific force")
        set_vector(msg.angular_velocity, payload[0])
        set_vector(msg.linear_acceleration, payload[1])
        if payload[2]:
            msg.linear_acceleration_covariance[0] = -1.0
    elif topic == 'control_wrench':
        set_vector(msg.wrench.torque, payload)
    elif topic == 'configuration_error':
        msg.data = payload
    elif topic in ('cone_margins', 'disturbance_estimate'):
        msg.data = [float(x) for x in payload]
    elif topic == 'motor_commands':         # (a JointState: the session in its header)
        msg.header.frame_id = payload[0]
        msg.effort = [float(x) for x in payload[1]]
    elif topic in ('esc_health', 'armed'):  # (key-values, as a DiagnosticStatus's)
        msg.values = [KeyValue(key=k, value=v) for k, v in payload]
    else:
        msg.data = list(payload)
    return msg


def fuzz_messages(examples, seed):
    n = nodes()
    ctl, bridge, view, sim = n.controller, n.bridge, n.view, n.sim
    subs = {}

    def check(events):
        refused_before = ctl.loop.pose.refused + ctl.loop.rate.refused
        for topic, stamp, payload in events:
            if topic not in subs:
                subs[topic] = n.callbacks(topic)
            for msg_type, callback in subs[topic]:
                callback(_message(msg_type, topic, stamp, payload))
        ctl._tick(ctl._now())
        motors = ctl.motors_msg.effort
        if not all(x == 0.0 for x in motors):
            raise AssertionError('disarmed, yet motor commands %r' % (list(motors),))
        torque = ctl.telemetry.wrench.wrench.torque
        if not all(math.isfinite(v) for v in (torque.x, torque.y, torque.z)):
            raise AssertionError('a non-finite control moment')
        now = time.monotonic()
        for frame in ([bridge.vehicle.attitude(now), bridge.vehicle.attitude_target(now),
                       bridge.vehicle.actuators(now), bridge.vehicle.sys_status()]
                      + bridge.vehicle.internals(now)):
            if frame is not None:
                finite_fields(frame)
        for marker in view.markers().markers:
            for p in marker.points:
                if not all(math.isfinite(v) for v in (p.x, p.y, p.z)):
                    raise AssertionError('a non-finite marker point in %s' % marker.ns)
        if not np.all(np.isfinite(sim.commands)):
            raise AssertionError('the sim took non-finite commands %r' % sim.commands)
        cal = n.calibrate           # calibrate keeps only samples it can use
        for name in ('poses', 'gyros', 'forces'):
            kept = getattr(cal, name)
            if kept and not np.all(np.isfinite(np.array(kept))):
                raise AssertionError('calibrate kept non-finite %s' % name)
            del kept[:]
        # the next valid input is answered (a future stamp is re-anchored past after three)
        accepted = ctl.loop.pose.accepted, ctl.loop.rate.accepted
        t = ctl.get_clock().now().nanoseconds * 1e-9
        for k in range(4):
            pose, imu = PoseStamped(), Imu()
            pose.header.stamp = imu.header.stamp = time_msg(t + 1e-3 * k)
            set_quaternion(pose.pose.orientation, (0.0, 0.0, 0.0, 1.0))
            set_vector(imu.angular_velocity, (0.0, 0.0, 0.0))
            ctl._on_pose(pose)
            ctl._on_imu(imu)
        if not (ctl.loop.pose.accepted > accepted[0] and ctl.loop.rate.accepted > accepted[1]):
            raise AssertionError('valid pose and imu refused after the hostile ones')
        got = ctl.loop.pose.refused + ctl.loop.rate.refused - refused_before
        return 'refused %d' % got if got else None
    return run_property(Tally('messages'), EVENTS, check, examples, seed)

