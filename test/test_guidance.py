"""Guidance round the cones (geoctl_ros.core.law.guidance) and the m*rho estimate, against values
derived here: brute-force sampling of arcs, the campaign's random cones, the sim's true m*rho.
"""
import math
import os

import numpy as np
import pytest

from geoctl_ros.campaign import manoeuvres
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law import guidance
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.core.law.gains import learning_time
from geoctl_ros.params import controller_setup, load_parameter_file
from geoctl_ros.sim import scenario
from geoctl_ros.sim.closed_loop import fly

# on the vehicle's stack too, but for the straight yaw's 16 s flight (the closed loop there is
# flown by the batch-against-alone flights of test_closed_loop)
odroid = pytest.mark.odroid

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENARIOS = os.path.join(ROOT, 'config', 'scenarios')
R_AXIS = np.array([1.0, 0.0, 0.0])


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _arc_points(a, b, n=2001):
    """n points along the short great-circle arc from a to b (brute force)."""
    angle = math.acos(min(1.0, float(a @ b)))
    axis = _unit(np.cross(a, b))
    return np.array([so3.exp(axis * (angle * t)) @ a for t in np.linspace(0.0, 1.0, n)])


@odroid
def test_arc_clearance_is_the_closest_approach_of_the_sampled_arc():
    rng = np.random.default_rng(3)
    a = np.array([_unit(rng.normal(size=3)) for _ in range(6)])
    b = np.array([_unit(rng.normal(size=3)) for _ in range(5)])
    axes = np.array([_unit(rng.normal(size=3)) for _ in range(4)])
    got = guidance.arc_clearance(a[:, None], b[None, :], axes)
    for i in range(len(a)):
        for j in range(len(b)):
            pts = _arc_points(a[i], b[j])
            sampled = np.degrees(np.arccos(np.clip(pts @ axes.T, -1.0, 1.0))).min(axis=0)
            assert np.degrees(got[i, j]) == pytest.approx(sampled, abs=0.1)



@odroid
def test_the_ways_judged_by_bounds_are_judged_as_the_whole_clearance_judges_them():
    """The visibility graph's pairs decided by bounds (an end's angle less half the arc, the
    arc's middle inside a cone) are decided as arc_clearance decides them, and a batch plans
    every run's way as it is planned alone: random starts, goals and cones, the joint's caps
    among them.
    """
    rng = np.random.default_rng(5)
    judged = 0
    for C in (1, 2, 4):
        n = 3
        ends = rng.normal(size=(n, 2, 3))
        ends /= np.linalg.norm(ends, axis=-1)[..., None]
        axes = rng.normal(size=(n, C, 3))
        axes /= np.linalg.norm(axes, axis=-1)[..., None]
        keep = rng.uniform(0.02, 1.2, (n, C))
        X = guidance._graph_nodes(ends, axes, keep)
        first, second = np.triu_indices(X.shape[1])
        need = keep[:, None] - 1e-9
        angles = np.arccos(np.clip(guidance._cosines(X, axes), -1.0, 1.0))
        inside = np.any(angles < need, axis=-1)
        length = np.arccos(np.clip(guidance._cosines(X, X), -1.0, 1.0))
        got = guidance._clear_ways(X, axes, angles, need, length, inside, first, second)
        whole = np.all(guidance.arc_clearance(X[:, first], X[:, second], axes[:, None]) >= need,
                       axis=-1)
        outside = ~(inside[:, first] | inside[:, second])
        assert np.array_equal(got[:, first, second][outside], whole[outside])
        judged += outside.sum()
        R0, goal = so3.exp(rng.normal(size=(n, 3))), so3.exp(rng.normal(size=(n, 3)))
        planned = guidance.plans(R0, goal, R_AXIS, axes, keep, 0.14, None, math.radians(40.0))
        for i in range(n):
            assert np.array_equal(planned[i], guidance.plan(R0[i], goal[i], R_AXIS, axes[i],
                                                            keep[i], 0.14, None,
                                                            math.radians(40.0)))
    assert judged > 20_000

def _campaign_case(seed, index):
    """A run's cones (axes, half-angles rad), start and goal of the campaign's draw."""
    m = manoeuvres.draw_manoeuvre(seed, index, R_AXIS)
    axes = np.array([_unit(v) for v, _ in m['cones']])
    theta = np.radians([t for _, t in m['cones']])
    return axes, theta, m['R0'], m['R_d']


@odroid
def test_the_upright_attitudes_point_the_sensor_and_tilt_the_least():
    """For 200 random directions d at once: R r = d, R is a rotation, and its z axis is tilted
    from up by |elevation of d - elevation of r| (the least any attitude pointing r along d
    has, checked against a sweep of the turns about d); directions straight up and down are
    rotations that point the sensor too.
    """
    rng = np.random.default_rng(3)
    up = np.array([0.0, 0.0, 1.0])
    for r in (R_AXIS, _unit([1.0, 0.0, 0.5])):
        d = rng.normal(size=(200, 3))
        d = np.concatenate([d / np.linalg.norm(d, axis=1)[:, None], [up, -up]])
        R = guidance.upright(d, r, up)
        assert np.allclose(R @ r, d, atol=1e-12)
        assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-12)
        assert np.allclose(np.linalg.det(R), 1.0)
        tilt = np.arccos(np.clip(R[:, :, 2] @ up, -1.0, 1.0))
        least = np.abs(np.arcsin(np.clip(d @ up, -1.0, 1.0)) - math.asin(r[2]))
        assert np.allclose(tilt[:-2], least[:-2], atol=1e-7)
        swept = [np.arccos(np.clip((so3.exp(d[k] * psi) @ R[k])[:, 2] @ up, -1.0, 1.0))
                 for k in range(5) for psi in np.linspace(-math.pi, math.pi, 73)]
        assert min(swept) >= tilt[:5].min() - 1e-9


@odroid
def test_a_path_through_the_same_point_twice_or_its_opposite_is_a_path():
    """Corners the same to the bit (a unit vector whose square sums to just below 1) or exactly
    opposite: the path is made of rotations with no NaN (before, the first gave the leg a NaN
    axis: 0/0), from the start to the goal in steps of at most PATH_STEP.
    """
    a = _unit([-1.0, 0.6, 0.8])
    assert float(so3.dot(a, a)) < 1.0              # (this one does not square to 1 exactly)
    up = np.array([0.0, 0.0, 1.0])
    R0 = guidance.upright(a[None], R_AXIS, up)[0]
    across = _unit(np.cross(a, up))
    for b, R_goal in ((a.copy(), so3.exp(a * 0.7) @ R0), (-a, so3.exp(across * math.pi) @ R0)):
        path = guidance.attitude_path(R0, R_goal, R_AXIS, [a, b], up)
        assert np.isfinite(path).all()
        assert np.allclose(path @ path.transpose(0, 2, 1), np.eye(3), atol=1e-9)
        assert np.array_equal(path[0], R0) and np.array_equal(path[-1], R_goal)
        d = path @ R_AXIS
        steps = np.arccos(np.clip(np.sum(d[:-1] * d[1:], axis=-1), -1.0, 1.0))
        assert steps.max() <= guidance.PATH_STEP + 1e-6


@odroid
@pytest.mark.parametrize('index', range(12))
def test_the_planned_path_keeps_every_cone_clear_and_ends_at_the_goal(index):
    """On the campaign's random cones (a straight way through the first one): every point of the
    attitude path keeps the sensor the clearance outside every cone's rim (less the rim points'
    slack and the arcs' sag), steps at most PATH_STEP, starts from the start's sensor direction
    and ends at the goal exactly.
    """
    axes, theta, R0, R_goal = _campaign_case(11, index)
    rims = theta + math.radians(2.0)                  # the barrier's half-angles (a 2 deg guard)
    clearance = math.radians(8.0)
    path = guidance.plan(R0, R_goal, R_AXIS, axes, rims, clearance)
    assert len(path) > 2
    assert np.array_equal(path[-1], R_goal)
    d = path @ R_AXIS
    assert np.allclose(d[0], R0 @ R_AXIS, atol=1e-9)
    steps = np.degrees(np.arccos(np.clip(np.einsum('ij,ij->i', d[:-1], d[1:]), -1.0, 1.0)))
    assert steps.max() <= math.degrees(guidance.PATH_STEP) + 1e-6
    ends = np.arccos(np.clip(np.stack([d[0], d[-1]]) @ axes.T, -1.0, 1.0)).min(axis=0)
    need = rims + np.minimum(clearance, 0.5 * (ends - rims))
    dense = np.concatenate([_arc_points(p, q, 20) for p, q in zip(d[:-1], d[1:])])
    angle = np.arccos(np.clip(dense @ axes.T, -1.0, 1.0))
    assert np.all(angle >= need - math.radians(0.2)), np.degrees((angle - need).min())
    # the straight way crosses the first cone: the path goes round, so it is longer
    assert np.sum(np.radians(steps)) > math.acos(float(d[0] @ d[-1]))


@odroid
def test_the_set_point_runs_at_most_the_lookahead_ahead_and_never_back():
    axes, theta, R0, R_goal = _campaign_case(11, 0)
    cones = ConeSet(R_AXIS, axes, theta, 8.0, math.radians(0.25), guard_rad=math.radians(2.0))
    g = guidance.Guidance(math.radians(20.0), math.radians(8.0))
    R = R0.copy()
    seen = []
    for _ in range(400):                   # a vehicle that moves 40 % of the way each step
        P = g.carrot(R, R_goal, cones)
        assert math.degrees(so3.angle(P.T @ R)) <= 20.0 + 1e-6
        seen.append(int(g.index[0]))
        R = R @ so3.exp(0.4 * so3.log(R.T @ P))
    assert seen == sorted(seen)
    assert np.array_equal(P, R_goal)
    assert math.degrees(so3.angle(R_goal.T @ R)) < 0.01


@odroid
def test_the_set_point_is_planned_again_for_a_vehicle_pushed_off_its_way():
    axes, theta, R0, R_goal = _campaign_case(11, 1)
    cones = ConeSet(R_AXIS, axes, theta, 8.0, math.radians(0.25))
    g = guidance.Guidance(math.radians(20.0), math.radians(8.0))
    g.carrot(R0, R_goal, cones)
    pushed = so3.exp(np.array([0.0, 0.0, math.radians(70.0)])) @ R0
    P = g.carrot(pushed, R_goal, cones)
    assert math.degrees(so3.angle(P.T @ pushed)) <= 20.0 + 1e-6
    assert np.allclose(g.paths[0, 0] @ R_AXIS, pushed @ R_AXIS)


@odroid
def test_a_batch_gives_each_run_the_set_points_it_gets_alone_when_one_is_planned_again():
    """Found by the falsifier: a run near its goal had its set point in its path's padding, past
    its own goal; a shorter plan of another run of the batch then put it off the end (an
    IndexError in the control step). Each run of a batch, moved and pushed as below, gets the
    set points it gets flown alone.
    """
    axes, theta, R0, R_goal = _campaign_case(11, 0)
    cones = ConeSet(R_AXIS, axes, theta, 8.0, math.radians(0.25), guard_rad=math.radians(2.0))
    near_goal = R_goal @ so3.exp(np.array([0.0, 0.0, math.radians(3.0)]))
    starts = [near_goal, R0]                 # a short path, and a long one
    batch = guidance.Guidance(math.radians(20.0), math.radians(8.0))
    alone = [guidance.Guidance(math.radians(20.0), math.radians(8.0)) for _ in starts]
    R = np.array(starts)
    goals = np.array([R_goal, R_goal])
    for k in range(30):
        if k == 10:             # the long run pushed next to its goal: a plan of a few points
            R[1] = R_goal @ so3.exp(np.array([0.0, math.radians(30.0), 0.0]))
        P = batch.carrot(R, goals, cones)
        assert np.all(batch.index <= batch.last)
        for i, g in enumerate(alone):
            assert np.array_equal(P[i], g.carrot(R[i], R_goal, cones))
        R = np.array([R[i] @ so3.exp(0.4 * so3.log(R[i].T @ P[i])) for i in range(2)])


@odroid
def test_the_law_follows_the_set_point_when_a_new_plan_puts_it_at_the_same_index():
    """Found by the falsifier at 150 ms of latency: a vehicle pushed off its way is planned for
    again, and the new set point can fall at the same index of the new path as the old one did
    of the old. The law rebuilt its linear map on a change of index only, so it went on towards
    the old set point, alone; in a batch another run's move rebuilt it, and the same run flew
    differently alone and in a batch (26 against 32 deg into the cone). testbed_yaw90 pushed
    40-140 deg about its yaw axis, either way: after every push the law's attractive error is the
    one to guidance's new set point, and some pushes (5 on the development machine) leave it at
    the same index of the new path.
    """
    s = scenario.from_sections(load_parameter_file(
        os.path.join(ROOT, 'config', 'scenarios', 'testbed_yaw90.yaml')), 'yaw90')
    setup = controller_setup(s.controller)
    same_index = 0
    for deg in [sign * d for sign in (1.0, -1.0) for d in range(40, 141, 10)]:
        ctl = AttitudeController(setup.config)
        ctl.R_d = setup.setpoint
        R0 = s.testbed.R0
        ctl.step(R0, np.zeros(3), 0.01, adapt=False)
        assert ctl.guidance is not None
        before = ctl.guidance.index.copy()
        P0 = ctl.guidance.paths[0, before[0]].copy()
        pushed = so3.exp(np.array([0.0, 0.0, math.radians(deg)])) @ R0
        ctl.step(pushed, np.zeros(3), 0.01, adapt=False)
        index = ctl.guidance.index
        P = ctl.guidance.paths[0, index[0]]
        same_index += bool(np.array_equal(index, before) and not np.array_equal(P, P0))
        # the law's A and e_RA are those of the path's set point P, by their definitions
        G = np.diag(ctl.config.G)
        M = G @ P.T @ pushed - pushed.T @ P @ G
        expected = [0.5 * np.trace(G @ (np.eye(3) - P.T @ pushed)),
                    0.5 * M[2, 1], 0.5 * M[0, 2], 0.5 * M[1, 0]]
        np.testing.assert_allclose(ctl._linear(pushed)[..., :4], expected, atol=1e-12)
    assert same_index >= 1


def _tilt_deg(R):
    """The body's z axis from the world's up (z), in degrees."""
    return np.degrees(np.arccos(np.clip(np.asarray(R)[..., 2, 2], -1.0, 1.0)))


@odroid
@pytest.mark.parametrize('index', [913, 0, 1, 4, 5, 7])
def test_a_start_resting_on_the_stops_is_lifted_off_them_and_led_to_the_goal(index):
    """The arming stratum's runs that rest on the joint's stops (45 deg; run 913 of seed 1 was
    planned past them, to 48 deg, and then swung between the stops and the cone into it): the
    path lifts the start within four steps to 2 deg inside the stops and keeps there (the tilt
    of each attitude, from its matrix), neighbours are at most two PATH_STEPs apart, and a
    vehicle that goes where the set point is (the carrot's own cones: 2 deg guard) reaches the
    goal.
    """
    m = manoeuvres.draw_manoeuvre(1, index, R_AXIS, stratum='arming', tilt_max_deg=45.0)
    assert m['start_mode'] == 'resting'
    axes = np.array([_unit(v) for v, _ in m['cones']])
    theta = np.radians([t for _, t in m['cones']])
    up = np.array([0.0, 0.0, 1.0])
    assert _tilt_deg(m['R0']) == pytest.approx(45.0, abs=1e-6)
    path = guidance.plan(m['R0'], m['R_d'], R_AXIS, axes, theta + math.radians(2.0),
                         math.radians(8.0), up, math.radians(45.0))
    assert np.array_equal(path[0], m['R0']) and np.array_equal(path[-1], m['R_d'])
    tilts = _tilt_deg(path[:-1])
    lifted = int(np.argmax(tilts <= 43.0 + 1e-6))        # the first 2 deg inside the stops
    assert 0 < lifted <= 4 and np.all(np.diff(tilts[:lifted + 1]) < 0.0), tilts[:lifted + 1]
    assert tilts[lifted:].max() <= 43.0 + 1e-6
    steps = [math.degrees(so3.angle(a.T @ b)) for a, b in zip(path[:-1], path[1:])]
    assert max(steps) <= 2.0 * math.degrees(guidance.PATH_STEP) + 1e-6
    cones = ConeSet(R_AXIS, axes, theta, 8.0, math.radians(0.25), guard_rad=math.radians(2.0))
    g = guidance.Guidance(math.radians(40.0), math.radians(8.0), up, math.radians(45.0))
    R = m['R0']
    for _ in range(300):
        R = g.carrot(R, m['R_d'], cones)
    assert np.array_equal(R, m['R_d'])


def test_the_straight_yaw_arrives_round_the_cone():
    """The issue's case: config/scenarios/testbed_yaw90.yaml (no schedule) is under 5 deg by 8 s
    and under 1 deg by 15 s, at least 2 deg clear of the cone all the way.
    """
    s = scenario.load(os.path.join(SCENARIOS, 'testbed_yaw90.yaml'))
    f = fly([s], duration=16.0)
    assert f.min_margin_deg.min() >= 2.0
    assert f.settle_s[0] <= 8.0
    assert f.settle_fine_s[0] <= 15.0
    assert f.final_error_deg[0] < 1.0


@odroid
def test_the_estimate_learns_the_true_m_rho_within_seconds():
    """The sim's centre of mass 20 % higher than the model's and its mass 20 % heavier (m*rho
    44 % off): the shipped gains learn m*rho with a time constant of a few seconds (derived,
    ``learning_time``), and flown to a set point tilted 30 deg for three of them, the model's m*rho
    plus the estimate agrees with the sim's true m*rho in the components that gravity shows there
    (those across it; the one along it is not observable at one attitude) to 10 % of the model's
    error (e^-3 is 5 %), and the attitude error is under 1 deg.
    """
    s = scenario.load(os.path.join(SCENARIOS, 'testbed_yaw90.yaml'))
    c = s.controller
    tau = learning_time(c['k_R'], c['c'], c['k_Delta_cog'], 9.81)
    assert tau <= 3.0
    s.controller['cones.names'] = []
    tilt = so3.exp(np.array([math.radians(30.0), 0.0, 0.0]))
    s.controller['setpoint'] = so3.rot_to_quat(tilt)
    s.sim['mass'] = 1.26 * 1.2
    s.sim['cog_offset'] = np.array([0.0, 0.0, 0.12])
    f = fly([s], duration=round(3.0 * tau, 2))
    model = 1.26 * np.array([0.0, 0.0, 0.1])
    truth = s.sim['mass'] * s.sim['cog_offset']
    learnt = model + f.final.delta_bar[0][3:]
    g_b = tilt.T @ np.array([0.0, 0.0, -1.0])            # gravity's direction, body frame
    across = np.eye(3) - np.outer(g_b, g_b)
    error = np.linalg.norm(across @ (learnt - truth))
    assert error <= 0.1 * np.linalg.norm(across @ (model - truth)), (learnt, truth)
    assert f.final_error_deg[0] < 1.0
