"""Hexrotor actuation: effectiveness against a hand computation, allocation within limits and by
priority, the thrust curve, dead and missing rotors, and the simulated rotors.
"""
import math

import numpy as np
import pytest

from geoctl_ros import params
from geoctl_ros.core.actuation.airframe import (
    AirframeError,
    RotorGeometry,
    effectiveness,
    tilted_ring,
)
from geoctl_ros.core.actuation.allocation import Allocator
from geoctl_ros.core.actuation.motors import ThrustCurve
from geoctl_ros.params import CONTROLLER, ConfigError, resolve
from geoctl_ros.sim.testbed import RotorActuator

pytestmark = pytest.mark.odroid

RHO = np.array([0.0, 0.0, 0.1])
LAB_CURVE = ThrustCurve(np.full(6, 6.0252e-5), np.full(6, 8.4086e-3), np.full(6, -2.5194e-2),
                        1.1261, 240)
rng = np.random.default_rng(3)

# Hand computation for the lab hexrotor (arm 0.31 m, tilt 15 deg, yaw coefficient 0.1 m, centre of
# mass 0.1 m above the pivot). Rotor 1: azimuth 0, spins counter-clockwise (s = +1), tilted towards
# its clockwise direction of travel (-y): n1 = (0, -sin 15, cos 15) = (0, -0.2588, 0.9659).
# Arm from the pivot a1 = (0.31, 0, 0.1); moment a1 x n1 - s k n1
#   = (0.1 * 0.2588, -0.31 * 0.9659, -0.31 * 0.2588) - 0.1 (0, -0.2588, 0.9659)
#   = (0.0259, -0.2736, -0.1768).
# The others follow at azimuths -60, -120, ... deg with spin and tilt alternating. Yaw per newton
# is 0.31 sin 15 + 0.1 cos 15 = 0.1768 on every rotor (tilt and reaction add up).
EXPECTED_B = np.array([
    [0.0, 0.2241, -0.2241, 0.0, 0.2241, -0.2241],
    [-0.2588, 0.1294, 0.1294, -0.2588, 0.1294, 0.1294],
    [0.9659, 0.9659, 0.9659, 0.9659, 0.9659, 0.9659],
    [0.0259, -0.2498, -0.2498, 0.0259, 0.2240, 0.2240],
    [-0.2736, -0.1144, 0.1144, 0.2736, 0.1592, -0.1592],
    [-0.1768, 0.1768, -0.1768, 0.1768, -0.1768, 0.1768],
])


def lab_allocator(**kw):
    return Allocator(effectiveness(tilted_ring(), RHO), kw.pop('lo', 0.2), kw.pop('hi', 6.5),
                     **kw)


def test_allocation_from_a_hand_written_matrix():
    """A flat quad in plus layout, B written out: thrust 1 per rotor along z; roll from rotors 2
    and 4 (y = +-0.2), pitch from 1 and 3 (x = +-0.2), yaw +-0.1 by spin.
    """
    B = np.array([[0, 0, 0, 0], [0, 0, 0, 0], [1, 1, 1, 1],
                  [0, 0.2, 0, -0.2], [-0.2, 0, 0.2, 0], [-0.1, 0.1, -0.1, 0.1]], dtype=float)
    al = Allocator(B, 0.0, 10.0)
    a = al.allocate(np.array([0.04, 0.0, 0.0]), 8.0)
    # by hand: each rotor 2 N, plus 0.1 N on rotor 2 and -0.1 N on rotor 4 for 0.04 N m of roll
    assert np.allclose(a.thrusts, [2.0, 2.1, 2.0, 1.9]) and not a.saturated
    a = al.allocate(np.array([0.0, 0.0, 0.2]), 8.0)
    assert np.allclose(a.thrusts, [1.5, 2.5, 1.5, 2.5])


def test_effectiveness_of_the_lab_hexrotor_matches_the_hand_computation():
    B = effectiveness(tilted_ring(), RHO)
    assert B.shape == (6, 6)
    assert np.allclose(B, EXPECTED_B, atol=6e-5)
    assert np.allclose(B[5], 0.31 * math.sin(math.radians(15)) * np.array([-1, 1, -1, 1, -1, 1])
                       + 0.1 * math.cos(math.radians(15)) * np.array([-1, 1, -1, 1, -1, 1]))
    health = lab_allocator().health
    assert health.rank == 6 and health.moment_rank == 3 and not health.warnings
    assert health.condition < 10.0


def test_hover_needs_2_13_newton_and_command_118_per_rotor():
    a = lab_allocator().allocate(np.zeros(3), 1.26 * 9.81)
    assert not a.saturated
    assert np.allclose(a.thrusts, 1.26 * 9.81 / (6 * math.cos(math.radians(15))))
    assert a.thrusts[0] == pytest.approx(2.13, abs=0.005)
    assert list(LAB_CURVE.command(a.thrusts)) == [118] * 6
    mixer = params.mixer(resolve(CONTROLLER, {}))          # the same from the defaults
    out = mixer.mix(np.zeros(3))
    assert list(out.commands) == [118] * 6
    assert np.allclose(out.normalised, 118 / 240)


def test_feasible_requests_are_met_exactly():
    al = lab_allocator()
    for _ in range(500):
        M = rng.normal(size=3) * 0.1
        a = al.allocate(M, 12.0)
        assert not a.saturated
        assert np.allclose(a.moment, M, atol=1e-12)
        assert a.collective == pytest.approx(12.0)
        assert np.allclose(a.moment_lost, 0.0, atol=1e-12)


def test_ten_thousand_random_requests_never_leave_the_thrust_limits():
    al = lab_allocator()
    scale = rng.choice([1e-3, 0.1, 1.0, 10.0, 1e6], size=10000)
    for M, T in zip(rng.normal(size=(10000, 3)) * scale[:, None], rng.uniform(-50, 100, 10000)):
        a = al.allocate(M, T)
        assert np.all(np.isfinite(a.thrusts))
        assert a.thrusts.min() >= 0.2 - 1e-12 and a.thrusts.max() <= 6.5 + 1e-12
        assert np.allclose(a.moment + a.moment_lost, M)
    for bad in ([np.nan, 0, 0], [0, np.inf, 0]):
        a = al.allocate(np.array(bad, dtype=float), 12.0)
        assert not a.valid and np.allclose(a.thrusts, 0.2)
    assert not al.allocate(np.zeros(3), float('nan')).valid


def test_infeasible_requests_keep_roll_and_pitch_ahead_of_yaw_and_collective():
    al = lab_allocator()
    # roll and pitch within reach, yaw too large: roll/pitch exact, yaw cut back
    a = al.allocate(np.array([0.3, -0.2, 5.0]), 12.0)
    assert a.saturated
    assert np.allclose(a.moment[:2], [0.3, -0.2], atol=1e-9)
    assert 0.0 < a.moment[2] < 5.0
    assert np.allclose(a.moment_lost, [0.0, 0.0, 5.0 - a.moment[2]], atol=1e-9)
    # roll beyond reach: direction kept, no yaw at all, the loss reported
    a = al.allocate(np.array([8.0, 4.0, 0.5]), 12.0)
    assert a.moment[2] == pytest.approx(0.0, abs=1e-9)
    assert a.moment[0] / a.moment[1] == pytest.approx(2.0)
    assert 0.0 < a.moment[0] < 8.0
    assert np.linalg.norm(a.moment_lost) > 1.0
    # collective gives way before yaw: a yaw that fits only if the rotors are unloaded
    big_yaw = np.array([0.0, 0.0, 2.5])
    a = al.allocate(big_yaw, 35.0)
    assert a.moment[2] == pytest.approx(2.5)
    assert a.collective < 35.0


def test_a_dead_rotor_is_flagged_and_the_rest_still_allocate():
    al = lab_allocator(failed=[3])
    assert al.health.alive == [1, 2, 4, 5, 6]
    assert 'rotor(s) [3] marked failed' in al.health.warnings[0]
    assert any('not fully actuated' in w for w in al.health.warnings)
    a = al.allocate(np.array([0.05, -0.05, 0.02]), 12.0)
    assert a.thrusts[2] == 0.0
    assert np.allclose(a.moment, [0.05, -0.05, 0.02], atol=1e-12)
    with pytest.raises(ConfigError, match='rotor 7 does not exist'):
        params.mixer(resolve(CONTROLLER, {'rotors.failed': [7]}))


def test_layouts_that_cannot_produce_every_moment_are_refused():
    two = RotorGeometry(np.array([[0.3, 0, 0], [-0.3, 0, 0]]), np.tile([0.0, 0.0, 1.0], (2, 1)),
                        np.array([1.0, -1.0]), 0.1)
    with pytest.raises(AirframeError, match='cannot produce every moment'):
        Allocator(effectiveness(two, RHO), 0.2, 6.5)
    # a flat quad whose rotors all spin the same way: yaw only together with thrust
    same = tilted_ring(count=4, tilt_deg=0.0)
    same = RotorGeometry(same.positions, same.axes, np.ones(4), 0.1)
    with pytest.raises(AirframeError, match='collective thrust independently'):
        Allocator(effectiveness(same, RHO), 0.2, 6.5)
    # three of six rotors dead (1, 3, 5: same spin left): refused through the parameters
    with pytest.raises(ConfigError) as info:
        params.mixer(resolve(CONTROLLER, {'rotors.failed': [2, 4, 6]}))
    assert 'rotors' in dict(info.value.errors)


def test_custom_layout_from_parameters():
    ring = tilted_ring()
    values = resolve(CONTROLLER, {
        'rotors.layout': 'custom',
        'rotors.positions': [float(v) for v in ring.positions.ravel()],
        'rotors.axes': [float(v) for v in ring.axes.ravel()],
        'rotors.spins': [int(v) for v in ring.spins]})
    geometry, curve, failed = params.airframe(values)
    assert np.allclose(effectiveness(geometry, RHO), EXPECTED_B, atol=6e-5)
    with pytest.raises(ConfigError, match='3 values per rotor'):
        params.airframe(resolve(CONTROLLER, {'rotors.layout': 'custom',
                                             'rotors.positions': [0.0, 0.0, 0.0],
                                             'rotors.spins': [1, -1]}))
    with pytest.raises(ConfigError, match='custom needs rotors.positions'):
        params.airframe(resolve(CONTROLLER, {'rotors.layout': 'custom'}))


def test_thrust_curve_commands():
    cmds = np.arange(0, 241)
    f = LAB_CURVE.thrust(np.tile(cmds[:, None], (1, 6)))[:, 0]
    assert np.all(f >= 0.0) and np.all(np.diff(f) >= 0.0)
    assert LAB_CURVE.max_thrust()[0] == pytest.approx(6.648, abs=1e-3)
    # the command is the smallest one that gives at least the requested thrust
    for target in np.linspace(0.05, 6.6, 200):
        c = LAB_CURVE.command(np.full(6, target))[0]
        assert LAB_CURVE.thrust(np.full(6, c))[0] >= target - 1e-9
        assert LAB_CURVE.thrust(np.full(6, c - 1))[0] < target
    # f < 0 counts as 0, like the lab; command 0 gives 0 N (the curve is clipped), which meets 0
    assert list(LAB_CURVE.command(np.array([-1.0, 0.0, 1e3, 2.13, 2.13, 1e-3]))) == [
        0, 0, 240, 118, 118, 3]
    assert LAB_CURVE.thrust(np.full(6, 2))[0] == 0.0 < LAB_CURVE.thrust(np.full(6, 3))[0]
    per_motor = ThrustCurve(np.array([0.6252, 0.8251, 0.7659, 0.8197, 0.8162, 0.7524]) * 1e-4,
                            np.array([0.0142, 0.0097, 0.0097, 0.0087, 0.0088, 0.0099]),
                            np.array([-0.3700, -0.2380, -0.2747, -0.2418, -0.2495, -0.2489]),
                            1.0, 240)
    c = per_motor.command(np.full(6, 2.0))
    assert len(set(c)) > 1                             # different motors, different commands
    assert np.all(per_motor.thrust(c) >= 2.0)


def test_thrust_limits_must_fit_the_curve():
    with pytest.raises(ConfigError, match='thrust_max: 9 N is more than the thrust curve'):
        params.mixer(resolve(CONTROLLER, {'thrust_max': 9.0}))
    with pytest.raises(ConfigError, match='motor.a: expected 1 value or 6'):
        params.mixer(resolve(CONTROLLER, {'motor.a': [1e-4, 1e-4]}))


def test_mixer_is_zero_when_disarmed():
    mixer = params.mixer(resolve(CONTROLLER, {}))
    out = mixer.mix(np.array([0.3, 0.1, 0.0]), armed=False)
    assert not out.commands.any() and not out.normalised.any()


def test_simulated_rotors_lag_and_push_about_the_pivot():
    act = RotorActuator(tilted_ring(), RHO, LAB_CURVE, time_constant=0.04)
    h = 1e-3
    for _ in range(40):                                 # one time constant
        M = act.moment(np.full(6, 118), h)
    target = LAB_CURVE.thrust(np.full(6, 118))
    assert np.allclose(act.thrusts, target * (1 - math.exp(-1.0)), rtol=1e-9)
    assert np.allclose(M, 0.0, atol=1e-12)             # symmetric: no moment
    act = RotorActuator(tilted_ring(), RHO, LAB_CURVE, time_constant=0.04, failed=[1])
    for _ in range(1000):
        M = act.moment(np.full(6, 118), h)
    assert act.thrusts[0] == 0.0 and np.linalg.norm(M) > 0.1


def test_lag_compensation_brings_the_lagged_rotors_to_the_allocation_by_the_next_step():
    """motor_lag_compensation: through the simulated rotors' 40 ms lag (integrated at 1 kHz), a
    step in the moment is produced by the end of the 10 ms control step; without it the rotors
    cover only 1 - exp(-0.25) = 22 % of the way.
    """
    dt, h = 0.01, 1e-3
    step = np.array([0.3, -0.2, 0.1])
    missing = {}
    for lag in (0.0, 0.04):
        mixer = params.mixer(resolve(CONTROLLER, {'motor_lag_compensation': lag}))
        act = RotorActuator(tilted_ring(), RHO, mixer.curve, time_constant=0.04)
        rotors = None                          # (the lag model: the mixer keeps none)
        for k in range(101):                   # 1 s at rest (no moment), then the step
            out = mixer.mix(step if k == 100 else np.zeros(3), rotors, dt=dt)
            rotors = out.rotors
            for _ in range(10):
                produced = act.moment(out.commands, h)
        missing[lag] = np.linalg.norm(produced - out.allocation.moment) / np.linalg.norm(step)
    assert missing[0.04] < 0.1, missing       # within command rounding (a count is ~2 %)
    assert missing[0.0] > 0.7, missing        # most of the step still to come
    mixer = params.mixer(resolve(CONTROLLER, {'motor_lag_compensation': 0.04}))
    out = mixer.mix(np.array([0.3, 0.1, 0.0]), armed=False, dt=dt)
    assert not out.commands.any()             # disarmed is still zero
    plain = params.mixer(resolve(CONTROLLER, {}))
    first = mixer.mix(step, dt=dt).commands   # arming: no kick from rest to the thrust limits
    assert np.array_equal(first, plain.mix(step).commands)


def test_lag_compensation_follows_the_real_holds_of_a_late_loop():
    """The control steps come 50 ms apart instead of 10 (a busy machine). The first late hold
    overshoots: its command was designed for 10 ms. Told the real holds, the mixer's model knows
    it and corrects at the next step, and from then on designs for 50 ms holds: the rotors land on
    the allocation at each step. Not told (its model assumes 10 ms), it keeps overshooting for
    steps.
    """
    dt, h = 0.01, 1e-3
    step = np.array([0.3, -0.2, 0.1])
    missing = {}
    for told in (False, True):
        mixer = params.mixer(resolve(CONTROLLER, {'motor_lag_compensation': 0.04}))
        act = RotorActuator(tilted_ring(), RHO, mixer.curve, time_constant=0.04)
        held, missing[told], rotors = None, [], None
        for k in range(110):                   # 1 s on time at rest, then the step, late
            out = mixer.mix(step if k >= 100 else np.zeros(3), rotors, dt=dt,
                            held=held if told else None)
            rotors = out.rotors
            hold = 50 if k >= 100 else 10
            for _ in range(hold):
                produced = act.moment(out.commands, h)
            held = hold * h
            if k >= 100:
                missing[told].append(np.linalg.norm(produced - out.allocation.moment)
                                     / np.linalg.norm(step))
    assert missing[True][0] > 1.0 and missing[False][0] > 1.0     # the first late hold: overshoot
    assert max(missing[True][1:]) < 0.05, missing[True]           # corrected at the next step
    assert missing[False][1] > 0.5 and missing[False][2] > 0.15, missing[False]
