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


def _brake(ctl, R, Omega, acc, blind, hold):
    """The testbed brake's moment at (R, Omega) with the law's acceleration acc."""
    cones = ctl.config.cones
    sc = cones.terms(R)
    return ctl.brake.moment(ctl.config.J, so3.vecmat(cones.V, R[None]), sc[..., 0],
                            sc[..., 1:], cones.theta, cones.r, Omega, acc, blind, hold)


def _approach(ctl, R, Omega):
    """w for the testbed's first cone (rad/s)."""
    return float(approach_rates(ctl.config.cones.terms(R), Omega)[0])


def test_the_brake_keeps_the_approach_under_its_curve_with_the_least_deceleration():
    """Where the law would let h = w_max - w fall faster than k_b h (less a_u, which the model
    does not know), the brake's moment makes the approach's rate of change, by finite
    differences along the flight, exactly -(dw_max/dG) w + k_b h - a_u; elsewhere it is None.
    """
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
    blind, hold = 0.06, 0.01
    T = blind + hold
    allowed = float(brake.allowed_rate(phi - theta, T))
    slope = brake.acceleration / (allowed + brake.acceleration * T)
    opening = np.array([0.0, 0.0, 1.0])                # yaw away from the cone's axis
    for w, pushed, acts in ((0.5 * allowed, 0.0, False), (0.5 * allowed, 30.0, True),
                            (allowed, 0.0, True), (allowed + 0.2, 0.0, True),
                            (allowed + 0.2, 5.0, True)):
        Omega = -w * opening
        assert _approach(ctl, R, Omega) == pytest.approx(w, rel=1e-9)
        acc = -pushed * opening                          # the law's, towards the cone
        u = _brake(ctl, R, Omega, acc, blind, hold)
        if not acts:
            assert u is None
            continue
        dt = 1e-6
        total = acc + np.linalg.solve(cfg.J, u)
        later = _approach(ctl, R @ so3.exp(Omega * dt), Omega + dt * total)
        expected = -slope * w + brake.rate * (allowed - w) - brake.unmodelled
        assert (later - w) / dt == pytest.approx(expected, rel=1e-4, abs=1e-3)


def test_the_approach_rates_change_is_its_finite_difference_along_any_motion():
    """dw_i/dt = kinematic_i - n_i . Omega' (``ApproachBrake.condition``) against finite
    differences of the approach rate, at 50 random attitudes, rates and accelerations (the yaw
    of the test above is a great circle, where the kinematic term is 0).
    """
    ctl = _testbed_controller()
    brake, cones = ctl.brake, ctl.config.cones
    rng = np.random.default_rng(11)
    for _ in range(50):
        R = so3.exp(rng.normal(size=3))
        Omega, acc = rng.normal(size=3), rng.normal(scale=5.0, size=3)
        sc = cones.terms(R)
        inv, w, kinematic, _, _ = brake.condition(
            so3.vecmat(cones.V, R[None]), sc[..., 0], sc[..., 1:], cones.theta, cones.r, Omega,
            0.02, 0.01)
        w_dot = kinematic - (sc[..., 1:] @ acc) * inv
        dt = 1e-6
        later = approach_rates(cones.terms(R @ so3.exp((Omega + 0.5 * dt * acc) * dt)),
                               Omega + dt * acc)
        np.testing.assert_allclose((later - w) / dt, w_dot, rtol=1e-4, atol=1e-3)


def test_under_the_worst_unlearnt_acceleration_the_brake_stops_the_sensor_outside_the_cone():
    """The derivation, flown: the sensor 10 deg outside the cone closing at 3 rad/s, the loop
    seeing at once (T_b = 0) and commanding every millisecond, the law asking nothing, and an
    unknown acceleration of a_u pushing it in all along. The brake stops it outside the cone,
    by the measurement's bound e that the curve keeps back (to 1 %; 0.300 deg).
    """
    ctl = _testbed_controller()
    brake, cfg = ctl.brake, ctl.config
    cones = cfg.cones
    axis = cones.V[0]
    theta = float(cones.theta[0])
    az = math.atan2(axis[1], axis[0]) + theta + math.radians(10.0)
    R = so3.exp(np.array([0.0, 0.0, az]))
    opening = np.array([0.0, 0.0, 1.0])
    Omega = -3.0 * opening
    h = 1e-3
    closest = math.inf
    for _ in range(1000):
        u = _brake(ctl, R, Omega, np.zeros(3), 0.0, h)
        acc = (np.zeros(3) if u is None else np.linalg.solve(cfg.J, u)) \
            - brake.unmodelled * opening
        R = R @ so3.exp((Omega + 0.5 * h * acc) * h)
        Omega = Omega + h * acc
        closest = min(closest, math.acos(float((R @ cones.r) @ axis)) - theta)
    assert _approach(ctl, R, Omega) < 1e-6             # stopped
    assert closest >= 0.99 * brake.measurement


def test_the_brake_is_the_delay_robust_laws_and_a_constraint_of_the_cbf_laws_qp():
    """The delay-robust law adds the brake's moment, the cbf law keeps its condition as
    constraints of its QP (the model's approach rate then meets it for every cone, to 1e-7
    rad/s^2, where it did not without them), and the paper's law has no brake.
    """
    R = so3.exp(np.array([0.0, 0.0, math.radians(60.0)]))
    Omega = np.array([0.0, 0.0, -6.0])
    blind, dt = 0.05, 0.01
    outs = {}
    for law in ('delay_robust', 'paper', 'cbf'):
        for rate in (0.0, 100.0):
            ctl = _testbed_controller(law=law, approach_brake_rate=rate)
            outs[law, rate] = ctl.step(R, Omega, dt, adapt=False, blind=blind).u
    assert not np.allclose(outs['delay_robust', 0.0], outs['delay_robust', 100.0])
    assert np.array_equal(outs['paper', 0.0], outs['paper', 100.0])
    assert _testbed_controller(approach_brake_rate=0.0).brake is None
    ctl = _testbed_controller(law='cbf')
    brake, cones = ctl.brake, ctl.config.cones
    sc = cones.terms(R)
    inv, w, kinematic, w_max, slope = brake.condition(
        so3.vecmat(cones.V, R[None]), sc[..., 0], sc[..., 1:], cones.theta, cones.r, Omega,
        blind, dt)
    n = sc[..., 1:] * inv[:, None]

    def excess(u):          # the condition's excess per cone under the model (the cbf's: no
        acc = ctl.model_acceleration(R, Omega, u, np.zeros_like(ctl.delta_bar))   # estimate)
        return kinematic - n @ acc + brake.unmodelled + slope * w - brake.rate * (w_max - w)
    assert np.max(excess(outs['cbf', 0.0])) > 1.0
    assert np.max(excess(outs['cbf', 100.0])) <= 1e-7


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
