"""What the node tests over DDS share (test_nodes, test_node_flights, test_node_escs): the
installed console scripts run as separate processes, and a monitor node in this process (``ros``)
checks what they publish and feeds inputs where a test needs it.
"""
import math
import os
import pathlib
import subprocess
import sys

import numpy as np
import rclpy
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from support import FakeInputs

from geoctl_ros.core.geometry import so3
from geoctl_ros.sil.processes import NodeProcess, executable

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TESTBED = os.path.join(ROOT, 'config', 'testbed.yaml')
LEVEL_YAW90 = (0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5))     # the testbed's start attitude

# When this process feeds the inputs, its (Python, single-threaded) publisher can stall for tens of
# milliseconds under load; generous timeouts keep those tests about what they test. The drop-out
# test checks that the failsafe still comes within them.
FED = ('-p', 'pose_timeout:=0.25', '-p', 'imu_timeout:=0.25')
# the lab's sources, emulated by the sim and given to the controller (docs/sensors.md)
LAB_SOURCES = ('-p', 'pose_world_frame:=ned', '-p', 'body_frame:=frd',
               '-p', 'marker_rotation_deg:=[3.0,-2.0,30.0]',
               '-p', 'imu_rotation_deg:=[1.0,2.0,-90.0]')


def node_processes(tmp_path):
    """The ``ros`` fixture (conftest.py): a monitor node in this process and a launcher for node
    processes; all stopped after.
    """
    procs = []
    rclpy.init()
    mon = FakeInputs()

    def launch(name, params_file=TESTBED, *ros_args):
        p = NodeProcess(name, params_file, ros_args, log_dir=tmp_path)
        procs.append(p)
        return p

    launch.procs = procs
    yield mon, launch
    mon.destroy_node()
    rclpy.try_shutdown()
    for p in procs:
        code = p.stop()
        # pytest shows this only for a test that failed: what each node said, and how it ended
        print('--- %s (exit %s), the end of its log:\n%s' % (p.name, code, p.output()[-3000:]))


def published_values_are_finite(mon):
    for key in ('motors', 'margins', 'psi', 'dbar', 'eR'):
        for _, v in mon.log[key]:
            assert np.all(np.isfinite(v)), (key, v)


def wait_for_controller(mon):
    mon.wait_for(lambda: mon.last_diagnostic() is not None, 30.0, 'controller diagnostics')


def fed_controller(mon, launch, arm=False):
    """A controller (generous input timeouts) fed level-at-yaw-90 attitude from this process."""
    launch('controller', TESTBED, *FED)
    wait_for_controller(mon)
    mon.feed(LEVEL_YAW90)
    mon.spin_for(0.5)
    if arm:            # (once the sensor checks have half a second of samples)
        mon.wait_for(lambda: mon.arm(True).success, 10.0, 'arming')


def zero_commands(mon):
    return mon.last('motors') is not None and not any(mon.last('motors'))


def read_back(path, axis):
    """A bag as rosbags' own reader (not the package's) sees it: message counts per topic,
    first and last stamps (s since the epoch), the angle of the recorded true sensor direction
    to axis (deg, plain numpy) and the stamps of those true poses.
    """
    with AnyReader([pathlib.Path(path)],
                   default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        counts = dict.fromkeys((c.topic for c in reader.connections), 0)
        angles, stamps = [], []
        for conn, _, raw in reader.messages():
            counts[conn.topic] += 1
            if conn.topic == '/sim/true_pose':
                msg = reader.deserialize(raw, conn.msgtype)
                q = msg.pose.orientation
                sensor = so3.quat_to_rot((q.x, q.y, q.z, q.w)) @ np.array([1.0, 0.0, 0.0])
                angles.append(math.degrees(math.acos(np.clip(sensor @ axis, -1.0, 1.0))))
                stamps.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
        # every message that metadata.yaml counts is there
        assert counts == {c.topic: c.msgcount for c in reader.connections}
        return (counts, reader.start_time * 1e-9, reader.end_time * 1e-9, np.array(angles),
                np.array(stamps))


class OperatorCommand:
    """An operator's command (``setpoint``, ``stop``: geoctl_ros.nodes.commands) as its console
    script runs it (``ros2 run geoctl_ros NAME`` runs the same file), a process beside the
    monitor; where the script is not installed, its module.
    """

    def __init__(self, name, *args):
        exe = executable(name)
        cmd = [exe] if exe else [sys.executable, '-m', 'geoctl_ros.nodes.commands', name]
        self.proc = subprocess.Popen(cmd + list(args), stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)

    def answer(self, mon, timeout=30.0):
        """(exit code, output), the monitor spinning (and recording) while the command runs."""
        try:
            mon.wait_for(lambda: self.proc.poll() is not None, timeout, 'the command to answer')
        except TimeoutError:
            self.proc.kill()
            self.proc.wait()
            raise
        return self.proc.returncode, self.proc.stdout.read()
