"""Input-to-command latency of the controller node against a bare relay (the DDS floor), over
real DDS on the loopback profile, each in a process of its own (issue 10).

    ./run shell benchmarks/latency.py [--seconds 10] [--rate 100]

A prober node (this process) publishes pose and imu at --rate Hz and times, for each imu sample,
how long until the answer arrives: from ``relay.py`` (``relay/motor_commands``, no work) and from
the controller node with ``step_on: imu`` (``motor_commands``: a whole control step, armed, on
config/testbed.yaml). (With the default ``step_on: timer`` a sample also waits for the next tick,
0 to 1 period, by the phase of the two clocks; that wait is not measured here.) Both are measured
one after the other with the same prober, so what the prober and DDS cost is in each; the
difference is what the controller adds. Prints p50, p99 and max in milliseconds. Not a test.
"""
import argparse
import math
import os
import subprocess
import sys
import time

from geometry_msgs.msg import PoseStamped
import numpy as np
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import Imu, JointState
from std_srvs.srv import SetBool

from geoctl_ros.nodes import qos
from geoctl_ros.nodes.conversions import set_quaternion, time_msg
from geoctl_ros.sil.processes import NodeProcess
from geoctl_ros.sil.rosenv import node_env, use_node_env

HERE = os.path.dirname(os.path.abspath(__file__))



def measure(seconds=10.0, rate=100.0, log_dir='/tmp/geoctl_latency'):
    """{'relay', 'controller'}: arrays of ms, over `seconds` each."""
    use_node_env()

    class Prober(Node):
        def __init__(self):
            super().__init__('latency_prober')
            self.pub_pose = self.create_publisher(PoseStamped, 'pose', qos.SENSOR)
            self.pub_imu = self.create_publisher(Imu, 'imu', qos.SENSOR)
            self.sent = None             # perf time of the last imu sent
            self.latencies = {'relay': [], 'controller': []}
            self.recording = None
            self.create_subscription(JointState, 'relay/motor_commands',
                                     lambda m: self._got('relay'), qos.COMMAND)
            self.create_subscription(JointState, 'motor_commands',
                                     lambda m: self._got('controller'), qos.COMMAND)
            self.pose, self.imu = PoseStamped(), Imu()
            set_quaternion(self.pose.pose.orientation, (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)))
            self.imu.linear_acceleration.z = 9.81            # level, at rest
            self.create_timer(1.0 / rate, self._send)

        def _send(self):
            self.pose.header.stamp = self.imu.header.stamp = time_msg(time.time())
            self.pub_pose.publish(self.pose)
            self.sent = time.perf_counter()
            self.pub_imu.publish(self.imu)

        def _got(self, who):
            t = time.perf_counter()
            if who == self.recording and self.sent is not None:
                self.latencies[who].append(1e3 * (t - self.sent))
                self.sent = None          # one answer per sample (the timer's stand-ins aside)

    def spin(node, executor, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)

    rclpy.init()
    node = Prober()
    executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    procs = []
    try:
        relay = subprocess.Popen([sys.executable, os.path.join(HERE, 'relay.py')], env=node_env(),
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        spin(node, executor, 3.0)                 # discovery
        node.recording = 'relay'
        spin(node, executor, seconds)
        node.recording = None
        relay.send_signal(2)
        relay.wait(10)
        arm = node.create_client(SetBool, '/controller/arm')
        testbed = os.path.join(os.path.dirname(HERE), 'config', 'testbed.yaml')
        ctrl = NodeProcess('controller', testbed,
                           ['-p', 'step_on:=imu'], log_dir=log_dir)
        procs.append(ctrl)
        spin(node, executor, 3.0)
        for _ in range(20):
            if arm.service_is_ready():
                future = arm.call_async(SetBool.Request(data=True))
                end = time.monotonic() + 5.0
                while not future.done() and time.monotonic() < end:
                    executor.spin_once(timeout_sec=0.05)
                if future.done() and future.result().success:
                    break
            spin(node, executor, 0.5)
        else:
            raise RuntimeError('the controller did not arm (log: %s)' % ctrl.log_path)
        node.recording = 'controller'
        spin(node, executor, seconds)
        node.recording = None
    finally:
        for p in procs:
            p.stop()
        node.destroy_node()
        rclpy.try_shutdown()
    return {k: np.array(v) for k, v in node.latencies.items()}


def table(lat):
    lines = ['%-34s %8s %8s %8s %8s' % ('imu sample -> command received', 'samples', 'p50 ms',
                                        'p99 ms', 'max ms')]
    for who, label in (('relay', 'bare relay (DDS floor)'),
                       ('controller', 'controller node, step_on: imu')):
        v = lat[who]
        lines.append('%-34s %8d %8.3f %8.3f %8.3f' % (label, len(v), np.percentile(v, 50),
                                                      np.percentile(v, 99), v.max()))
    r, c = lat['relay'], lat['controller']
    lines.append('controller - relay: p50 %+.3f ms, p99 %+.3f ms' % (
        np.percentile(c, 50) - np.percentile(r, 50), np.percentile(c, 99) - np.percentile(r, 99)))
    return '\n'.join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=10.0)
    ap.add_argument('--rate', type=float, default=100.0)
    args = ap.parse_args(argv)
    print(table(measure(args.seconds, args.rate)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
