"""The controller node's decisions without ROS: input checks, arming, failsafe, set points,
schedule, adaptation only while armed, diagnostics, the tick against the batch's. (Input gaps:
test_gaps.py.)
"""
from dataclasses import replace
import math
import os

from loop_support import CONE, ROOT, SPIN, YAW90, feed, make_loop, spinning
import numpy as np
import pytest

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law import hold
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.core.supervisor.control_tick import ControlTick
from geoctl_ros.core.supervisor.loop import NON_FINITE, ControlLoop
from geoctl_ros.core.supervisor.loop_types import step_period
from geoctl_ros.core.telemetry.diagnostics import ERROR, OK, WARN
from geoctl_ros.params import CONTROLLER, ConfigError, controller_setup, resolve
from geoctl_ros.sim import scenario

pytestmark = pytest.mark.odroid


def test_disarmed_until_armed_with_fresh_inputs():
    loop = make_loop()
    tick = loop.tick(0.0, 0.01)
    assert tick.control is None and not tick.motors.commands.any()
    refused = loop.arm(0.0)
    assert not refused.ok and 'no pose received yet' in refused.message
    feed(loop, 1.0)
    tick = loop.tick(1.0, 0.01)
    assert tick.control is not None and not tick.armed and not tick.motors.commands.any()
    assert loop.arm(1.0).ok
    tick = loop.tick(1.01, 0.01)
    assert tick.armed and np.all(tick.motors.commands > 0)


def test_a_loop_nobody_configured_refuses_every_arm_until_the_opt_in():
    why = 'no configuration given: started without a parameter file'
    loop = ControlLoop(controller_setup(resolve(CONTROLLER, dict(CONE, consistency_checks=False))),
                       unconfigured=why)
    for t in (1.0, 2.0):
        feed(loop, t)
        refused = loop.arm(t)                     # fresh inputs, and still no
        assert not refused.ok and why in refused.message
        tick = loop.tick(t, 0.01)
        assert not tick.armed and not tick.motors.commands.any()
    st = loop.status(2.0)
    assert st.level == WARN and why in st.message
    # the opt-in, set at run time
    assert loop.reconfigure(controller_setup(resolve(CONTROLLER, dict(
        CONE, allow_default_configuration=True, consistency_checks=False)))) is None
    feed(loop, 3.0)
    assert loop.arm(3.0).ok and loop.tick(3.0, 0.01).motors.commands.all()


def test_without_ride_through_a_stale_input_disarms_at_its_timeout_and_stays_disarmed():
    loop = make_loop(imu_timeout=0.05, pose_timeout=0.1, imu_ride_through=0.0,
                     pose_ride_through=0.0)
    feed(loop, 0.0)
    assert loop.arm(0.0).ok
    assert loop.offer_pose(YAW90, 0.04, 0.04) is None        # pose goes on, imu stops
    assert loop.tick(0.04, 0.01).armed
    tick = loop.tick(0.06, 0.01)
    assert not tick.armed and not tick.motors.commands.any()
    assert loop.supervisor.reason.startswith('failsafe: angular velocity lost')
    feed(loop, 0.07)                                          # data back: still disarmed
    assert not loop.tick(0.08, 0.01).armed
    assert not loop.arm(0.5).ok                               # now stale again
    feed(loop, 0.5)
    assert loop.arm(0.5).ok


@pytest.mark.parametrize('q, reason', [
    ((math.nan, 0.0, 0.0, 1.0), 'not finite'),
    ((0.0, 0.0, 0.0, 1.01), 'not unit length'),
    ((0.0, 0.0, 0.0, 0.0), 'not unit length'),
])
def test_bad_poses_are_refused_and_the_last_good_one_stays(q, reason):
    loop = make_loop()
    feed(loop, 1.0)
    R_before = loop.R.copy()
    assert reason in loop.offer_pose(q, 1.1, 1.1)
    assert np.array_equal(loop.R, R_before) and loop.pose.refused == 1
    assert reason in loop.pose.take_refusals()[0]


def test_out_of_order_and_too_fast_samples_are_refused():
    loop = make_loop()
    feed(loop, 1.0)
    assert 'not newer' in loop.offer_pose(YAW90, 0.5, 1.01)
    assert 'not newer' in loop.offer_angular_velocity((0, 0, 0), 1.0, 1.01)
    assert 'max_angular_velocity' in loop.offer_angular_velocity((0, 0, 150.0), 1.1, 1.1)
    assert 'not finite' in loop.offer_angular_velocity((0, math.inf, 0), 1.2, 1.2)


def test_setpoint_requests():
    loop = make_loop()
    assert "inside cone 'obstacle'" in loop.request_setpoint(
        so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(45))))
    assert loop.setpoint_note.startswith('setpoint rejected')
    assert np.allclose(loop.controller.R_d, np.eye(3))
    assert loop.request_setpoint((0.0, 0.0, 0.0, 3.0)) is not None
    assert loop.request_setpoint(YAW90) is None and loop.setpoint_note is None
    assert np.allclose(loop.controller.R_d @ [1, 0, 0], [0, 1, 0])


def test_schedule_plays_from_arming_when_configured_and_not_into_a_hold():
    q1 = list(so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(80))))
    schedule = {'setpoint_schedule.times': [0.0, 2.0],
                'setpoint_schedule.quaternions': q1 + [0.0, 0.0, 0.0, 1.0]}
    loop = make_loop(arming_setpoint='configured', **schedule)
    feed(loop, 10.0)
    loop.tick(10.0, 0.01)
    assert np.allclose(loop.controller.R_d, np.eye(3))        # not before arming
    assert loop.arm(10.0).ok
    loop.tick(10.0, 0.01)
    assert np.allclose(loop.controller.R_d, so3.quat_to_rot(q1))
    feed(loop, 12.05)
    loop.tick(12.05, 0.01)
    assert np.allclose(loop.controller.R_d, np.eye(3))
    held = make_loop(**schedule)                               # arming_setpoint hold
    for t in (10.0, 10.01, 12.05):
        feed(held, t)
        if t == 10.0:
            assert held.arm(t).ok
        held.tick(t, 0.01)
        assert np.allclose(held.controller.R_d, so3.quat_to_rot(YAW90))


def test_arming_holds_the_attitude_measured_then_and_the_operator_commands_what_follows():
    """arming_setpoint hold (the default): an arming flies the attitude measured at it,
    resting on a stop (45 deg) or anywhere; a set point sent afterwards is flown; ~/hold takes
    the attitude measured last; each new arming holds where the vehicle is then.
    """
    loop = make_loop()
    on_stop = so3.quat_to_rot(YAW90) @ so3.axis_angle([0, 1, 0], math.radians(45.0))
    feed(loop, 0.0, q=so3.rot_to_quat(on_stop))
    assert np.allclose(loop.controller.R_d, np.eye(3))        # the configured one, disarmed
    assert loop.arm(0.0).ok
    assert np.allclose(loop.controller.R_d, on_stop)
    tick = loop.tick(0.0, 0.01)
    assert np.allclose(tick.setpoint, on_stop)                # what active_setpoint shows
    assert loop.request_setpoint((0.0, 0.0, 0.0, 1.0)) is None
    assert np.allclose(loop.controller.R_d, np.eye(3))
    feed(loop, 0.01)                                          # level at yaw 90 now
    assert loop.hold() is None
    assert np.allclose(loop.controller.R_d, so3.quat_to_rot(YAW90))
    assert loop.arm(0.01).ok                                  # armed already: nothing changes
    assert loop.request_setpoint((0.0, 0.0, 0.0, 1.0)) is None
    loop.disarm()
    tilted = so3.quat_to_rot(YAW90) @ so3.axis_angle([1, 0, 0], math.radians(-20.0))
    feed(loop, 0.02, q=so3.rot_to_quat(tilted))
    assert loop.arm(0.02).ok
    assert np.allclose(loop.controller.R_d, tilted)
    assert make_loop().hold() == 'no pose received yet'


def test_a_hold_lifts_a_vehicle_resting_on_its_stops_five_degrees_inside_them():
    """With the joint's stops at 45 deg, the attitude measured resting on them (45.3 deg: sunk
    into their spring) is held at 40 deg, turned towards upright about the horizontal axis across
    its tilt: the direction it leans in and its turn about its own z axis are kept. 30 deg of
    tilt, within the stops, is held as measured; so is 45 deg without stops (make_loop's).
    """
    up = np.array([0.0, 0.0, 1.0])
    on_stop = so3.quat_to_rot(YAW90) @ so3.axis_angle([0, 1, 0], math.radians(45.3))
    loop = make_loop(joint_tilt_max_deg=45.0)
    feed(loop, 0.0, q=so3.rot_to_quat(on_stop))
    assert loop.arm(0.0).ok
    held = loop.controller.R_d
    assert math.degrees(hold.tilt(held, up)) == pytest.approx(40.0, abs=1e-9)
    lean = held[:2, 2] / np.linalg.norm(held[:2, 2])               # the body's z, seen from above
    assert np.allclose(lean, on_stop[:2, 2] / np.linalg.norm(on_stop[:2, 2]), atol=1e-12)
    turn = held.T @ on_stop                                        # the lift, in the body
    assert math.degrees(so3.angle(turn)) == pytest.approx(5.3, abs=1e-9)
    assert abs(so3.log(turn)[2]) < 1e-12                           # none of it about z
    within = so3.quat_to_rot(YAW90) @ so3.axis_angle([1, 0, 0], math.radians(30.0))
    feed(loop, 0.01, q=so3.rot_to_quat(within))
    assert loop.hold() is None and np.allclose(loop.controller.R_d, within)
    free = make_loop()
    feed(free, 0.0, q=so3.rot_to_quat(on_stop))
    assert free.hold() is None and np.allclose(free.controller.R_d, on_stop)


def test_an_arming_whose_hold_the_configuration_refuses_is_refused_with_the_reason():
    """The attitude to hold is checked as any set point is: 5 deg clear of the cone, the
    barrier cannot hold unmodelled_moment_max 0.1 N m there (the default k_R: about 11 deg is
    needed), so the arming is refused naming it, and nothing changes; configured, the same
    arming flies the set point in force.
    """
    near = so3.axis_angle([0, 0, 1], math.radians(45.0 - 17.0))          # 5 deg clear
    for arming in ('hold', 'configured'):
        loop = make_loop(unmodelled_moment_max=0.1, arming_setpoint=arming)
        feed(loop, 0.0, q=so3.rot_to_quat(near))
        result = loop.arm(0.0)
        assert result.ok == (arming == 'configured'), result.message
        assert np.allclose(loop.controller.R_d, np.eye(3))
        if arming == 'hold':
            assert ("the attitude to hold: setpoint is 5.00 deg clear of cone 'obstacle'; "
                    'against unmodelled_moment_max = 0.1 N m') in result.message
            assert loop.hold().startswith('setpoint is 5.00 deg clear')


def test_schedule_through_a_cone_is_refused_at_configuration():
    inside = list(so3.rot_to_quat(so3.axis_angle([0, 0, 1], math.radians(45))))
    with pytest.raises(ConfigError, match='set point 1: setpoint puts the sensor axis inside'):
        make_loop(**{'setpoint_schedule.times': [1.0],
                     'setpoint_schedule.quaternions': inside})
    with pytest.raises(ConfigError, match='4 values per time'):
        make_loop(**{'setpoint_schedule.times': [1.0, 2.0],
                     'setpoint_schedule.quaternions': [0.0, 0.0, 0.0, 1.0]})


def test_adaptation_runs_only_while_armed():
    loop = make_loop()
    feed(loop, 0.0, w=(0.0, 0.0, -0.5))
    for k in range(10):
        loop.tick(0.001 * k, 0.01)
    assert not loop.controller.delta_bar.any()
    assert loop.arm(0.01).ok
    loop.tick(0.02, 0.01)
    assert loop.controller.delta_bar.any()


def test_the_command_does_not_wait_for_the_bookkeeping_of_the_next_tick():
    """The node publishes a tick's command before the step learns from it (the estimate) and
    notes it (the prediction's command history): left to the caller, both wait until it settles
    the tick, or until the next tick does, and the commands are the same as settled at once.
    """
    loops = [make_loop(), make_loop(), make_loop()]      # settled at once, by hand, by the next
    commands = [[], [], []]
    for k in range(30):
        t = 0.01 * k
        for i, loop in enumerate(loops):
            feed(loop, t, q=so3.rot_to_quat(spinning(t)), w=SPIN)
            if k == 0:
                assert loop.arm(t).ok
            before = (loop.controller.delta_bar.copy(), loop.step.history.count)
            commands[i].append(loop.tick(t, 0.01, settle=i == 0).motors.commands)
            if i == 1 and k > 20:        # (flying, the estimate learning)
                assert np.array_equal(loop.controller.delta_bar, before[0])
                assert loop.step.history.count == before[1]
            if i == 1:
                loop.settle()
                assert not np.array_equal(loop.controller.delta_bar, before[0]) or k <= 20
    assert loops[0].controller.delta_bar.any()
    assert np.array_equal(commands[0], commands[1])
    assert np.array_equal(commands[0], commands[2])


# --- riding through input gaps (exact times; the defaults: pose 0.1 s stale, 0.5 s lost; imu
# 0.05 s stale, 0.25 s lost) ------------------------------------------------------------------
def test_a_non_finite_control_output_disarms_and_publishes_zero(monkeypatch):
    loop = make_loop()
    feed(loop, 0.0)
    assert loop.arm(0.0).ok
    real_law = loop.controller.control

    def poisoned(*args, **kwargs):           # stands in for a defect in the control law
        out = real_law(*args, **kwargs)
        out.u[1] = math.nan
        return out
    monkeypatch.setattr(loop.controller, 'control', poisoned)
    tick = loop.tick(0.01, 0.01)
    assert tick.control is None and not tick.armed and not tick.motors.commands.any()
    assert loop.supervisor.reason == NON_FINITE
    assert loop.status(0.01).level == ERROR


def test_diagnostics_levels_and_fixed_windows():
    loop = make_loop()
    assert loop.status(0.0).level == WARN                      # disarmed at start-up
    feed(loop, 0.0)
    assert loop.arm(0.0).ok
    for k in range(5):
        if k:
            feed(loop, 0.01 * k)
        loop.tick(0.01 * k, 0.01)
    st = loop.status(0.04)
    assert st.level == OK and st.message == 'armed, all inputs fresh'
    assert st.figures.ticks == 5
    loop.status(0.04)                                          # an event publish: same window
    assert loop.status(0.04).figures.ticks == 5
    loop.end_window()
    assert loop.status(0.04).figures.ticks == 0
    # near a cone: the set point close to the obstacle, the attitude at it
    near = so3.axis_angle([0, 0, 1], math.radians(45.0 - 13.0))
    loop.request_setpoint(so3.rot_to_quat(near))
    feed(loop, 0.05, q=so3.rot_to_quat(near))
    loop.tick(0.05, 0.01)
    st = loop.status(0.05)
    assert st.level == WARN and "near cone 'obstacle' (margin 1.00 deg)" in st.message


def test_a_burst_of_samples_does_not_make_the_lag_compensation_command_extreme_thrusts():
    """step_on: a step started by a sample 0.1 ms after the last one is given step_period's dt
    (half the period), and after a 0.05 rad/s change in the rate its commands stay near the last
    ones. Even given the raw 0.1 ms they do: the mixer designs its lead for the longest recent
    hold (10 ms here), not for this step's dt. Designed for 0.1 ms it would divide the thrust
    change by 1 - exp(-0.1 ms / 40 ms) and command the rotors' limits (141 counts of change, an
    earlier version), which the motors would then hold until the next sample.
    """
    assert step_period(1e-4, 0.01) == 0.005 and step_period(0.012, 0.01) == 0.012
    assert step_period(0.5, 0.01) == 0.02
    spread = {}
    for dt in (step_period(1e-4, 0.01), 1e-4):
        loop = make_loop(motor_lag_compensation=0.04)
        feed(loop, 0.0)
        assert loop.arm(0.0).ok
        for k in range(1, 50):                      # settle at 100 Hz
            feed(loop, 0.01 * k, w=(0.0, 0.0, 0.3))
            before = loop.tick(0.01 * k, 0.01).motors.commands
        feed(loop, 0.4901, w=(0.0, 0.0, 0.25))         # the burst's second sample
        after = loop.tick(0.4901, dt).motors.commands
        spread[dt] = int(np.abs(after - before).max())
    assert spread[0.005] < 30 and spread[1e-4] < 30, spread   # counts of 240 (6 here)


def test_a_batch_of_one_commands_what_the_control_loop_does_tick_for_tick():
    """The closed loop's tick exists once (geoctl_ros.core.supervisor.control_tick.ControlTick):
    ControlLoop (the node's logic) and a batch of one as the campaign builds it (batched cone set,
    set point and estimate), fed the same recorded inputs, command the same motors at every tick.
    """
    sc = scenario.load(os.path.join(ROOT, 'config', 'scenarios', 'testbed_yaw90.yaml'))
    recorded = scenario.run(sc, duration=3.0)          # the flight's true states, 100 Hz
    cols = recorded.columns
    q = recorded.history[:, [cols.index(c) for c in ('qx', 'qy', 'qz', 'qw')]]
    w = recorded.history[:, [cols.index(c) for c in ('wx', 'wy', 'wz')]]
    # a noisy, late measurement of them, so that the prediction and the lag model both work
    rng = np.random.default_rng(7)
    w = w + 0.02 * rng.standard_normal(w.shape)
    values = dict(sc.controller, **{'setpoint_schedule.times': np.zeros(0),
                                    'setpoint_schedule.quaternions': np.zeros(0),
                                    'setpoint': list(YAW90), 'measurement_delay': 0.01,
                                    'consistency_checks': False})
    loop = ControlLoop(controller_setup(values))
    setup = controller_setup(values)
    c = setup.config.cones
    one = ConeSet(c.r, c.V[None], c.theta[None], c.alpha, c.floor, c.names, c.guard)
    controller = AttitudeController(replace(setup.config, cones=one))
    controller.R_d = setup.setpoint[None]
    controller.delta_bar = np.zeros((1, setup.config.n_params))
    batch = ControlTick(controller, setup.mixer)
    d = setup.loop.measurement_delay          # (what the loop's streams add to an age)
    dt = 1.0 / sc.controller['rate_hz']
    # armed first, the rotors spool up while the vehicle is held where the flight starts
    spool = setup.mixer.spool_ticks(dt)
    q = np.concatenate([np.repeat(q[:1], spool, axis=0), q])
    w = np.concatenate([0.02 * rng.standard_normal((spool, 3)), w])
    moved = 0
    for k in range(len(q)):
        t = k * dt + 0.002 * (k % 3)        # the node's ticks are not exactly on time
        loop.offer_pose(q[k], t - 0.004, t - 0.003)
        loop.offer_angular_velocity(w[k], t - 0.002, t - 0.001)
        if k == 0:
            assert loop.arm(t).ok
        tick = loop.tick(t, dt)
        out, motors = batch(so3.quat_to_rot(q[k])[None], w[k][None], dt, now=t,
                            ages=(d + 0.003, d + 0.001))[:2]
        assert np.array_equal(motors.commands[0], tick.motors.commands), k
        assert np.allclose(out.u[0], tick.control.u, rtol=0, atol=1e-12), k
        assert np.allclose(out.delta_bar[0], tick.control.delta_bar, rtol=0, atol=1e-12), k
        moved += bool(tick.motors.commands.any())
    assert moved > 0.9 * len(q)                       # the motors were running all along


def test_poses_before_any_imu_sample_are_flown_on_without_an_exception():
    """A (re)started controller may get poses before its first imu sample: the rate then comes
    from successive poses (bridged, not predicted), and the tick must not fail on the imu's
    missing receipt (a live restart once killed the node that way).
    """
    loop = make_loop()
    for k in range(5):
        t = 0.01 * k
        assert loop.offer_pose(so3.rot_to_quat(spinning(t)), t, t) is None
        tick = loop.tick(t, 0.01)
    assert tick.bridging and tick.control is not None and np.isfinite(tick.control.u).all()
    assert not tick.motors.commands.any()                       # disarmed: commands zero


def test_a_step_flown_on_poses_alone_reports_the_rate_it_used():
    """Poses and no gyro yet (a restarted controller hears the motion capture first): the step
    flies on the rate from successive poses, and the tick carries that rate with the attitude,
    which the node publishes (``attitude``, ``body_rate``); a tick before any input carries none.
    """
    loop = make_loop()
    assert loop.tick(0.0, 0.01).measured is None
    turning = [so3.rot_to_quat(so3.exp(np.array([0.0, 0.0, math.pi / 2 + 0.2 * 0.005 * k])))
               for k in range(30)]
    for k, q in enumerate(turning):
        assert loop.offer_pose(q, 0.005 * k, 0.005 * k) is None
    tick = loop.tick(0.15, 0.01)
    assert loop.Omega is None and tick.control is not None
    R, Omega = tick.measured
    assert np.allclose(R, so3.quat_to_rot(turning[-1])) and abs(Omega[2] - 0.2) < 0.01
