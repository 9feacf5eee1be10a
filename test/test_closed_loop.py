"""The closed loop exists once (geoctl_ros.sim.closed_loop): a run flown in a batch gives the same
bits as the same run flown alone, whatever the loop models (rotors or torque, latency, stalls, late
steps, a time-varying disturbance, a set-point schedule); and a scenario file gives the same
figures through the scenario runner and through a campaign's replay.
"""
import os

import numpy as np
import pytest
from tools_support import NO_EXTRA

from geoctl_ros.campaign import manoeuvres
from geoctl_ros.params import load_parameter_file
from geoctl_ros.sim import scenario
from geoctl_ros.sim.closed_loop import fly

pytestmark = pytest.mark.headless
# on the vehicle's stack too, but for the campaign's runs in a batch against alone (campaigns
# are the development stack's; the torque runs below are the same check there)
odroid = pytest.mark.odroid

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TESTBED = os.path.join(ROOT, 'config', 'testbed.yaml')
SCENARIOS = os.path.join(ROOT, 'config', 'scenarios')

FIGURES = ('min_angle_deg', 'final_error_deg', 'final_angular_velocity', 'saturated_steps',
           'max_rate', 'settle_s', 'settle_fine_s', 'psi_settle_s', 'margin_series',
           'sensor_series')


def assert_same_bits(batch, alone, p):
    """Run p of the batch against the Flight of that run alone: every figure, bit for bit."""
    for name in FIGURES:
        a, b = getattr(batch, name), getattr(alone, name)
        a = a[:, p] if name.endswith('_series') else a[p]
        assert np.array_equal(a, b[:, 0] if name.endswith('_series') else b[0],
                              equal_nan=True), name
    assert np.array_equal(batch.final.psi[p], alone.final.psi[0])
    assert np.array_equal(batch.final.delta_bar[p], alone.final.delta_bar[0])
    history = batch.history.table(p)
    assert np.array_equal(history, alone.history.table(0))


def test_a_run_in_a_batch_flies_as_it_does_alone_with_rotors_latency_and_stalls():
    # runs of the campaign with one cone: latency, stalls, model errors, disturbance, noise differ
    base = load_parameter_file(TESTBED)
    picked = [i for i in range(40) if manoeuvres.cone_count(1, i) == 1][:3]
    runs = [scenario.from_sections(manoeuvres.run_sections(base, 1, i, 2.0), 'run_%d' % i)
            for i in picked]
    assert len({s.options.latency for s in runs}) > 1
    assert any(s.options.stalls for s in runs)
    batch = fly(runs, series=True, history=True)
    for p, s in enumerate(runs):
        assert_same_bits(batch, fly([s], series=True, history=True), p)


@odroid
def test_a_run_in_a_batch_flies_as_it_does_alone_with_torque_late_steps_and_a_schedule():
    """The dissertation's time-varying disturbance with ideal torque, varied per run in what a
    batch may vary, with late steps (shared by the runs: one noise seed) and a schedule.
    """
    path = os.path.join(SCENARIOS, 'dissertation_time_varying.yaml')
    runs = []
    for p, w0 in enumerate(([0.0, 0.0, 0.0], [0.2, -0.1, 0.0], [0.0, 0.3, 0.1])):
        sections = load_parameter_file(path)
        sections.setdefault('sim', {}).update(initial_angular_velocity=w0, mass=1.0 + 0.1 * p)
        sections.setdefault('scenario', {}).update(duration=2.0, tick_jitter=0.004,
                                                   latency=0.002 * p)
        sections.setdefault('controller', {}).update({
            'setpoint_schedule.times': [1.0],
            'setpoint_schedule.quaternions': [0.0, 0.0, 0.0872, 0.9962]})   # 10 deg yaw
        runs.append(scenario.from_sections(sections, 'run_%d' % p))
    batch = fly(runs, series=True, history=True)
    assert len(batch.times) < round(2.0 / batch.dt)      # late steps: fewer than 2 s of periods
    assert not np.allclose(np.diff(batch.times), batch.dt)
    for p, s in enumerate(runs):
        assert_same_bits(batch, fly([s], series=True, history=True), p)
    # the schedule took over at the first step from 1 s: e_R jumps there
    e_R = batch.history.arrays['eR']
    k = int(np.searchsorted(batch.times, 1.0))
    jump = np.linalg.norm(e_R[k] - e_R[k - 1], axis=-1)
    assert np.all(jump > 10.0 * np.linalg.norm(e_R[k - 1] - e_R[k - 2], axis=-1))
    other = scenario.from_sections(load_parameter_file(path), 'other')
    other.controller.update({k: runs[0].controller[k] for k in other.controller})
    other.option_values.update(runs[0].option_values)
    other.sim['noise.seed'] = 99
    with pytest.raises(ValueError, match='same tick_jitter_seed'):
        fly([runs[0], other])


@odroid
def test_a_campaign_replay_reports_the_closest_approach_of_the_flown_attitudes(tmp_path, capsys):
    """A campaign run written out and replayed (``campaign --replay``): the closest approach it
    prints is the one the flight's own attitudes give, computed here from the recorded quaternions
    with plain numpy (the angle between the sensor axis R r and each cone's axis, less its
    half-angle), not by the code that flew it.
    """
    path = tmp_path / 'run.yaml'
    i = [i for i in range(20) if manoeuvres.cone_count(1, i) == 2][0]
    sections = manoeuvres.run_sections(load_parameter_file(TESTBED), 1, i, 3.0)
    manoeuvres.write_scenario_file(sections, str(path))
    flown = scenario.run(scenario.load(str(path)))
    cols = flown.columns
    q = flown.history[:, [cols.index(c) for c in ('qx', 'qy', 'qz', 'qw')]]
    x, y, z, w = (q / np.linalg.norm(q, axis=1)[:, None]).T
    r = np.array(scenario.load(str(path)).controller['sensor_axis'], dtype=float)
    r /= np.linalg.norm(r)
    # R r for each attitude, R of the unit quaternion (x, y, z, w)
    Rr = np.stack([(1 - 2 * (y * y + z * z)) * r[0] + 2 * (x * y - z * w) * r[1]
                   + 2 * (x * z + y * w) * r[2],
                   2 * (x * y + z * w) * r[0] + (1 - 2 * (x * x + z * z)) * r[1]
                   + 2 * (y * z - x * w) * r[2],
                   2 * (x * z - y * w) * r[0] + 2 * (y * z + x * w) * r[1]
                   + (1 - 2 * (x * x + y * y)) * r[2]], axis=1)
    c = sections['controller']
    margins = []
    for name in c['cones.names']:
        v = np.array(c['cones.%s.axis' % name], dtype=float)
        v /= np.linalg.norm(v)
        margins.append(np.degrees(np.arccos(np.clip(Rr @ v, -1.0, 1.0)))
                       - c['cones.%s.half_angle_deg' % name])
    closest = float(np.min(margins))
    runner = pytest.importorskip('geoctl_ros.campaign.runner', reason=NO_EXTRA)
    runner.replay([str(path)])
    printed = capsys.readouterr().out
    got = float(printed.split('closest approach ')[1].split(' deg')[0])
    # (the loop judges its margins at the integration steps; the history keeps the control
    # steps: the flown figure is at most a step's travel closer)
    assert closest - 0.05 <= got <= closest + 1e-9, (got, closest)
    assert 'final error %.3f deg' % flown.summary['final_attitude_error_deg'] in printed


@odroid
def test_what_the_brakes_model_does_not_know_is_the_disturbance_not_yet_learnt():
    """What the falsifier judges the approach brake's a_u against (``assumed``): how far each
    approach's true rate of change is from the brake's model of it, frozen at the tick. The
    dissertation's case models the testbed exactly but for its disturbance (torque, no noise),
    so at the take-over, before the estimate and the observer have learnt anything, it is the
    disturbance's acceleration J^-1 Delta(0) along the cone's opening direction (computed here
    from the geometry), and it falls as they learn.
    """
    s = scenario.from_sections(load_parameter_file(
        os.path.join(SCENARIOS, 'dissertation_time_varying.yaml')), 'dissertation')
    flight = fly([s], assumed=True, duration=2.0)
    unknown = flight.assumed.unknown[:, 0]
    J = s.testbed.plant.J
    acc = np.linalg.solve(J, [0.2, 0.22, 0.21])
    R0, r = s.testbed.R0, np.asarray(s.controller['sensor_axis'], dtype=float)
    expected = 0.0
    for name in s.controller['cones.names']:
        v = np.asarray(s.controller['cones.%s.axis' % name], dtype=float)
        c = np.cross(R0.T @ v / np.linalg.norm(v), r / np.linalg.norm(r))
        expected = max(expected, abs(c @ acc) / np.linalg.norm(c))      # n . J^-1 Delta
    assert unknown[0] == pytest.approx(expected, rel=2e-2)
    assert unknown[-1] < 0.2 * expected
    assert flight.assumed.ok[-1, 0]     # (exact measurements, torque: within the bounds, learnt)
    assert fly([s], duration=2.0).assumed is None

