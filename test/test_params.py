"""The parameter schema: defaults, ROS-strict types, one clear error per bad parameter, YAML files,
and the parameter table (docs/parameters.md) generated from the schema.
"""
import os
import re

import numpy as np
import pytest
from support import past_bounds

from geoctl_ros import params
from geoctl_ros.params import CONTROLLER, SIM, ConfigError, controller_setup, resolve
from geoctl_ros.params import readme as readme_table
from geoctl_ros.params.testbed import plant_config
from geoctl_ros.sim import scenario

pytestmark = pytest.mark.odroid

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

ONE_CONE = {'cones.names': ['sun'], 'cones.sun.axis': [1.0, 1.0, 0.0],
            'cones.sun.half_angle_deg': 12.0}


def errors_of(node, overrides):
    with pytest.raises(ConfigError) as info:
        resolve(node, overrides)
    return dict(info.value.errors), str(info.value)


def test_defaults_build_a_controller_and_a_plant():
    c = resolve(CONTROLLER, {})
    cfg = params.controller_config(c)
    assert cfg.k_R == 0.4 and len(cfg.cones) == 0
    assert np.allclose(cfg.J[0, 0], 5.5710e-3 + 1.26 * 0.1 ** 2)   # pivot inertia
    plant = plant_config(resolve(SIM, {}))
    assert plant.mass == 1.26


def test_cones_from_parameters():
    cfg = params.controller_config(resolve(CONTROLLER, ONE_CONE))
    assert cfg.cones.names == ['sun']
    assert np.allclose(cfg.cones.V[0], [2 ** -0.5, 2 ** -0.5, 0.0])
    assert np.degrees(cfg.cones.theta[0]) == pytest.approx(12.0)


@pytest.mark.parametrize('name, value, reason', [
    ('k_R', -0.4, 'must be > 0'),
    ('k_Omega', 0.0, 'must be > 0'),
    ('k_R', 1, 'expected a double, got int 1 (write 1.0)'),
    ('G', [1.0, 1.0, 0.5], 'must be distinct'),
    ('G', [1, 2, 3], 'write every element as a float'),
    ('G', [1.0, 2.0], 'expected 3 values, got 2'),
    ('sensor_axis', [0.0, 0.0, 0.0], 'zero vector'),
    ('inertia', [1.0, 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], 'symmetric'),
    ('inertia', [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0], 'positive definite'),
    ('inertia', [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 3.0], 'triangle inequality'),
    ('setpoint', [0.0, 0.0, 0.0, 2.0], 'unit quaternion'),
    ('disturbance_model', 'linear', 'must be one of constant, constant+cog'),
    ('adaptive', 'yes', 'expected true or false'),
    ('rate_hz', float('nan'), 'must be finite'),
    ('barrier_floor_deg', 0.0, 'must be > 0'),
])
def test_bad_values_name_the_parameter_and_the_reason(name, value, reason):
    errs, text = errors_of(CONTROLLER, {name: value})
    assert list(errs) == [name]
    assert reason in errs[name]
    assert name in text


@pytest.mark.parametrize('half_angle', [0.0, 90.0, 120.0, -5.0])
def test_half_angle_outside_0_90_is_refused(half_angle):
    errs, _ = errors_of(CONTROLLER, dict(ONE_CONE, **{'cones.sun.half_angle_deg': half_angle}))
    assert 'in (0, 90) degrees' in errs['cones.sun.half_angle_deg']


def test_cone_problems():
    errs, _ = errors_of(CONTROLLER, {'cones.names': ['sun']})
    assert 'missing' in errs['cones.sun.axis'] and 'missing' in errs['cones.sun.half_angle_deg']
    errs, _ = errors_of(CONTROLLER, dict(ONE_CONE, **{'cones.moon.axis': [0.0, 0.0, 1.0]}))
    assert "cone 'moon' is not in cones.names" in errs['cones.moon.axis']
    errs, _ = errors_of(CONTROLLER, dict(ONE_CONE, **{'cones.sun.axis': [0.0, 0.0, 0.0]}))
    assert 'zero vector' in errs['cones.sun.axis']
    errs, _ = errors_of(CONTROLLER, {'cones.names': ['a', 'a'], 'cones.a.axis': [1.0, 0.0, 0.0],
                                     'cones.a.half_angle_deg': 10.0})
    assert 'unique' in errs['cones.names']


def test_unknown_parameter_suggests_the_right_name():
    errs, _ = errors_of(CONTROLLER, {'k_r': 0.4})
    assert errs['k_r'] == "unknown parameter (did you mean 'k_R'?)"


def test_every_problem_is_reported_at_once():
    errs, _ = errors_of(CONTROLLER, {'k_R': -1.0, 'alpha': 0.0, 'G': [1.0, 1.0, 1.0]})
    assert set(errs) == {'k_R', 'alpha', 'G'}


def test_parameter_file_sections_and_nesting(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text("""
/**:
  ros__parameters:
    mass: 2.0
    k_R: 0.9            # a controller parameter in the shared section
controller:
  ros__parameters:
    mass: 1.5           # the node's own section wins
    cones:
      names: [sun]
      sun: {axis: [0.0, 1.0, 0.0], half_angle_deg: 30.0}
sim:
  ros__parameters:
    disturbance:
      constant: [0.1, 0.0, 0.0]
""")
    sections = params.load_parameter_file(path)
    ctrl = resolve(CONTROLLER, params.node_overrides(sections, CONTROLLER))
    sim = resolve(SIM, params.node_overrides(sections, SIM))
    assert ctrl['mass'] == 1.5 and ctrl['k_R'] == 0.9
    assert ctrl['cones.sun.half_angle_deg'] == 30.0
    assert sim['mass'] == 2.0 and 'k_R' not in sim
    assert np.allclose(sim['disturbance.constant'], [0.1, 0.0, 0.0])


def test_malformed_parameter_files_are_refused(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('controller:\n  k_R: 0.4\n')
    with pytest.raises(ConfigError, match='ros__parameters'):
        params.load_parameter_file(path)
    path.write_text('- 1\n- 2\n')
    with pytest.raises(ConfigError, match='top level must be a mapping'):
        params.load_parameter_file(path)


def test_shipped_configs_are_valid():
    folder = os.path.join(ROOT, 'config', 'scenarios')
    files = sorted(f for f in os.listdir(folder) if f.endswith('.yaml'))
    assert len(files) >= 5
    for f in files:
        scenario.load(os.path.join(folder, f))


def test_readme_parameter_table_is_in_sync_with_the_schema():
    """A documentation snapshot (it keeps docs/parameters.md true), not a correctness test."""
    with open(os.path.join(ROOT, 'docs', 'parameters.md')) as f:
        readme = f.read()
    m = re.search(r'<!-- params:begin -->\n(.*?)\n<!-- params:end -->', readme, re.S)
    assert m, 'docs/parameters.md lacks the generated parameter table markers'
    assert m.group(1).strip() == readme_table.markdown_table().strip(), (
        'docs/parameters.md is stale: regenerate it with '
        '`./run shell -m geoctl_ros.params.readme --write-readme docs/parameters.md`')


def test_every_default_passes_its_own_type_and_check():
    for p in params.SCHEMA:
        value, reason = params.check_value(p, p.default)
        assert reason is None, (p.name, reason)


def test_a_node_reads_its_settings_by_name_and_cannot_change_them():
    values = resolve(params.MAVLINK, {'mavlink.url': 'udpin:127.0.0.1:14550'})
    cfg = params.settings(values, 'mavlink.')
    assert cfg.url == 'udpin:127.0.0.1:14550' and cfg.system_id == values['mavlink.system_id']
    assert len(cfg) == len(values)                      # one attribute per parameter
    sim = params.settings(resolve(SIM, {}))
    assert sim.noise_seed == resolve(SIM, {})['noise.seed']
    with pytest.raises(AttributeError):
        cfg.url = 'udpin:0.0.0.0:1'


NUMERIC = [p for p in params.SCHEMA + params.CONE_SCHEMA
           if p.type in ('double', 'double_array', 'integer', 'integer_array')]


def test_every_numeric_parameter_has_a_documented_range_holding_its_default():
    for p in NUMERIC:
        assert p.lo is not None and p.lo < p.hi, p.name
        if p.default:
            values = np.atleast_1d(np.asarray(p.default, dtype=float))
            assert p.lo <= values.min() and values.max() <= p.hi, p.name
    table = readme_table.markdown_table()
    assert '| `pose_ride_through` | controller | double | `0.5` |  | [0, 1] | s |' in table


def test_each_numeric_parameter_refuses_nan_inf_1e30_and_just_past_its_bounds():
    """The table the issue asks for, through the one check every path uses (files, ros2 param,
    PARAM_SET): every value refused, with a reason; the DDS tests send the same values through
    the parameter service and MAVLink.
    """
    for p in NUMERIC:
        for label, value in past_bounds(p):
            got, reason = params.check_value(p, value)
            assert got is None and reason, (p.name, label, value)


def test_the_issues_hostile_values_are_refused_and_safety_parameters_are_bounded():
    """What a signed ground station and the parameter service accepted before: ride-throughs of
    1000 s, a 100 s pose timeout, a sensor axis of 1e200 (it normalised to zero), 1e30 kg.
    """
    for name, value in (('pose_ride_through', 1000.0), ('pose_timeout', 100.0),
                        ('imu_ride_through', 1000.0), ('sensor_axis', [1e200, 0.0, 0.0]),
                        ('mass', 1e30), ('k_R', 1e30)):
        errors, _ = errors_of(CONTROLLER, {name: value})
        assert 'must be in' in errors[name], (name, errors)


def test_while_armed_only_gains_and_goals_may_change():
    assert params.change_problem({'k_R', 'setpoint'}, params.CHANGE_WHILE_ARMED, 'x') is None
    problem = params.change_problem({'k_R', 'pose_timeout', 'cones.sun.axis', 'cones.names'},
                                    params.CHANGE_WHILE_ARMED, 'while disarmed')
    assert problem == ('cones.names, cones.sun.axis, pose_timeout may change while disarmed '
                       'only')


def test_shared_values_alone_do_not_configure_a_controller():
    """A /** section (mass, gravity: the sim reads them too) reaching a controller that its file's
    controller: section does not address is no configuration; one parameter of its own is.
    """
    shared = set(params.node_overrides(params.load_parameter_file(
        os.path.join(ROOT, 'config', 'testbed.yaml')), 'sim')) & {'mass', 'cog_offset', 'gravity'}
    assert shared and not params.configuration_given(CONTROLLER, shared)
    assert params.configuration_given(CONTROLLER, shared | {'k_R'})
    assert params.configuration_given(CONTROLLER, {'cones.sun.axis'})


def test_a_thrust_curve_whose_inverse_would_overflow_is_refused():
    """Found by the fuzzer on the vehicle's stack: motor.a = 5e-324 passed "> 0", and the curve's
    inverse, 1 / (2 a vs), overflowed (numpy warns). It is refused, naming the parameter.
    """
    for a in ([5e-324], [0.0], [-1e-5]):
        with pytest.raises(ConfigError, match='motor.a: must be at least 1e-12'):
            controller_setup(resolve(CONTROLLER, {'motor.a': a}))
    with pytest.raises(ConfigError) as refused:       # (the minimum itself is no motor.a error:
        controller_setup(resolve(CONTROLLER, {'motor.a': [1e-12]}))   # its curve lifts little)
    assert [name for name, _ in refused.value.errors] == ['thrust_max']


def test_thrust_limits_that_cannot_carry_the_collective_thrust_are_refused():
    """Found by the fuzzer (a ground station's THRUST_MAX of 1 N): thrust limits that leave the
    rotors no way to carry the collective thrust left the moment polytope empty, and the brake's
    authority over it raised. They are refused, naming the limit and the shares.
    """
    for over, name in (({'thrust_max': 1.0}, 'thrust_max'), ({'thrust_min': 3.0}, 'thrust_min')):
        with pytest.raises(ConfigError) as refused:
            controller_setup(resolve(CONTROLLER, over))
        [(got, reason)] = refused.value.errors
        assert got == name and 'cannot carry the collective thrust' in reason, reason
    # limits that carry it, but leave the rotors no deceleration against gravity at the stops
    with pytest.raises(ConfigError, match='brake_acceleration: the rotors cannot decelerate'):
        controller_setup(resolve(CONTROLLER, {'thrust_max': 3.0}))


@pytest.mark.parametrize('order', ['wildcard first', 'node first'])
def test_a_files_sections_apply_in_its_order_as_rclpy_applies_them(tmp_path, order):
    """k_R set in '/**' (0.7) and in the controller's section (0.9) of one file: what the tools
    read of it (``node_overrides``) is what a node given that file holds, in either order of
    the sections (the later one's value: rclpy's order of first appearance).
    """
    rclpy = pytest.importorskip('rclpy')
    from rclpy.context import Context  # noqa: PLC0415  (after the skip above)
    from rclpy.node import Node  # noqa: PLC0415
    wildcard = '/**:\n  ros__parameters:\n    k_R: 0.7\n'
    own = 'controller:\n  ros__parameters:\n    k_R: 0.9\n'
    path = tmp_path / 'lab.yaml'
    path.write_text(wildcard + own if order == 'wildcard first' else own + wildcard)
    read = params.node_overrides(params.load_parameter_file(str(path)), CONTROLLER)['k_R']
    context = Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(path)])
    try:
        node = Node('controller', context=context,
                    automatically_declare_parameters_from_overrides=True)
        held = node.get_parameter('k_R').value
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert read == held == (0.9 if order == 'wildcard first' else 0.7)
