"""Flights over real DDS: the sim in the loop round the cone with the lab's sources and the real
`ros2` command beside it, the sim's clock, and a recorded flight read back by rosbags
(node_support.py: the processes and the monitor node).
"""
import json
import math
import os
import time

from node_support import (
    LAB_SOURCES,
    LEVEL_YAW90,
    TESTBED,
    OperatorCommand,
    published_values_are_finite,
    read_back,
    zero_commands,
)
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock
from std_srvs.srv import Trigger

from geoctl_ros.cli import report as report_cli
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.telemetry.diagnostics import ERROR, OK, WARN, aggregate_ms
from geoctl_ros.esc.virtual import VirtualEscBus
from geoctl_ros.nodes import qos
from geoctl_ros.nodes.conversions import stamp_seconds
from geoctl_ros.params import (
    cone_set,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.params.topics import TOPICS
from geoctl_ros.records import bag, report
from geoctl_ros.sil.loads import ros2_command, start_loads, stop_loads
from geoctl_ros.sil.processes import NodeProcess
from geoctl_ros.sim import scenario

pytestmark = pytest.mark.dds


FLIGHT_S = 8.0         # the guided yaw is under 1 deg in about 3 s
HOLD_S = 5.0           # the hold an arming flies, watched before the set point is sent


@pytest.mark.odroid          # the one flight over DDS on the vehicle's stack too
@pytest.mark.realtime
def test_sim_in_the_loop_flies_round_the_cone_and_converges(ros, tmp_path):
    """The testbed's manoeuvre, sim, controller and ESC node as processes, watched and recorded
    as the lab does it: where the ``ros2`` command is installed, the README's monitoring commands
    run in a loop through the flight from the set point on (tools/soak.py's ``cli`` load; with
    the operator's commands starting beside them on two cores, the sim starved past the IMU's
    ride-through), and ``record`` writes
    the flight to a bag, which reads back with rosbags' own reader and whose report finds the
    closest approach the recorded true attitude has.

    The sensors are the lab's (docs/sensors.md): motion capture and IMU in NED/FRD, the marker
    set turned against the airframe, the IMU mounted turned, a gyro bias; the controller is given
    them (the sim emulates them, the controller undoes them).

    The motors are driven as on the vehicle: ``esc_i2c`` writes the commands to the six ESCs,
    here a virtual I2C bus that the sim reads (the real byte encoding, the node's watchdog).

    The arming holds the attitude it finds (the shipped file's ``arming_setpoint`` hold): under
    2 deg of motion in HOLD_S; then the operator's ``setpoint --yaw-deg 0`` (the console script)
    sends the file's goal, and one into the cone is refused with the reason. The
    manoeuvre keeps the cone as its headless twin does (test_launch.py flies the topic path
    against the same twin); the motor test is refused while armed; and at the end the controller
    is SIGKILLed: every ESC is written zero one watchdog timeout later, from the bus's own record.
    """
    mon, launch = ros
    twin = scenario.run(scenario.load(TESTBED)).summary          # (before: it takes a second)
    headless = twin['min_cone_angle_deg']['obstacle'] - twin['cone_half_angle_deg']['obstacle']
    path = str(tmp_path / 'esc_bus')
    launch('sim', TESTBED, '-p', 'esc.virtual_bus:=' + path, *LAB_SOURCES,
           '-p', 'noise.gyro_bias:=[0.02,-0.01,0.0]')
    esc = launch('esc_i2c', TESTBED, '-p', 'esc.virtual_bus:=' + path,
                 '-p', 'esc.probe_timeout:=20.0')
    controller = launch('controller', TESTBED, *LAB_SOURCES,
                        '-p', 'gyro_bias:=[0.02,-0.01,0.0]')
    recorder = launch('record', None, '-p', 'record.path:=%s' % (tmp_path / 'flight'))
    mon.wait_for(mon.controller_has_inputs, 30.0, 'the sim and the controller')
    # (the recorder hears the controller's diagnostics before the arming: the record's armed
    # span starts at the arming, not when discovery happens to match that topic. Every node
    # publishes /diagnostics, so its first message proves nothing about the controller's: the
    # recorder has also found the controller itself (its cone parameters stored). A run on a
    # busy machine had the recorder match the controller 1.5 s after the arming, the sim's and
    # the ESC node's diagnostics long before.)
    mon.wait_for(lambda: all(line in recorder.output() for line in (
        'first message on /sim/true_pose', 'first message on /diagnostics',
        "stored the controller's")), 20.0, 'the recorder')
    # the diagnostics can reach this monitor before its motor_commands subscription is matched
    mon.wait_for(lambda: mon.last('motors') is not None, 10.0, 'a first motor command')
    # (and the sim's true pose, which the hold is measured against: matched later on a busy
    # machine, it once was not yet heard at the arming)
    mon.wait_for(lambda: mon.last('true_pose') is not None, 20.0, 'the true pose')
    assert zero_commands(mon)                                  # disarmed at start-up
    assert mon.last_diagnostic().figures.armed is False
    mon.wait_for(lambda: '6 ESCs on virtual ESC bus' in esc.output(), 30.0, 'the ESC node')
    addresses = resolve('esc_i2c', {})['esc.addresses']
    bus = VirtualEscBus(path, addresses)
    assert [data for data, _ in bus.setpoints()] == [b'\x00'] * 6           # disarmed: zero
    intruder = [1.0] * 6        # full throttle: the controller, never saturated, never sends it

    def intrude(seconds):
        """A plain publisher (a replayed record, a hand-typed command) on motor_commands; the
        bus's own record of that time.
        """
        first, t_end = bus.count(), time.monotonic() + seconds
        while time.monotonic() < t_end:
            mon.publish_commands(intruder)
            mon.spin_for(0.02)
        mon.stop_commands()
        return bus.log(first)
    seen = intrude(0.5)                                   # 1. the controller disarmed
    assert len(seen) > 0 and np.all(seen['b0'] == 0)
    mon.wait_for(lambda: mon.arm(True).success, 20.0, 'arming once the publisher is gone')
    t_arm, wall0 = time.monotonic(), time.time()
    R_armed = so3.quat_to_rot(mon.last('true_pose')[1])
    armed_at = bus.count()           # once the ESCs turn, a motor test is refused
    mon.wait_for(lambda: np.any(bus.log(armed_at)['b0'] > 0), 10.0, 'the ESCs following')
    refused = mon._call(mon.create_client(Trigger, '/esc_i2c/motor_test'), Trigger.Request())
    assert not refused.success and ('armed' in refused.message or 'commands the motors'
                                    in refused.message), refused.message
    mon.spin_for(2.0)
    seen = intrude(0.5)                                   # 2. armed: a second publisher
    assert len(seen) > 0 and np.all(seen['b0'] < 240) and np.all(seen['b0'] > 0)
    # a set point into the cone (yaw 45 puts the sensor on its axis): refused, with the reason,
    # and the hold goes on
    code, out = OperatorCommand('setpoint', '--yaw-deg', '45').answer(mon)
    assert code == 1 and out.strip() == (
        "refused: setpoint: setpoint puts the sensor axis inside cone 'obstacle' (angle to its "
        "axis 0.00 deg, half-angle 12.00 deg)"), (code, out)
    mon.spin_for(t_arm + HOLD_S - time.monotonic())
    # the arming held the attitude it found (arming_setpoint hold, the file's default)
    t_held = time.monotonic()
    moved = max(math.degrees(so3.angle(R_armed.T @ so3.quat_to_rot(q)))
                for _, q in mon.between('true_pose', t_arm, t_held))
    print('the hold: moved at most %.2f deg in %.1f s' % (moved, t_held - t_arm))
    assert moved < 2.0, moved
    # the operator's command: the file's goal (R_d = I, yaw 0), round the cone
    t0 = time.monotonic()
    code, out = OperatorCommand('setpoint', '--yaw-deg', '0').answer(mon)
    assert code == 0 and out.startswith('accepted: set point [0.0000, 0.0000, 0.0000, '
                                        '1.0000]'), (code, out)
    print('setpoint answered in %.1f s' % (time.monotonic() - t0))
    loads = start_loads(('cli',), os.environ) if ros2_command() else []
    try:
        mon.spin_for(t0 + FLIGHT_S - time.monotonic())    # and the flight goes on
    finally:
        stop_loads(loads, os.environ)
    t1, wall1 = time.monotonic(), time.time()
    values = resolve('controller', node_overrides(load_parameter_file(TESTBED), 'controller'))
    cones = cone_set(values)
    true = [so3.quat_to_rot(q) for _, q in mon.between('true_pose', t0, t1)]
    margins = [cones.margins_deg(R)[0] for R in true]
    # kept the cone as the headless twin does (13.8 deg clear; live latency and CPU load take
    # some of that)
    assert min(margins) > 0.0 and abs(min(margins) - headless) < 0.5, (min(margins), headless)
    assert all(0 < data[0] < 240 for data, _ in bus.setpoints())             # flying
    psi = mon.between('psi', t0, t1)
    assert psi[-1] < 0.05 * max(psi)
    setup = controller_setup(values)
    final = setup.schedule.rotations[-1] if len(setup.schedule) else setup.setpoint
    assert math.degrees(so3.angle(final.T @ true[-1])) < 1.0          # arrived (guided, tuned)
    cmds = np.array(mon.between('motors', t0, t1))
    cmds = cmds[~np.all(cmds == intruder, axis=1)]         # (this monitor hears its own too)
    # armed, at 100 Hz: as this monitor hears them, over the hold and the flight (beside the
    # commands' processes and the loads on two cores, it heard 75 % of them over the flight)
    heard = len(mon.between('motors', t_arm, t1))
    print('heard %d motor commands in %.1f s armed' % (heard, t1 - t_arm))
    assert heard > 0.75 * 100 * (t1 - t_arm) and cmds.shape[1] == 6, (heard, t1 - t_arm)
    # armed: every rotor at least at thrust_min (0.2 N: command 21 of 240), none saturated
    # (the first few may be zeros published just before the arm took effect)
    assert np.all((cmds[10:] >= 21 / 240 - 1e-9) & (cmds[10:] < 1.0)), cmds[10:].min()
    # no failsafe, and the loop never paused beyond the imu's ride-through (its own figures)
    diags = mon.between('diagnostics', t0, t1)
    assert all(d.figures.armed for d in diags), [d.message for d in diags if d.level == ERROR]
    assert aggregate_ms(diags, 'loop_period').max < 250.0
    diag = mon.last_diagnostic()
    # OK, or a WARN of the delay bound's watch only (a starved machine makes the loop blind past
    # its bound, docs/safety.md: said, and the gains come down; not a failure of the flight)
    assert diag.figures.armed and (diag.level == OK or diag.level == WARN and all(
        part.startswith(('loop blind', 'degraded:')) for part in diag.message.split('; '))), (
        diag.message)
    assert diag.figures.pose_counts.refused == 0
    published_values_are_finite(mon)
    # the record, stopped before the disarm (disarmed, the testbed falls): every stream through
    # the flight (best effort ones at least half their rate), and the report's closest approach
    # that of the recorded true attitude
    assert recorder.stop() == 0, recorder.output()
    # the controller dies armed: the ESC node's watchdog, alone, stops every motor
    first = bus.count()
    t_kill = time.monotonic()
    controller.kill()
    mon.wait_for(lambda: all(data == b'\x00' for data, _ in bus.setpoints()), 2.0,
                 'zero at every ESC')
    log = bus.log(first)
    seen = intrude(0.5)                                   # 3. the controller stopped
    assert len(seen) > 0 and np.all(seen['b0'] == 0)
    bus.close()
    for a in addresses:
        mine = log[log['address'] == a]
        zero = mine['t'][mine['b0'] == 0].min()
        # the last command came at most a control period (10 ms) before the kill; the ESC node
        # holds it for its timeout (0.1 s), and zero goes out at the next write cycle (10 ms)
        assert 0.1 - 0.01 < zero - t_kill <= 0.1 + 0.01 + 0.005, (hex(a), zero - t_kill)
        assert np.all(mine['b0'][mine['t'] > zero] == 0)
    assert esc.stop() == 0 and 'zero written to every ESC' in esc.output()
    axis = cones.V[0]
    counts, first, last, angles, _ = read_back(tmp_path / 'flight', axis)
    assert first < wall0 and last > wall1
    assert counts['/motor_commands'] > 0.75 * 100 * FLIGHT_S, counts
    assert counts['/sim/true_pose'] > 0.5 * 200 * FLIGHT_S, counts
    assert counts['/cone_margins'] > 0.5 * 100 * FLIGHT_S and counts['/diagnostics'] > FLIGHT_S
    flight = report.load_flight(str(tmp_path / 'flight'))
    s = report.summary(flight)
    closest = s['closest_approach_deg']['obstacle']
    assert closest['angle'] == pytest.approx(angles.min(), abs=0.01)
    assert closest['margin'] == pytest.approx(min(margins), abs=0.05)    # as this monitor saw
    assert s['failsafes'] == 0 and s['armed_s'][1] - s['armed_s'][0] > FLIGHT_S - 1.0
    # settled, as this monitor saw it (two samples of a decaying, oscillating Psi taken at
    # different instants are not compared with each other)
    assert 0.0 < s['final_psi'] < 0.05 * max(psi)
    assert s['gaps_ridden']['pose'] >= diag.figures.pose_gaps.ridden     # counters: the record
    assert s['gaps_ridden']['imu'] >= diag.figures.imu_gaps.ridden       # ends a little later


@pytest.mark.realtime
def test_sim_time_the_sim_drives_the_controllers_clock(ros):
    """use_sim_time: the sim publishes /clock and the controller's timer and timeouts follow it."""
    mon, launch = ros
    clock_log = []
    mon.create_subscription(Clock, '/clock', lambda m: clock_log.append(
        (time.monotonic(), stamp_seconds(m.clock))), qos.EVENT)
    # at half real time: a controller on the wall clock would show its windows twice as often
    launch('sim', TESTBED, '-p', 'publish_clock:=true', '-p', 'real_time_factor:=0.5')
    launch('controller', TESTBED, '-p', 'use_sim_time:=true')
    reply = mon.arm_when_ready()
    assert reply.success, reply.message
    # measure only once this process receives the sim's streams (discovering a new participant
    # can take one DDS announcement period, ~3 s, after the controller already flies on them)
    mon.wait_for(lambda: clock_log and mon.log['true_pose'], 15.0, '/clock and the true pose')
    t0 = time.monotonic()
    mon.spin_for(6.0)                               # 3 s of sim time: six 0.5 s windows
    clock = [(t, c) for t, c in clock_log if t >= t0]
    sim_span = clock[-1][1] - clock[0][1]
    assert sim_span > 2.0, sim_span                 # the sim's clock went on (at its own pace)
    # the controller's timer and diagnostics window follow /clock, not the wall: 100 Hz ticks in
    # a 0.5 s window of sim time, however fast the machine runs the sim (its own counts)
    windows = [(t, d.figures.ticks) for t, d in mon.log['diagnostics'] if t >= t0]
    ticks = sorted(n for _, n in windows)
    assert len(ticks) >= 4 and 45 <= ticks[len(ticks) // 2] <= 55, ticks
    # and those 0.5 s windows of sim time take at least 0.75 s of the wall at half real time
    gaps = sorted(b[0] - a[0] for a, b in zip(windows, windows[1:]) if b[1] >= 45)
    assert gaps and gaps[len(gaps) // 2] > 0.75, gaps
    values = resolve('controller', node_overrides(load_parameter_file(TESTBED), 'controller'))
    cones = cone_set(values)
    assert min(cones.margins_deg(so3.quat_to_rot(v[1]))[0]
               for t, v in mon.log['true_pose'] if t >= t0) > 0.0
    assert mon.last_diagnostic().figures.armed
    published_values_are_finite(mon)


@pytest.mark.realtime
def test_a_moment_the_model_lacks_past_a_u_is_warned_on_diagnostics(ros):
    """The approach brake's a_u watched on the vehicle: the sim's testbed carries 0.4 N m the
    controller's model lacks (a constant disturbance, four times ``cbf_moment_bound``); armed
    into the hold, the controller's /diagnostics says at WARN that the model did not know the
    acceleration past the brake's a_u, with the count of rate samples, and its figures carry it.
    """
    mon, launch = ros
    launch('sim', TESTBED, '-p', 'disturbance.constant:=[0.4, 0.0, 0.0]')
    launch('controller', TESTBED)
    reply = mon.arm_when_ready()
    assert reply.success, reply.message

    def warned():
        return [d for _, d in mon.log['diagnostics'] if d.level == WARN and d.figures.armed
                and "past the approach brake's a_u" in d.message]
    mon.wait_for(lambda: warned(), 15.0, 'the unlearnt-acceleration warning')
    d = warned()[0]
    part = next(p for p in d.message.split('; ') if "approach brake's a_u" in p)
    over = int(part.split(' at ')[1].split(' rate samples')[0])
    bound = float(part.split('a_u of ')[1].split(' rad/s^2')[0])
    seen = float(part.split('up to ')[1].split(' rad/s^2')[0])
    assert over > 0 and seen > bound > 0.0, part
    assert d.figures.unlearnt is not None
    published_values_are_finite(mon)


def _true_poses_on_disk(path):
    """Whether the bag being written at path has true poses on disk (read as report reads a
    bag cut short).
    """
    try:
        return bool(bag.read_bag(str(path), ['/sim/true_pose']).get('/sim/true_pose'))
    except ValueError:
        return False


def test_a_recorded_flight_reads_back_with_rosbags_and_reports_its_closest_approach(ros,
                                                                                      tmp_path):
    """``record`` beside the sim and the controller, in both storages. The sim starts tilted 20
    deg towards the cone, and disarmed the testbed (its centre of mass above the pivot, its
    joint without stops) falls, so the sensor sweeps into the cone; the recording runs until it
    has. The bags read back with rosbags' own reader (not the package's), and ``report`` gives
    the closest approach that the recorded true attitude gives, computed here with plain numpy.
    A third recorder, killed mid-flight, leaves a bag that still reports. The live view runs
    beside them, and its markers are in the records too.
    """
    mon, launch = ros
    launch('controller')
    view = launch('view', None)
    recorders = {}
    for name, storage in (('mcap', 'mcap'), ('sqlite3', 'sqlite3'), ('killed', 'mcap')):
        p = NodeProcess('record', None, ('-p', 'record.path:=%s' % (tmp_path / name),
                                         '-p', 'record.storage:=%s' % storage),
                        log_dir=tmp_path / ('log_' + name))
        launch.procs.append(p)
        recorders[name] = p
    # the testbed starts falling when the sim starts: everything else is ready first
    mon.wait_for(lambda: 'drawing 1 cone' in view.output() and all(
        "stored the controller's" in p.output() for p in recorders.values()), 30.0,
        'the cones in the view and in the three records')
    tilted = so3.rot_to_quat(so3.quat_to_rot(LEVEL_YAW90) @ so3.axis_angle([0, 1, 0],
                                                                           math.radians(-20.0)))
    # (without the joint's stops: resting on them, 45 deg tilted, the sensor stays clear
    # of the level cone, whichever way the testbed falls)
    launch('sim', TESTBED, '-p', 'sim:initial_attitude:=[%s]' % ', '.join('%r' % float(v)
                                                                      for v in tilted),
           '-p', 'sim:joint_tilt_max_deg:=180.0')
    mon.wait_for(lambda: all('first message on /sim/true_pose' in p.output()
                             for p in recorders.values()), 30.0, 'the true pose in the records')
    t_start, t_mon = time.time(), time.monotonic()
    # until the sensor has fallen a degree into the cone (the controller's own margins)
    mon.wait_for(lambda: any(m[0] < -1.0 for m in mon.since('margins', t_mon)), 30.0,
                 'the sensor in the cone')
    # (a checkpoint of the recorder about to be killed holds the true pose: at nice 19 beside
    # the flights its writer can lag the fall, and a Prescott CI run killed it before one did)
    mon.wait_for(lambda: _true_poses_on_disk(tmp_path / 'killed'), 30.0,
                 'a checkpoint with the true pose')
    recorders.pop('killed').kill()                # mid-flight, as a crash or a full disk would
    mon.spin_for(0.5)
    for p in recorders.values():
        assert p.stop() == 0, p.output()
    t_end = time.time()
    values = resolve('controller', node_overrides(load_parameter_file(TESTBED), 'controller'))
    cones = cone_set(values)
    axis = np.array(values['cones.obstacle.axis']) / np.linalg.norm(values['cones.obstacle.axis'])
    # the live view, as recorded: the cone drawn at its half-angle, red while the
    # sensor was within view.warning_deg (5) of it; the sensor arrow a unit vector
    with AnyReader([tmp_path / 'mcap'], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as rd:
        views = [rd.deserialize(raw, c.msgtype) for c, _, raw in rd.messages(
            connections=[c for c in rd.connections if c.topic == '/view/markers'])]
    assert views
    cones_drawn = [m for v in views for m in v.markers if m.ns == 'cones']
    assert cones_drawn
    rim = np.array([[p.x, p.y, p.z] for p in cones_drawn[-1].points[1::3]])
    assert np.allclose(np.degrees(np.arccos(rim @ axis / np.linalg.norm(rim, axis=1))), 12.0)
    red = {m.color.r == 1.0 and m.color.g == 0.0 for m in cones_drawn}
    assert red == {True, False}                # it swept from 36 deg clear into the cone
    for v in views:
        for m in v.markers:
            if m.ns == 'sensor':
                tip = m.points[1]
                assert math.isclose(math.hypot(tip.x, tip.y, tip.z), 1.0, abs_tol=1e-9)
    reports, series = {}, {}
    for storage in recorders:
        path = tmp_path / storage
        counts, first, last, angles, stamps = read_back(path, axis)
        series[storage] = dict(zip(stamps.tolist(), angles.tolist()))
        assert first < t_start and t_start < last < t_end
        # every stream is in it (this test runs beside the flights at nice 19, so the rates are
        # not this test's to judge: the recorded flight of the sim-in-the-loop test judges them)
        silent = [t.name for t in TOPICS if counts.get(t.name, 0) == 0]
        assert silent == ['/attitude_setpoint'], counts         # nobody sends a set point here
        assert len(angles) == counts['/sim/true_pose']
        out = tmp_path / ('report_' + storage)
        assert report_cli.main([str(path), '--out', str(out)]) == 0
        reports[storage] = json.loads((out / 'summary.json').read_text())
        closest = reports[storage]['closest_approach_deg']['obstacle']
        assert closest['angle'] == pytest.approx(min(angles), abs=0.01)
        assert max(angles) - min(angles) > 5.0                        # the sensor did move
        assert closest['half_angle'] == pytest.approx(math.degrees(cones.theta[0]))
        assert reports[storage]['attitude_source'] == '/sim/true_pose'
        assert reports[storage]['failsafes'] == 0 and reports[storage]['gaps_ridden'] is not None
        for png in ('flight.png', 'sensor_path.png'):
            assert (out / png).stat().st_size > 10_000
    # the same flight in both storages: the same true poses, compared at the same stamps (the
    # recorders stop a moment apart while the testbed falls fast, so their ends differ)
    common = sorted(set(series['mcap']) & set(series['sqlite3']))
    # (best effort: at nice 19 each recorder drops its own, and a sim that fell behind catches
    # up a second at a time, publishing once per catch-up: a CI run had 3 in common)
    assert len(common) >= 2
    assert all(series['mcap'][t] == series['sqlite3'][t] for t in common)
    # the killed recorder's bag (no metadata.yaml, its file cut) reports what it had written:
    # the flight up to its last second, its cones from the bag itself
    assert not (tmp_path / 'killed' / 'metadata.yaml').exists()
    out = tmp_path / 'report_killed'
    assert report_cli.main([str(tmp_path / 'killed'), '--out', str(out), '--no-plots']) == 0
    cut = json.loads((out / 'summary.json').read_text())
    assert cut['duration_s'] > 1.0 and cut['attitude_source'] == '/sim/true_pose'
    assert cut['closest_approach_deg']['obstacle']['angle'] >= reports['mcap'][
        'closest_approach_deg']['obstacle']['angle'] - 0.5          # a part of the same flight
