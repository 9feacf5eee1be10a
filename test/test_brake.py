"""The approach brake (geoctl_ros.core.law.brake): its allowed rate against the derivation's
braking distance, the direction and size of its moment against finite differences of the approach
rate, and where it acts.
"""
import math

import numpy as np
import pytest

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.brake import ApproachBrake, assumptions_held, braking_distance
from geoctl_ros.core.law.configuration_error import approach_rates
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.params import (
    CONTROLLER,
    controller_config,
    load_parameter_file,
    node_overrides,
    resolve,
)

pytestmark = pytest.mark.odroid

BRAKE = ApproachBrake(rate=100.0, acceleration=40.0, unmodelled=22.0, measurement=0.005)


def test_the_allowed_rate_closes_exactly_the_margin_left():
    """w_max inverts the derivation: from w_max, blind for T, then braking at a_b, the sensor
    closes by the gap less the measurement error; with no gap left past the unmodelled drift, no
    approach is allowed.
    """
    rng = np.random.default_rng(5)
    for _ in range(200):
        T = rng.uniform(0.005, 0.2)
        gap = rng.uniform(0.0, 0.5)
        w = float(BRAKE.allowed_rate(gap, T))
        room = gap - BRAKE.measurement - 0.5 * BRAKE.unmodelled * T * T
        if room <= 0.0:
            assert w == 0.0
        else:
            assert w > 0.0
            assert braking_distance(BRAKE, w, T) == pytest.approx(gap - BRAKE.measurement,
                                                                  rel=1e-9, abs=1e-12)
    # the faster the loop sees, the faster it may approach
    assert BRAKE.allowed_rate(0.1, 0.01) > BRAKE.allowed_rate(0.1, 0.05) > \
        BRAKE.allowed_rate(0.1, 0.1)


def _testbed_controller(**over):
    values = resolve(CONTROLLER, node_overrides(load_parameter_file('config/testbed.yaml'),
                                                CONTROLLER))
    values.update(over)
    return AttitudeController(controller_config(values))


def test_the_brake_takes_away_the_excess_approach_and_nothing_else():
    ctl = _testbed_controller()
    brake, cfg = ctl.brake, ctl.config
    assert brake is not None
    assert brake.unmodelled == pytest.approx(cfg.cbf_moment_bound
                                             / np.linalg.eigvalsh(cfg.J).min())
    cones = cfg.cones
    # the sensor 3 deg outside the cone, turning towards it (about the world z axis) at w
    axis = cones.V[0]
    theta = float(cones.theta[0])
    phi = theta + math.radians(3.0)
    az = math.atan2(axis[1], axis[0]) + phi            # the sensor (body x) at yaw az
    R = so3.exp(np.array([0.0, 0.0, az]))
    assert math.degrees(math.acos(float((R @ cones.r) @ axis))) == pytest.approx(
        math.degrees(phi))
    sc = cones.terms(R)
    s, cross = sc[..., 0], sc[..., 1:]
    allowed = float(brake.allowed_rate(phi - theta, 0.06 + 0.01))
    for w, acts in ((0.5 * allowed, False), (allowed + 0.2, True), (allowed + 3.0, True)):
        Omega = np.array([0.0, 0.0, -w])            # yaw towards the cone's axis
        assert float(approach_rates(sc, Omega)[0]) == pytest.approx(w, rel=1e-9)
        u = brake.moment(cfg.J, s, cross, cones.theta, Omega, 0.06, 0.01)
        if not acts:
            assert u is None
            continue
        # its angular acceleration takes the excess away at k_b, at most a_b (finite
        # differences of the approach rate under it)
        dt = 1e-6
        later = approach_rates(sc, Omega + dt * np.linalg.solve(cfg.J, u))[0]
        decel = (w - float(later)) / dt
        assert decel == pytest.approx(min(brake.rate * (w - allowed), brake.acceleration),
                                      rel=1e-5)


def test_the_brake_is_the_delay_robust_laws_alone():
    R = so3.exp(np.array([0.0, 0.0, math.radians(60.0)]))
    Omega = np.array([0.0, 0.0, -6.0])
    outs = {}
    for law in ('delay_robust', 'paper'):
        for rate in (0.0, 100.0):
            ctl = _testbed_controller(law=law, approach_brake_rate=rate)
            outs[law, rate] = ctl.step(R, Omega, 0.01, adapt=False, blind=0.05).u
    assert not np.allclose(outs['delay_robust', 0.0], outs['delay_robust', 100.0])
    assert np.array_equal(outs['paper', 0.0], outs['paper', 100.0])
    assert _testbed_controller(approach_brake_rate=0.0).brake is None


def test_the_derivation_speaks_of_a_step_only_when_its_bounds_held_over_the_window_before():
    """``assumptions_held``: a step counts when, over the ASSUMED_WINDOW_S (0.3 s, 30 steps at
    100 Hz) up to it, no step saturated, the unlearnt acceleration stayed within a_u and the
    measurement's error within e, and the rotors had spooled up (80 ms) by the window's start.
    """
    steps, runs, dt = 100, 4, 0.01
    unlearnt = np.full((steps, runs), 0.5 * BRAKE.unmodelled)
    measurement = np.full((steps, runs), 0.5 * BRAKE.measurement)
    saturated = np.zeros((steps, runs), dtype=bool)
    unlearnt[50, 1] = 1.01 * BRAKE.unmodelled          # run 1: one step past a_u
    measurement[60, 2] = 1.01 * BRAKE.measurement      # run 2: one measurement past e
    saturated[70, 3] = True                            # run 3: one saturated step
    held = assumptions_held(BRAKE, unlearnt, measurement, saturated, dt, 0.08)
    first = 30 + 8
    assert not held[:first].any() and held[first:, 0].all()
    for run, bad in ((1, 50), (2, 60), (3, 70)):
        expected = np.arange(steps) >= first
        expected[bad:bad + 31] = False                # the bad step and the 30 after it
        assert np.array_equal(held[:, run], expected), run
