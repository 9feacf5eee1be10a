"""The shipped scenarios reproduce the paper's figures; the runner's files and exit codes."""
import csv
import importlib
import json
import math
import multiprocessing
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from tools_support import NO_EXTRA

from geoctl_ros.cli import scenario as scenario_cli
from geoctl_ros.cli.demo import table_row
from geoctl_ros.params import load_parameter_file, node_overrides, resolve
from geoctl_ros.sim import scenario

# On the vehicle's stack the tests without the shipped scenarios' full runs: their summaries were
# the same on both stacks when compared by hand (docs/stacks.md, "Two stacks"), and the full
# runs alone would double that stack's share of ./run test.
odroid = pytest.mark.odroid
pytestmark = pytest.mark.headless

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENARIOS = os.path.join(ROOT, 'config', 'scenarios')
PLOTTED = ('paper_four_cones_adaptive', 'testbed_yaw90')
FIGURES = ['attitude_error.png', 'psi.png', 'cone_angles.png', 'disturbance.png',
           'control_moment.png', 'sensor_path.png']
SUMMARY_KEYS = {'min_cone_angle_deg', 'cone_half_angle_deg', 'constraint_violated', 'final_psi',
                'final_attitude_error_deg', 'final_eR_norm', 'final_angular_velocity_norm',
                'final_disturbance_estimate', 'settle_time_s', 'max_abs_moment_Nm',
                'control_steps', 'wall_time_s'}


def _run(args):
    return scenario_cli.main(args)


@pytest.fixture(scope='module')
def runs(tmp_path_factory):
    """Run every shipped scenario once through the command-line entry point (one process per
    core, as they are independent). The workers come from a fork server, not a fork of this
    process: earlier tests leave DDS threads here, and a fork taken while one of them holds a
    lock deadlocks the child (seen once: a worker blocked on a futex for minutes).
    """
    names = [f[:-len('.yaml')] for f in sorted(os.listdir(SCENARIOS))]
    dirs = {name: tmp_path_factory.mktemp(name) for name in names}
    # the figures of two (torque and rotors, every kind of figure; they cost a third of a run)
    jobs = [[os.path.join(SCENARIOS, name + '.yaml'), '--out', str(dirs[name])]
            + ([] if name in PLOTTED else ['--no-plots']) for name in names]
    with multiprocessing.get_context('forkserver').Pool(os.cpu_count() or 1) as pool:
        codes = pool.map(_run, jobs, chunksize=1)
    assert codes == [0] * len(names)
    out = {}
    for name in names:
        with open(dirs[name] / 'summary.json') as fh:
            out[name] = (json.load(fh), dirs[name])
    return out


def imread(path):
    """A figure's pixels (matplotlib's reader)."""
    return pytest.importorskip('matplotlib.image', reason=NO_EXTRA).imread(path)


def test_every_run_writes_summary_history_and_figures(runs):
    for name, (summary, d) in runs.items():
        assert SUMMARY_KEYS <= set(summary), name
        with open(d / 'history.csv') as fh:
            rows = list(csv.DictReader(fh))
        assert len(rows) == summary['control_steps']
        for col in ['t', 'qx', 'qy', 'qz', 'qw', 'wx', 'wy', 'wz', 'eR_x', 'eR_y', 'eR_z', 'psi',
                    'u_x', 'u_y', 'u_z', 'dbar_0', 'dbar_1', 'dbar_2']:
            assert col in rows[0], (name, col)
        for cone in summary['cone_half_angle_deg']:
            assert 'angle_' + cone in rows[0]
            assert min(float(r['angle_' + cone]) for r in rows) >= (
                summary['min_cone_angle_deg'][cone] - 1e-6)
        if name not in PLOTTED:
            assert not list(d.glob('*.png')), name                    # --no-plots
            continue
        for fig in FIGURES:
            img = imread(d / fig)
            assert img.shape[0] > 300 and img.shape[1] > 300 and img.std() > 0.01, (name, fig)


def test_paper_fig3_four_cones_with_adaptation_converges(runs):
    s, _ = runs['paper_four_cones_adaptive']
    assert not s['constraint_violated']
    for cone, angle in s['min_cone_angle_deg'].items():
        assert angle > s['cone_half_angle_deg'][cone]
    assert s['final_attitude_error_deg'] < 0.01
    assert s['settle_time_s'] is not None and s['settle_time_s'] < 15.0
    assert s['final_disturbance_estimate'] == pytest.approx([0.2, 0.2, 0.2], abs=1e-3)


def test_paper_fig2_without_adaptation_keeps_a_steady_error(runs):
    s, _ = runs['paper_four_cones_no_adaptation']
    assert not s['constraint_violated']
    assert s['final_psi'] > 0.1 and s['final_attitude_error_deg'] > 10.0
    assert s['settle_time_s'] is None
    assert s['final_disturbance_estimate'] == [0.0, 0.0, 0.0]
    assert s['final_angular_velocity_norm'] < 1e-3       # at rest, balanced by the disturbance


def test_code_variant_also_converges(runs):
    s, _ = runs['paper_four_cones_code_variant']
    assert not s['constraint_violated'] and s['final_attitude_error_deg'] < 0.01


def test_time_varying_disturbance_is_tracked_around_its_mean(runs):
    s, d = runs['dissertation_time_varying']
    assert not s['constraint_violated']
    assert s['min_cone_angle_deg']['obstacle'] > 12.0
    assert s['final_attitude_error_deg'] < 1.0
    assert s['final_disturbance_estimate'] == pytest.approx([0.2, 0.2, 0.2], abs=0.03)


def test_hexrotor_experiment_goes_round_the_cone(runs):
    s, d = runs['hexrotor_experiment_yaw90']
    angle = s['min_cone_angle_deg']['obstacle']
    # the lab measured 14 deg at its closest; the straight path would go through the axis (0 deg)
    assert 12.0 < angle < 20.0
    assert s['final_attitude_error_deg'] < 10.0
    with open(d / 'history.csv') as fh:
        psi = [float(r['psi']) for r in csv.DictReader(fh)]
    assert psi[-1] < 0.01 * psi[0]


@odroid
def test_duration_option_and_errors(tmp_path, capsys):
    f = os.path.join(SCENARIOS, 'hexrotor_experiment_yaw90.yaml')
    assert scenario_cli.main([f, '--out', str(tmp_path), '--duration', '0.5', '--no-plots']) == 0
    with open(tmp_path / 'summary.json') as fh:
        assert json.load(fh)['control_steps'] == 50
    bad = tmp_path / 'bad.yaml'
    bad.write_text('controller:\n  ros__parameters:\n    k_R: -1.0\n    alpha: 1\n')
    assert scenario_cli.main([str(bad), '--out', str(tmp_path / 'x')]) == 2
    err = capsys.readouterr().err
    assert 'controller: k_R: must be > 0' in err and 'controller: alpha: expected a double' in err
    inside = tmp_path / 'inside.yaml'
    inside.write_text("""controller:
  ros__parameters:
    setpoint: [0.0, 0.0, 0.3826834323650898, 0.9238795325112867]
    cones:
      names: [obstacle]
      obstacle: {axis: [1.0, 1.0, 0.0], half_angle_deg: 12.0}
""")
    assert scenario_cli.main([str(inside), '--out', str(tmp_path / 'y')]) == 2
    assert "inside cone 'obstacle'" in capsys.readouterr().err
    assert not os.path.exists(tmp_path / 'y')
    rates = tmp_path / 'rates.yaml'
    rates.write_text('sim:\n  ros__parameters:\n    integration_rate_hz: 250.0\n')
    assert scenario_cli.main([str(rates), '--out', str(tmp_path / 'z')]) == 2
    assert 'integer multiple' in capsys.readouterr().err
    assert not os.path.exists(tmp_path / 'z')          # nothing written for a refused file


def test_readme_results_table_matches_the_runs(runs):
    """The README's table of what each scenario gives is what the runs give (wall time aside)."""
    with open(os.path.join(ROOT, 'docs', 'scenarios.md')) as fh:
        readme = fh.read()
    number = re.compile(r'-?\d+(?:\.\d+)?(?:e[-+]?\d+)?')
    for name, (summary, _) in runs.items():
        expected = table_row(summary).rsplit('|', 2)[0]       # drop the wall-time column
        line = next((ln for ln in readme.splitlines() if ln.startswith('| `%s` |' % name)), None)
        assert line is not None, 'docs/scenarios.md lacks the results row of %s' % name
        shown = line.rsplit('|', 2)[0]
        assert re.sub(number, '#', shown) == re.sub(number, '#', expected), (shown, expected)
        got = [float(x) for x in number.findall(shown)]
        want = [float(x) for x in number.findall(expected)]
        assert got == pytest.approx(want, rel=0.05, abs=2e-3), (name, shown, expected)


def _history(d):
    with open(d / 'history.csv') as fh:
        return list(csv.DictReader(fh))


def test_testbed_rotors_keep_the_cone_converge_and_plot_motor_commands(runs):
    s, d = runs['testbed_yaw90']
    assert s['actuation'] == 'rotors' and not s['constraint_violated']
    assert 12.0 + 2.0 < s['min_cone_angle_deg']['obstacle'] < 12.0 + 20.0
    rows = _history(d)
    psi = [float(r['psi']) for r in rows]
    assert psi[-1] < 0.01 * max(psi)
    # guided round the cone and tuned: there in seconds (issue 37: under 5 deg by 8 s and under
    # 1 deg by 15 s), and the estimate does not wander off once there
    assert s['time_to_5deg_s'] <= 8.0 and s['time_to_1deg_s'] <= 15.0
    assert s['final_attitude_error_deg'] < 1.0
    # the tuned gains turn it in half a second: the allocation saturates at most a step or two
    assert s['min_command'] >= 0 and s['max_command'] <= 240
    assert s['saturated_fraction'] < 0.01
    cmds = [int(float(rows[-1]['cmd_%d' % i])) for i in range(1, 7)]
    assert all(110 <= c <= 125 for c in cmds)                            # near hover (118)
    img = imread(d / 'motor_commands.png')
    assert img.shape[0] > 300 and img.std() > 0.01


def test_testbed_without_gravity_compensation_or_adaptation_falls_onto_its_stops(runs):
    """Without gravity compensation or adaptation the testbed falls over its pivot, onto the
    joint's stops (45 deg of tilt in its file: it rests there, within the stops' contact), and
    ends far from the goal.
    """
    s, d = runs['testbed_yaw90_uncompensated']
    assert s['final_attitude_error_deg'] > 30.0
    tilt = [math.degrees(math.acos(max(-1.0, min(1.0, 1 - 2 * (float(r['qx']) ** 2
                                                                + float(r['qy']) ** 2)))))
            for r in _history(d)]
    assert 44.0 < max(tilt) < 46.0 and tilt[-1] > 44.0


def test_testbed_with_wrong_mass_recovers_with_the_cog_model(runs):
    s, _ = runs['testbed_yaw90_wrong_mass']
    good, _ = runs['testbed_yaw90']
    assert not s['constraint_violated']
    assert len(s['final_disturbance_estimate']) == 6
    assert s['final_attitude_error_deg'] < good['final_attitude_error_deg'] + 1.0


@odroid
def test_a_late_loop_keeps_the_lag_compensated_testbed_steady():
    """config/testbed.yaml with motor_lag_compensation on, its steps coming 10-55 ms apart
    (scenario.tick_jitter 45 ms), as a busy machine runs the node. The mixer's lag model follows
    the real holds and its lead is designed for the longest recent one, so the testbed flies as on
    time. A model that assumed every command was held 10 ms drove the rotors 3.3 times past the
    allocation at each 50 ms hold: saturated half the time, 9.8 rad/s (one live CI run went
    9 deg into the cone that way).
    """
    s = scenario.load(os.path.join(ROOT, 'config', 'testbed.yaml'))
    s.controller['motor_lag_compensation'] = 0.04
    s.option_values.update(tick_jitter=0.045, duration=20.0)
    r = scenario.run(s)
    holds = r.history[1:, 0] - r.history[:-1, 0]
    assert holds.min() < 0.012 and holds.max() > 0.05          # the loop really was late
    assert r.summary['saturated_fraction'] == 0.0
    assert abs(r.history[:, 5:8]).max() < 3.0                   # rad/s
    assert not r.summary['constraint_violated']
    assert min(r.summary['min_cone_angle_deg'].values()) > 12.0 + 8.0     # guidance's clearance


def _scenario_cli(*args):
    """The scenario command as a user runs it, in a process of its own."""
    return subprocess.run([sys.executable, '-m', 'geoctl_ros.cli.scenario', *map(str, args)],
                          capture_output=True, text=True)


def test_scenario_reports_a_bad_file_or_output_in_one_line(tmp_path):
    bad_yaml = tmp_path / 'broken.yaml'
    bad_yaml.write_text('controller:\n  ros__parameters:\n    k_R: [0.4\n')
    r = _scenario_cli(bad_yaml, '--out', tmp_path / 'o')
    assert r.returncode == 2 and 'Traceback' not in r.stderr
    assert str(bad_yaml) in r.stderr and 'line 3' in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    missing = tmp_path / 'nope.yaml'
    r = _scenario_cli(missing, '--out', tmp_path / 'o')
    assert r.returncode == 2 and 'Traceback' not in r.stderr and str(missing) in r.stderr
    blocker = tmp_path / 'file'
    blocker.write_text('')
    r = _scenario_cli(os.path.join(ROOT, 'config', 'testbed.yaml'), '--out', blocker / 'out',
                      '--duration', '0.05', '--no-plots')
    assert r.returncode == 2 and 'Traceback' not in r.stderr, r.stderr
    assert str(blocker / 'out') in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_the_testbed_scenarios_fly_the_testbeds_own_gains():
    """testbed_yaw90 and its wrong-mass variant are config/testbed.yaml's manoeuvre with its gains,
    its estimate and its guidance (the files repeat them: a scenario file is whole in itself), and
    testbed_experiment the paper's experiment's.
    """
    keys = pytest.importorskip('geoctl_ros.benchmark.run', reason=NO_EXTRA).GAIN_KEYS

    def gains(name):
        path = os.path.join(ROOT, 'config', *name)
        return {k: v for k, v in resolve('controller', node_overrides(
            load_parameter_file(path), 'controller')).items() if k in keys}
    testbed = gains(['testbed.yaml'])
    for name in ('testbed_yaw90.yaml', 'testbed_yaw90_wrong_mass.yaml'):
        assert gains(['scenarios', name]) == testbed, name
    experiment = gains(['scenarios', 'testbed_experiment.yaml'])
    assert (experiment['k_R'], experiment['k_Omega'], experiment['c'], experiment['k_Delta'],
            experiment['disturbance_model'], experiment['guidance_lookahead_deg']) == (
        0.4, 0.7, 0.1, 0.05, 'constant', 0.0)


# every shipped scenario's first seconds, the sha256 of its history, printed per line
_HASHES = """
import hashlib, os, sys
from geoctl_ros.core.supervisor.loop import ControlLoop
from geoctl_ros.params import controller_setup
from geoctl_ros.sim import scenario
flights = {}
for name in sorted(os.listdir(sys.argv[1])):
    flight = flights[name] = scenario.run(scenario.load(os.path.join(sys.argv[1], name)),
                                          duration=1.5)
    print(name, hashlib.sha256(flight.history.tobytes()).hexdigest())
# the node's control loop (as controller_node runs it) fed testbed_yaw90's attitude and rates
flight = flights['testbed_yaw90.yaml']
loop = ControlLoop(controller_setup(dict(flight.scenario.controller, consistency_checks=False)))
cols, h = flight.columns, hashlib.sha256()
for k, row in enumerate(flight.history):
    t = 0.01 * k
    loop.offer_pose(row[[cols.index(c) for c in ('qx', 'qy', 'qz', 'qw')]], t - 0.004, t - 0.003)
    loop.offer_angular_velocity(row[[cols.index(c) for c in ('wx', 'wy', 'wz')]], t - 0.002,
                                t - 0.001)
    if k == 0:
        assert loop.arm(t).ok
    tick = loop.tick(t, 0.01)
    h.update(tick.motors.commands.tobytes())
    h.update(tick.control.u.tobytes() if tick.control is not None else b'')
print('node', h.hexdigest())
"""


def test_numpy_here_computes_exp_arccos_and_arctan2_as_the_c_library_does():
    """This process (as every process of the package: geoctl_ros/__init__.py) has numpy compute
    exp, arccos and arctan2 on arrays to the bits of the C library's, which is what numpy does on
    a CPU without AVX-512 (with its AVX-512 kernels, some hundred of these 2,000 values differ).
    """
    rng = np.random.default_rng(3)
    x, y = rng.uniform(-1.0, 1.0, 2000), rng.uniform(-5.0, 5.0, 2000)
    assert np.array_equal(np.exp(y), [math.exp(v) for v in y])
    assert np.array_equal(np.arccos(x), [math.acos(v) for v in x])
    assert np.array_equal(np.arctan2(x, y), [math.atan2(a, b) for a, b in zip(x, y)])


def test_every_scenario_flies_to_the_same_bits_under_another_blas_kernel_and_simd_target():
    """Every shipped scenario's first 1.5 s (its whole history: attitude, rates, moments, the
    estimate, the rotors), and the node's control loop's commands fed one of them, have the same
    sha256 with OpenBLAS's Prescott kernel (the oldest x86 one) as with the kernel this CPU
    picks: nothing on the path goes through BLAS, whose kernels round by the CPU. And the same
    with every one of numpy's own CPU-specific targets turned off (as on the oldest CPU numpy
    runs on) as with those the package leaves on: numpy's AVX-512 kernels of exp, arccos,
    arctan2 and the like round otherwise than the C library's functions, and the package keeps
    numpy off them (geoctl_ros/__init__.py). So docs/scenarios.md's figures hold on any CPU, and
    on both stacks, and the node flies a recorded flight again to its bits on any CPU.
    """
    def hashes(kernel, numpy_targets=None):
        env = {k: v for k, v in os.environ.items() if k != 'OPENBLAS_CORETYPE'}
        env.update({'OPENBLAS_CORETYPE': kernel} if kernel else {})
        if numpy_targets is not None:
            env['NPY_DISABLE_CPU_FEATURES'] = numpy_targets
        out = subprocess.run([sys.executable, '-c', _HASHES, SCENARIOS], capture_output=True,
                             text=True, env=env, check=True).stdout
        return dict(line.split() for line in out.splitlines())
    prescott = hashes('Prescott')
    assert len(prescott) == len(os.listdir(SCENARIOS)) + 1
    assert hashes(None) == prescott
    dispatched = importlib.import_module('numpy._core._multiarray_umath').__cpu_dispatch__
    assert hashes(None, ' '.join(dispatched)) == prescott
