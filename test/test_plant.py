"""The testbed simulator: conservation laws, order of accuracy, the pendulum about the pivot."""
import math

import numpy as np
import pytest

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.mechanics import gravity_moment, pivot_inertia
from geoctl_ros.params import LAB_INERTIA
from geoctl_ros.params.testbed import Disturbance, PlantConfig
from geoctl_ros.sim.plant import Plant
from geoctl_ros.sim.testbed import EscWatchdog

pytestmark = pytest.mark.odroid

J_LAB = np.array(LAB_INERTIA).reshape(3, 3)
NO_DIST = Disturbance(np.zeros(3), np.zeros(3), 0.0)
G_W = np.array([0.0, 0.0, -9.81])


def tumbling(h, seconds):
    plant = Plant(PlantConfig(J_LAB, 1.26, np.zeros(3), G_W, NO_DIST),
                  so3.exp([0.3, -0.2, 0.1]), [3.0, -1.0, 2.0])
    for _ in range(int(round(seconds / h))):
        plant.step(np.zeros(3), h)
    return plant


def test_torque_free_motion_conserves_energy_and_momentum_and_stays_on_SO3():
    start = tumbling(1e-3, 0.0)
    end = tumbling(1e-3, 10.0)
    assert end.kinetic_energy() == pytest.approx(start.kinetic_energy(), rel=1e-9)
    assert np.allclose(end.angular_momentum_world(), start.angular_momentum_world(), rtol=1e-9,
                       atol=1e-12)
    assert np.abs(end.R.T @ end.R - np.eye(3)).max() < 1e-13


def test_rkmk4_is_fourth_order():
    reference = tumbling(1.25e-4, 2.0).R
    errors = [so3.angle(reference.T @ tumbling(h, 2.0).R) for h in (8e-3, 4e-3, 2e-3)]
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    assert all(12.0 < r < 20.0 for r in ratios), (errors, ratios)   # 2^4 = 16
    assert errors[2] < 1e-8


def test_pivot_inertia_and_gravity_moment():
    rho = np.array([0.0, 0.0, 0.1])
    Jp = pivot_inertia(J_LAB, 1.26, rho)
    assert Jp[0, 0] == pytest.approx(J_LAB[0, 0] + 1.26 * 0.01)
    assert Jp[2, 2] == pytest.approx(J_LAB[2, 2])
    # tilted 30 deg about x with the centre of mass above the pivot: gravity tips it further
    R = so3.axis_angle([1, 0, 0], math.radians(30.0))
    M = gravity_moment(R, 1.26 * rho, G_W)
    assert M[0] == pytest.approx(1.26 * 9.81 * 0.1 * math.sin(math.radians(30.0)))
    assert M[1] == pytest.approx(0.0) and M[2] == pytest.approx(0.0)


def test_centre_of_mass_above_the_pivot_falls_over():
    plant = Plant(PlantConfig(J_LAB, 1.26, np.array([0.0, 0.0, 0.1]), G_W, NO_DIST),
                  so3.axis_angle([1, 0, 0], math.radians(1.0)))
    for _ in range(1500):
        plant.step(np.zeros(3), 1e-3)
    tilt = math.degrees(math.acos(np.clip(plant.R[2, 2], -1, 1)))
    assert tilt > 60.0


def test_centre_of_mass_below_the_pivot_swings_with_the_pendulum_period():
    length, m = 0.1, 1.26
    plant = Plant(PlantConfig(J_LAB, m, np.array([0.0, 0.0, -length]), G_W, NO_DIST),
                  so3.axis_angle([1, 0, 0], math.radians(2.0)))
    roll, t = [], []
    for _ in range(4000):
        plant.step(np.zeros(3), 1e-3)
        roll.append(so3.log(plant.R)[0])
        t.append(plant.t)
    roll, t = np.array(roll), np.array(t)
    up = np.nonzero((roll[:-1] < 0) & (roll[1:] >= 0))[0]
    period = np.mean(np.diff(t[up]))
    J_pivot = pivot_inertia(J_LAB, m, [0, 0, -length])
    expected = 2 * math.pi * math.sqrt(J_pivot[0, 0] / (m * 9.81 * length))
    assert period == pytest.approx(expected, rel=2e-3)


def test_disturbance_follows_the_dissertation_pattern():
    d = Disturbance(np.array([0.2, 0.2, 0.2]), np.array([0.02, 0.02, 0.02]), 9.0)
    t = 0.37
    s, c = math.sin(9 * t), math.cos(9 * t)
    assert np.allclose(d(t), [0.2 + 0.02 * s, 0.2 + 0.02 * c, 0.2 + 0.01 * (s + c)])
    assert np.allclose(Disturbance(np.ones(3), np.zeros(3), 0.0)(5.0), 1.0)


def test_the_esc_timeout_counts_the_links_silence_not_the_simulators_own_stall():
    esc = EscWatchdog(timeout=0.1, stall=0.05)
    assert not esc.fresh(0.0)                       # never commanded: motors stopped
    t = 0.0
    for _ in range(20):                             # commands every 10 ms, ticks every 5 ms
        esc.received(t)
        assert esc.fresh(t) and esc.fresh(t + 0.005)
        t += 0.01
    # the simulator stalls 0.15 s (SIGSTOP): its first tick after it still drives the motors...
    assert esc.fresh(t + 0.15)
    # ...and the commands queued during the stall arrive: running on
    esc.received(t + 0.151)
    assert esc.fresh(t + 0.155)
    # the controller really stops: the motors stop once the silence passes the timeout
    assert esc.fresh(t + 0.25)
    assert not esc.fresh(t + 0.2515)
    # a stall that follows a silence already past the timeout does not restart the motors
    assert not esc.fresh(t + 0.6)
    # the controller gone while the simulator was stalled: one catch-up on the last command,
    # then stopped at the next tick
    esc.received(t + 0.7)
    assert esc.fresh(t + 0.705) and esc.fresh(t + 1.5) and not esc.fresh(t + 1.505)


def test_the_stops_catch_a_falling_testbed_alone_and_in_a_batch_to_the_same_bits():
    """A centre of mass 5 cm above the pivot, 10 deg off upright, falls onto stops at 30 deg:
    they catch it within a degree past them and hold it there. In a batch beside a testbed
    that swings within its stops (centre of mass below the pivot), it steps to the bits it
    steps to alone (the batch skips the stops' moment only where no testbed is near them).
    """
    limit = math.radians(30.0)

    def config(offsets):
        n = len(offsets)
        if n == 1:
            return PlantConfig(J_LAB, 1.26, np.array(offsets[0]), G_W, NO_DIST, limit)
        return PlantConfig(np.repeat(J_LAB[None], n, axis=0), np.full(n, 1.26),
                           np.array(offsets), G_W,
                           Disturbance(np.zeros((n, 3)), np.zeros((n, 3)), 0.0), limit)
    R0 = so3.axis_angle([1.0, 0.3, 0.0], math.radians(10.0))
    alone = Plant(config([[0.0, 0.0, 0.05]]), R0, np.zeros(3))
    batch = Plant(config([[0.0, 0.0, 0.05], [0.0, 0.0, -0.05]]), np.stack([R0, R0]),
                  np.zeros((2, 3)))
    tilts = []
    for _ in range(2000):                                   # 2 s at 1 kHz
        alone.step(np.zeros(3), 1e-3)
        batch.step(np.zeros((2, 3)), 1e-3)
        tilts.append(math.degrees(math.acos(alone.R[2, 2])))
        assert np.array_equal(alone.R, batch.R[0]) and np.array_equal(alone.Omega,
                                                                      batch.Omega[0])
    assert 30.0 < max(tilts) < 31.0 and abs(tilts[-1] - 30.0) < 0.2, (max(tilts), tilts[-1])
    assert math.degrees(math.acos(batch.R[1, 2, 2])) < 10.0        # the other: within them
