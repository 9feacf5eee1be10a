"""The controller and sim nodes over real DDS (loopback, a domain of this test run's own): how they
arm, refuse, fail safe, restart and take their parameters (node_support.py: the processes and the
monitor node).
"""
import math
import time

from diagnostic_msgs.msg import DiagnosticStatus
from node_support import (
    FED,
    LEVEL_YAW90,
    TESTBED,
    OperatorCommand,
    fed_controller,
    published_values_are_finite,
    wait_for_controller,
    zero_commands,
)
import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.telemetry.diagnostics import ERROR, WARN
from geoctl_ros.nodes import commands, qos
from geoctl_ros.nodes.controller import ControllerNode
from geoctl_ros.nodes.conversions import (
    armed_state_of,
    refusal_reason,
    session_of,
    stamp_seconds,
)

pytestmark = pytest.mark.dds


@pytest.mark.realtime
def test_arming_needs_fresh_inputs_and_disarming_zeroes_the_motors(ros):
    mon, launch = ros
    launch('controller', TESTBED, *FED)
    wait_for_controller(mon)
    mon.spin_for(0.5)
    assert zero_commands(mon)
    reply = mon.arm(True)
    assert not reply.success and 'no pose received yet' in reply.message
    diag = mon.last_diagnostic()
    assert diag.level == WARN and 'disarmed' in diag.message
    # an IMU that is FRD (its gravity down the body's z) where the file says FLU: refused,
    # named, and the ground station's diagnostics say it too
    mon.feed_force_axes = np.diag([1.0, -1.0, -1.0])
    mon.feed(LEVEL_YAW90)
    mon.wait_for(lambda: 'sensor check' in mon.last_diagnostic().message, 10.0,
                 'the sensor check in the diagnostics')
    assert 'the IMU looks FRD while body_frame says flu' in mon.last_diagnostic().message
    reply = mon.arm(True)
    assert not reply.success and 'the IMU looks FRD while body_frame says flu' in reply.message
    mon.feed_force_axes = np.eye(3)                          # an FLU IMU: it arms
    mon.wait_for(lambda: mon.arm(True).success, 10.0, 'arming with the IMU that agrees')
    # about hover (118/240): a condition, since this process's feeder can stall beside the other
    # DDS tests, and the commands move while the controller rides its gap through
    mon.wait_for(lambda: all(0.3 < c < 0.7 for c in mon.last('motors')), 5.0, 'about hover')
    # each command as a receiver sees it: its rotors by name, when it was made, and the session
    # the controller's armed state names (what esc_i2c follows)
    sent, armed = [], []
    mon.create_subscription(JointState, 'motor_commands', sent.append, qos.COMMAND)
    mon.create_subscription(DiagnosticStatus, '/controller/armed', armed.append, qos.LATCHED)
    mon.wait_for(lambda: sent and armed, 5.0, 'a command and the armed state')
    state, msg = armed_state_of(armed[-1]), sent[-1]
    assert state.armed and session_of(msg) == state.session != 0
    assert list(msg.name) == ['rotor %d' % i for i in range(1, 7)] and len(msg.effort) == 6
    assert abs(stamp_seconds(msg.header.stamp) - time.time()) < 2.0
    # the arming holds the attitude fed (arming_setpoint hold); a set point 90 deg from it, sent
    # as the setpoint command sends it, is taken armed
    assert mon.set_parameter('setpoint', [0.0, 0.0, 0.0, 1.0]).successful
    # 90 deg from R_d: the estimate grows (a condition: beside the flights at nice 19 this test's
    # feeder stalls, and the controller learns nothing while it rides the gaps through)
    mon.wait_for(lambda: np.linalg.norm(mon.last('dbar')) > 1e-3, 10.0, 'the estimate to grow')
    before = np.linalg.norm(mon.last('dbar'))
    assert mon.reset_adaptation().success
    t_reset = time.monotonic()
    mon.spin_for(0.2)
    # zeroed: the first estimates after the reset have grown for a tick or two only (the inputs
    # are held still, so the controller's delay compensation predicts a motion that never comes
    # and the estimate keeps growing afterwards); the least heard since, as one published
    # before the reset may still be taken after it
    assert min(np.linalg.norm(v) for v in mon.since('dbar', t_reset)) < 0.2 * before
    # the operator's commands (their console scripts): hold the attitude now, then stop
    code, out = OperatorCommand('setpoint', '--hold').answer(mon)
    assert (code, out.strip()) == (0, 'accepted: holding [0.0000, 0.0000, 0.7071, 0.7071] '
                                      '(x, y, z, w)'), out
    code, out = OperatorCommand('stop').answer(mon)
    assert (code, out.strip()) == (0, 'accepted: disarmed'), out
    mon.wait_for(lambda: zero_commands(mon), 2.0, 'zero commands after disarming')
    assert mon.last_diagnostic().figures.state == 'disarm requested'


@pytest.mark.realtime
def test_input_dropout_fails_safe_to_zero_and_disarms(ros):
    mon, launch = ros
    fed_controller(mon, launch, arm=True)
    mon.spin_for(0.5)
    assert any(mon.last('motors'))
    mon.stop_feed()                                           # motion capture and IMU go quiet
    t_drop = time.monotonic()
    mon.wait_for(lambda: zero_commands(mon), 2.0, 'zero commands after the drop-out')
    assert time.monotonic() - t_drop < 0.25 + 0.5              # the timeout, plus slack
    mon.wait_for(lambda: mon.last_diagnostic().level == ERROR, 2.0, 'an ERROR diagnostic')
    diag = mon.last_diagnostic()
    assert diag.figures.armed is False
    assert 'failsafe' in diag.message and 'stale' in diag.message
    mon.feed(LEVEL_YAW90)                                     # data back: stays disarmed
    mon.spin_for(0.5)
    assert zero_commands(mon)
    mon.wait_for(lambda: mon.arm(True).success, 10.0, 'armed again')   # until armed again


@pytest.mark.realtime
def test_nan_and_garbage_inputs_are_refused_and_never_reach_a_topic(ros):
    mon, launch = ros
    fed_controller(mon, launch, arm=True)
    bad_poses = [(math.nan, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 2.0), (0.0, 0.0, 0.0, 0.0),
                 (math.inf, 0.0, 0.0, 0.0)]
    for q in bad_poses:
        mon.publish_pose(q)
        mon.spin_for(0.05)
    old = rclpy.time.Time(seconds=1.0).to_msg()               # out of order
    mon.publish_pose(LEVEL_YAW90, old)
    for w in [(math.nan, 0.0, 0.0), (500.0, 0.0, 0.0)]:
        mon.publish_imu(w)
        mon.spin_for(0.05)
    mon.wait_for(lambda: mon.last_diagnostic().figures.pose_counts.refused == 5
                 and mon.last_diagnostic().figures.imu_counts.refused == 2, 3.0,
                 'the refusals to show in the diagnostics')
    refusals = ' '.join(d.message for _, d in mon.log['diagnostics'])
    for reason in ('not finite', 'not unit length', 'not newer than', 'max_angular_velocity'):
        assert reason in refusals
    assert mon.last_diagnostic().figures.armed          # the good stream went on
    published_values_are_finite(mon)


def test_parameters_change_at_run_time_and_bad_ones_are_refused(ros):
    mon, launch = ros
    fed_controller(mon, launch)
    assert mon.set_parameter('k_R', 0.5).successful
    bad = mon.set_parameter('k_R', -1.0)
    assert not bad.successful and 'k_R: must be > 0' in bad.reason
    typo = mon.set_parameter('k_r', 0.5)
    assert not typo.successful and "did you mean 'k_R'" in typo.reason
    wrong_type = mon.set_parameter('k_R', 1)
    assert not wrong_type.successful
    # add a cone at run time: its parameters first, then its name
    assert mon.set_parameter('cones.sun.axis', [0.0, 0.0, 1.0]).successful
    assert mon.set_parameter('cones.sun.half_angle_deg', 10.0).successful
    assert mon.set_parameter('cones.names', ['obstacle', 'sun']).successful
    mon.wait_for(lambda: len(mon.last('margins')) == 2, 2.0, 'two cone margins')
    assert mon.last('margins')[1] == pytest.approx(80.0, abs=0.5)    # sensor level: 90 - 10
    # a cone round the current set point (R_d = I puts the sensor on +x) is refused
    assert mon.set_parameter('cones.bad.axis', [1.0, 0.0, 0.0]).successful
    assert mon.set_parameter('cones.bad.half_angle_deg', 5.0).successful
    refused = mon.set_parameter('cones.names', ['obstacle', 'sun', 'bad'])
    assert not refused.successful and "inside cone 'bad'" in refused.reason
    assert mon.set_parameter('cones.names', ['obstacle']).successful
    mon.wait_for(lambda: len(mon.last('margins')) == 1, 2.0, 'one cone margin')
    # a set point flown from the topic is protected too: a cone round it is refused
    mon.publish_setpoint(so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(-90.0))))
    mon.spin_for(0.3)
    assert mon.set_parameter('cones.south.axis', [0.0, -1.0, 0.0]).successful
    assert mon.set_parameter('cones.south.half_angle_deg', 10.0).successful
    refused = mon.set_parameter('cones.names', ['obstacle', 'south'])
    assert not refused.successful and 'the current setpoint' in refused.reason
    # the controller kept running throughout
    n = len(mon.log['motors'])
    # (a condition, not a rate: at nice 19 beside the flights the sim can stall 0.4 s)
    mon.wait_for(lambda: len(mon.log['motors']) > n + 20, 5.0, 'more motor commands')


def test_setpoint_inside_a_cone_is_rejected(ros):
    mon, launch = ros
    fed_controller(mon, launch)
    mon.wait_for(lambda: mon.last('eR') is not None, 10.0, 'the attitude error')
    e_before = mon.last('eR')
    inside = so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(45.0)))
    mon.publish_setpoint(inside)
    mon.wait_for(lambda: 'setpoint rejected' in mon.last_diagnostic().message, 2.0,
                 'the rejection in the diagnostics')
    assert "inside cone 'obstacle'" in mon.last_diagnostic().message
    mon.spin_for(0.3)
    assert np.allclose(mon.last('eR'), e_before, atol=1e-3)   # the old set point stays
    fine = so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(80.0)))
    mon.publish_setpoint(fine)
    mon.spin_for(0.5)
    assert np.linalg.norm(mon.last('eR')) < np.linalg.norm(e_before)


def test_controller_restart_comes_back_disarmed_and_the_sim_stops_its_motors(ros):
    mon, launch = ros
    launch('sim')
    first = launch('controller')
    assert mon.arm_when_ready().success
    mon.spin_for(1.0)
    first.kill()                                              # a crash: no last words
    # with no commands the sim's motors stop after command_timeout, as the ESCs would
    sim = [p for p in launch.procs if p.name == 'sim'][0]
    mon.wait_for(lambda: 'motors stopped' in sim.output(), 5.0, 'the sim to stop its motors')
    # the sim's joint has no friction: a spin the crash left stays (once, in a CI run at nice 19,
    # 138 rad/s, which a controller at the default max_angular_velocity rightly refuses; this
    # test is about the restart, not about that limit: the restarted one takes its range's top)
    launch('controller', TESTBED, '-p', 'max_angular_velocity:=200.0')
    # (messages the old one sent just before it died may still arrive: tell them apart by state)
    mon.wait_for(lambda: mon.last_diagnostic().figures.state == 'disarmed at start-up', 30.0,
                 'the restarted controller')
    t_new = time.monotonic()
    mon.wait_for(mon.controller_has_inputs, 10.0, 'the restarted controller to receive the sim')
    mon.spin_for(0.3)
    # the restarted controller comes up disarmed and sends only zeros
    new_commands = [c for t, c in mon.log['motors'] if t > t_new]
    assert new_commands and all(not any(c) for c in new_commands)
    assert mon.last_diagnostic().figures.armed is False
    # it answers an arm request: it arms, or the preflight checks name what stands in the way
    # (the crash left the testbed falling, perhaps into the cone, and the new controller has not
    # seen it rest: a refusal that holds for 10 s is the answer)
    reply = mon.arm_when_ready(timeout=10.0)
    assert reply.success or any(w in reply.message for w in (
        'inside cone', 'within the guard', 'disagree', 'has not rested since start')), (
        reply.message)


def test_a_bad_parameter_file_stops_the_node_with_the_reason(ros, tmp_path):
    _, launch = ros
    bad = tmp_path / 'bad.yaml'
    bad.write_text('controller:\n  ros__parameters:\n    k_Omega: -0.7\n    G: [1.0, 1.0, 1.0]\n')
    p = launch('controller', bad)
    assert p.proc.wait(30) == 2
    out = p.output()
    assert 'k_Omega: must be > 0' in out and 'G: weights must be distinct' in out


def test_a_parameter_file_that_does_not_exist_stops_the_node_naming_it(ros, tmp_path):
    _, launch = ros
    p = launch('controller', tmp_path / 'missing.yaml')
    assert p.proc.wait(30) == 2
    out = p.output()
    assert 'controller: cannot start' in out and 'missing.yaml' in out
    assert 'Traceback' not in out


def test_without_a_parameter_file_every_arm_is_refused_until_the_opt_in(ros):
    mon, launch = ros
    launch('controller', None)             # as `ros2 run geoctl_ros controller`, nothing given
    wait_for_controller(mon)
    mon.feed(LEVEL_YAW90)
    mon.wait_for(mon.controller_has_inputs, 10.0, 'fresh inputs at the controller')
    reply = mon.arm(True)
    assert not reply.success and 'no configuration given' in reply.message, reply.message
    mon.spin_for(0.6)                      # a diagnostics window
    diag = mon.last_diagnostic()
    assert diag.level == WARN and 'no configuration given' in diag.message
    assert zero_commands(mon) and diag.figures.armed is False
    assert mon.set_parameter('allow_default_configuration', True).successful
    reply = mon.arm_when_ready()
    assert reply.success, reply.message
    mon.wait_for(lambda: not zero_commands(mon), 2.0, 'the motors running on the defaults')
    assert mon.arm(False).success


def test_a_controller_whose_file_does_not_address_its_namespace_is_not_configured(ros):
    """The issue's case: `controller --ros-args -r __ns:=/hex --params-file testbed.yaml` got the
    file's /** values (mass, gravity) and armed with 0 cones. Those alone no longer count: it
    says it has no configuration of its own, naming itself, and refuses every arm.
    """
    mon, launch = ros
    hexed = launch('controller', TESTBED, '-r', '__ns:=/hex')
    mon.wait_for(lambda: 'no configuration given for /hex/controller' in hexed.output(), 30.0,
                 'the namespaced controller')
    arm = mon.create_client(SetBool, '/hex/controller/arm')
    reply = mon._call(arm, SetBool.Request(data=True))
    assert not reply.success and 'no configuration given for /hex/controller' in reply.message


def test_sim_refuses_garbage_motor_commands(ros):
    mon, launch = ros
    sim = launch('sim')
    mon.wait_for(lambda: len(mon.log['pose']) > 5, 30.0, 'the sim')
    for data in ([0.5] * 5, [math.nan] * 6, [2.0] * 6):
        mon.publish_commands(data)
        mon.spin_for(0.2)
    # (at nice 19 beside the flights a starved sim has taken 2 s to get to the last one)
    mon.wait_for(lambda: 'expected 6 finite values' in sim.output()
                 and 'outside [0, 1]' in sim.output(), 30.0, 'both refusals in the log')
    assert len(mon.log['true_pose']) > 5


def test_arming_is_refused_while_another_node_commands_the_motors(ros):
    mon, launch = ros
    launch('controller', TESTBED, *FED)
    wait_for_controller(mon)
    mon.feed(LEVEL_YAW90)
    mon.publish_commands([0.0] * 6)            # a second "controller" on motor_commands
    mon.spin_for(1.0)
    reply = mon.arm(True)
    assert not reply.success and 'other publisher(s) on /motor_commands' in reply.message
    mon.wait_for(lambda: 'another controller' in mon.last_diagnostic().message, 2.0,
                 'the warning in the diagnostics')


@pytest.mark.realtime
def test_step_on_imu_steps_on_every_sample_and_the_timer_still_fails_safe(ros):
    """step_on: imu (the least input-to-command latency, see benchmarks/latency.py): fed at
    200 Hz, twice rate_hz, the controller steps (and publishes a command) for every imu sample it
    accepts, not 100 times a second; when the samples stop the 100 Hz timer stands in and the
    failsafe still comes. Counted by the controller itself (its diagnostics windows): the sensor
    and command topics keep only the newest message, so on a busy machine this process may miss
    some of either. (With step_on: timer the windows hold 50 ticks for about 100 samples.)
    """
    mon, launch = ros
    launch('controller', TESTBED, *FED, '-p', 'step_on:=imu')
    wait_for_controller(mon)
    mon.feed(LEVEL_YAW90, rate_hz=200.0)
    mon.spin_for(0.5)
    mon.wait_for(lambda: mon.arm(True).success, 10.0, 'arming')
    sent0, t0 = mon.fed, time.monotonic()
    mon.spin_for(2.0)
    sent, commands = mon.fed - sent0, len(mon.since('motors', t0))
    t1 = time.monotonic()
    assert sent > 250, sent                                   # the feeder kept up (> 125 Hz)
    assert commands > 0.5 * sent, (commands, sent)            # and the commands came back
    # the controller's 0.5 s windows (diagnostics published between them on events are skipped)
    diags = [(t, d) for t, d in mon.log['diagnostics'] if t0 < t <= t1]
    pairs = [(b.figures.ticks, b.figures.imu_counts.accepted - a.figures.imu_counts.accepted)
             for (ta, a), (tb, b) in zip(diags, diags[1:]) if tb - ta > 0.4]
    assert len([p for p in pairs if p[1] > 1.2 * 50]) >= 2, pairs      # samples came fast
    for ticks, accepted in pairs:     # a step per sample (and the timer's where one was late)
        assert ticks >= accepted - 2, pairs                             # the timer: 50 a window
    mon.stop_feed()
    t_drop = time.monotonic()
    mon.wait_for(lambda: zero_commands(mon), 2.0, 'zero commands after the drop-out')
    assert time.monotonic() - t_drop < 0.25 + 0.5
    mon.wait_for(lambda: mon.last_diagnostic().level == ERROR, 2.0, 'an ERROR diagnostic')
    assert 'stale' in mon.last_diagnostic().message


def test_a_control_step_that_raises_disarms_and_commands_zero_and_the_node_stays_up(ros,
                                                                                    monkeypatch):
    """A defect in a tick (one killed the node once: a TypeError on a stream never received)
    must leave the node up, disarmed, with zero commands and the reason in its diagnostics. The
    node runs in this process here, so that its loop can be made to fail.
    """
    mon, _ = ros
    node = ControllerNode(parameter_overrides=[Parameter('allow_default_configuration',
                                                         value=True)])
    executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    executor.add_node(mon)
    try:
        def fail(now, dt, settle=True):
            raise TypeError('planted')
        monkeypatch.setattr(node.loop, 'tick', fail)
        end = time.monotonic() + 10.0
        while time.monotonic() < end and not (
                mon.last_diagnostic() is not None and 'planted' in mon.last_diagnostic().message
                and mon.last('motors') is not None):
            executor.spin_once(timeout_sec=0.05)
        diag = mon.last_diagnostic()
        assert diag is not None and diag.level == ERROR, diag
        assert 'failsafe: control step failed: TypeError: planted' in diag.message
        assert zero_commands(mon) and not diag.figures.armed
    finally:
        executor.remove_node(mon)
        executor.shutdown()
        node.destroy_node()


def test_the_setpoint_command_takes_one_set_point_in_the_packages_frames(capsys):
    """What ``setpoint`` sends: yaw, pitch and roll (z-y-x, deg) as the quaternion the
    controller's ``setpoint`` takes; arguments that name no one set point, or no number, exit 2
    before any node starts; a command that no controller answers exits 3.
    """
    assert np.allclose(commands.setpoint_quaternion(90.0, 0.0, 0.0),
                       [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)])
    R = so3.quat_to_rot(commands.setpoint_quaternion(30.0, 10.0, -5.0))
    assert np.allclose(R, so3.axis_angle([0, 0, 1], math.radians(30.0))
                       @ so3.axis_angle([0, 1, 0], math.radians(10.0))
                       @ so3.axis_angle([1, 0, 0], math.radians(-5.0)))
    for argv in ([], ['--hold', '--yaw-deg', '0'], ['--quaternion', '0', '0', '0', '1',
                                                   '--pitch-deg', '5'],
                 ['--quaternion', '0', '0', '0', '1', '--hold'], ['--yaw-deg', 'nan'],
                 ['--hold', '--wait', '0']):
        with pytest.raises(SystemExit) as e:
            commands.setpoint(['setpoint'] + argv)
        assert e.value.code == commands.BAD_ARGUMENTS, argv
    assert 'give one of --yaw-deg/--pitch-deg/--roll-deg' in capsys.readouterr().err
    assert refusal_reason('invalid parameters:\n  setpoint: setpoint is not finite\n') == (
        'setpoint: setpoint is not finite')
    # no controller of that name answers: exit 3, saying so
    assert commands.stop(['stop', '--controller', 'nobody', '--wait', '0.5']) == (
        commands.NO_ANSWER)
    assert 'stop: no answer from /nobody within 0.5 s' in capsys.readouterr().err
