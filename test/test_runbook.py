"""The runbook as a test: docs/first-flight.md's commands, as written there, fly a first flight in
the sim-in-the-loop for an ENU lab and a NED lab.

The sim stands in for the motion-capture and IMU drivers: it publishes on the drivers' topics
(``/vicon/hexrotor/pose``, ``/vn100/imu``) in the lab's conventions (``pose_world_frame``,
``body_frame``: docs/sensors.md) with a marker set turned 7 deg in yaw (and tilted) against the
airframe, started as the runbook starts a driver (``ros2 run --prefix "<realtime> 50" ...``),
the vehicle resting level with its nose along the motion capture's x axis. Then, in the
runbook's order, each command read from the runbook (``~`` and ``$HOME`` the lab's folder) and run
with the real ``ros2`` command on the package as colcon installs it:

- steps 2-3: the lab's parameter file is the shipped one with step 3's row for the lab's
  conventions; ``calibrate`` writes a marker yaw within 1 deg of the truth;
- steps 5 and 9: ``ros2 launch geoctl_ros testbed.launch.xml`` on the lab's file and the
  calibration (without ``esc:=true`` and the bridge: no I2C bus, no ground station here), and
  the flight's ``record`` (``flight1``) on the drivers' topics (step 9's clamped arming, and its
  bag, are not flown here);
- step 10: ``ros2 service call /controller/arm``: the arming holds (under 2 deg); a set point
  into the cone is refused with its reason; one round the cone is flown (the goal reached, the
  cone kept); ``ros2 run geoctl_ros stop`` disarms;
- step 11: ``record`` stopped, ``ros2 run geoctl_ros report flight1``: its closest approach is the
  one the monitor heard.

Shortened against the runbook for the suite's time: ``calibrate --seconds 2`` (not 5), and the
hold watched 2 s (the runbook's flight has no fixed wait). Every wait is for a condition.
"""
import json
import math
import os
import re
import shlex
import signal
import subprocess
import time

import numpy as np
import pytest
import rclpy
from workspace import BIN, HAVE_LAUNCH, NO_LAUNCH, ROOT
import yaml

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.sensors.frames import matrix_rpy, rpy_matrix
from geoctl_ros.params import cone_set, load_parameter_file, node_overrides, resolve
from geoctl_ros.sil.processes import Monitor
from geoctl_ros.sil.rosenv import cli_env

pytestmark = [pytest.mark.dds, pytest.mark.skipif(not HAVE_LAUNCH, reason=NO_LAUNCH)]

RUNBOOK = os.path.join(ROOT, 'docs', 'first-flight.md')
TESTBED = os.path.join(ROOT, 'config', 'testbed.yaml')
ROS2 = os.path.join(BIN, 'ros2')
MARKER_TRUTH = (1.5, -2.0, 7.0)     # the marker set against the airframe (roll, pitch, yaw deg)
HOLD_S = 2.0
# per lab: the sim's emulation, step 3's table row (what the poses show), the vehicle's rest
# (its nose along the motion capture's x axis: ENU yaw 0; NED north, ENU yaw 90) and the set
# point round the cone from there (the shipped manoeuvre, or its mirror image), in ENU yaw
LABS = {
    'enu': ({'pose_world_frame': 'enu', 'body_frame': 'flu'},
            ('z rises (positive)', '+9.8'), 0.0, 90.0),
    'ned': ({'pose_world_frame': 'ned', 'body_frame': 'frd'},
            ('z falls (negative)', '-9.8'), 90.0, 0.0),
}
INTO_THE_CONE = ('setpoint', '--yaw-deg', '45')      # the sensor on the cone's axis


def runbook_commands():
    """Every command in the runbook's indented blocks, continuation lines joined."""
    lines, out, pending = open(RUNBOOK).read().splitlines(), [], ''
    for line in lines:
        if not line.startswith('    ') or line.strip().startswith('#'):
            pending = ''
            continue
        text = pending + line.strip()
        if text.endswith('\\'):
            pending = text[:-1] + ' '
            continue
        pending = ''
        out.append(text)
    return out


def runbook_command(start, lab):
    """The one runbook command beginning with start, as argv, ~ and $HOME the lab's folder."""
    found = sorted(set(c for c in runbook_commands() if c.startswith(start)))
    assert len(found) == 1, (start, found)
    text = found[0].replace('$HOME/', str(lab) + '/').replace('~/', str(lab) + '/')
    return shlex.split(text.replace('<laptop IP>', '127.0.0.1'))


def table_row(shows):
    """Step 3's settings for what the pose shows turned left and what the IMU reads level:
    {name: value}, parsed from the runbook.
    """
    for line in open(RUNBOOK).read().splitlines():
        cells = [c.strip() for c in line.strip('|').split('|')]
        if len(cells) == 3 and tuple(cells[:2]) == shows:
            if cells[2].startswith('nothing'):
                return {}
            return {k: yaml.safe_load(v) for k, v in re.findall(r'`(\w+): ([^`]+)`', cells[2])}
    raise AssertionError('no row %r in step 3 of docs/first-flight.md' % (shows,))


def quaternion_of_yaw(yaw_deg):
    return [float(v) for v in so3.rot_to_quat(rpy_matrix((0.0, 0.0, yaw_deg)))]


class Command:
    """A runbook command (argv starting with ros2) in the lab's folder, in a process group of its
    own (in this session: see workspace.Launch); nodes with the loopback profile (env), the plain
    `ros2` verbs as a lab's shell has them.
    """

    def __init__(self, argv, env, lab, log=None):
        assert argv[0] == 'ros2', argv
        self.log = open(log, 'w+') if log else None
        self.proc = subprocess.Popen(
            [ROS2] + argv[1:], env=env, cwd=str(lab), text=True, process_group=0,
            stdout=self.log or subprocess.PIPE, stderr=subprocess.STDOUT)

    def answer(self, mon, timeout=40.0):
        """(exit code, output), the monitor spinning while the command runs."""
        try:
            mon.wait_for(lambda: self.proc.poll() is not None, timeout, 'the command: %s' %
                         ' '.join(self.proc.args[1:]))
        finally:
            if self.proc.poll() is None:
                self.interrupt(kill=True)
        return self.proc.returncode, self.output()

    def output(self):
        if self.log is None:
            return self.proc.stdout.read()
        self.log.flush()
        with open(self.log.name) as fh:
            return fh.read()

    def interrupt(self, kill=False):
        """Ctrl-C in its terminal (SIGKILL with kill, or when it does not end in 15 s)."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL if kill else signal.SIGINT)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        return self.proc.returncode


def rotation(mon, t):
    """The true attitude last heard at or before t (monotonic)."""
    return so3.quat_to_rot([q for s, (_, q) in mon.log['true_pose'] if s <= t][-1])


@pytest.mark.realtime
@pytest.mark.rtchain
@pytest.mark.parametrize('world', sorted(LABS))
def test_the_runbook_flies_a_first_flight(installed, tmp_path, world):
    env, prefix = installed
    sources, shows, rest_yaw, goal_yaw = LABS[world]
    lab = tmp_path
    shell = dict(cli_env(env), PATH=BIN + os.pathsep + env['PATH'])     # the `ros2` verbs
    # step 2: the lab's file, the shipped one with step 3's row for what its poses show
    runbook_command('cp ~/ws/src/geoctl_ros/config/testbed.yaml ~/testbed.yaml', lab)
    doc = yaml.safe_load(open(TESTBED))
    doc['/**']['ros__parameters'].update(table_row(shows))
    (lab / 'testbed.yaml').write_text(yaml.safe_dump(doc))
    # the drivers: the sim, on their topics, in the lab's conventions (the shipped file: the lab's
    # conventions reach it only as the truth it emulates), started as the runbook starts one
    realtime = str(prefix / 'lib' / 'geoctl_ros' / 'realtime')
    # (its rest in a file of its own: a -p does not override the file's sim section)
    doc = yaml.safe_load(open(TESTBED))
    doc['sim']['ros__parameters']['initial_attitude'] = quaternion_of_yaw(rest_yaw)
    (lab / 'sim.yaml').write_text(yaml.safe_dump(doc))
    emulation = ['-p', 'marker_rotation_deg:=[%s]' % ','.join(map(str, MARKER_TRUTH))]
    for k, v in sources.items():
        emulation += ['-p', '%s:=%s' % (k, v)]
    procs = []
    rclpy.init()
    mon = Monitor(record=('true_pose', 'diagnostics', 'psi'))
    try:
        procs.append(Command(
            ['ros2', 'run', '--prefix', '%s 50' % realtime, 'geoctl_ros', 'sim', '--ros-args',
             '--params-file', str(lab / 'sim.yaml'), '-r', 'pose:=/vicon/hexrotor/pose', '-r',
             'imu:=/vn100/imu'] + emulation, env, lab, lab / 'sim.log'))
        mon.wait_for(lambda: mon.log['true_pose'], 30.0, 'the sim')
        # step 3: calibrate, level and at rest, nose along the motion capture's x axis
        calibrate = runbook_command('ros2 run geoctl_ros calibrate', lab)
        calibrate[calibrate.index('--seconds') + 1] = '2'
        code, out = Command(calibrate, env, lab).answer(mon, 60.0)
        assert code == 0, out
        assert ("heading: 0.0 deg from the motion capture's x axis (stated; yaw %.1f deg in "
                "ENU)" % rest_yaw) in out, out
        written = load_parameter_file(str(lab / 'calibration.yaml'))['controller']
        marker = written['marker_rotation_deg']
        print('%s: calibrate wrote marker_rotation_deg %s (truth %s)' % (world, marker,
                                                                        list(MARKER_TRUTH)))
        assert abs(marker[2] - MARKER_TRUTH[2]) < 1.0, (marker, out)
        # steps 5 and 8: the chain (no ESC bus, no ground station here) and the record
        launch = runbook_command('ros2 launch geoctl_ros testbed.launch.xml', lab)
        launch = [a for a in launch if not a.startswith(('esc', 'mavlink'))]
        procs.append(Command(launch, env, lab, lab / 'launch.log'))
        chain = procs[-1]
        # (the flight's bag: the clamped arming's, step 8's clamp1, is not flown here)
        recorder = Command(runbook_command('ros2 run geoctl_ros record --ros-args -p '
                                           'record.path:=flight1', lab), env, lab,
                           lab / 'record.log')
        procs.append(recorder)
        mon.wait_for(mon.controller_can_judge_its_sensors, 40.0, 'the launched controller')
        mon.wait_for(lambda: "stored the controller's" in recorder.output(), 30.0, 'record')
        assert 'inputs: pose world %s, body %s' % (sources['pose_world_frame'],
                                                  sources['body_frame']) in chain.output()
        # step 10: arm, into the hold
        arm = runbook_command('ros2 service call /controller/arm std_srvs/srv/SetBool '
                              '"{data: true}"', lab)
        for _ in range(3):              # (a refusal for a sample late by a load spike passes)
            t_call = time.monotonic()
            code, out = Command(arm, shell, lab).answer(mon)
            if "success=True, message='armed'" in out:
                break
        assert "std_srvs.srv.SetBool_Response(success=True, message='armed')" in out, out
        R_armed = rotation(mon, t_call)
        # a set point into the cone: refused, with its reason, and the hold goes on
        code, out = Command(['ros2', 'run', 'geoctl_ros', *INTO_THE_CONE], env, lab).answer(mon)
        assert code == 1 and (
            "refused: setpoint: setpoint puts the sensor axis inside cone 'obstacle' (angle to "
            "its axis 0.00 deg, half-angle 12.00 deg)") in out.splitlines(), (code, out)
        mon.wait_for(lambda: mon.log['true_pose'][-1][0] > t_call + HOLD_S, 10.0, 'the hold')
        t_round = time.monotonic()
        moved = max(math.degrees(so3.angle(R_armed.T @ so3.quat_to_rot(q)))
                    for _, q in mon.between('true_pose', t_call, t_round))
        print('%s: the hold moved %.2f deg in %.1f s' % (world, moved, t_round - t_call))
        assert moved < 2.0, moved
        # a set point round the cone
        code, out = Command(['ros2', 'run', 'geoctl_ros', 'setpoint', '--yaw-deg',
                             '%g' % goal_yaw], env, lab).answer(mon)
        accepted = 'accepted: set point [%s] (x, y, z, w; yaw %g, pitch 0, roll 0 deg)' % (
            ', '.join('%.4f' % v for v in quaternion_of_yaw(goal_yaw)), goal_yaw)
        assert code == 0 and accepted in out.splitlines(), (code, out)
        goal = rpy_matrix((0.0, 0.0, goal_yaw))
        mon.wait_for(lambda: math.degrees(so3.angle(goal.T @ rotation(mon, time.monotonic())))
                     < 1.0, 15.0, 'the goal, within 1 deg')
        t_there = time.monotonic()
        values = resolve('controller', node_overrides(
            load_parameter_file(str(lab / 'testbed.yaml')), 'controller'))
        flown = min(float(np.min(cone_set(values).margins_deg(so3.quat_to_rot(q))))
                    for _, q in mon.between('true_pose', t_round, t_there))
        print('%s: round the cone to yaw %g (ENU): reached in %.1f s, %.2f deg clear at closest'
              % (world, goal_yaw, t_there - t_round, flown))
        assert flown > 0.0
        assert all(d.figures.armed for d in mon.between('diagnostics', t_round, t_there))
        assert abs(matrix_rpy(rotation(mon, t_there))[2] - goal_yaw) < 1.0
        # the stop
        code, out = Command(runbook_command('ros2 run geoctl_ros stop', lab), env, lab
                            ).answer(mon)
        assert code == 0 and 'accepted: disarmed' in out.splitlines(), (code, out)
        # step 11: the record stopped, its report
        assert recorder.interrupt() == 0, recorder.output()[-2000:]
        t_end = time.monotonic()
        assert 'wrote flight1: /vicon/hexrotor/pose' in recorder.output(), recorder.output()
        code, out = Command(runbook_command('ros2 run geoctl_ros report flight1', lab), env, lab
                            ).answer(mon, 60.0)
    finally:
        mon.destroy_node()
        rclpy.try_shutdown()
        for p in reversed(procs):
            p.interrupt()
    assert code == 0, out
    closest = re.search(r'\| closest approach, cone obstacle \| ([-\d.]+) deg '
                        r'\(half-angle 12.0\): margin ([-\d.]+) deg at ([\d.]+) s \|', out)
    assert closest, out
    print('%s: report flight1: closest approach %s deg, margin %s deg at %s s' % (
        world, *closest.groups()))
    summary = json.loads((lab / 'flight1' / 'report' / 'summary.json').read_text())
    assert summary is not None
    # the report's closest approach is the one heard over the recording (the fall after the stop
    # included), within the few poses the monitor and the recorder did not both hear
    heard = min(float(np.min(cone_set(values).margins_deg(so3.quat_to_rot(q))))
                for t, (_, q) in mon.log['true_pose'] if t <= t_end)
    assert abs(float(closest.group(2)) - heard) < 0.3, (closest.group(0), heard)
    assert float(closest.group(2)) > 0.0
