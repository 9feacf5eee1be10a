"""One formula for one run and for a batch (geoctl_ros.core.geometry.elementwise): the brake's
view of each cone, its backup travel and least deceleration, and the model's acceleration run in
Python floats for one run and in whole arrays for a batch, and must give the same bits either way
(a run's figures may not depend on the batch it flies in). And the brake's view against the
kinematics it claims, by finite differences written here.
"""
import math

import numpy as np
import pytest

from geoctl_ros.core.geometry import elementwise, so3
from geoctl_ros.core.law.brake import (
    ApproachBrake,
    BrakeInputs,
    backup_travel,
    brake_terms,
    braked,
    least_deceleration,
    opening,
)
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.configuration_error import barrier_at_step
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.params import (
    CONTROLLER,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)

pytestmark = pytest.mark.odroid

RUNS = 40       # a batch this large goes through whole arrays (elementwise.FLOATS_MAX)


def _controller():
    values = resolve(CONTROLLER, node_overrides(load_parameter_file('config/testbed.yaml'),
                                                CONTROLLER))
    setup = controller_setup(values)
    return AttitudeController(setup.config), setup


def _ticks(rng, n):
    """n random ticks near the testbed's cone: attitudes, rates, moments."""
    R = np.stack([so3.exp(np.array([0.0, 0.0, rng.uniform(-math.pi, math.pi)]))
                  @ so3.exp(rng.normal(0.0, 0.2, 3)) for _ in range(n)])
    return R, rng.normal(0.0, 0.8, (n, 3)), rng.normal(0.0, 0.5, (n, 3))


def test_the_brakes_view_of_a_run_is_the_same_bits_alone_and_in_a_batch():
    """``brake_terms`` and ``braked`` of 40 random ticks at once (whole arrays) equal, bit for
    bit, each tick's alone (Python floats, cone by cone), and so do the backup travel and the
    least deceleration of 40 random cones.
    """
    assert RUNS > elementwise.FLOATS_MAX
    ctl, setup = _controller()
    cfg = setup.config
    rng = np.random.default_rng(5)
    R, Omega, u = _ticks(rng, RUNS)
    f = rng.normal(0.0, 0.3, (RUNS, 3))
    gravity = rng.normal(0.0, 0.3, (RUNS, 3))
    rotors = rng.normal(0.0, 0.3, (RUNS, 3))
    age = rng.uniform(0.0, 0.06, RUNS)
    batch = BrakeInputs(R, Omega, age, 0.01, rotors, f, gravity)
    together = brake_terms(ctl.brake, cfg.cones, ctl.J_inv, batch)
    moments = braked(ctl.brake, cfg.cones, ctl.J_inv, cfg.moment_limits, batch, u)
    for k in range(RUNS):
        x = BrakeInputs(R[k], Omega[k], float(age[k]), 0.01, rotors[k], f[k], gravity[k])
        alone = brake_terms(ctl.brake, cfg.cones, ctl.J_inv, x)
        for name, a, b in zip(alone._fields, alone, together):
            assert np.array_equal(a, b[k]), (k, name)
        assert np.array_equal(braked(ctl.brake, cfg.cones, ctl.J_inv, cfg.moment_limits, x,
                                     u[k]).u, moments.u[k]), k
    brake = ApproachBrake.bounds_of(cfg)
    gap, w = rng.uniform(0.0, 0.3, RUNS), rng.uniform(-1.0, 3.0, RUNS)
    D_s, authority = rng.uniform(-20.0, 40.0, RUNS), rng.uniform(10.0, 45.0, RUNS)
    travel = backup_travel(brake, w, D_s, D_s, authority, 0.01)
    least, margin = least_deceleration(brake, gap, w, D_s, 0.02, 0.5, authority, 0.01)
    for k in range(RUNS):
        assert backup_travel(brake, float(w[k]), float(D_s[k]), float(D_s[k]),
                             float(authority[k]), 0.01) == travel[k]
        one = least_deceleration(brake, gap[k:k + 1], w[k:k + 1], D_s[k:k + 1], 0.02, 0.5,
                                 authority[k:k + 1], 0.01)
        assert (one[0][0], one[1][0]) == (least[k], margin[k])


@pytest.mark.parametrize('cones', [1, 3])
def test_the_barrier_at_the_step_is_the_same_bits_alone_and_in_a_batch(cones):
    """The cones' barrier at a step, widened by the blind time (``barrier_at_step``), of 40
    random ticks at once (whole arrays) equals each tick's alone (floats, cone by cone) bit for
    bit, where cones are approached and widened, left alone, and in their floor band (the
    extension: arrays for both).
    """
    rng = np.random.default_rng(7 + cones)
    axes = rng.normal(size=(cones, 3))
    set_ = ConeSet([1.0, 0.0, 0.0], axes, rng.uniform(0.2, 0.5, cones), 8.0, math.radians(0.5),
                   guard_rad=math.radians(2.0))
    R, Omega, _ = _ticks(rng, RUNS)
    blind = rng.uniform(0.0, 0.08, RUNS)
    blind[::5] = 0.0
    sc = set_.terms(R)
    together = barrier_at_step(set_, sc, Omega, blind, math.radians(5.0))
    widened = banded = 0
    for k in range(RUNS):
        one = slice(k, k + 1)           # a batch of one (the sim's), and the node's one run
        alone = barrier_at_step(set_, sc[one], Omega[one], blind[one], math.radians(5.0))
        node = barrier_at_step(set_, sc[k], Omega[k], float(blind[k]), math.radians(5.0))
        for name in ('s', 'B', 'weight', 'saturated', 'e_RB_sum'):
            assert np.array_equal(getattr(alone, name), getattr(together, name)[one]), (k, name)
            assert np.array_equal(getattr(node, name), getattr(together, name)[k]), (k, name)
        banded += bool(alone.any_saturated[0])
        plain = barrier_at_step(set_, sc[k], Omega[k], 0.0, 0.0)
        widened += not np.array_equal(plain.B, node.B)
    assert widened >= 3 and banded >= 1 and widened + banded < RUNS


def test_the_mix_of_one_run_is_the_same_bits_as_in_a_batch():
    """The mixer's lag compensation and thrust curve of one run (floats, rotor by rotor) give
    the commands, the cut and the rotors' model of a batch of 40 (whole arrays), bit for bit:
    random moments (some beyond the rotors), rotor states and holds, spooling and flying.
    """
    _, setup = _controller()
    mixer = setup.mixer
    rng = np.random.default_rng(9)
    u = rng.normal(0.0, 0.6, (RUNS, 3))
    first = mixer.mix(np.zeros((RUNS, 3)), None, dt=0.01)       # the rotors at rest, spooling
    lo, hi = mixer.allocator.lo, mixer.allocator.hi
    sent = rng.uniform(lo, hi, first.rotors.sent.shape)
    modelled = rng.uniform(lo, hi, sent.shape)
    # half the runs' rotors near what the moment needs (the compensation not cut)
    near = mixer.allocator.allocate(u, mixer.collective_thrust).thrusts[::2]
    sent[::2] = modelled[::2] = near + rng.normal(0.0, 0.01, near.shape)
    clipped = 0
    for spool_left in (0.03, -0.01):
        rotors = first.rotors._replace(sent=sent, modelled=modelled, design_hold=0.02,
                                       spool_left=spool_left)
        together = mixer.mix(u, rotors, dt=0.01, held=0.013)
        for k in range(RUNS):
            one = rotors._replace(sent=sent[k], modelled=modelled[k])
            alone = mixer.mix(u[k], one, dt=0.01, held=0.013)
            assert np.array_equal(alone.commands, together.commands[k]), k
            assert np.array_equal(alone.normalised, together.normalised[k]), k
            assert alone.clipped == (together.clipped[k] if np.ndim(together.clipped)
                                     else together.clipped), k
            for name in ('sent', 'modelled'):
                assert np.array_equal(getattr(alone.rotors, name),
                                      getattr(together.rotors, name)[k]), (k, name)
            assert (alone.rotors.design_hold, alone.rotors.spool_left) == (
                together.rotors.design_hold, together.rotors.spool_left)
            clipped += bool(alone.clipped)
    assert 0 < clipped < RUNS


def test_the_models_acceleration_is_the_same_bits_alone_and_in_a_batch():
    """``Dynamics.acceleration`` and ``moments`` of 40 random states at once equal each one's
    alone, bit for bit, and J times the acceleration is the moments' sum (to rounding).
    """
    ctl, _ = _controller()
    rng = np.random.default_rng(6)
    R, Omega, moment = _ticks(rng, RUNS)
    ctl.delta_bar = rng.normal(0.0, 0.05, (RUNS,) + ctl.delta_bar.shape)
    together = ctl.dynamics.acceleration(R, Omega, moment)
    M_g, f = ctl.dynamics.moments(R, Omega)
    for k in range(RUNS):
        one = ctl.dynamics._replace(delta_bar=ctl.delta_bar[k])
        assert np.array_equal(one.acceleration(R[k], Omega[k], moment[k]), together[k])
        assert np.array_equal(one.moments(R[k], Omega[k])[1], f[k])
        assert np.allclose(ctl.config.J @ together[k], moment[k] + f[k], atol=1e-12)
        assert np.array_equal(M_g[k], np.cross(ctl.config.m_rho, R[k].T @ ctl.config.gravity))


def test_the_opening_is_the_gap_its_approach_rate_and_that_rates_change():
    """``opening`` against the motion it describes, by finite differences: turning at a constant
    body rate Omega, the gap to the cone (the sensor's angle to the axis, less the half-angle)
    falls at w, and w changes at kin (no angular acceleration), for 50 random attitudes and
    rates.
    """
    _, setup = _controller()
    cones = setup.config.cones
    r, v, theta = cones.r, cones.V[0], float(cones.theta[0])
    rng = np.random.default_rng(7)
    h = 1e-5
    for R, Omega, _ in zip(*_ticks(rng, 50)):
        gap, n, w, kin = (float(a[0]) if a.ndim == 1 else a[0] for a in opening(cones, R, Omega))

        def gap_at(t):
            d = R @ so3.exp(Omega * t) @ r
            return math.acos(max(-1.0, min(1.0, float(v @ d)))) - theta
        assert gap == pytest.approx(gap_at(0.0), abs=1e-12)
        assert -(gap_at(h) - gap_at(-h)) / (2 * h) == pytest.approx(w, abs=1e-6)
        w_at = [float(opening(cones, R @ so3.exp(Omega * t), Omega)[2][0]) for t in (-h, h)]
        assert (w_at[1] - w_at[0]) / (2 * h) == pytest.approx(kin, rel=1e-4, abs=1e-5)
        assert np.linalg.norm(n) == pytest.approx(1.0)
