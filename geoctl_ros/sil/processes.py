"""Sim-in-the-loop plumbing shared by the demo, the soak tool and the tests: start the installed
nodes as processes (as ``ros2 run`` would), and a monitor node that records their topics and calls
their services and parameters.

Every process started here runs with the loopback DDS profile and the caller's ``ROS_DOMAIN_ID``
(``geoctl_ros.sil.rosenv.node_env``), so DDS traffic stays on 127.0.0.1.
"""
import ipaddress
import os
import shutil
import signal
import struct
import subprocess
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from rcl_interfaces.srv import SetParameters
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray
from std_srvs.srv import SetBool, Trigger

from geoctl_ros.core.telemetry.diagnostics import NAME as CONTROLLER_STATUS
from geoctl_ros.mavlink.health import NAME as BRIDGE_STATUS
from geoctl_ros.nodes import qos
from geoctl_ros.nodes.conversions import (
    bridge_report,
    commands_of,
    key_values,
    stamp_seconds,
    status_of,
)
from geoctl_ros.records.fields import quaternion
from geoctl_ros.sil.rosenv import node_env


def executable(name):
    """Path of an installed console script: beside this Python (venv, pip) or in an ament
    prefix's lib/geoctl_ros (colcon). None if not found.
    """
    candidates = [os.path.join(os.path.dirname(sys.executable), name)]
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            candidates.append(os.path.join(prefix, 'lib', 'geoctl_ros', name))
    for c in candidates:
        if os.access(c, os.X_OK):
            return c
    return shutil.which(name)


# What the experiment runners over DDS (the demo's flight, the sensor cases, the soak) give the
# controller: an arming flies the file's set point (and schedule), as the headless runners do,
# where the shipped testbed arms into a hold (``arming_setpoint``, docs/parameters.md).
FLY_CONFIGURED = ('-p', 'controller:arming_setpoint:=configured')   # (the node's own: a
# wildcard '-p' loses to the file's controller section)


class NodeProcess:
    """One node as a child process, its output in a log file."""

    def __init__(self, name, params_file=None, ros_args=(), log_dir='.', env=None, prefix=()):
        """env: the process's environment (default: geoctl_ros.sil.rosenv.node_env()); prefix: a
        command to run it under (as ``ros2 run --prefix``), e.g. ('nice', '-n', '-10').
        """
        exe = executable(name)
        cmd = list(prefix) + ([exe] if exe else [sys.executable, '-m', 'geoctl_ros.nodes.' + name])
        cmd += ['--ros-args'] + (['--params-file', str(params_file)] if params_file else [])
        cmd += list(ros_args)
        self.name = name
        os.makedirs(str(log_dir), exist_ok=True)
        self.log_path = os.path.join(str(log_dir), '%s.log' % name)
        self._log = open(self.log_path, 'w')
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT,
                                     env=dict(node_env() if env is None else env,
                                              PYTHONUNBUFFERED='1'))

    def stop(self, timeout=5.0):
        """SIGINT (a clean stop), then SIGKILL if need be; returns the exit code."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()
        return self.proc.returncode

    def kill(self):
        """Die at once, as a crash would."""
        self.proc.kill()
        self.proc.wait()
        self._log.close()

    def output(self):
        if not self._log.closed:
            self._log.flush()
        with open(self.log_path) as f:
            return f.read()


RECORD_DEPTH = 50     # a monitor's history of each monitoring topic (0.5 s at 100 Hz)


class Monitor(Node):
    """Records what the controller and the sim publish; arms, sets parameters, injects input."""

    def __init__(self, controller='controller', record=None):
        """record: the log keys to subscribe to (default: all of them)."""
        super().__init__('geoctl_monitor')
        self._record = None if record is None else set(record)
        self.log = {k: [] for k in ('motors', 'margins', 'psi', 'dbar', 'true_pose', 'pose',
                                    'diagnostics', 'eR')}
        # the monitoring topics as they are published (best effort), with room for what arrives
        # while this process is busy: at depth 1 a stall kept only the newest, a series with holes
        tel = QoSProfile(depth=RECORD_DEPTH, reliability=ReliabilityPolicy.BEST_EFFORT)
        self._sub(JointState, 'motor_commands', 'motors', qos.COMMAND,
                  lambda m: list(commands_of(m)))
        self._sub(Float64MultiArray, 'cone_margins', 'margins', tel, lambda m: list(m.data))
        self._sub(Float64, 'configuration_error', 'psi', tel, lambda m: m.data)
        self._sub(Float64MultiArray, 'disturbance_estimate', 'dbar', tel, lambda m: list(m.data))
        self._sub(PoseStamped, 'sim/true_pose', 'true_pose', tel, _pose_quat)
        self._sub(PoseStamped, 'pose', 'pose', qos.SENSOR, _pose_quat)
        self.log['bridge'] = []                 # the MAVLink bridge's, typed
        self.log['other diagnostics'] = []
        self._sub(DiagnosticArray, '/diagnostics', 'diagnostics', qos.EVENT, None)
        self._sub(Vector3Stamped, 'attitude_error', 'eR', tel,
                  lambda m: (m.vector.x, m.vector.y, m.vector.z))
        self.arm_client = self.create_client(SetBool, '/%s/arm' % controller)
        self.reset_client = self.create_client(Trigger, '/%s/reset_adaptation' % controller)
        self.param_client = self.create_client(SetParameters, '/%s/set_parameters' % controller)
        self.executor_ = rclpy.executors.SingleThreadedExecutor()
        self.executor_.add_node(self)

    def _sub(self, msg_type, topic, key, qos, convert):
        if self._record is not None and key not in self._record:
            return

        def record(msg):
            if key == 'diagnostics':     # the controller's and the bridge's typed, others' as text
                for s in msg.status:
                    if s.name == CONTROLLER_STATUS:
                        self.log[key].append((time.monotonic(), status_of(s)))
                    elif s.name == BRIDGE_STATUS:
                        self.log['bridge'].append((time.monotonic(), bridge_report(s)))
                    else:
                        self.log['other diagnostics'].append((time.monotonic(), key_values(s)))
                return
            self.log[key].append((time.monotonic(), convert(msg)))
        self.create_subscription(msg_type, topic, record, qos)

    # --- waiting -----------------------------------------------------------------------------
    def spin_for(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor_.spin_once(timeout_sec=min(0.05, max(end - time.monotonic(), 0.0)))

    def wait_for(self, predicate, timeout, what='condition'):
        """Spin until predicate() is true; raises TimeoutError naming what did not happen."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return
            self.executor_.spin_once(timeout_sec=0.05)
        if predicate():
            return
        raise TimeoutError('timed out after %.1f s waiting for %s' % (timeout, what))

    def controller_has_inputs(self):
        """True once the controller's diagnostics show accepted pose and imu samples."""
        d = self.last_diagnostic()
        return (d is not None and d.figures.pose_counts.accepted > 0
                and d.figures.imu_counts.accepted > 0)

    def controller_can_judge_its_sensors(self):
        """True once the controller's diagnostics show 60 accepted samples of each input: more
        than the half second of poses and IMU samples its sensor checks judge at arming, at the
        rates a testbed streams (100-200 Hz).
        """
        d = self.last_diagnostic()
        return (d is not None and d.figures.pose_counts.accepted >= 60
                and d.figures.imu_counts.accepted >= 60)

    def since(self, key, t0):
        return [v for t, v in self.log[key] if t >= t0]

    def between(self, key, t0, t1):
        return [v for t, v in self.log[key] if t0 <= t <= t1]

    def last(self, key):
        return self.log[key][-1][1] if self.log[key] else None

    def last_diagnostic(self):
        return self.last('diagnostics')

    # --- calls -------------------------------------------------------------------------------
    def _call(self, client, request, timeout=10.0):
        self.wait_for(client.service_is_ready, timeout, 'service %s' % client.srv_name)
        future = client.call_async(request)
        self.wait_for(future.done, timeout, 'reply from %s' % client.srv_name)
        return future.result()

    def arm(self, on=True):
        return self._call(self.arm_client, SetBool.Request(data=on))

    def arm_when_ready(self, timeout=30.0):
        """Wait for the controller to report inputs, then ask it to arm every 0.2 s until it
        does or timeout s have passed (as an operator would: a refusal for an input late by a
        load spike passes, one that holds is the last reply); returns the last reply.
        """
        end = time.monotonic() + timeout
        self.wait_for(self.controller_has_inputs, timeout, 'the controller to receive its inputs')
        while True:
            reply = self.arm(True)
            if reply.success or time.monotonic() > end:
                return reply
            self.spin_for(0.2)

    def reset_adaptation(self):
        return self._call(self.reset_client, Trigger.Request())

    def set_parameter(self, name, value):
        return self.set_parameters([(name, value)])[0]

    def set_parameters(self, pairs):
        """Each (name, value) set on the controller by itself, in one service call (the
        non-atomic SetParameters: each is judged alone); the results in order.
        """
        msgs = [Parameter(name, value=value).to_parameter_msg() for name, value in pairs]
        return self._call(self.param_client, SetParameters.Request(parameters=msgs)).results


def _pose_quat(msg):
    return (stamp_seconds(msg.header.stamp), quaternion(msg.pose.orientation))


def process_sockets(pid):
    """The IP sockets process pid holds, as (protocol, local address, local port, remote address),
    read from /proc (Linux). The tests use it to prove that every socket is on loopback.
    """
    inodes = set()
    fd_dir = '/proc/%d/fd' % pid
    for fd in os.listdir(fd_dir):
        try:
            target = os.readlink(os.path.join(fd_dir, fd))
        except OSError:
            continue
        if target.startswith('socket:['):
            inodes.add(target[8:-1])
    out = []
    for proto in ('udp', 'tcp', 'udp6', 'tcp6'):
        try:
            with open('/proc/%d/net/%s' % (pid, proto)) as f:
                rows = f.read().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            cols = row.split()
            if cols[9] in inodes:
                local_ip, local_port = _proc_address(cols[1])
                remote_ip, _ = _proc_address(cols[2])
                out.append((proto, local_ip, local_port, remote_ip))
    return out


def _proc_address(text):
    """'0100007F:1C8B' (/proc/net: 32-bit words in host byte order) -> ('127.0.0.1', 7307)."""
    addr, port = text.split(':')
    words = [int(addr[k:k + 8], 16) for k in range(0, len(addr), 8)]
    raw = b''.join(struct.pack('=I', w) for w in words)
    ip = ipaddress.IPv4Address(raw) if len(raw) == 4 else ipaddress.IPv6Address(raw)
    return str(ip), int(port, 16)
