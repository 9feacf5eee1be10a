"""The shared parameter schema as ROS 2 parameters: declaration, reading, run-time validation.

Every schema parameter of the node is declared with its default, type and description (the
parameter-file overrides apply at declaration), and every one has a value, so that ``ros2 param
dump`` lists them all (rclpy answers a get_parameters request with nothing at all when one name in
it has no value). An empty array is declared with its type and then set to a typed empty value: a
parameter file's ``[]`` reaches rclpy as "not set", which is how a dump of an empty array reads
back. Cones listed in ``cones.names`` are declared too; cones added at run time are set as new
parameters (the node allows undeclared ones) and take effect when their name joins ``cones.names``.
A file may define cones that ``cones.names`` does not list (a dump taken while a cone was being
added does): they are declared, and take effect when named. Every change is validated as a whole
configuration by the same code the headless runner uses; a refused change leaves the running node
untouched and the reason is returned to the caller (``ros2 param set`` prints it).
"""
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.parameter import Parameter

from geoctl_ros.nodes.conversions import python_value
from geoctl_ros.params import (
    BY_NAME,
    CONE_KEY,
    CONE_SCHEMA,
    CONTROLLER,
    ConfigError,
    cone_param,
    resolve,
    schema_for,
)

ROS_TYPE = {
    'double': Parameter.Type.DOUBLE, 'double_array': Parameter.Type.DOUBLE_ARRAY,
    'bool': Parameter.Type.BOOL, 'string': Parameter.Type.STRING,
    'string_array': Parameter.Type.STRING_ARRAY, 'integer': Parameter.Type.INTEGER,
    'integer_array': Parameter.Type.INTEGER_ARRAY,
}
# Changing these needs a restart (timers, frames, links); ROS refuses them at run time. So do all
# of the MAVLink bridge's (mavlink.*) and of the ESC node's (esc.*; its motor_test.* may change).
READ_ONLY = {'rate_hz', 'integration_rate_hz', 'pose_rate_hz', 'imu_rate_hz', 'publish_clock',
             'real_time_factor', 'frame_id', 'world_frame_id', 'actuation',
             # the inputs' conventions: set at start (a change in flight would move the cones)
             'pose_world_frame', 'body_frame', 'marker_rotation_deg', 'imu_rotation_deg',
             'gyro_bias'}
ROS_OWN = ('use_sim_time', 'start_type_description_service', 'qos_overrides.')


def _descriptor(p):
    return ParameterDescriptor(description='%s [%s]' % (p.doc, p.unit),
                               read_only=(p.name in READ_ONLY
                                          or p.name.startswith(('mavlink.', 'esc.'))))


def _declare(node, p, errors):
    try:
        if p.default is None or p.default == []:
            node.declare_parameter(p.name, ROS_TYPE[p.type], _descriptor(p))
            if p.default == [] and _get(node, p.name) is None:
                node.set_parameters([Parameter(p.name, ROS_TYPE[p.type], [])])
        else:
            node.declare_parameter(p.name, p.default, _descriptor(p))
    except (InvalidParameterTypeException, InvalidParameterValueException, TypeError) as e:
        errors.append((p.name, 'expected a %s: %s' % (p.type.replace('_', ' of '), e)))


def file_overrides(node):
    """The parameter-file (and -p) values the node was started with, by name.

    rclpy (Jazzy) keeps them only in the private ``Node._parameter_overrides`` and offers no
    public accessor (``automatically_declare_parameters_from_overrides`` would declare them
    without our types and descriptions, and fails on an empty array). Read here and nowhere else.
    """
    return dict(getattr(node, '_parameter_overrides', {}))


def _get(node, name):
    """A declared parameter's value, or None while it is declared without a value."""
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None


def declare(node, kind):
    """Declare kind's parameters on node; returns (parameter, reason) pairs for bad overrides."""
    errors = []
    for p in schema_for(kind):
        _declare(node, p, errors)
    if kind == CONTROLLER:
        names = list(_get(node, 'cones.names') or [])
        for name in names:
            for template in CONE_SCHEMA:
                p = cone_param(name, template.name.rsplit('.', 1)[1])
                if not node.has_parameter(p.name):
                    _declare(node, p, errors)
        for key in file_overrides(node):      # what the file defines of cones it does not name
            m = CONE_KEY.match(key)
            if m and m.group(1) not in names and not node.has_parameter(key):
                _declare(node, cone_param(m.group(1), m.group(2)), errors)
    return errors


def load(node, kind):
    """Declare kind's parameters on node and return them resolved (the schema's checks applied);
    raises ConfigError naming every bad one.
    """
    errors = declare(node, kind)
    if errors:
        raise ConfigError(errors)
    return resolve(kind, values(node, kind))


def unnamed_cones(node):
    """Cones with parameters on the node that cones.names does not list (not in effect)."""
    names = set(_get(node, 'cones.names') or [])
    return sorted({m.group(1) for n in node.list_parameters([], 0).names
                   for m in [CONE_KEY.match(n)] if m and m.group(1) not in names})


def values(node, kind, pending=()):
    """The node's parameters as a flat dict of Python values, with pending (not yet applied)
    rclpy Parameters laid over them, and any parameter-file entries that are not declared (so
    that validation reports them as unknown; those of the other node, which a shared '/**'
    section gives every node, are left out).
    """
    out = {}
    for name in node.list_parameters([], 0).names:
        if name.startswith(ROS_OWN):
            continue
        value = _get(node, name)
        if value is not None:
            out[name] = python_value(value)
    for name, param in file_overrides(node).items():
        if name in out or name.startswith(ROS_OWN) or node.has_parameter(name):
            continue
        if name in BY_NAME and kind not in BY_NAME[name].nodes:
            continue
        out[name] = python_value(param.value)
    for param in pending:
        if param.name.startswith(ROS_OWN):
            continue
        if param.type_ == Parameter.Type.NOT_SET:
            out.pop(param.name, None)
        else:
            out[param.name] = python_value(param.value)
    return out


def watch(node, kind, build, apply):
    """Validate every parameter change with build(values, changed names) (raising ConfigError);
    after a change is accepted, call apply(build(values, changed), changed names).
    """
    def on_set(params):
        try:
            build(values(node, kind, params), {p.name for p in params})
        except ConfigError as e:
            return SetParametersResult(successful=False, reason=str(e))
        return SetParametersResult(successful=True)

    def after_set(params):
        changed = {p.name for p in params}
        apply(build(values(node, kind), changed), changed)

    node.add_on_set_parameters_callback(on_set)
    node.add_post_set_parameters_callback(after_set)
