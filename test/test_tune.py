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
from geoctl_ros.params import CONTROLLER, load_parameter_file, node_overrides, resolve

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHORT = ['--trials', '4', '--runs', '6', '--duration', '2', '--latency-duration', '2',
         '--seed', '3', '--check-runs', '6']


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
    assert [int(r['trial']) for r in rows] == [0, 1, 2, 3]
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
        assert int(r['runs']) == 6
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


@pytest.mark.parametrize('argv', [['--trials', '0'], ['--runs', '-1'], ['--duration', 'nan']])
def test_the_tuner_refuses_bad_arguments_in_one_line(argv, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        tune_cli.main(argv + ['--out', str(tmp_path / 'o')])
    assert e.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith('tune: error: '), err
