"""Campaigns on a real Dask cluster (127.0.0.1 only): the same runs.csv on 2 workers as on 1
worker in another batch size, none lost or doubled when a worker is killed mid-campaign, Ctrl-C
writes the runs flown so far, and a small gain study whose best parameter file the controller
accepts. The 1-worker reference makes a local cluster (the command's default), the killed
worker's test a cluster of its own, and the rest fly on a shared one (conftest.py's
``dask_scheduler``). Campaigns are a development tool (the extra tools): not on the vehicle's
stack. (With Ubuntu 24.04's Dask 2023.12 every test here passed when checked by hand.)
"""
import csv
import os
import signal
import subprocess
import sys
import threading
import time

import pytest
from tools_support import NO_EXTRA

pytest.importorskip('matplotlib', reason=NO_EXTRA)
pytest.importorskip('distributed', reason=NO_EXTRA)

from distributed import Client, LocalCluster
import numpy as np

from geoctl_ros.cli import campaign
from geoctl_ros.params import (
    CONTROLLER,
    controller_setup,
    load_parameter_file,
    node_overrides,
    resolve,
)

# (not marked `headless`: in ./run test these run in the foreground stream, which is the shorter
# of the two; the headless stream was the first phase's longest)

RUNS, DURATION = '16', '1'          # (runs 0-3 have 1, 2, 3 and 4 cones)


def read(path):
    with open(path) as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope='module')
def reference(tmp_path_factory):
    """The campaign on one worker of a local cluster, in batches of 3: its runs.csv."""
    out = tmp_path_factory.mktemp('one_worker')
    code = campaign.main(['--runs', RUNS, '--duration', DURATION, '--workers', '1',
                          '--batch', '3', '--worst', '1', '--out', str(out)])
    assert code == 0
    return out / 'runs.csv'


def test_two_workers_give_the_runs_csv_of_one_worker_in_another_batch_size(
        reference, dask_scheduler, tmp_path, capsys):
    out = tmp_path / 'two_workers'
    code = campaign.main(['--runs', RUNS, '--duration', DURATION, '--scheduler', dask_scheduler,
                          '--out', str(out)])
    printed = capsys.readouterr()
    assert code == 0, printed.out
    assert 'on scheduler %s (2 workers now)' % dask_scheduler in printed.err
    assert '100.0 % of 16 runs flown' in printed.err                   # progress was shown
    assert (out / 'runs.csv').read_bytes() == reference.read_bytes()
    rows = read(out / 'runs.csv')
    assert [int(r['run']) for r in rows] == list(range(16))
    assert all(r['violated'] == 'False' and float(r['closest_deg']) > 0.0 for r in rows)
    assert len({r['cones'] for r in rows}) == 4
    assert '| violations | 0 |' in printed.out
    for png in ('closest_approach.png', 'worst_runs.png'):
        assert (out / png).stat().st_size > 10_000
    # the worst runs' files fly again to the figures in runs.csv
    assert len(os.listdir(out / 'worst')) == 5
    worst = min(rows, key=lambda r: float(r['closest_deg']))
    replay = campaign.main(['--replay', str(out / 'worst' / ('run_%04d.yaml' % int(worst['run']))),
                            '--out', str(tmp_path)])
    assert replay == 0
    assert 'closest approach %s deg' % worst['closest_deg'] in capsys.readouterr().out


def test_a_worker_killed_mid_campaign_loses_no_run_and_doubles_none(reference, tmp_path):
    """A cluster of its own (as `dask scheduler` and `dask worker` would make one), the campaign
    on it through --scheduler; one worker process is SIGKILLed while it flies a batch.
    """
    out = tmp_path / 'killed'
    with LocalCluster(n_workers=2, threads_per_worker=1, host='127.0.0.1',
                      dashboard_address=None) as cluster, Client(cluster) as client:
        result = {}
        flying = threading.Thread(target=lambda: result.setdefault('code', campaign.main(
            ['--scheduler', cluster.scheduler_address, '--runs', RUNS, '--duration', DURATION,
             '--batch', '8', '--worst', '1', '--out', str(out)])))
        flying.start()
        pids = client.run(os.getpid)
        victim = None
        deadline = time.monotonic() + 60
        while victim is None and time.monotonic() < deadline:
            busy = [w for w, tasks in client.processing().items() if tasks]
            victim = busy[0] if busy else None
            time.sleep(0.05)
        assert victim is not None, 'no batch was ever in flight'
        os.kill(pids[victim], signal.SIGKILL)
        flying.join(120)
        assert not flying.is_alive()
        assert victim not in client.scheduler_info()['workers']        # it did die
    assert result['code'] == 0
    assert (out / 'runs.csv').read_bytes() == reference.read_bytes()


@pytest.mark.headless        # (the foreground stream is the first phase's longest now)
def test_a_worker_whose_numpy_rounds_otherwise_is_refused_naming_the_fix(tmp_path, capsys):
    """A `dask worker` started plainly imports numpy before the package, so on a CPU with
    AVX-512 its numpy runs the kernels the package keeps it off (geoctl_ros/__init__.py), and
    its runs would not be what they are elsewhere: the campaign refuses the cluster, naming the
    worker and the environment to start it with, and flies nothing. (Where the CPU has no such
    kernels there is nothing to refuse.)
    """
    plain = {k: v for k, v in os.environ.items() if k != 'NPY_DISABLE_CPU_FEATURES'}
    probe = subprocess.run([sys.executable, '-c', 'import numpy, geoctl_ros; '
                            'print(geoctl_ros.numpy_rounding_problem() or "")'],
                           env=plain, capture_output=True, text=True, check=True).stdout
    if not probe.strip():
        pytest.skip('numpy has no kernels here that round otherwise than the C library')
    with LocalCluster(n_workers=0, host='127.0.0.1', dashboard_address=None) as cluster, \
            Client(cluster) as client:
        worker = subprocess.Popen(
            [sys.executable, '-m', 'distributed.cli.dask_worker', cluster.scheduler_address,
             '--nworkers', '1', '--nthreads', '1', '--host', '127.0.0.1', '--no-dashboard'],
            env=plain, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            client.wait_for_workers(1, timeout=60)
            code = campaign.main(['--scheduler', cluster.scheduler_address, '--runs', '2',
                                  '--duration', '1', '--out', str(tmp_path / 'refused')])
        finally:
            worker.terminate()
            worker.wait(30)
    err = capsys.readouterr().err
    assert code == 2 and 'campaign: refused: worker tcp://127.0.0.1:' in err, err
    assert "start it with NPY_DISABLE_CPU_FEATURES='" in err
    assert not (tmp_path / 'refused' / 'runs.csv').exists()


def test_ctrl_c_writes_the_runs_flown_so_far(dask_scheduler, tmp_path):
    out = tmp_path / 'interrupted'
    proc = subprocess.Popen([sys.executable, '-m', 'geoctl_ros.cli.campaign', '--runs', '60',
                             '--duration', '1', '--batch', '2', '--worst', '1',
                             '--scheduler', dask_scheduler, '--out', str(out)],
                            stderr=subprocess.PIPE, text=True)
    seen = []
    for line in proc.stderr:                 # progress every 10 % (not a terminal)
        seen.append(line)
        if ' % of 60 runs flown' in line and float(line.split()[1]) >= 20.0:
            proc.send_signal(signal.SIGINT)
            break
    rest = proc.communicate(timeout=60)[1]
    assert proc.returncode == 130, ''.join(seen) + rest
    flown = read(out / 'runs.csv')
    assert 'interrupted: %d of 60 runs flown' % len(flown) in rest
    assert 1 <= len(flown) < 60     # (the progress counts batches in flight: 20 % is not 12 runs)
    runs = [int(r['run']) for r in flown]
    assert runs == sorted(set(runs))


def test_a_gain_study_flies_every_set_on_the_same_runs_and_writes_files_the_controller_takes(
        dask_scheduler, tmp_path, capsys):
    out = tmp_path / 'study'
    code = campaign.main(['--runs', '8', '--duration', '2', '--grid', 'k_R=0.4,0.8',
                          '--grid', 'alpha=8', '--worst', '1', '--scheduler', dask_scheduler,
                          '--out', str(out)])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    rows = read(out / 'runs.csv')
    by_set = {}
    for r in rows:
        by_set.setdefault(r['gain_set'], []).append(r)
    assert sorted(by_set) == ['1', '2'] and all(len(v) == 8 for v in by_set.values())
    for a, b in zip(by_set['1'], by_set['2']):                # the same manoeuvres
        assert (a['run'], a['cones'], a['latency_ms'], a['disturbance_Nm']) == (
            b['run'], b['cones'], b['latency_ms'], b['disturbance_Nm'])
    assert by_set['1'] != by_set['2']                         # flown with other gains
    sets = read(out / 'gain_sets.csv')
    assert [(s['k_R'], s['alpha']) for s in sets] == [('0.4', '8.0'), ('0.8', '8.0')]
    for s in sets:                     # each set's figures are its runs'
        mine = by_set[s['gain_set']]
        assert int(s['violations']) == sum(r['violated'] == 'True' for r in mine)
        assert float(s['converged_share']) == np.mean([r['converged'] == 'True' for r in mine])
    assert (out / 'gain_study.png').stat().st_size > 10_000
    best = sorted(os.listdir(out / 'best'))
    assert best and all(s['non_dominated'] == 'True' for s in sets
                        if 'gain_set_%s.yaml' % s['gain_set'] in best)
    for name in best:                  # the controller takes it as it is
        sections = load_parameter_file(str(out / 'best' / name))
        setup = controller_setup(resolve(CONTROLLER, node_overrides(sections, CONTROLLER)))
        k = int(name.split('_')[-1].split('.')[0])
        assert setup.config.k_R == float(sets[k - 1]['k_R'])
        assert setup.config.cones.names == ['obstacle']       # the testbed's own cone
    assert '| gain set |' in printed.out


def test_a_gain_set_the_controller_would_refuse_is_refused_before_anything_flies(
        tmp_path, capsys):
    code = campaign.main(['--runs', '8', '--grid', 'k_R=0.4,-1', '--grid', 'alpha=8',
                          '--out', str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    assert 'gain set 2 (k_R=-1.0 alpha=8.0)' in err and 'k_R: must be > 0' in err
    assert 'local cluster' not in err and not os.path.exists(tmp_path / 'runs.csv')
    assert campaign.main(['--runs', '8', '--grid', 'setpoint=1', '--out', str(tmp_path)]) == 2
    assert 'setpoint: each run of a campaign sets it' in capsys.readouterr().err
