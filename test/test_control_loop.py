"""The control law in closed loop with the plant: Lyapunov decrease, convergence, tracking, and
the adaptive estimate (convergence, projection, holding and reset).
"""
import math

from control_support import (
    J_PAPER,
    config,
    four_cones,
    one_cone,
)
import numpy as np
import pytest

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.params.testbed import Disturbance, PlantConfig
from geoctl_ros.sim.plant import Plant

# on the vehicle's stack too, but for the four long closed-loop flights: the scenario and campaign
# tests and the sim-in-the-loop flight fly the same loop there
odroid = pytest.mark.odroid


# --- Prop. 3: closed loop without disturbance ---------------------------------------------------
def closed_loop(cfg, R0, rate_hz, seconds, disturbance=None, sub=1, setpoint=None):
    """Run controller (ZOH at rate_hz) and plant; yields (controller output, plant) per step."""
    plant = Plant(PlantConfig(cfg.inertia, cfg.mass, cfg.cog_offset, cfg.gravity,
                                disturbance or Disturbance(np.zeros(3), np.zeros(3), 0.0)), R0)
    ctrl = AttitudeController(cfg)
    if setpoint is not None:
        ctrl.set_setpoint(setpoint)
    dt = 1.0 / rate_hz
    for _ in range(int(seconds * rate_hz)):
        out = ctrl.step(plant.R, plant.Omega, dt)
        yield out, plant, ctrl
        for _ in range(sub):
            plant.step(out.u, dt / sub)


@odroid
def test_lyapunov_function_never_increases_without_disturbance():
    cfg = config(four_cones(), adaptive=False)
    V = []
    min_margin = np.inf
    for out, plant, _ in closed_loop(cfg, so3.axis_angle([0, 0, 1], math.radians(225.0)),
                                     rate_hz=1000.0, seconds=8.0):
        V.append(plant.kinetic_energy() + cfg.k_R * out.psi)
        min_margin = min(min_margin, out.margins_deg.min())
    V = np.array(V)
    # Continuous time: V' = -k_Omega |Omega|^2. The 1 kHz zero-order hold may add O(dt^2) per step.
    assert np.all(np.diff(V) <= 1e-9 * V[0])
    assert V[-1] < 0.05 * V[0]
    assert min_margin > 0.0


@odroid
def test_stabilises_to_the_desired_attitude_and_keeps_the_cone():
    cfg = config(one_cone(), k_Omega=0.7)
    outs = list(closed_loop(cfg, so3.axis_angle([0, 0, 1], math.pi / 2), 200.0, 25.0))
    out, plant, ctrl = outs[-1]
    assert so3.angle(plant.R) < math.radians(0.1)
    assert min(o.margins_deg[0] for o, _, _ in outs) > 1.0


def test_tracking_a_rotating_setpoint_converges():
    cfg = config(ConeSet([1, 0, 0], np.zeros((0, 3)), [], 8.0, 0.01), adaptive=False,
                 k_Omega=0.7)
    w = np.array([0.0, 0.3, 0.5])
    plant = Plant(PlantConfig(J_PAPER, 1.0, np.zeros(3), np.zeros(3),
                                Disturbance(np.zeros(3), np.zeros(3), 0.0)),
                    so3.axis_angle([1, 0, 0], 1.0))
    ctrl = AttitudeController(cfg)
    dt = 0.002
    for k in range(int(15.0 / dt)):
        R_d = so3.exp(w * (k * dt))
        ctrl.set_setpoint(R_d, Omega_d=w)
        out = ctrl.step(plant.R, plant.Omega, dt)
        plant.step(out.u, dt)
    R_d = so3.exp(w * (plant.t))          # the set point at the plant's time
    assert so3.angle(R_d.T @ plant.R) < math.radians(0.01)
    assert np.linalg.norm(out.e_Omega) < 1e-3


# --- Prop. 5: adaptation -----------------------------------------------------------------------
def test_adaptive_estimate_converges_to_constant_disturbance():
    cfg = config(four_cones())
    dist = Disturbance(np.array([0.2, 0.2, 0.2]), np.zeros(3), 0.0)
    outs = list(closed_loop(cfg, so3.axis_angle([0, 0, 1], math.radians(225.0)), 500.0, 20.0,
                            disturbance=dist, sub=2))
    out, plant, ctrl = outs[-1]
    assert np.allclose(ctrl.delta_bar, 0.2, atol=1e-3)
    assert so3.angle(plant.R) < math.radians(0.01)


def test_without_adaptation_a_disturbance_leaves_a_steady_error():
    cfg = config(four_cones(), adaptive=False)
    dist = Disturbance(np.array([0.2, 0.2, 0.2]), np.zeros(3), 0.0)
    outs = list(closed_loop(cfg, so3.axis_angle([0, 0, 1], math.radians(225.0)), 500.0, 20.0,
                            disturbance=dist, sub=2))
    out, plant, ctrl = outs[-1]
    assert np.all(ctrl.delta_bar == 0.0)
    assert so3.angle(plant.R) > math.radians(10.0)
    # at rest the feedback balances the disturbance: k_R e_R = Delta
    assert np.allclose(cfg.k_R * out.e_R, 0.2, atol=2e-3)


@odroid
def test_estimate_projection_bounds_the_estimate():
    cfg = config(one_cone(), delta_bar_max=0.05, k_Delta=50.0)
    ctrl = AttitudeController(cfg)
    R = so3.axis_angle([0, 0, 1], math.pi / 2)
    for _ in range(100):
        ctrl.step(R, np.array([0.5, -0.5, 2.0]), 0.01)
    assert np.linalg.norm(ctrl.delta_bar) == pytest.approx(0.05)


@odroid
def test_adapt_false_holds_the_estimate_and_reset_zeroes_it():
    ctrl = AttitudeController(config(one_cone()))
    R = so3.axis_angle([0, 0, 1], math.pi / 2)
    ctrl.step(R, np.ones(3), 0.01)
    held = ctrl.delta_bar.copy()
    assert np.linalg.norm(held) > 0
    ctrl.step(R, np.ones(3), 0.01, adapt=False)
    assert np.array_equal(ctrl.delta_bar, held)
    ctrl.reset_adaptation()
    assert not ctrl.delta_bar.any()
