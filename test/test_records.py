"""Flight records and the 3D view without DDS: what report says of what is not a usable bag, a
bag with some topics missing, and the view's geometry. (A recorded flight over DDS, with the
view's markers in it: test_nodes.py.)
"""
import json
import math
import os
from typing import NamedTuple

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64

from geoctl_ros.core.view import Trail, cone_triangles, in_warning
from geoctl_ros.records import bag
from geoctl_ros.records.bag import Topic
from geoctl_ros.tools.report import main as report_main

pytestmark = pytest.mark.odroid


class Ran(NamedTuple):
    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def report(capsys):
    """The report command, as its console script calls it (in this process: no start-up)."""
    def run(*args):
        code = report_main([str(a) for a in args])
        out, err = capsys.readouterr()
        return Ran(code, out, err)
    return run


def one_line_refusal(r, *words):
    assert r.returncode == 2, r
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    for w in words:
        assert w in r.stderr, r.stderr


def write(path, topic, values, storage='mcap'):
    w = bag.BagWriter(str(path), [topic], storage)
    for i, v in enumerate(values):
        w.put(topic.name, 1_000_000_000 + i * 10_000_000, serialize_message(Float64(data=v)))
    w.close()
    assert w.error is None and w.counts[topic.name] == len(values)


def test_what_is_not_a_bag_is_refused_in_one_line(tmp_path, report):
    one_line_refusal(report(tmp_path / 'nowhere'), 'nowhere', 'not a rosbag2 bag')
    (tmp_path / 'empty').mkdir()
    one_line_refusal(report(tmp_path / 'empty'), 'empty', 'no metadata.yaml')
    garbage = tmp_path / 'garbage'
    garbage.mkdir()
    (garbage / 'garbage.mcap').write_bytes(os.urandom(4096))
    one_line_refusal(report(garbage), 'garbage')
    other = tmp_path / 'other_robot'
    write(other, Topic('/other/altitude', 'std_msgs/msg/Float64', True), [1.0, 2.0])
    one_line_refusal(report(other), 'none of the topics geoctl_ros publishes', '/other/altitude')


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_bag_with_some_topics_reports_what_it_can_and_names_the_rest(tmp_path, storage,
                                                                      report):
    path = tmp_path / 'psi_only'
    psi = [0.5, 0.2, 0.05, 0.0009, 0.0004]
    write(path, bag.BY_NAME['/configuration_error'], psi, storage)
    out = tmp_path / 'out'
    r = report(path, '--out', out)
    assert r.returncode == 0, r.stderr
    assert '/sim/true_pose' in r.stderr and 'no cones' in r.stderr
    s = json.loads((out / 'summary.json').read_text())
    assert s['final_psi'] == pytest.approx(0.0004)
    assert s['settle_time_s'] == pytest.approx(0.03)        # below 1e-3 from the fourth sample
    assert 'closest_approach_deg' not in s and '/pose' in s['missing_topics']
    assert (out / 'flight.png').stat().st_size > 10_000 and not (out / 'sensor_path.png').exists()


def test_the_view_draws_each_cone_at_its_half_angle_and_the_trail_oldest_first():
    axis, theta = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0), math.radians(12.0)
    tris = cone_triangles(axis, theta, length=2.0, segments=16).reshape(16, 3, 3)
    assert np.all(tris[:, 0] == 0.0)                                    # apex at the pivot
    rim = tris[:, 1:].reshape(-1, 3)
    assert np.allclose(np.linalg.norm(rim, axis=1), 2.0)
    assert np.allclose(np.degrees(np.arccos(rim @ axis / 2.0)), 12.0)
    assert np.allclose(tris[:-1, 2], tris[1:, 1])                       # a closed surface
    assert np.allclose(tris[-1, 2], tris[0, 1])
    assert list(in_warning([30.0, 4.9, -1.0], 5.0)) == [False, True, True]
    trail = Trail(3)
    for k in range(5):
        trail.add([k, 0.0, 0.0])
    assert list(trail.points()[:, 0]) == [2.0, 3.0, 4.0]
