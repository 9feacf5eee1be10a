"""The control laws behind the LAWS table on a case derived by hand, and the cbf law's constraint
and QP (finite differences, KKT) and what it holds.
"""
import itertools
import math
import os

from control_support import (
    config,
    one_cone,
)
import numpy as np
import pytest

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.cbf_law import pointing_cbf
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.core.law.mechanics import gravity_moment
from geoctl_ros.core.law.projection import closest_admissible, project
from geoctl_ros.params import (
    CONTROLLER,
    controller_config,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.sim import scenario

# on the vehicle's stack too: the formulas (finite differences, the QP's optimality); the closed
# loops flown here are the same code as the batch-against-alone flights there (test_closed_loop)
odroid = pytest.mark.odroid


@pytest.mark.parametrize('law', ['paper', 'delay_robust', 'geometric', 'cbf'])
def test_each_law_flies_the_derived_yaw_past_a_cone_as_expected(law):
    """The control-law interface (``law``) on a case derived here: testbed_yaw90 with ideal
    torque and no noise, a 90 deg yaw from exp(pi/2 e3^) to I. Without a barrier the error
    e_RA of a pure yaw stays about e3, so the motion is a pure yaw: the sensor (body x) sweeps the
    horizon from 90 to 0 deg of azimuth through the axis of the 12 deg cone at 45 deg, i.e. 12 deg
    deep. So the geometric baseline's closest approach is -12 deg; the paper's law (and its
    delay-robust variant, the same here: nothing is late) and the cbf filter keep the cone. (The
    straight set point: guidance off. With it, test_guidance.py flies the file as it is.)
    """
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    s = scenario.load(os.path.join(root, 'config', 'scenarios', 'testbed_yaw90.yaml'))
    s.controller['law'] = law
    s.controller['guidance_lookahead_deg'] = 0.0
    s.sim.update({'actuation': 'torque', 'noise.attitude_deg': 0.0,
                  'noise.angular_velocity': 0.0})
    r = scenario.run(s, duration=10.0)
    closest = r.summary['min_cone_angle_deg']['obstacle'] - 12.0
    if law == 'geometric':
        # (the closest approach is sampled at the 1 kHz integration steps: the axis is swept
        # through at up to 2 rad/s, so a sample lands within 0.06 deg of it)
        assert closest == pytest.approx(-12.0, abs=0.1), closest
    else:
        assert closest > 0.5, closest


@odroid
def test_the_cbf_laws_constraint_terms_match_finite_differences_of_h():
    """pointing_cbf's h' and h'' (through a_i . u - (the rest)) against central finite
    differences of h_i(t) = cos(theta_i + guard) - (R^T v_i) . r along the model's own motion
    under a moment u: the independent expectation of the constraint the QP enforces.
    """
    cones = ConeSet([1, 0, 0], [[1.0, 1.0, 0.0], [0.0, -1.0, 1.0]], np.radians([12.0, 20.0]),
                    8.0, math.radians(0.25), guard_rad=math.radians(2.0))
    cfg = config(cones, law='cbf', mass=1.2, cog_offset=np.array([0.0, 0.01, 0.1]))
    c = AttitudeController(cfg)
    R, Omega = so3.exp(np.array([0.1, -0.2, 0.4])), np.array([0.3, -0.7, 1.1])
    u = np.array([0.2, -0.1, 0.3])
    J, J_inv = cfg.J, np.linalg.inv(cfg.J)

    def flow(t):                        # the model's motion under u (no estimate), to 2nd order
        acc = J_inv @ (u + gravity_moment(R, cfg.m_rho, cfg.gravity) - np.cross(Omega, J @ Omega))
        W = Omega + acc * t
        return R @ so3.exp(Omega * t + 0.5 * acc * t * t), W

    def h(t):
        R_t, _ = flow(t)
        return np.cos(cones.theta_b) - (cones.V @ R_t) @ cones.r
    A, beta, h0, h_dot = pointing_cbf(c.law_model, R, Omega, c.terms(R, Omega))[:4]
    eps = 1e-4
    np.testing.assert_allclose(h0, h(0.0), atol=1e-12)
    np.testing.assert_allclose(h_dot, (h(eps) - h(-eps)) / (2 * eps), rtol=1e-6, atol=1e-9)
    h_ddot = (h(eps) - 2 * h(0.0) + h(-eps)) / (eps * eps)
    lam = cfg.cbf_rate
    # a_i . u - beta_i = h'' + 2 lambda h' + lambda^2 h
    np.testing.assert_allclose(A @ u - beta, h_ddot + 2 * lam * h_dot + lam * lam * h0,
                               rtol=1e-4, atol=1e-5)


@odroid
def test_the_cbf_qp_is_the_closest_admissible_moment():
    """One constraint: the closed form u0 + max(0, beta - a.u0) a / |a|^2. Two: the projection
    onto their intersection where both bind, checked against the KKT conditions; an admissible
    u0 is returned unchanged.
    """
    u0 = np.array([1.0, -2.0, 0.5])
    a = np.array([[0.0, 1.0, 0.0]])
    got = closest_admissible(u0, a, np.array([1.0]))
    np.testing.assert_allclose(got, [1.0, 1.0, 0.5])
    np.testing.assert_allclose(closest_admissible(u0, a, np.array([-3.0])), u0)
    A = np.array([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    beta = np.array([1.0, 3.0])
    got = closest_admissible(u0, A, beta)
    assert np.all(A @ got >= beta - 1e-9)
    lam = np.linalg.lstsq(A.T, got - u0, rcond=None)[0]       # u - u0 = A^T lambda, lambda >= 0
    np.testing.assert_allclose(A.T @ lam, got - u0, atol=1e-9)
    assert np.all(lam >= -1e-9)
    np.testing.assert_allclose(got, [2.0, 1.0, 0.5])
    # a batch: each run its own
    batch = closest_admissible(np.stack([u0, u0]), np.stack([A, A]),
                               np.stack([beta, np.array([-5.0, -5.0])]))
    np.testing.assert_allclose(batch, [[2.0, 1.0, 0.5], u0])


def test_the_cbf_law_holds_the_guarded_cone_in_the_ideal_loop():
    """The derived yaw (the geometric baseline's path crosses the 12 deg cone's axis), flown by
    the cbf law on the model itself: control at 100 Hz, the moment held, the rigid body
    integrated at 1 kHz, no noise or delay. The filter holds the sensor on the guarded cone
    (12 + 2 deg), never past it: the closest approach is the 2 deg guard. (It then stays there:
    the QP's known deadlock where the nominal moment points straight into the constraint; the
    paper's barrier goes round. docs/control-law.md, "Laws".)
    """
    cfg = controller_config(resolve(CONTROLLER, {
        'law': 'cbf', 'cones.names': ['a'], 'cones.a.axis': np.array([1.0, 1.0, 0.0]),
        'cones.a.half_angle_deg': 12.0, 'cone_guard_deg': 2.0, 'adaptive': False}))
    c = AttitudeController(cfg)
    R, W = so3.axis_angle([0, 0, 1], math.pi / 2), np.zeros(3)
    J, J_inv, h = cfg.J, np.linalg.inv(cfg.J), 1e-3
    closest = 90.0
    for _ in range(500):
        u = c.step(R, W, 0.01).u
        for _ in range(10):
            acc = J_inv @ (u + gravity_moment(R, cfg.m_rho, cfg.gravity) - np.cross(W, J @ W))
            R, W = R @ so3.exp(W * h + 0.5 * acc * h * h), W + acc * h
            closest = min(closest, float(cfg.cones.margins_deg(R)[0]))
    assert 1.99 < closest < 2.1, closest


def test_the_cbf_filter_holds_the_cone_against_an_unlearnt_moment_up_to_its_bound():
    """The robust condition: with ``cbf_moment_bound`` D every row's beta_i grows by exactly
    D |a_i| (the worst a moment |d| <= D does to h''). Flown from a goal 1 deg outside a 20 deg
    cone against 0.05 N m that turns the sensor towards it, not learnt (adaptive off): the filter
    on its exact model (D = 0) lets the sensor in; with D = 0.05 it holds it out.
    """
    cones = one_cone(theta_deg=20.0)
    axis = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
    R0, W0 = so3.exp(np.array([0.1, -0.2, 0.3])), np.array([0.2, 0.1, -0.3])
    exact = AttitudeController(config(cones, law='cbf', adaptive=False))
    robust = AttitudeController(config(cones, law='cbf', adaptive=False, cbf_moment_bound=0.05))
    A0, beta0 = pointing_cbf(exact.law_model, R0, W0, exact.terms(R0, W0))[:2]
    A1, beta1 = pointing_cbf(robust.law_model, R0, W0, robust.terms(R0, W0))[:2]
    np.testing.assert_array_equal(A0, A1)
    np.testing.assert_allclose(beta1 - beta0, 0.05 * np.linalg.norm(A0, axis=-1), rtol=1e-12)

    def fly(bound):
        c = AttitudeController(config(cones, law='cbf', adaptive=False, cbf_moment_bound=bound,
                                      cbf_rate=8.0))
        c.set_setpoint(so3.axis_angle([0, 0, 1], math.pi / 4 - math.radians(21.0)))
        R, w, dt, closest = c.R_d.copy(), np.zeros(3), 0.002, 90.0
        J = c.config.J
        for _ in range(2500):
            towards = np.cross(R @ [1.0, 0.0, 0.0], axis)     # turns the sensor to the cone
            d = R.T @ (0.05 * towards / np.linalg.norm(towards))
            u = c.step(R, w, dt).u
            w = w + dt * np.linalg.solve(J, u + d - np.cross(w, J @ w))
            R = R @ so3.exp(w * dt)
            closest = min(closest, float(cones.margins_deg(R)[0]))
        return closest
    assert fly(0.0) < 0.0                  # the exact model's filter: pushed in
    assert fly(0.05) > 0.0                 # the robust one: held out


@odroid
def test_the_qp_solver_finds_the_kkt_point_among_the_rotors_limits_and_the_cones():
    """``project`` (Goldfarb-Idnani) against the brute force: the testbed's 12 rotor rows and 2-4
    random cone rows, 300 problems; the KKT point found by trying every set of at most 3
    constraints held with equality is the one it returns, to 1e-9 N m.
    """
    testbed = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                           'config', 'testbed.yaml')
    values = resolve(CONTROLLER, node_overrides(load_parameter_file(testbed), CONTROLLER))
    polytope = controller_setup(values).config.moment_limits
    A_m, beta_m = polytope.A, polytope.beta
    assert A_m.shape == (12, 3)
    rng = np.random.default_rng(3)
    solved = 0
    for _ in range(300):
        k = int(rng.integers(2, 5))
        A = np.concatenate((rng.normal(size=(k, 3)), A_m))
        beta = np.concatenate((rng.normal(scale=0.5, size=k), beta_m))
        u0 = rng.normal(scale=1.5, size=3)
        u, feasible = project(u0, A, beta)
        best = None
        for size in (0, 1, 2, 3):
            for S in itertools.combinations(range(len(beta)), size):
                A_S = A[list(S)]
                if size and abs(np.linalg.det(A_S @ A_S.T)) < 1e-12:
                    continue
                lam = np.linalg.solve(A_S @ A_S.T, beta[list(S)] - A_S @ u0) if size else []
                x = u0 + (A_S.T @ lam if size else 0.0)
                if np.all(A @ x >= beta - 1e-9) and np.all(np.asarray(lam) >= -1e-9):
                    best = x
                    break
            if best is not None:
                break
        assert feasible == (best is not None)
        if feasible:
            np.testing.assert_allclose(u, best, atol=1e-9)
            solved += 1
    assert solved > 100
