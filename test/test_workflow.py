"""The lab's own workflow over real DDS: sockets stay on loopback, short input gaps are ridden
through and long ones fail safe, and ``ros2 param dump`` round-trips through ``--params-file``.
(The flight watched by the real ``ros2`` command is test_node_flights.py's sim-in-the-loop flight.)

Tests that need the ``ros2`` command (../shared/wheels/ros2cli, installed by ./run) are skipped,
with the reason, where it is missing.
"""
import os
import subprocess
import time

import numpy as np
import pytest
import rclpy
import yaml

from geoctl_ros.core.geometry import so3
from geoctl_ros.sil import measures
from geoctl_ros.sil.loads import ros2_command
from geoctl_ros.sil.processes import NodeProcess, process_sockets
from geoctl_ros.sil.rosenv import cli_env, config_dir
from geoctl_ros.sil.soak import Session
from geoctl_ros.sim import scenario

pytestmark = pytest.mark.dds

TESTBED = os.path.join(config_dir(), 'testbed.yaml')
ROS2 = ros2_command()
needs_ros2 = pytest.mark.skipif(ROS2 is None, reason='no `ros2` command: install it from '
                                '../shared/wheels/ros2cli (./run does when the folder exists)')


def _rot(q):
    return so3.quat_to_rot(q)


def ros2(*args, timeout=60):
    """Run the real `ros2` command as a lab's shell would (LOCALHOST, no profile)."""
    env = cli_env()
    env['PATH'] = os.path.dirname(ROS2) + os.pathsep + env.get('PATH', '')
    return subprocess.run([ROS2, *args], env=env, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture
def stop_daemon():
    yield
    if ROS2:
        ros2('daemon', 'stop')


def test_every_socket_of_the_nodes_and_of_this_process_is_on_loopback(tmp_path):
    procs = [NodeProcess('sim', TESTBED, log_dir=tmp_path),
             NodeProcess('controller', TESTBED, log_dir=tmp_path)]
    rclpy.init()
    node = rclpy.create_node('socket_probe')
    try:
        # once the nodes have found each other and this process (discovery is what multicasts)
        deadline = time.monotonic() + 30.0
        while not {'sim', 'controller'} <= set(node.get_node_names()):
            assert time.monotonic() < deadline, 'the nodes were not discovered in 30 s'
            rclpy.spin_once(node, timeout_sec=0.1)
        for pid in [p.proc.pid for p in procs] + [os.getpid()]:
            socks = process_sockets(pid)
            assert socks, 'no sockets found for pid %d' % pid
            assert all(ip == '127.0.0.1' for _, ip, _, _ in socks), socks
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for p in procs:
            p.stop()


@pytest.mark.realtime
def test_short_gaps_are_ridden_through_and_a_long_one_fails_safe(tmp_path):
    s = Session(TESTBED, str(tmp_path), relay=True)
    mon = s.mon
    try:
        t0 = time.monotonic()
        for kind, arg in (('drop_pose', 0.4), ('drop_imu', 0.15)):
            s.fault(kind, arg)
            mon.spin_for(1.5)
        t_pause = time.monotonic()
        s.fault('pause', 0.15)                  # the sim SIGSTOPped: both inputs missing
        mon.spin_for(1.5)
        diags = [d for t, d in mon.log['diagnostics'] if t >= t0]
        assert all(d.figures.armed for d in diags), [d.figures.state for d in diags][-3:]
        messages = ' '.join(d.message for d in diags if d.level == 1)
        assert 'pose gap: attitude propagated with the gyro' in messages
        assert 'angular velocity gap: rate from successive poses' in messages
        last = diags[-1]
        assert last.figures.pose_gaps.ridden > 0
        assert last.figures.imu_gaps.ridden > 0
        def margin(t_from, t_to):
            return min(np.min(s.cones.margins_deg(_rot(q))) for t, (_, q) in mon.log['true_pose']
                       if t_from <= t < t_to)
        assert margin(t0, t_pause) > 0.0          # through the pose and imu gaps
        pause_margin = margin(t_pause, time.monotonic())
        print('150 ms sim pause: min cone margin %.1f deg' % pause_margin)
        # a 2 s pause: the failsafe at the imu's ride-through limit, motors zero
        t_long = time.monotonic()
        s.fault('pause', 2.0)
        mon.spin_for(0.5)
        d = mon.last_diagnostic()
        assert d.figures.armed is False and d.level == 2
        assert d.figures.state.startswith('failsafe: angular velocity lost') and \
            'ride-through limit 0.250 s' in d.figures.state
        assert d.figures.motor_commands == (0,) * 6
        times = s.command_times()
        assert len(times) > 100                  # the listener heard the flight
        # the soak's closest approach covers the whole armed flight, the yaw past the cone
        # right after the arming too: as close as its headless twin comes, not the hover's
        twin = scenario.run(scenario.load(TESTBED)).summary
        twin_margin = min(twin['min_cone_angle_deg'][n] - twin['cone_half_angle_deg'][n]
                          for n in twin['min_cone_angle_deg'])
        flown = measures.figures(mon, t0, t_long, s.cones, s.t_armed)   # (not the fall after)
        assert abs(flown['closest approach [deg]'] - twin_margin) < 1.5, (flown, twin_margin)
    finally:
        s.close()
    # the sim's own pause: before the ESC watchdog judged command age by the link, the sim
    # caught up with its motors stopped and once ended 5.9 deg inside (docs/safety-behaviour.md,
    # "Input gaps")
    assert pause_margin > 0.0, '150 ms sim pause: sensor %.1f deg inside the cone' % -pause_margin


@needs_ros2
@pytest.mark.parametrize('node', ['controller', 'sim'])
def test_param_dump_restarts_a_node_with_identical_parameters(tmp_path, stop_daemon, node):
    first = NodeProcess(node, TESTBED, log_dir=tmp_path)
    try:
        if node == 'controller':       # a cone added at run time, and one half-defined
            r = ros2('param', 'set', '--timeout', '20', '/' + node, 'cones.sun.axis',
                     '[0.0, 0.0, 1.0]')
            assert 'successful' in r.stdout, r.stdout + r.stderr
            # the rest in one call, set one by one in the file's order
            (tmp_path / 'more.yaml').write_text(
                '/controller:\n  ros__parameters:\n    cones:\n'
                '      sun: {half_angle_deg: 10.0}\n      names: [obstacle, sun]\n'
                '      moon: {axis: [0.0, 0.0, -1.0]}\n')
            r = ros2('param', 'load', '--timeout', '20', '/' + node, str(tmp_path / 'more.yaml'))
            assert r.returncode == 0 and r.stdout.count('successful') == 3, r.stdout + r.stderr
        dump = ros2('param', 'dump', '--timeout', '20', '/' + node)
        assert dump.returncode == 0, dump.stderr
    finally:
        first.stop()
    params = yaml.safe_load(dump.stdout)['/' + node]['ros__parameters']
    assert 'k_R' in params if node == 'controller' else 'integration_rate_hz' in params
    assert params['rotors']['failed'] == []                   # an empty array is listed
    (tmp_path / 'dump.yaml').write_text(dump.stdout)
    second = NodeProcess(node, tmp_path / 'dump.yaml', log_dir=tmp_path / 'second')
    try:
        again = ros2('param', 'dump', '--timeout', '20', '/' + node)
    finally:
        second.stop()
    assert yaml.safe_load(again.stdout) == yaml.safe_load(dump.stdout)
