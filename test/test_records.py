"""Flight records and the 3D view without DDS: what report says of what is not a usable bag, a
bag with some topics missing, and the view's geometry. (A recorded flight over DDS, with the
view's markers in it: test_node_flights.py.)
"""
import importlib.util
import json
import math
import os
import subprocess
import sys
import time
from typing import NamedTuple

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, QuaternionStamped
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64
import yaml

from geoctl_ros.cli.report import main as report_main
from geoctl_ros.core.telemetry.diagnostics import Figures, Status
from geoctl_ros.core.telemetry.view import Trail, cone_triangles, in_warning
from geoctl_ros.nodes.conversions import set_quaternion, status_msg
from geoctl_ros.params.topics import BY_NAME, Topic
from geoctl_ros.records import bag
from geoctl_ros.sim import scenario

# on the vehicle's stack too, but for compare's headless flight (the development stack's; the
# closed loop there is test_closed_loop's)
odroid = pytest.mark.odroid
TESTBED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'config',
                       'testbed.yaml')
EXPERIMENT = os.path.join(os.path.dirname(TESTBED), 'scenarios', 'testbed_experiment.yaml')
# report draws its figures where matplotlib is (the extra tools); on the vehicle's stack it says
# in one line that it does not, and writes the rest
FIGURES = importlib.util.find_spec('matplotlib') is not None


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


def drew(r, out, figure):
    """report drew FIGURE in out where it can; elsewhere it said so in one line, and drew none."""
    if FIGURES:
        assert (out / figure).stat().st_size > 10_000
    else:
        assert [line for line in r.stderr.splitlines() if 'figures' in line] == [
            "report: no figures: matplotlib is not installed here (the extra 'tools': pip install "
            "-e '.[tools]' in a clone, or draw them on a development machine); the rest is "
            'written'], r.stderr
        assert not list(out.glob('*.png'))


def write(path, topic, values, storage='mcap'):
    w = bag.BagWriter(str(path), [topic], storage)
    for i, v in enumerate(values):
        w.put(topic.name, 1_000_000_000 + i * 10_000_000, serialize_message(Float64(data=v)))
    w.close()
    assert w.error is None and w.counts[topic.name] == len(values)


@odroid
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


@odroid
@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_bag_with_some_topics_reports_what_it_can_and_names_the_rest(tmp_path, storage,
                                                                      report):
    path = tmp_path / 'psi_only'
    psi = [0.5, 0.2, 0.05, 0.0009, 0.0004]
    write(path, BY_NAME['/configuration_error'], psi, storage)
    out = tmp_path / 'out'
    r = report(path, '--out', out)
    assert r.returncode == 0, r.stderr
    assert '/sim/true_pose' in r.stderr and 'no cones' in r.stderr
    s = json.loads((out / 'summary.json').read_text())
    assert s['final_psi'] == pytest.approx(0.0004)
    assert s['settle_time_s'] == pytest.approx(0.03)        # below 1e-3 from the fourth sample
    assert 'closest_approach_deg' not in s and '/pose' in s['missing_topics']
    drew(r, out, 'flight.png')
    assert not (out / 'sensor_path.png').exists()


@odroid
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


def test_compare_flies_a_record_again_headless_and_finds_the_same_flight(tmp_path, report):
    """A record made from a headless run of the testbed flying the lab's hand-made set points
    (config/scenarios/testbed_experiment.yaml: its true attitude, Psi, set points and armed
    diagnostics, at the runner's steps), compared with that file stripped of its start and its
    set points: the headless twin starts at the record's attitude at arming and flies the
    record's set points, so it finds the same closest approach.
    """
    flown = scenario.run(scenario.load(EXPERIMENT), duration=8.0)
    cols = flown.columns
    t = flown.history[:, 0]
    names = [n for n in BY_NAME if n in ('/sim/true_pose', '/configuration_error',
                                         '/active_setpoint', '/diagnostics')]
    w = bag.BagWriter(str(tmp_path / 'flight'), [BY_NAME[n] for n in names])
    ns = (1_000_000_000 + np.round(t * 1e9)).astype(int)
    for k, row in enumerate(flown.history):
        pose = PoseStamped()
        set_quaternion(pose.pose.orientation, row[[cols.index(c) for c in ('qx', 'qy', 'qz',
                                                                           'qw')]])
        w.put('/sim/true_pose', int(ns[k]), serialize_message(pose))
        w.put('/configuration_error', int(ns[k]),
              serialize_message(Float64(data=float(row[cols.index('psi')]))))
    schedule = flown.scenario.controller
    for t_set, q in zip(schedule['setpoint_schedule.times'],
                        np.reshape(schedule['setpoint_schedule.quaternions'], (-1, 4))):
        sp = QuaternionStamped()
        set_quaternion(sp.quaternion, q)
        w.put('/active_setpoint', int(1_000_000_000 + t_set * 1e9), serialize_message(sp))
    for t_d in np.arange(0.0, 8.0, 0.5):
        status = status_msg(Status(0, 'armed', Figures(armed=True, state='armed')),
                            'geoctl_ros: controller', 'geoctl_ros')
        w.put('/diagnostics', int(1_000_000_000 + t_d * 1e9),
              serialize_message(DiagnosticArray(status=[status])))
    w.close()
    # the scenario file compared with has neither the start nor the set points: they must come
    # from the record
    doc = yaml.safe_load(open(EXPERIMENT))
    del doc['controller']['ros__parameters']['setpoint_schedule']
    doc['sim']['ros__parameters']['initial_attitude'] = [0.0, 0.0, 0.0, 1.0]
    bare = tmp_path / 'bare.yaml'
    bare.write_text(yaml.safe_dump(doc))
    out = tmp_path / 'out'
    r = report(tmp_path / 'flight', '--out', out, '--params-file', EXPERIMENT, '--compare', bare)
    assert r.returncode == 0, r.stderr
    s = json.loads((out / 'summary.json').read_text())
    recorded = s['closest_approach_deg']['obstacle']['angle']
    assert recorded == pytest.approx(flown.summary['min_cone_angle_deg']['obstacle'], abs=0.01)
    assert s['headless']['closest_approach_deg']['obstacle'] == pytest.approx(recorded, abs=0.05)
    drew(r, out, 'compare.png')
    never = tmp_path / 'never_armed'
    write(never, BY_NAME['/configuration_error'], [0.5, 0.4])
    assert report(never, '--out', tmp_path / 'o2', '--compare', TESTBED).returncode == 2


@odroid
@pytest.mark.dds
def test_record_writes_the_remapped_raw_topics_under_their_real_names_and_report_reads_them(
        ros, tmp_path, report):
    """``record`` with the controller's remaps (the runbook's command) hears the drivers' own
    topics and writes them under their real names: rosbags' own reader finds
    /vicon/hexrotor/pose and /vn100/imu, and nothing of what another node publishes on the
    package's plain /pose. ``report`` reads them as /pose and /imu.
    """
    from geometry_msgs.msg import PoseStamped as Pose  # noqa: PLC0415
    from rosbags.highlevel import AnyReader  # noqa: PLC0415
    from rosbags.typesys import Stores, get_typestore  # noqa: PLC0415
    from sensor_msgs.msg import Imu  # noqa: PLC0415

    from geoctl_ros.nodes import qos  # noqa: PLC0415
    mon, launch = ros
    path = tmp_path / 'flight1'
    rec = launch('record', None, '-p', 'record.path:=%s' % path,
                 '-r', 'pose:=/vicon/hexrotor/pose', '-r', 'imu:=/vn100/imu')
    raw_pose = mon.create_publisher(Pose, '/vicon/hexrotor/pose', qos.SENSOR)
    raw_imu = mon.create_publisher(Imu, '/vn100/imu', qos.SENSOR)
    plain = mon.create_publisher(Pose, '/pose', qos.SENSOR)

    def feed():
        raw_pose.publish(Pose())
        raw_imu.publish(Imu())
        plain.publish(Pose())
    timer = mon.create_timer(0.01, feed)
    try:
        mon.wait_for(lambda: all('first message on %s' % t in rec.output() for t in (
            '/vicon/hexrotor/pose', '/vn100/imu')), 30.0, 'the raw topics in the record')
    finally:
        mon.destroy_timer(timer)
    assert rec.stop() == 0, rec.output()
    assert ('recording 16 topics to %s (mcap), /pose as /vicon/hexrotor/pose, /imu as /vn100/imu'
            % path) in rec.output()
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts['/vicon/hexrotor/pose'] > 0 and counts['/vn100/imu'] > 0, counts
    assert '/pose' not in counts and '/imu' not in counts
    out = tmp_path / 'out'
    r = report(path, '--out', out)
    assert r.returncode == 0, r.stderr
    s = json.loads((out / 'summary.json').read_text())
    assert s['attitude_source'] == '/pose'
    assert '/pose' not in s['missing_topics'] and '/imu' not in s['missing_topics']
    assert '/attitude' in s['missing_topics']


@odroid
def test_a_closed_bag_whose_file_was_cut_still_reports(tmp_path):
    """Issue (hostile input): a bag closed and then cut (its metadata.yaml present, its MCAP file
    short: a copy that stopped, a card pulled) was refused with "File end magic is invalid"; the
    same cut without metadata.yaml was mended. Both are read up to the cut now.
    """
    path = tmp_path / 'cut'
    psi = [0.5 - 0.001 * i for i in range(200)]
    write(path, BY_NAME['/configuration_error'], psi)
    (mcap,) = path.glob('*.mcap')
    data = mcap.read_bytes()
    mcap.write_bytes(data[:len(data) - 40])                    # into its summary and footer
    got = bag.read_bag(str(path), ['/configuration_error'])['/configuration_error']
    assert [m.msg.data for m in got] == psi
    mcap.write_bytes(data[:40])                                # nothing but a header is left
    with pytest.raises(ValueError, match='cannot be read as a rosbag2 bag'):
        bag.read_bag(str(path))


FULL_DISK = """
import resource, signal, sys, time
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64
from geoctl_ros.records import bag
from geoctl_ros.params.topics import BY_NAME
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # a write past the limit fails, as on a full disk
resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, 1_000_000))
w = bag.BagWriter(sys.argv[1], [BY_NAME['/configuration_error']], 'mcap')
t_end = time.monotonic() + 10.0
psi = serialize_message(Float64(data=0.0))
while w.error is None and time.monotonic() < t_end:     # some 400 kB a second
    for _ in range(100):
        w.put('/configuration_error', time.time_ns(), psi)
    time.sleep(0.01)
for _ in range(100_500):         # more than the queue holds: close() must not wait on it
    w.put('/configuration_error', time.time_ns(), psi)
w.close()
print('error:', w.error)
print('dropped:', w.dropped)
"""


@odroid
def test_a_full_disk_stops_the_bag_cleanly_and_what_was_written_reads_back(tmp_path):
    """Issue (hostile input): a full disk ended the writer thread silently and close() could
    wait forever on a full queue. Here a file size limit stands in for the full disk (the
    writes fail with EFBIG as they would with ENOSPC): the writer reports the error, close()
    returns, later messages are counted as dropped, and the bag's checkpoints read back.
    """
    path = tmp_path / 'full'
    r = subprocess.run([sys.executable, '-c', FULL_DISK, str(path)], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert 'error: [Errno 27] File too large' in r.stdout, r.stdout
    assert int(r.stdout.split('dropped:')[1]) > 0
    got = bag.read_bag(str(path), ['/configuration_error'])
    assert len(got['/configuration_error']) > 0


@odroid
def test_each_checkpoint_puts_the_bag_on_the_disk_not_only_in_the_page_cache(tmp_path,
                                                                             monkeypatch):
    """Issue (hostile input): the 1 s checkpoint flushed the MCAP file but did not fsync it, so a
    power cut could lose what the checkpoint promised. The disk is the hardware edge: os.fsync is
    watched (and still called) while a bag records for a little over one checkpoint.
    """
    synced = []
    real = os.fsync

    def fsync(fd):
        synced.append(os.fstat(fd).st_ino)
        return real(fd)
    monkeypatch.setattr(os, 'fsync', fsync)
    path = tmp_path / 'synced'
    topic = BY_NAME['/configuration_error']
    w = bag.BagWriter(str(path), [topic], 'mcap')
    t_end = time.monotonic() + 1.5 * bag.CHECKPOINT_S
    while time.monotonic() < t_end:
        w.put(topic.name, time.time_ns(), serialize_message(Float64(data=0.5)))
        time.sleep(0.01)
    checkpointed = list(synced)          # before close() (which may sync again)
    w.close()
    (mcap,) = path.glob('*.mcap')
    assert os.stat(mcap).st_ino in checkpointed
