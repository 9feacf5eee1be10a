"""The safety campaign: the worst runs replay exactly, and a 50-manoeuvre campaign of the
testbed keeps every cone (a batch against its runs alone: test_closed_loop.py).
"""
import os

import numpy as np
import pytest
from tools_support import NO_EXTRA

from geoctl_ros.campaign import manoeuvres
from geoctl_ros.params import load_parameter_file
from geoctl_ros.sim import scenario
from geoctl_ros.sim.closed_loop import fly

# on the vehicle's stack too, but for the campaign and the replay of a written run: they fly the
# same batches as these, and a 50-run campaign's runs.csv was byte-identical on both stacks when
# checked by hand (docs/stacks.md, "Two stacks")
odroid = pytest.mark.odroid
pytestmark = pytest.mark.headless

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TESTBED = os.path.join(ROOT, 'config', 'testbed.yaml')


def sections(index, duration=20.0, seed=1):
    return manoeuvres.run_sections(load_parameter_file(TESTBED), seed, index, duration)


@odroid
def test_the_distribution_is_what_the_readme_says():
    r = np.array([1.0, 0.0, 0.0])
    for i in range(40):
        m = manoeuvres.draw_manoeuvre(7, i, r)
        assert 1 <= len(m['cones']) <= 4 and 0 <= m['latency_ms'] <= 80
        assert all(0.01 <= length <= 0.04 for _, length in m['stalls'])
        axes = [np.array(v) for v, _ in m['cones']]
        for (v, theta) in m['cones']:
            assert 10.0 <= theta <= 35.0
            for d in (m['R0'] @ r, m['R_d'] @ r):            # start and goal 5 deg clear
                assert np.degrees(np.arccos(d @ np.array(v))) >= theta + 5.0
        for a in range(len(axes)):                             # a way round every pair
            for b in range(a):
                gap = (np.degrees(np.arccos(axes[a] @ axes[b]))
                       - m['cones'][a][1] - m['cones'][b][1])
                assert gap >= 10.0
        for R in (m['R0'], m['R_d']):                          # within the joint's range
            assert np.degrees(np.arccos(R[2, 2])) <= manoeuvres.TILT_DEG + 1e-9
        # the straight way from start to goal crosses the first cone
        v0, th0 = axes[0], m['cones'][0][1]
        d0, d1 = m['R0'] @ r, m['R_d'] @ r
        arc = [(1 - s) * d0 + s * d1 for s in np.linspace(0, 1, 101)]
        assert min(np.degrees(np.arccos(p @ v0 / np.linalg.norm(p))) for p in arc) < th0
    # run i does not depend on the others
    assert np.array_equal(manoeuvres.draw_manoeuvre(7, 3, r)['R_d'],
                          manoeuvres.draw_manoeuvre(7, 3, r)['R_d'])


@odroid
def test_the_near_cone_stratum_starts_near_a_cone_with_a_late_loop():
    """Its runs start 5-11 deg from their first cone with 30-60 ms of latency, and the
    campaign's own draw is what it was without the option.
    """
    r = np.array([1.0, 0.0, 0.0])
    for i in range(20):
        m = manoeuvres.draw_manoeuvre(7, i, r, stratum='near-cone')
        v0, th0 = np.array(m['cones'][0][0]), m['cones'][0][1]
        clear = np.degrees(np.arccos(m['R0'] @ r @ v0)) - th0
        assert 5.0 - 1e-9 <= clear <= 11.0 + 1e-9 and 30 <= m['latency_ms'] <= 60
        plain = manoeuvres.draw_manoeuvre(7, i, r)
        assert np.array_equal(plain['R_d'],
                              manoeuvres.draw_manoeuvre(7, i, r, stratum='all')['R_d'])


def test_a_run_written_out_replays_to_the_same_figures(tmp_path):
    """A campaign's batch (flown as a worker flies it) and one of its runs alone from its file."""
    base = load_parameter_file(TESTBED)
    indices = [i for i in range(30) if manoeuvres.cone_count(1, i) == 2][:6]
    runner = pytest.importorskip('geoctl_ros.campaign.runner', reason=NO_EXTRA)
    figures = runner.fly_batch((base, 1, 2.0, manoeuvres.DISTURBANCE_MAX, 1, {}, indices, 2,
                                'all'))
    assert list(figures['run']) == indices and set(figures['cones']) == {2}
    i = indices[4]
    path = tmp_path / 'run.yaml'
    manoeuvres.write_scenario_file(sections(i, duration=2.0), str(path))
    again = fly([scenario.load(str(path))])                      # alone, from the file
    assert again.min_margin_deg[0].min() == figures['closest_deg'][4]
    assert again.final_error_deg[0] == figures['final_error_deg'][4]
    assert again.settle_s[0] == figures['settle_s'][4] or np.isnan(figures['settle_s'][4])
    # the batch kept the series of its 2 worst runs only: the worst one's, as flown alone
    assert len(figures['worst']) == 2
    closest, _, worst, margins, sensor, _ = figures['worst'][0]
    assert closest == figures['closest_deg'].min()
    alone = fly([scenario.from_sections(sections(worst, duration=2.0), 'w')], series=True)
    assert np.array_equal(alone.margin_series[:, 0], margins)
    assert np.array_equal(alone.sensor_series[:, 0], sensor)


@odroid
def test_a_batch_refuses_runs_that_differ_in_what_it_shares():
    a = scenario.from_sections(sections(0, duration=1.0), 'a')
    s = sections(0, duration=1.0)
    s['controller']['k_R'] = 0.5
    with pytest.raises(ValueError, match='k_R'):
        fly([a, scenario.from_sections(s, 'b')])




@odroid
def test_a_gain_studys_goals_are_checked_with_its_own_barrier_and_a_refused_one_is_counted():
    """Issue (hostile input): ``--grid k_R=0.35,0.45 --grid alpha=6,10`` died midway: the goal
    was checked against the testbed's alpha (8), not the gain set's, so the scenario then refused
    a goal the check had let through. Every run of every gain set now builds, and the goals the
    gain set's barrier cannot hold are flown with the check off and counted.
    """
    draw = manoeuvres.Manoeuvres(load_parameter_file(TESTBED))
    refused = 0
    for gains in ({'k_R': 0.35, 'alpha': 10.0}, {'k_R': 0.45, 'alpha': 10.0}):
        for i in range(20):
            s = draw.sections(7, i, gains)
            scenario.from_sections(s, 'run')                      # no ConfigError
            refused += draw.goal_refused(s)
    # (the runs' goals are those the testbed's own controller, k_R 1.26, accepts: the softer
    # k_R 0.35 and 0.45 refuse more of them)
    assert refused == 19
