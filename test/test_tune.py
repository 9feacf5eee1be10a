"""The tuner (`tune`, geoctl_ros.campaign.tune) on a real Dask cluster on 127.0.0.1, short: it
flies its trials, writes a best set as a parameter file that loads, and a second run with the
same seed proposes and finds the same gain sets, bit for bit.
"""
import csv
import os

import pytest
from tools_support import NO_EXTRA

pytest.importorskip('matplotlib', reason=NO_EXTRA)
pytest.importorskip('distributed', reason=NO_EXTRA)
pytest.importorskip('optuna', reason=NO_EXTRA)

from matplotlib.image import imread
import numpy as np

from geoctl_ros.campaign import tune
from geoctl_ros.cli import tune as tune_cli
from geoctl_ros.params import (
    CONTROLLER,
    LAB_INERTIA,
    load_parameter_file,
    node_overrides,
    resolve,
    write_parameter_file,
)
from geoctl_ros.sim import closed_loop
from geoctl_ros.sim.scenario import from_sections

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHORT = ['--trials', '3', '--runs', '4', '--duration', '1.5', '--latency-duration', '1.5',
         '--seed', '3', '--check-runs', '4']


def test_a_short_tuning_writes_its_trials_front_and_figure_and_repeats_from_its_seed(
        dask_scheduler, tmp_path, capsys):
    outs = []
    for k in (1, 2):
        out = tmp_path / ('tune%d' % k)
        code = tune_cli.main(SHORT + ['--out', str(out), '--scheduler', dask_scheduler])
        printed = capsys.readouterr()
        assert code == (0 if (out / 'best.yaml').exists() else 1), printed.err
        outs.append(out)
    first, second = ((o / 'trials.csv').read_text() for o in outs)
    assert first == second                                  # the same trials, to the bit
    with open(outs[0] / 'trials.csv') as f:
        rows = list(csv.DictReader(f))
    assert [int(r['trial']) for r in rows] == [0, 1, 2]
    # trial 0 is the testbed's own gains (the study starts from where it stands)
    testbed = resolve(CONTROLLER, node_overrides(load_parameter_file(
        os.path.join(ROOT, 'config', 'testbed.yaml')), CONTROLLER))
    assert [float(rows[0][k]) for k in tune.GAINS] == pytest.approx(
        [testbed[k] for k in tune.GAINS], rel=1e-9)
    for r in rows:             # every trial's gains lie in the search space, as derived there
        point = tune.search_point({k: float(r[k]) for k in tune.GAINS}, 9.81)
        assert tuple(tune.SPACE) == point._fields
        for x, (name, (lo, hi, _)) in zip(point, tune.SPACE.items()):
            assert lo * (1 - 1e-9) <= x <= hi * (1 + 1e-9), (name, x)
        assert int(r['runs']) == 4
        assert (r['feasible'] == 'True') == (int(r['violations']) == 0 and
                                             float(r['closest_p1_deg']) >= 2.5 and
                                             float(r['saturated_runs']) <= 0.01 and
                                             float(r['saturating_runs']) <= 0.10 and
                                             float(r['latency_min_margin_deg']) >= 2.5)
    best = sorted(outs[0].glob('best/*.yaml'))
    feasible = [r for r in rows if r['feasible'] == 'True']
    assert bool(best) == bool(feasible)
    if best:                                   # a front set loads as the testbed's file does
        values = resolve(CONTROLLER, node_overrides(load_parameter_file(str(best[0])),
                                                    CONTROLLER))
        assert any(all(values[k] == float(r[k]) for k in tune.GAINS) for r in feasible)
    image = imread(str(outs[0] / 'pareto.png'))
    assert image.shape[0] > 300 and np.std(image) > 0.05
    summary = (outs[0] / 'summary.md').read_text()
    assert 'checked in turn on' in summary
    # the chosen set is the first checked one that passed; none passed: no best.yaml, exit 1
    assert (outs[0] / 'best.yaml').exists() == (' (chosen) ' in summary)


def _closest_of_latency_rows(inertia, gains, duration):
    """testbed_yaw90 with the gains, flown here at each of a trial's latency rows for duration s
    on the inertia given (None: the file's own, the lab's): the closest approach of all (deg).
    """
    closest = []
    for latency, jitter in tune.TRIAL_LATENCY_ROWS:
        sections = load_parameter_file(os.path.join(ROOT, 'config', 'scenarios',
                                                    'testbed_yaw90.yaml'))
        if inertia is not None:
            sections['/**']['inertia'] = inertia
        sections['controller'].update(gains)
        sections.setdefault('scenario', {}).update(latency=latency, tick_jitter=jitter,
                                                   duration=duration)
        closest.append(closed_loop.fly([from_sections(sections, 'row')]).min_margin_deg.min())
    return float(min(closest))


def test_another_airframe_is_tuned_with_its_latency_rows_flown_on_it(dask_scheduler, tmp_path,
                                                                      capsys):
    """`tune --params-file` with 1.5 times the lab's inertia, one trial of one short run: the
    trial's latency rows are testbed_yaw90 flown on that inertia (their closest approach the same
    to the bit) and not on the lab's; the summary names that airframe and the brake's bounds
    computed from it.
    """
    base = load_parameter_file(os.path.join(ROOT, 'config', 'testbed.yaml'))
    inertia = [1.5 * j for j in LAB_INERTIA]
    base['/**']['inertia'] = inertia
    other = str(tmp_path / 'heavier.yaml')
    write_parameter_file(base, other, 'the testbed with 1.5 times its inertia')
    out = tmp_path / 'tune'
    code = tune_cli.main(['--params-file', other, '--trials', '1', '--runs', '1',
                          '--duration', '0.3', '--latency-duration', '0.3', '--check-runs', '1',
                          '--best', '1', '--out', str(out), '--scheduler', dask_scheduler])
    printed = capsys.readouterr()
    assert code in (0, 1), printed.err
    with open(out / 'trials.csv') as f:
        (row,) = list(csv.DictReader(f))
    gains = {k: float(row[k]) for k in tune.GAINS}
    got = float(row['latency_min_margin_deg'])
    assert got == _closest_of_latency_rows(inertia, gains, 0.3)
    assert got != _closest_of_latency_rows(None, gains, 0.3)
    airframe = tune.airframe_of(base)
    assert airframe.brake.unmodelled < tune.airframe_of(load_parameter_file(
        os.path.join(ROOT, 'config', 'testbed.yaml'))).brake.unmodelled
    assert airframe.describe() in (out / 'summary.md').read_text()
    assert airframe.describe() in printed.err


@pytest.mark.parametrize('argv, says', [
    (['--trials', '0'], 'must be positive'), (['--runs', '-1'], 'must be positive'),
    (['--duration', 'nan'], 'duration'),
    (['--k-R', '3', '0.5'], '--k-R: 3-0.5 is no range'),
    (['--k-Omega', '0.0001', '1.5'], 'k_Omega: must be in [0.001, 10] (got 0.0001)'),
    (['--c-share', '0.25', '200'], 'c: must be in [0.0001, 100]')])
def test_the_tuner_refuses_bad_arguments_in_one_line(argv, says, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        tune_cli.main(argv + ['--out', str(tmp_path / 'o')])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith('tune: error: ') and says in err[-1], err
