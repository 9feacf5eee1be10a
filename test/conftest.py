"""Test-wide settings: ROS traffic on loopback in a domain of this run's own, Agg plots.

Set before anything imports rclpy: every node of the tests (this process's and the ones it
starts) uses the loopback DDS profile (geoctl_ros.sil.rosenv), so nothing can leave 127.0.0.1.
"""
import os

import pytest

from geoctl_ros.sil.rosenv import use_node_env

use_node_env()
os.environ['MPLBACKEND'] = 'Agg'


@pytest.fixture(scope='session')
def dask_scheduler():
    """A Dask cluster of two worker processes on 127.0.0.1 (as `dask scheduler` and two `dask
    worker`s would make one), shared by the tests that fly on a cluster they are given
    (``--scheduler``): its address. Made once, on first use.
    """
    # (imported on first use: most runs of the tests never make a cluster)
    import dask  # noqa: PLC0415
    from distributed import LocalCluster  # noqa: PLC0415

    from geoctl_ros.campaign.cluster import LOOPBACK, WORKER_CONFIG  # noqa: PLC0415
    with dask.config.set(WORKER_CONFIG):
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, host=LOOPBACK,
                               dashboard_address=None)
    with cluster:
        yield cluster.scheduler_address


@pytest.fixture
def ros(tmp_path):
    """The node tests' monitor node and a launcher for node processes (node_support.py)."""
    from node_support import node_processes  # noqa: PLC0415  (rclpy: only the DDS tests)
    yield from node_processes(tmp_path)


@pytest.fixture(scope='session')
def installed(tmp_path_factory):
    """The package built and installed by colcon in a workspace of its own (workspace.py), and
    the environment `ros2 launch` and `ros2 run` need to find it (the loopback profile and this
    run's domain from use_node_env above): (env, install prefix). Built once, on first use.
    """
    import pathlib  # noqa: PLC0415
    import sys  # noqa: PLC0415

    from workspace import Workspace  # noqa: PLC0415
    ws = Workspace(str(tmp_path_factory.mktemp('ws')))
    ws.colcon('build', '--packages-select', 'geoctl_ros')
    env, prefix = ws.env, pathlib.Path(ws.prefix)
    env['AMENT_PREFIX_PATH'] = os.pathsep.join([str(prefix), sys.prefix])
    env['PYTHONUNBUFFERED'] = '1'
    return env, prefix
