"""The one parameter schema of geoctl_ros, ROS 2 parameter-file loading, and validation.

Every parameter any part of the project reads is declared once in ``SCHEMA`` with its type, default,
unit, one-line doc and check. The ROS nodes declare their parameters from it, the headless
``scenario`` runner reads the same ROS 2 parameter YAML files through ``load_parameter_file``, and the
README's parameter table is generated from it (``python -m geoctl_ros.params``).

Types follow ROS 2 parameter types strictly, as rclpy would: a ``double`` must be written as a float
(``1.0``, not ``1``), arrays of doubles likewise. Cones are parameters too:
``cones.names: [a, b]`` plus ``cones.<name>.axis`` and ``cones.<name>.half_angle_deg`` per name.

Validation collects every problem and raises one ``ConfigError`` naming each parameter; a
configuration is built only when nothing is wrong, so nothing starts half-configured.
"""
from dataclasses import dataclass
import math
import re
import sys

import numpy as np
import yaml

from geoctl_ros import so3
from geoctl_ros.cones import ConeSet
from geoctl_ros.control import DISTURBANCE_MODELS, ControllerConfig
from geoctl_ros.plant import Disturbance, PlantConfig

CONTROLLER, SIM, SCENARIO = 'controller', 'sim', 'scenario'
BOTH = (CONTROLLER, SIM)

LAB_INERTIA = [5.5710e-3, 6.1766e-5, -2.5028e-5,
               6.1766e-5, 5.5757e-3, 1.0068e-5,
               -2.5028e-5, 1.0068e-5, 1.0505e-2]


class ConfigError(ValueError):
    """One or more invalid parameters; ``errors`` lists (parameter, reason) pairs."""

    def __init__(self, errors):
        self.errors = list(errors)
        super().__init__('invalid parameters:\n' + '\n'.join(
            '  %s: %s' % (name, reason) for name, reason in self.errors))


# --- checks: each returns a reason (str) or None ---------------------------------------------------
def _positive(v):
    return None if v > 0.0 else 'must be > 0 (got %r)' % v


def _nonnegative(v):
    return None if v >= 0.0 else 'must be >= 0 (got %r)' % v


def _nonzero_vector(v):
    return None if np.linalg.norm(v) > 1e-9 else 'must not be the zero vector'


def _unit_quaternion(q):
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > 1e-3:
        return 'must be a unit quaternion (x, y, z, w); its norm is %.6g' % n
    return None


def _half_angle(v):
    return None if 0.0 < v < 90.0 else 'must be in (0, 90) degrees (got %r)' % v


def _weights(G):
    if min(G) <= 0.0:
        return 'weights must be positive (got %s)' % list(G)
    if len(set(G)) < 3:
        return 'weights must be distinct (Prop. 1 of the paper; got %s)' % list(G)
    return None


def _inertia(vals):
    J = np.asarray(vals).reshape(3, 3)
    if not np.allclose(J, J.T, rtol=0.0, atol=1e-12 + 1e-9 * np.abs(J).max()):
        return 'must be symmetric (row-major 3x3)'
    eig = np.linalg.eigvalsh(J)
    if eig[0] <= 0.0:
        return 'must be positive definite (smallest eigenvalue %.3g)' % eig[0]
    if eig[0] + eig[1] < eig[2] * (1.0 - 1e-9):
        return 'violates the triangle inequality of principal moments (not a physical body)'
    return None


def _rate(v):
    return None if 0.0 < v <= 10000.0 else 'must be in (0, 10000] Hz (got %r)' % v


def _floor(v):
    return None if 0.0 < v < 10.0 else 'must be in (0, 10) degrees (got %r)' % v


@dataclass(frozen=True)
class Param:
    """One parameter: ROS type ('double', 'double_array', 'bool', 'string', 'string_array'),
    array length (0: any), default, unit, one-line doc, the nodes that read it, and a check."""

    name: str
    type: str
    default: object
    unit: str
    doc: str
    nodes: tuple
    length: int = 0
    check: object = None
    choices: tuple = ()


def _p(name, type_, default, unit, doc, nodes, length=0, check=None, choices=()):
    return Param(name, type_, default, unit, doc, nodes if isinstance(nodes, tuple) else (nodes,),
                 length, check, choices)


SCHEMA = [
    # Controller gains and shape (paper notation).
    _p('k_R', 'double', 0.4, 'N m', 'attitude gain k_R', CONTROLLER, check=_positive),
    _p('k_Omega', 'double', 0.7, 'N m s', 'angular-velocity gain k_Omega', CONTROLLER,
       check=_positive),
    _p('k_Delta', 'double', 0.05, '-', 'adaptation gain k_Delta', CONTROLLER, check=_positive),
    _p('c', 'double', 0.1, '1/s', 'weight of e_R in the adaptive law (Prop. 5)', CONTROLLER,
       check=_positive),
    _p('alpha', 'double', 8.0, '-', 'barrier shape alpha (larger: barrier acts closer to a cone)',
       CONTROLLER, check=_positive),
    _p('G', 'double_array', [0.9, 1.1, 1.0], '-',
       'diagonal weights g1, g2, g3 of the attitude error A (distinct, positive)', CONTROLLER,
       length=3, check=_weights),
    _p('adaptive', 'bool', True, '-', 'run the adaptive law (else Delta_bar stays 0)', CONTROLLER),
    _p('disturbance_model', 'string', 'constant', '-',
       'regressor W: constant (W = I) or constant+cog (also estimates the error in m*rho)',
       CONTROLLER, choices=tuple(DISTURBANCE_MODELS)),
    _p('delta_bar_max', 'double', 1.0, 'N m',
       'bound on |constant disturbance estimate| (projection); 0 = unbounded', CONTROLLER,
       check=_nonnegative),
    _p('cog_estimate_max', 'double', 0.1, 'kg m',
       'bound on |m*rho estimate| of the constant+cog model; 0 = unbounded', CONTROLLER,
       check=_nonnegative),
    _p('gravity_compensation', 'bool', True, '-',
       'subtract the modelled gravity moment of the centre-of-mass offset', CONTROLLER),
    _p('sensor_axis', 'double_array', [1.0, 0.0, 0.0], '-',
       'body-fixed sensor axis r (normalised)', CONTROLLER, length=3, check=_nonzero_vector),
    _p('barrier_floor_deg', 'double', 0.25, 'deg',
       'within this angle of a cone boundary the barrier is extended linearly (saturated)',
       CONTROLLER, check=_floor),
    _p('cones.names', 'string_array', [], '-',
       'names of the forbidden cones; each needs cones.<name>.axis and .half_angle_deg',
       CONTROLLER),
    _p('setpoint', 'double_array', [0.0, 0.0, 0.0, 1.0], '-',
       'desired attitude R_d as a quaternion (x, y, z, w), world frame', CONTROLLER, length=4,
       check=_unit_quaternion),
    _p('rate_hz', 'double', 100.0, 'Hz', 'control rate', CONTROLLER, check=_rate),
    # Physical model, read by the controller (its model) and the simulator (the truth).
    _p('inertia', 'double_array', LAB_INERTIA, 'kg m^2',
       'inertia about the centre of mass, 9 values row-major', BOTH, length=9, check=_inertia),
    _p('mass', 'double', 1.26, 'kg', 'mass', BOTH, check=_positive),
    _p('cog_offset', 'double_array', [0.0, 0.0, 0.1], 'm',
       'pivot -> centre of mass, body frame (z up: above the pivot)', BOTH, length=3),
    _p('gravity', 'double_array', [0.0, 0.0, -9.81], 'm/s^2', 'gravity vector, world frame',
       BOTH, length=3),
    # Simulator.
    _p('integration_rate_hz', 'double', 1000.0, 'Hz', 'simulator integration rate (RKMK4)', SIM,
       check=_rate),
    _p('initial_attitude', 'double_array', [0.0, 0.0, 0.0, 1.0], '-',
       'initial attitude quaternion (x, y, z, w)', SIM, length=4, check=_unit_quaternion),
    _p('initial_angular_velocity', 'double_array', [0.0, 0.0, 0.0], 'rad/s',
       'initial body angular velocity', SIM, length=3),
    _p('disturbance.constant', 'double_array', [0.0, 0.0, 0.0], 'N m',
       'constant disturbance moment, body frame', SIM, length=3),
    _p('disturbance.amplitude', 'double_array', [0.0, 0.0, 0.0], 'N m',
       'amplitudes of [sin wt, cos wt, (sin wt + cos wt)/2] added to it', SIM, length=3),
    _p('disturbance.frequency', 'double', 0.0, 'rad/s', 'w of the sinusoidal disturbance', SIM,
       check=_nonnegative),
    # Headless runner.
    _p('duration', 'double', 20.0, 's', 'simulated time of a scenario run', SCENARIO,
       check=_positive),
    _p('title', 'string', '', '-', 'title for a scenario run\'s plots and summary', SCENARIO),
]

# Per-cone parameters; <name> is one of cones.names.
CONE_SCHEMA = [
    _p('cones.<name>.axis', 'double_array', None, '-', 'cone axis v_i, world frame (normalised)',
       CONTROLLER, length=3, check=_nonzero_vector),
    _p('cones.<name>.half_angle_deg', 'double', None, 'deg', 'cone half-angle theta_i',
       CONTROLLER, check=_half_angle),
]

BY_NAME = {p.name: p for p in SCHEMA}
_CONE_KEY = re.compile(r'^cones\.([^.]+)\.(axis|half_angle_deg)$')
_CONE_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')


def schema_for(node):
    """The parameters node ('controller', 'sim' or 'scenario') reads, in schema order."""
    return [p for p in SCHEMA if node in p.nodes]


def cone_param(name, field_):
    """The schema entry for cones.<name>.<field_> (field_ is 'axis' or 'half_angle_deg')."""
    template = {'axis': CONE_SCHEMA[0], 'half_angle_deg': CONE_SCHEMA[1]}[field_]
    return Param(template.name.replace('<name>', name), template.type, None, template.unit,
                 template.doc, template.nodes, template.length, template.check)


# --- type checking, shared with the nodes --------------------------------------------------------
def check_value(p, value):
    """(converted value, None) or (None, reason) for a value of parameter p, ROS-strict."""
    t = p.type
    if t == 'double':
        if isinstance(value, bool) or not isinstance(value, float):
            hint = ' (write %r)' % float(value) if isinstance(value, int) and not isinstance(
                value, bool) else ''
            return None, 'expected a double, got %s%s' % (_describe(value), hint)
        if not math.isfinite(value):
            return None, 'must be finite (got %r)' % value
        out = value
    elif t == 'double_array':
        if not isinstance(value, (list, tuple, np.ndarray)) or not all(
                isinstance(v, float) for v in value):
            hint = ''
            if isinstance(value, (list, tuple)) and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                hint = ' (write every element as a float, e.g. %s)' % [float(v) for v in value]
            return None, 'expected an array of doubles, got %s%s' % (_describe(value), hint)
        out = np.array(value, dtype=float)
        if p.length and out.size != p.length:
            return None, 'expected %d values, got %d' % (p.length, out.size)
        if not np.all(np.isfinite(out)):
            return None, 'must be finite'
    elif t == 'bool':
        if not isinstance(value, bool):
            return None, 'expected true or false, got %s' % _describe(value)
        out = value
    elif t == 'string':
        if not isinstance(value, str):
            return None, 'expected a string, got %s' % _describe(value)
        if p.choices and value not in p.choices:
            return None, 'must be one of %s (got %r)' % (', '.join(p.choices), value)
        out = value
    elif t == 'string_array':
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            return None, 'expected an array of strings, got %s' % _describe(value)
        out = list(value)
    else:  # pragma: no cover - schema error
        raise AssertionError('unknown parameter type %r' % t)
    reason = p.check(out) if p.check else None
    return (None, reason) if reason else (out, None)


def _describe(value):
    return '%s %r' % (type(value).__name__, value)


# --- resolving a node's parameters ---------------------------------------------------------------
def resolve(node, overrides):
    """Merge overrides (flat dict) into node's defaults and check everything.

    Returns a flat dict of converted values (cone keys included). Raises ConfigError listing every
    problem: wrong types, failed checks, unknown parameters, cones without their parameters.
    """
    errors = []
    known_elsewhere = {p.name for p in SCHEMA}
    out = {}
    for p in schema_for(node):
        value, reason = check_value(p, overrides.get(p.name, p.default))
        if reason:
            errors.append((p.name, reason))
        else:
            out[p.name] = value
    names = out.get('cones.names', []) if node == CONTROLLER else []
    for name in names:
        if not _CONE_NAME.match(name):
            errors.append(('cones.names', 'cone name %r must be a letter followed by letters, '
                           'digits or _' % name))
            continue
        for field_ in ('axis', 'half_angle_deg'):
            p = cone_param(name, field_)
            if p.name not in overrides:
                errors.append((p.name, 'missing (cone %r is in cones.names)' % name))
                continue
            value, reason = check_value(p, overrides[p.name])
            if reason:
                errors.append((p.name, reason))
            else:
                out[p.name] = value
    if len(set(names)) != len(names):
        errors.append(('cones.names', 'names must be unique (got %s)' % names))
    for key in overrides:
        if key in known_elsewhere:
            continue
        m = _CONE_KEY.match(key)
        if m:
            if node == CONTROLLER and m.group(1) not in names:
                errors.append((key, 'cone %r is not in cones.names %s' % (m.group(1), names)))
            continue
        errors.append((key, 'unknown parameter' + _suggest(key)))
    if errors:
        raise ConfigError(errors)
    return out


def _suggest(key):
    import difflib
    close = difflib.get_close_matches(key, list(BY_NAME), n=1)
    return ' (did you mean %r?)' % close[0] if close else ''


# --- building the core's configuration objects ---------------------------------------------------
def cone_set(values):
    """The ConeSet described by resolved controller parameters."""
    names = values['cones.names']
    return ConeSet(values['sensor_axis'],
                   [values['cones.%s.axis' % n] for n in names] or np.zeros((0, 3)),
                   np.radians([values['cones.%s.half_angle_deg' % n] for n in names]),
                   values['alpha'], math.radians(values['barrier_floor_deg']), names)


def controller_config(values):
    """ControllerConfig from resolved controller parameters (see ``resolve``)."""
    return ControllerConfig(
        k_R=values['k_R'], k_Omega=values['k_Omega'], k_Delta=values['k_Delta'], c=values['c'],
        G=values['G'], cones=cone_set(values), inertia=values['inertia'].reshape(3, 3),
        mass=values['mass'], cog_offset=values['cog_offset'], gravity=values['gravity'],
        adaptive=values['adaptive'], gravity_compensation=values['gravity_compensation'],
        disturbance_model=values['disturbance_model'], delta_bar_max=values['delta_bar_max'],
        cog_estimate_max=values['cog_estimate_max'])


def setpoint_rotation(values):
    """R_d of the resolved controller parameters."""
    return so3.quat_to_rot(values['setpoint'])


def plant_config(values):
    """PlantConfig from resolved sim parameters."""
    return PlantConfig(
        inertia=values['inertia'].reshape(3, 3), mass=values['mass'],
        cog_offset=values['cog_offset'], gravity=values['gravity'],
        disturbance=Disturbance(constant=values['disturbance.constant'],
                                amplitude=values['disturbance.amplitude'],
                                frequency=values['disturbance.frequency']))


# --- ROS 2 parameter files -----------------------------------------------------------------------
def flatten(tree, prefix=''):
    """Nested dicts -> one dict with dotted keys, as ROS 2 reads parameter files."""
    out = {}
    for key, value in tree.items():
        name = '%s.%s' % (prefix, key) if prefix else str(key)
        if isinstance(value, dict):
            out.update(flatten(value, name))
        else:
            out[name] = value
    return out


def load_parameter_file(path):
    """Read a ROS 2 parameter YAML file: {node name or '/**': flat parameter dict}."""
    with open(path) as f:
        doc = yaml.safe_load(f) or {}
    if not isinstance(doc, dict):
        raise ConfigError([(str(path), 'not a ROS 2 parameter file (top level must be a mapping)')])
    sections = {}
    for node, body in doc.items():
        if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
            raise ConfigError([(str(node), 'section needs a ros__parameters mapping')])
        sections[str(node)] = flatten(body['ros__parameters'])
    return sections


def node_overrides(sections, node):
    """The flat overrides node gets from a parameter file: '/**' first, then its own section.

    Parameters in '/**' that node does not read are dropped (ROS ignores them too); its own section
    must contain only its parameters.
    """
    own = {p.name for p in schema_for(node)}
    merged = {k: v for k, v in sections.get('/**', {}).items()
              if k in own or (node == CONTROLLER and _CONE_KEY.match(k))
              or k not in BY_NAME and not _CONE_KEY.match(k)}
    for key in (node, '/' + node):
        merged.update(sections.get(key, {}))
    return merged


def markdown_table():
    """The README's parameter table."""
    rows = ['| parameter | node | type | default | unit | meaning |', '|---|---|---|---|---|---|']
    for p in SCHEMA + CONE_SCHEMA:
        default = '(required)' if p.default is None else _fmt_default(p.default)
        rows.append('| `%s` | %s | %s%s | %s | %s | %s |' % (
            p.name, ', '.join(p.nodes), p.type, '[%d]' % p.length if p.length else '', default,
            p.unit, p.doc))
    return '\n'.join(rows)


def _fmt_default(value):
    if isinstance(value, bool):
        return '`%s`' % str(value).lower()
    if isinstance(value, str):
        return '`%s`' % value if value else '`""`'
    if isinstance(value, list) and len(value) > 4:
        return '(lab hexrotor)' if value == LAB_INERTIA else '`%s`' % value
    return '`%s`' % (value,)


README_MARKERS = ('<!-- params:begin -->', '<!-- params:end -->')


def update_readme(path):
    """Replace the table between README_MARKERS in the file at path; True if it changed."""
    with open(path) as f:
        text = f.read()
    begin, end = README_MARKERS
    i, j = text.index(begin) + len(begin), text.index(end)
    new = text[:i] + '\n' + markdown_table() + '\n' + text[j:]
    if new != text:
        with open(path, 'w') as f:
            f.write(new)
    return new != text


if __name__ == '__main__':
    if sys.argv[1:2] == ['--write-readme']:
        print('updated' if update_readme(sys.argv[2]) else 'up to date')
    else:
        sys.stdout.write(markdown_table() + '\n')
