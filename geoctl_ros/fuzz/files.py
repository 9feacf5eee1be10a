"""The ``files`` and ``bags`` boundaries: random YAML trees and the testbed's file with a value
replaced, as parameter and scenario files; a recorded bag cut or corrupted, read as ``report``
reads it.
"""
import math
import os
import shutil
import tempfile

from geometry_msgs.msg import PoseStamped
from hypothesis import strategies as st
from rclpy.serialization import serialize_message
from std_msgs.msg import Float64
import yaml

from geoctl_ros.fuzz.hostile import (
    Tally,
    hostile_float,
    run_property,
)
from geoctl_ros.params import ConfigError, load_parameter_file
from geoctl_ros.params.topics import BY_NAME
from geoctl_ros.records import bag
from geoctl_ros.sil.rosenv import config_dir
from geoctl_ros.sim import scenario

# --- files -------------------------------------------------------------------------------------
YAML_SCALARS = st.one_of(st.none(), st.booleans(), st.integers(), hostile_float(),
                         st.text(max_size=12), st.just([]), st.just({}))


YAML_KEYS = st.one_of(st.sampled_from(('/**', 'controller', 'sim', 'scenario', 'ros__parameters',
                                       'k_R', 'cones', 'names', 'obstacle', 'axis',
                                       'half_angle_deg', 'setpoint', 'duration', 'latency',
                                       'inertia', 'mass', 'noise')), st.text(max_size=8))


YAML_TREES = st.recursive(YAML_SCALARS, lambda children: st.one_of(
    st.lists(children, min_size=1, max_size=5),
    st.dictionaries(YAML_KEYS, children, min_size=1, max_size=5)),
    max_leaves=30)


def fuzz_files(examples, seed):
    with open(os.path.join(config_dir(), 'scenarios', 'testbed_yaw90.yaml')) as f:
        testbed = yaml.safe_load(f)
    tmp = tempfile.mkdtemp(prefix='fuzz-files-')
    path = os.path.join(tmp, 'case.yaml')
    strategy = st.one_of(
        YAML_TREES.map(lambda tree: ('tree', tree)),
        st.tuples(st.just('edit'), st.sampled_from(sorted(
            (section, key) for section, body in testbed.items()
            for key in body.get('ros__parameters', {}))), YAML_TREES))

    def check(case):
        if case[0] == 'tree':
            tree = case[1]
        else:
            _, (section, key), value = case
            tree = {s: {'ros__parameters': dict(b['ros__parameters'])}
                    for s, b in testbed.items()}
            tree[section]['ros__parameters'][key] = value
        with open(path, 'w') as f:
            try:
                yaml.safe_dump(tree, f)
            except yaml.YAMLError as e:
                return 'not YAML: %s' % e
        try:
            load_parameter_file(path)
            scenario.load(path)
        except ConfigError as e:
            return str(e)
        return None
    try:
        return run_property(Tally('files'), strategy, check, examples, seed)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# --- bags --------------------------------------------------------------------------------------
def _sample_bags(folder):
    """Two small bags of a flight's topics (MCAP and sqlite3)."""
    level = PoseStamped()
    level.header.frame_id = 'world'
    level.pose.orientation.w = 1.0
    pose, psi = serialize_message(level), serialize_message(Float64(data=0.0))
    out = []
    for storage in ('mcap', 'sqlite3'):
        path = os.path.join(folder, storage)
        w = bag.BagWriter(path, [BY_NAME['/sim/true_pose'],
                                 BY_NAME['/configuration_error']], storage)
        for i in range(200):
            w.put('/sim/true_pose', 10 ** 18 + i * 10 ** 7, pose)
            w.put('/configuration_error', 10 ** 18 + i * 10 ** 7, psi)
        w.close()
        out.append(path)
    return out


def fuzz_bags(examples, seed):
    tmp = tempfile.mkdtemp(prefix='fuzz-bags-')
    sources = _sample_bags(os.path.join(tmp, 'sources'))
    files = {}
    for src in sources:
        for name in os.listdir(src):
            with open(os.path.join(src, name), 'rb') as f:
                files[(src, name)] = f.read()
    case_dir = os.path.join(tmp, 'case')
    strategy = st.tuples(st.sampled_from(sorted(files)), st.floats(0.0, 1.0),
                         st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)),
                                  max_size=4), st.booleans())

    def check(case):
        (src, name), cut, flips, keep_metadata = case
        shutil.rmtree(case_dir, ignore_errors=True)
        os.makedirs(case_dir)
        for (s, n), data in files.items():
            if s != src or (n == 'metadata.yaml' and n != name and not keep_metadata):
                continue
            if n == name:
                data = bytearray(data[:int(cut * len(data))])
                for where, value in flips:
                    if data:
                        data[min(int(where * len(data)), len(data) - 1)] = value
            with open(os.path.join(case_dir, n), 'wb') as f:
                f.write(bytes(data))
        try:
            got = bag.read_bag(case_dir)
        except ValueError as e:
            return str(e)
        for messages in got.values():
            for m in messages:
                if not math.isfinite(m.t):
                    raise AssertionError('a message at time %r' % m.t)
        return None
    try:
        return run_property(Tally('bags'), strategy, check, examples, seed)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

