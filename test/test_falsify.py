"""The falsifier (`falsify`, geoctl_ros.falsify): its STL monitors against the robustness worked
out by hand, its envelope's rules, and a short falsification on a real Dask cluster on
127.0.0.1 whose worst flight, replayed alone from its scenario file, has the same robustness to
the bit.
"""
import csv
import math

import pytest
from tools_support import NO_EXTRA

pytest.importorskip('matplotlib', reason=NO_EXTRA)
pytest.importorskip('distributed', reason=NO_EXTRA)
pytest.importorskip('rtamt', reason=NO_EXTRA)
pytest.importorskip('staliro', reason=NO_EXTRA)

from matplotlib.image import imread
import numpy as np

from geoctl_ros.campaign.manoeuvres import CLEAR_DEG, angle_deg
from geoctl_ros.cli import falsify as falsify_cli
from geoctl_ros.falsify.envelope import JITTER_STEP_MS, OUTSIDE, Envelope, Space
from geoctl_ros.falsify.requirements import COVERED, REQUIREMENTS, Monitor
from geoctl_ros.falsify.search import closest_assumed
from geoctl_ros.params import load_parameter_file
from geoctl_ros.sim import closed_loop
from geoctl_ros.sim.scenario import from_sections

pytestmark = pytest.mark.headless


def test_the_monitors_robustness_is_the_formulas():
    """Safety: the lowest margin. Settle: the best over t <= 10 s of the worst 5 - error after.
    Assumed: the lowest closest approach over the steps the brake's derivation speaks of
    (COVERED where it speaks of none).
    """
    dt = 0.01
    t = np.arange(1200) * dt
    rng = np.random.default_rng(4)
    margin = 3.0 + np.cumsum(rng.normal(0.0, 0.2, t.size))
    error = 40.0 * np.exp(-t / 1.5) + 0.3 * np.abs(np.sin(7.0 * t))
    closest = margin - np.abs(rng.normal(0.0, 0.3, t.size))
    covered = np.zeros(t.size, dtype=bool)
    covered[200:500] = covered[800:900] = True
    signals = {'margin': margin, 'error': error, 'closest': closest,
               'assumed': np.where(covered, COVERED, -COVERED)}
    safety = Monitor(REQUIREMENTS['safety'], dt).robustness(t, signals)
    assert safety == pytest.approx(margin.min(), abs=1e-12)
    settle = Monitor(REQUIREMENTS['settle'], dt).robustness(t, signals)
    later_worst = np.minimum.accumulate((5.0 - error)[::-1])[::-1]   # min over s >= t
    assert settle == pytest.approx(later_worst[t <= 10.0 + 1e-9].max(), abs=1e-12)
    # an error that is still 6 deg at 10 s and after: violated, by 1 deg
    late = dict(signals, error=np.where(t < 11.0, 6.0, 1.0))
    assert Monitor(REQUIREMENTS['settle'], dt).robustness(t, late) == pytest.approx(-1.0)
    assumed = Monitor(REQUIREMENTS['assumed'], dt)
    assert assumed.robustness(t, signals) == pytest.approx(closest[covered].min(), abs=1e-12)
    assert closest_assumed(closest[:, None], covered[:, None])[0] == closest[covered].min()
    none = dict(signals, assumed=np.full(t.size, -COVERED))
    assert assumed.robustness(t, none) == pytest.approx(COVERED)


def test_a_point_of_the_envelope_is_a_campaign_manoeuvre_or_outside():
    space = Space(load_parameter_file('config/testbed.yaml'), Envelope())
    rng = np.random.default_rng(2)
    inside = 0
    for _ in range(60):
        x = space.low + (space.high - space.low) * rng.random(len(space.low))
        m = space.manoeuvre(x)
        if m is None:
            continue
        inside += 1
        p = space.point(x)
        assert m['latency_ms'] == round(p['latency_ms']) <= 60
        assert m['jitter_ms'] % JITTER_STEP_MS == 0 and m['jitter_ms'] <= 10
        assert len(m['stalls']) == 2 and all(0.01 <= b <= 0.04 for _, b in m['stalls'])
        r = np.array([1.0, 0.0, 0.0])                    # the testbed's sensor axis
        for R in (m['R0'], m['R_d']):
            for axis, half_angle in m['cones']:
                assert angle_deg(R @ r, np.asarray(axis)) >= half_angle + CLEAR_DEG - 1e-9
        sections = space.sections(x, 'p')
        assert sections['scenario']['latency'] == m['latency_ms'] / 1000.0
    assert 5 <= inside <= 55


def test_a_short_falsification_writes_its_table_and_a_worst_flight_that_replays_to_the_bit(
        dask_scheduler, tmp_path, capsys):
    """Searches of the safety requirement and of the brake's claim (``assumed``), on a real Dask
    cluster: the worst flight, flown alone from its file, has the same robustness to the bit,
    and the brake's claim judged on it again (RTAMT, and the closest approach over the covered
    steps taken here) is the search's.
    """
    out = tmp_path / 'f'
    code = falsify_cli.main(['--budget', '16', '--duration', '1.0', '--out', str(out),
                             '--requirements', 'safety,assumed', '--scheduler', dask_scheduler])
    printed = capsys.readouterr()
    summary = (out / 'summary.md').read_text()
    assert code in (0, 1), printed.err
    assert (code == 1) == ('falsified: none' not in summary)
    for row in ('| uniform, safety | 16 |', '| de, safety |', '| uniform, assumed | 16 |'):
        assert row in summary
    with open(out / 'evaluations.csv') as f:
        rows = list(csv.DictReader(f))
    searches = {(r['optimizer'], r['target']) for r in rows}
    assert searches == {('uniform', 'safety'), ('de', 'safety'), ('uniform', 'assumed'),
                        ('de', 'assumed')}
    inside = [r for r in rows if r['inside'] == 'True']
    assert inside and all(float(r['safety']) == 180.0 for r in rows if r['inside'] == 'False')
    # the noise's seed is a coordinate: the points searched differ in it
    assert len({r['noise_seed'] for r in inside}) > 5
    worst = min(inside, key=lambda r: float(r['safety']))
    # the worst flight, flown alone from its file as `scenario` flies it: the same robustness
    sections = load_parameter_file(str(out / 'worst_safety.yaml'))
    flight = closed_loop.fly([from_sections(sections, 'replay')], series=True, assumed=True)
    a = flight.assumed
    covered = a.covered()
    closest = np.minimum(a.hold_margin, flight.margin_series)
    signals = {'margin': flight.margin_series[:, 0], 'error': flight.error_series[:, 0],
               'closest': closest[:, 0],
               'assumed': np.where(covered, COVERED, -COVERED)[:, 0]}
    again = Monitor(REQUIREMENTS['safety'], flight.dt).robustness(flight.times, signals)
    assert again == float(worst['safety'])
    assert float(worst['closest_deg']) == flight.min_margin_deg.min()
    assert math.isfinite(again)
    # the brake's claim on it: RTAMT's robustness and the lowest closest approach over the
    # steps its derivation speaks of, taken here
    claim = Monitor(REQUIREMENTS['assumed'], flight.dt).robustness(flight.times, signals)
    here = closest[covered[:, 0], 0].min() if covered.any() else COVERED
    assert claim == pytest.approx(here, abs=1e-12)
    assert float(worst['assumed']) == pytest.approx(min(claim, OUTSIDE), abs=1e-12)
    assert float(worst['closest_assumed_deg']) == (here if covered.any() else math.inf)
    assert "runs within the brake's assumptions" in summary
    image = imread(str(out / 'robustness.png'))
    assert image.shape[0] > 300 and np.std(image) > 0.05


@pytest.mark.parametrize('argv', [['--budget', '0'], ['--optimizers', 'cmaes'],
                                  ['--requirements', 'comfort'], ['--latency-max-ms', '-5']])
def test_bad_arguments_are_refused(argv, tmp_path):
    with pytest.raises(SystemExit) as e:
        falsify_cli.main(argv + ['--out', str(tmp_path)])
    assert e.value.code == 2
