"""The approach brake (geoctl_ros.core.law.brake), derived for the sampled, held and delayed loop:
its closed forms against fine numerical integration, its rows joined in one QP, its authority
against the rotors' polytope computed here, the judge of its assumptions, and the derivation
flown at 0, 20 and 60 ms of blindness with a 10 ms hold, the 40 ms motor lag and the unknown
acceleration pushing in all along, against a one-axis simulation of the same loop written here
without brake.py.
"""
import itertools
import math

import numpy as np
import pytest

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law import brake as brake_module
from geoctl_ros.core.law.brake import (
    ApproachBrake,
    BrakeInputs,
    backup_travel,
    brake_authority,
    braked,
    covered,
    least_deceleration,
    meets,
    opening,
    rows,
)
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.core.law.prediction import CommandHistory, Observer, predict
from geoctl_ros.params import (
    CONTROLLER,
    ConfigError,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)
from geoctl_ros.params.build import airframe
from geoctl_ros.params.testbed import Disturbance, PlantConfig
from geoctl_ros.sim.plant import Plant
from geoctl_ros.sim.testbed import RotorActuator

pytestmark = pytest.mark.odroid

BRAKE = ApproachBrake(authority=40.0, unmodelled=9.5, measurement=0.005, rate_error=0.015,
                      lag=0.04)


def _travel(w, phases, a_u, dt=1e-5):
    """The farthest the sensor travels towards the cone, stepped through in time: w (rad/s)
    now, phases [(duration s or inf, deceleration rad/s^2)], the unknown a_u pushing in all
    along (each step exact for its constant acceleration, the stop within a step caught).
    """
    x, best = 0.0, 0.0
    for duration, decel in phases:
        acc, t = a_u - decel, 0.0
        while t < duration - 1e-12:
            if math.isinf(duration) and w <= 0.0:
                break
            step = min(dt, duration - t)
            w_next = w + acc * step
            if w > 0.0 > w_next:
                best = max(best, x + w * w / (2.0 * -acc))
            x += (w + 0.5 * acc * step) * step
            w = w_next
            best = max(best, x)
            t += step
    return best


def _backup(D_s, D, a_b, lag, hold=0.01, spans=brake_module.BACKUP_SPANS, pieces=20):
    """The backup's phases as the module states them, written here: the hold at min(D_s, D),
    then over each span (span * lag long) rising linearly from a_b - e^-c (a_b - min(D, a_b))
    to a_b - e^-(c + span) (...), c the spans before it (in ``pieces`` steps of constant
    deceleration, each at the chord's middle: exact in the rate at their ends), then for ever
    at the level reached.
    """
    phases = [(hold, min(D_s, D))]
    share, gap = 1.0, a_b - min(D, a_b)
    for span in (spans if lag > 0.0 else ()):
        start, end = a_b - share * gap, a_b - share * math.exp(-span) * gap
        phases += [(span * lag / pieces, start + (end - start) * (i + 0.5) / pieces)
                   for i in range(pieces)]
        share *= math.exp(-span)
    return phases + [(math.inf, a_b - share * gap)]


def test_the_backup_travel_is_its_phases_integrated_and_bounds_the_true_lag():
    """``backup_travel``: its phases stepped through here (each span's chord in 20 steps), to
    2e-5 rad; and never less than the travel under the rotors' true
    exponential approach to a_b (a first-order lag of 40 ms from the end of the command's
    hold), nor more than what its truncation after the BACKUP_SPANS leaves beyond.
    """
    rng = np.random.default_rng(1)
    for _ in range(25):
        w, D_s, D = rng.uniform(-0.5, 3.0), rng.uniform(-30.0, 40.0), rng.uniform(-30.0, 40.0)
        got = float(backup_travel(BRAKE, w, D_s, D, BRAKE.authority, 0.01))
        phases = _backup(min(D_s, BRAKE.authority), D, BRAKE.authority, BRAKE.lag)
        assert got == pytest.approx(_travel(w, phases, BRAKE.unmodelled), abs=2e-5)
        # the true lag: from min(D, a_b) at the hold's end, exponentially to a_b
        x, v, best, t, dt = 0.0, w, 0.0, 0.0, 1e-5
        start = min(D, BRAKE.authority)
        while t < 2.0 and (t < 0.01 or v > 0.0):
            decel = min(D_s, D) if t < 0.01 else BRAKE.authority - (
                BRAKE.authority - start) * math.exp(-(t - 0.01) / BRAKE.lag)
            v += (BRAKE.unmodelled - decel) * dt
            x += v * dt
            best, t = max(best, x), t + dt
        assert got >= best - 1e-5
        assert got <= 1.1 * best + 2e-3, (got, best)


def test_the_least_deceleration_is_where_the_worst_case_just_stops_outside():
    """``least_deceleration`` on states the backup holds (Phi >= 0): with the command reaching D
    at the end of its hold and the backup after it, the worst case (the state off by the
    uncertainty, a_u pushing in) peaks within the gap less its uncertainty, stepped through
    here, and 1 rad/s^2 less overruns it (``meets`` says the same of a law's deceleration
    above and below it); past the curve, the backup's own first command.
    """
    rng = np.random.default_rng(3)
    keep = BRAKE.keep(0.01)
    checked = 0
    for _ in range(300):
        gap, w = rng.uniform(0.02, 0.3), rng.uniform(-0.5, 3.0)
        D_s, age, hold = rng.uniform(-20.0, 40.0), rng.uniform(0.0, 0.06), 0.01
        spin = abs(w)
        D, margin = least_deceleration(BRAKE, gap, w, D_s, age, spin, BRAKE.authority, hold)
        D, margin = float(D), float(margin)
        Ds = min(D_s, BRAKE.authority)
        first = keep * Ds + (1.0 - keep) * BRAKE.authority
        if margin < 0.0:
            assert D == pytest.approx(first)
            continue
        dg = BRAKE.measurement + (BRAKE.rate_error + BRAKE.measurement * spin) * age \
            + 0.5 * BRAKE.unmodelled * age * age
        dw = BRAKE.rate_error + BRAKE.measurement * spin + BRAKE.unmodelled * age

        def peak(d):
            return _travel(w + dw, _backup(Ds, d, BRAKE.authority, BRAKE.lag), BRAKE.unmodelled,
                           2e-5)
        if D <= Ds - 4.0 * BRAKE.authority + 1e-3:        # (a far cone: no real need)
            continue
        assert peak(D) <= gap - dg + 2e-5, (gap, w, D_s, age, D)
        assert peak(D - 1.0) > gap - dg, (gap, w, D_s, age, D)
        # the check of a law's deceleration without the search agrees on either side
        above, below = D + rng.uniform(0.0, 20.0), D - 1.0 - rng.uniform(0.0, 20.0)
        assert meets(BRAKE, gap, w, D_s, age, spin, BRAKE.authority, hold, above)
        assert not meets(BRAKE, gap, w, D_s, age, spin, BRAKE.authority, hold, below)
        checked += 1
    assert checked > 50


def _testbed_values(**over):
    values = resolve(CONTROLLER, node_overrides(load_parameter_file('config/testbed.yaml'),
                                                CONTROLLER))
    values.update(over)
    return values


def test_the_brakes_authority_is_the_polytopes_less_gravity_at_the_stops():
    """``brake_authority`` against a computation here: every vertex of the rotors' moment
    polytope found by brute force (numpy's solver on every triple of its faces), the gravity
    moment sampled over a grid of attitudes within the joint's stops, 360 opening directions:
    within 0.5 %. And the configuration refuses a brake_acceleration above it, naming both.
    """
    setup = controller_setup(_testbed_values())
    cfg = setup.config
    A, beta = cfg.moment_limits.A, cfg.moment_limits.beta
    vertices = []
    for rows_ in itertools.combinations(range(len(beta)), 3):
        M = A[list(rows_)]
        if abs(np.linalg.det(M)) < 1e-9:
            continue
        u = np.linalg.solve(M, beta[list(rows_)])
        if np.all(A @ u >= beta - 1e-9):
            vertices.append(u)
    vertices = np.array(vertices)
    J_inv = np.linalg.inv(cfg.J)
    r = cfg.cones.r
    e1 = np.cross(r, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(r, e1)
    # gravity in the body frame at every sampled attitude within the stops
    g_b = []
    for tilt in np.linspace(0.0, cfg.tilt_max, 46):
        for az in np.linspace(0.0, 2.0 * math.pi, 720, endpoint=False):
            R = so3.exp(np.array([math.cos(az), math.sin(az), 0.0]) * tilt)
            g_b.append(R.T @ cfg.gravity)
    M_g = np.cross(cfg.m_rho, np.array(g_b))                          # (attitudes, 3)
    worst_dir = math.inf
    for t in np.linspace(0.0, 2.0 * math.pi, 720, endpoint=False):
        c = J_inv @ (math.cos(t) * e1 + math.sin(t) * e2)
        worst_dir = min(worst_dir, (vertices @ c).max() - max((-(M_g @ c)).max(), 0.0))
    assert cfg.brake_acceleration == pytest.approx(worst_dir, rel=2e-3)
    assert brake_authority(cfg.moment_limits.vertices, J_inv, cfg.m_rho, cfg.gravity,
                           cfg.tilt_max, r) == pytest.approx(cfg.brake_acceleration)
    with pytest.raises(ConfigError, match='brake_acceleration'):
        controller_setup(_testbed_values(brake_acceleration=1.01 * cfg.brake_acceleration))
    lower = controller_setup(_testbed_values(brake_acceleration=30.0)).config
    assert lower.brake_acceleration == 30.0


def test_the_rate_error_budget_covers_an_attitude_error_of_e_at_any_angle_to_the_cone():
    """``ApproachBrake.uncertainty``'s rate term: an attitude error of e turns the opening
    direction n by up to e / sin phi, so the approach rate w = -n . Omega seen through it is off
    by up to e |Omega| / sin phi (what ``rows`` budgets): random attitudes and rates near the
    testbed's cone, each seen through 40 random errors of size e (``opening`` on the true and
    the erred attitude), stay within it, and near the cone they exceed e |Omega| alone.
    """
    setup = controller_setup(_testbed_values())
    cfg = setup.config
    cones, e = cfg.cones, ApproachBrake.bounds_of(cfg).measurement
    axis, theta = cones.V[0], float(cones.theta[0])
    rng = np.random.default_rng(11)
    beyond = 0
    for _ in range(200):
        phi = theta + math.radians(rng.uniform(0.5, 30.0))
        az = math.atan2(axis[1], axis[0]) + phi * rng.choice([-1.0, 1.0])
        R = so3.exp(np.array([0.0, 0.0, az])) @ so3.exp(rng.normal(0.0, 0.05, 3))
        Omega = rng.normal(0.0, 1.0, 3)
        gap, _, w, _ = opening(cones, R, Omega)
        sin_phi = math.sin(float(gap[0]) + theta)
        spin = float(np.linalg.norm(Omega))
        worst = 0.0
        for _ in range(40):
            d = rng.normal(size=3)
            R_seen = R @ so3.exp(e * d / np.linalg.norm(d))
            worst = max(worst, abs(float(opening(cones, R_seen, Omega)[2][0] - w[0])))
        assert worst <= e * spin / sin_phi * 1.05 + 1e-9, (worst, e * spin / sin_phi)
        beyond += worst > 1.5 * e * spin
    assert beyond > 20


def test_several_cones_are_one_qp_and_a_corridor_is_shared_not_given_up():
    """``braked``: where the law's moment breaks a cone's condition, the moment returned meets
    every cone's row within the rotors' polytope and is the closest that does (KKT by brute
    force over the active sets); where two cones' rows contradict each other (a fast run down
    a narrow corridor), both are relaxed by the same least amount and it says so (unmet).
    """
    setup = controller_setup(_testbed_values())
    ctl = AttitudeController(setup.config)
    cfg = ctl.config
    cones = cfg.cones
    axis = cones.V[0]
    theta = float(cones.theta[0])
    az = math.atan2(axis[1], axis[0]) + theta + math.radians(4.0)
    R = so3.exp(np.array([0.0, 0.0, az]))
    Omega = np.array([0.0, 0.0, -2.5])                 # yawing towards the cone
    M_g = ctl.gravity_moment(R)
    x = BrakeInputs(R, Omega, 0.03, 0.01, np.zeros(3), ctl.dynamics.moment(R, Omega), M_g,
                    np.zeros(6))                 # (the rotors at the hover allocation)
    b = braked(ctl.brake, cones, ctl.J_inv, cfg.moment_limits, x, np.zeros(3))
    r = rows(ctl.brake, cones, ctl.J_inv, x)
    assert b.braking and not b.unmet
    assert np.all(r.A @ b.u >= r.beta - 1e-7)
    polytope = cfg.moment_limits
    # within the rotors' reach this hold from no moment: (1 - a) P
    reach = (1.0 - ctl.brake.keep(0.01)) * polytope.beta
    assert np.all(polytope.A @ b.u >= reach - 1e-9)
    # the closest: the brute-force KKT point over the cone's row and the reach's
    A_all = np.concatenate((r.A, polytope.A))
    beta_all = np.concatenate((r.beta, reach))
    best = None
    for size in (1, 2, 3):
        for S in itertools.combinations(range(len(beta_all)), size):
            A_S = A_all[list(S)]
            if abs(np.linalg.det(A_S @ A_S.T)) < 1e-12:
                continue
            lam = np.linalg.solve(A_S @ A_S.T, beta_all[list(S)])
            u = A_S.T @ lam
            if np.all(A_all @ u >= beta_all - 1e-9) and np.all(lam >= -1e-9):
                best = u
                break
        if best is not None:
            break
    np.testing.assert_allclose(b.u, best, atol=1e-7)
    # a corridor: two rows whose normals oppose, both asking more than the polytope allows
    A = np.array([[0.0, 0.0, 90.0], [0.0, 0.0, -90.0]])
    A_p = np.concatenate((A, polytope.A))
    beta_p = np.concatenate(([120.0, 100.0], polytope.beta))
    u = brake_module._compromise(np.zeros(3), A_p, beta_p, 2, np.zeros(3))
    slack = A @ u - np.array([120.0, 100.0])
    assert slack[0] == pytest.approx(slack[1], abs=1e-6) and slack[0] < 0.0   # shared
    assert np.all(polytope.A @ u >= polytope.beta - 1e-9)


def test_the_far_cone_shortcut_bounds_the_backup_travel_and_decides_as_the_whole_working():
    """``braked`` leaves a cone's backup travels out where a bound shows the law's moment keeps
    it (``_surely_met``). The bound is above the travel worked out whole, on 20,000 random
    states (receding and approaching, the law pushing in or braking past a_b, with and without a
    lag); and at 2,000 random attitudes, rates and moments of the testbed near and far from its
    cone, ``braked`` with the shortcut returns what it returns without it, to the bit.
    """
    rng = np.random.default_rng(11)
    n = 20000
    w0, Ds = rng.uniform(-3.0, 6.0, n), rng.uniform(-60.0, 60.0, n)
    D = rng.uniform(-200.0, 80.0, n)
    authority = rng.uniform(12.0, 60.0, n)
    for lag, hold in ((0.04, 0.01), (0.0, 0.02), (0.1, 0.005)):
        p = brake_module.phases(ApproachBrake(40.0, 9.5, 0.005, 0.015, lag), hold)
        travel = brake_module.backup_travel(ApproachBrake(40.0, 9.5, 0.005, 0.015, lag), w0,
                                            np.minimum(Ds, authority), D, authority, hold)
        bound = brake_module.evaluate(lambda ops, *v: brake_module._travel_bound(ops, p, *v), w0,
                                      np.minimum(Ds, authority), D, authority)
        # (without a lag the bound is the travel's own formula: equal but for rounding, far
        # inside the TRAVEL_SURE the shortcut keeps)
        slack = bound - travel
        assert np.all(slack >= -1e-12 * np.maximum(1.0, bound)), (lag, float(np.min(slack)))
        assert brake_module.TRAVEL_SURE > 1e6 * float(np.max(-slack[bound < 4.0], initial=0.0))
    setup = controller_setup(_testbed_values())
    ctl = AttitudeController(setup.config)
    cfg = ctl.config
    quick_taken = 0
    for _ in range(2000):
        R = so3.exp(rng.normal(size=3) * rng.uniform(0.0, 1.5))
        Omega = rng.normal(size=3) * rng.uniform(0.0, 3.0)
        u = rng.normal(size=3) * rng.uniform(0.0, 0.5)
        x = BrakeInputs(R, Omega, rng.uniform(0.0, 0.06), 0.01, rng.normal(size=3) * 0.1,
                        ctl.dynamics.moment(R, Omega), ctl.gravity_moment(R), np.zeros(6))
        got = braked(ctl.brake, cfg.cones, ctl.J_inv, cfg.moment_limits, x, u)
        view = brake_module._cones_at(ctl.brake, cfg.cones, ctl.J_inv, x, u, worst=True)
        quick = brake_module._cones_at(ctl.brake, cfg.cones, ctl.J_inv, x, u, worst=True,
                                       quick=True)
        quick_taken += not quick.whole
        assert bool(quick.met) == bool(view.met) and bool(quick.weak) == bool(view.weak)
        # the whole working, as braked did it before the shortcut
        A_p, beta_p = brake_module.reachable(cfg.moment_limits, ctl.brake.keep(0.01), x.thrusts)
        unreached = bool(np.any(brake_module.slack_of(A_p, u, beta_p) < -brake_module.TOL))
        if bool(view.met) and not unreached:
            assert np.array_equal(got.u, u) and not got.braking
        else:
            r = rows(ctl.brake, cfg.cones, ctl.J_inv, x, view.terms, view.worst)
            assert np.all(r.A @ got.u >= r.beta - 1e-7) or got.unmet
    assert 200 < quick_taken < 1900, quick_taken           # both ways were taken


def test_the_derivation_speaks_of_steps_from_a_safe_state_while_the_bounds_hold():
    """``covered``: a step counts from one on the safe set whose measurements (lead steps before
    it) were within the bounds, for as long as they hold; a break ends it until the next safe
    step.
    """
    steps, runs, lead = 40, 3, 3
    ok = np.ones((steps, runs), dtype=bool)
    safe = np.zeros((steps, runs), dtype=bool)
    safe[2, :] = True                  # every run safe at step 2 only ...
    safe[25, 1] = True                 # ... and run 1 at 25 again
    ok[1, 0] = False                   # run 0: its lead broken: 2 does not start it
    ok[10, 1] = False                  # run 1: broken at 10, started again at 25
    got = covered(ok, safe, lead)
    assert not got[:, 0].any()
    assert got[2:10, 1].all() and not got[10:25, 1].any() and got[25:, 1].all()
    assert not got[:2, 2].any() and got[2:, 2].all()


def test_the_lag_compensations_clipping_counts_as_saturation():
    """The mixer flags a command whose lag compensation was cut at a thrust limit: the rotors
    do not reach the allocation by the end of the hold, so the brake's derivation does not
    speak of it (``MotorOutput.saturated``).
    """
    mixer, rotors = controller_setup(_testbed_values()).mixer, None
    for _ in range(mixer.spool_ticks(0.01)):
        assert mixer.spools(rotors, 0.01, 0.01)
        rotors = mixer.mix(np.zeros(3), rotors, armed=True, dt=0.01, held=0.01).rotors
    assert not mixer.spools(rotors, 0.01, 0.01)
    calm = mixer.mix(np.zeros(3), rotors, armed=True, dt=0.01, held=0.01)
    assert not calm.saturated
    jump = mixer.mix(np.array([0.0, 1.2, 0.0]), calm.rotors, armed=True, dt=0.01, held=0.01)
    assert jump.clipped and jump.saturated and not jump.allocation.saturated


# --- the derivation, flown ----------------------------------------------------------------

HOLD, LAG = 0.01, 0.04


def _flown(T_b):
    """The brake alone (the law asks nothing) on the testbed's rotors with their 40 ms lag,
    compensated, commanding every 10 ms from measurements T_b old, exact but for the unknown
    acceleration a_u that pushes the sensor in all along (the observer off: the prediction is
    exact but for it). No gravity moment (a centre of mass at the pivot), so the sensor's yaw
    about the vertical is a great circle through the cone's axis: one axis. The sensor starts
    10 deg out closing at 3 rad/s. Returns (the true closest approach, the brake's bounds and
    authority, the start) in rad.
    """
    values = _testbed_values(cog_offset=np.zeros(3), k_R=0.001, k_Omega=0.001, adaptive=False,
                             guidance_lookahead_deg=0.0, blind_guard_max_deg=0.0,
                             cone_guard_deg=0.0, motor_lag_compensation=LAG,
                             unmodelled_moment_max=0.0)
    setup = controller_setup(values)
    ctl = AttitudeController(setup.config)
    brake, cones, mixer = ctl.brake, ctl.config.cones, setup.mixer
    axis, theta = cones.V[0], float(cones.theta[0])
    yaw0 = math.atan2(axis[1], axis[0]) + theta + math.radians(10.0)
    w0 = 3.0
    ctl.R_d = so3.exp(np.array([0.0, 0.0, yaw0]))
    n_sign = float(np.sign(opening(cones, ctl.R_d, np.zeros(3))[1][0, 2]))   # n = +-e3
    push = -brake.unmodelled * n_sign                     # the unknown: -a_u n (body z)
    plant_cfg = PlantConfig(setup.config.inertia, setup.config.mass, np.zeros(3),
                            setup.config.gravity,
                            Disturbance(setup.config.J @ np.array([0.0, 0.0, push]),
                                        np.zeros(3), 0.0))
    # the past T_b (and a hold) before the start: the yaw under a_u alone (the rotors
    # spooled, making no moment), known to the prediction as no moment
    h = 1e-3
    ring = int(round(T_b / h)) + 1

    def yaw_state(t):                                     # t <= 0: before the start
        rate = -w0 * n_sign + push * t
        return so3.exp(np.array([0.0, 0.0, yaw0 - w0 * n_sign * t + 0.5 * push * t * t])), \
            np.array([0.0, 0.0, rate])
    past = [yaw_state(-(ring - 1 - i) * h) for i in range(ring)]
    plant = Plant(plant_cfg, *past[-1])
    # the true rotors: the same airframe about the pivot (no offset), the same curve and lag
    geometry, curve, _ = airframe(values)
    actuator = RotorActuator(geometry, np.zeros(3), curve, LAG)
    rotors = None
    for _ in range(mixer.spool_ticks(HOLD)):               # spooled before the start
        spooled = mixer.mix(np.zeros(3), rotors, armed=True, dt=HOLD, held=HOLD)
        rotors = spooled.rotors
        for _ in range(int(round(HOLD / h))):
            actuator.moment(spooled.commands, h)
    history = CommandHistory(64, LAG)
    made = mixer.moments(rotors, HOLD)
    history.push(-T_b - HOLD, made[0], made[1])
    closest = math.inf
    steps = int(round(HOLD / h))
    for k in range(int(0.8 / HOLD)):
        t = k * HOLD
        R_m, W_m = past[0]
        # (the observer off: a fresh one each tick learns nothing)
        _, (R_b, W_b), (R_l, W_l), _ = predict(Observer(), ctl.dynamics, R_m, W_m, T_b, T_b,
                                               history, t, 0.5 * HOLD)
        M_g = ctl.gravity_moment(R_b)
        x = BrakeInputs(R_b, W_b, T_b, mixer.design_hold_for(rotors, HOLD, HOLD),
                        history.at(t), ctl.dynamics.moment(R_b, W_b), M_g,
                        mixer.thrust_offsets(rotors, HOLD))
        out = ctl.step(R_l, W_l, HOLD, adapt=False, brake=x)
        motors = mixer.mix(out.u, rotors, armed=True, dt=HOLD, held=HOLD)
        rotors = motors.rotors
        assert not motors.saturated, (T_b, t)            # (within the assumptions)
        history.push(t, *mixer.moments(rotors))
        for _ in range(steps):
            plant.step(actuator.moment(motors.commands, h), h)
            past = past[1:] + [(plant.R.copy(), plant.Omega.copy())]
            closest = min(closest, float(np.arccos(np.clip(
                cones.cosines(plant.R)[0], -1.0, 1.0))) - theta)
    return closest, brake, math.radians(10.0), w0


def _one_axis(T_b, brake, gap0, w0, dt=1e-4):
    """The same loop in one axis, written here: the gap g and the approach w, dw/dt = a_u - D(t)
    with D the rotors' deceleration, which reaches each command at the end of its hold along
    the compensated first-order lag; each command from the state T_b before, predicted by the
    exact model but for a_u, the least deceleration whose worst case (``_backup``'s phases)
    stops outside found by bisection on the travel stepped through (``_travel``), the law asking
    nothing.
    """
    e, e_w, a_u, a_b = brake.measurement, brake.rate_error, brake.unmodelled, brake.authority
    a = math.exp(-HOLD / LAG)
    g, w, D = gap0, w0, 0.0
    n_past = int(round(T_b / dt))
    past = [(g + w0 * (n_past - i) * dt, w0) for i in range(n_past)] + [(g, w)]
    # (before the start: the same uniform approach under a_u alone, near enough for 60 ms)
    closest = g
    sched = []                                       # (time, D at the tick, D_c): the rotors
    for k in range(int(0.8 / HOLD)):
        g_m, w_m = past[0]
        # predict over T_b with the rotors' known deceleration and no a_u
        g_p, w_p, tt = g_m, w_m, k * HOLD - T_b
        for _ in range(n_past):
            d_known = _rotor_at(sched, tt)
            w_p -= d_known * dt
            g_p -= w_p * dt
            tt += dt
        spin = abs(w_p)
        dg = e + (e_w + e * spin) * T_b + 0.5 * a_u * T_b * T_b
        dw = e_w + e * spin + a_u * T_b
        G0, W0 = g_p - dg, w_p + dw
        D_s = min(D, a_b)
        first = a * D_s + (1.0 - a) * a_b             # the backup's first command

        def stops(d):
            return _travel(W0, _backup(D_s, d, a_b, LAG, HOLD), a_u, 5e-5) <= G0
        if stops(0.0):
            D_cmd = 0.0
        elif not stops(first):
            D_cmd = first                             # past the curve: the backup
        else:
            lo, hi = 0.0, first
            for _ in range(30):
                mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if stops(mid) else (mid, hi)
            D_cmd = hi
        D_c = (D_cmd - a * D) / (1.0 - a)
        sched.append((k * HOLD, D, D_c))
        for _ in range(int(round(HOLD / dt))):
            t = k * HOLD + _ * dt
            d_now = D_c + (D - D_c) * math.exp(-(t - k * HOLD) / LAG)
            w += (a_u - d_now) * dt
            g -= w * dt
            closest = min(closest, g)
            past = past[1:] + [(g, w)]
        D = D_cmd
    return closest


def _rotor_at(sched, t):
    """The rotors' deceleration at t by the schedule of commands (0 before the first)."""
    for start, d0, d_c in reversed(sched):
        if t >= start:
            return d_c + (d0 - d_c) * math.exp(-(t - start) / LAG)
    return 0.0


@pytest.mark.parametrize('T_b', [0.0, 0.02, 0.06])
def test_the_derivation_flown_keeps_the_cone_as_its_one_axis_model_says(T_b):
    """The done-when of the sampled-data derivation: the sensor 10 deg out closing at 3 rad/s,
    the loop blind for T_b, a command every 10 ms reached by the lagged rotors at the end of its
    hold, the unknown acceleration a_u pushing in all along: the true margin stays >= 0, and the
    closest approach is the one the one-axis simulation of the same loop (written here, not
    brake.py's closed forms) gives, to 0.15 deg.
    """
    closest, brake, gap0, w0 = _flown(T_b)
    assert closest >= 0.0, math.degrees(closest)
    reference = _one_axis(T_b, brake, gap0, w0)
    assert reference >= 0.0
    assert math.degrees(closest) == pytest.approx(math.degrees(reference), abs=0.15), \
        (math.degrees(closest), math.degrees(reference))
