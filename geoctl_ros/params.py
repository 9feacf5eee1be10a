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


def _ring_defaults():
    from geoctl_ros.airframe import tilted_ring
    g = tilted_ring()
    return ([round(float(v), 6) for v in g.positions.ravel()],
            [round(float(v), 6) for v in g.axes.ravel()], [int(v) for v in g.spins])


_RING_POSITIONS, _RING_AXES, _RING_SPINS = _ring_defaults()


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
    _p('pose_timeout', 'double', 0.1, 's', 'pose older than this (by receipt) is stale',
       CONTROLLER, check=_positive),
    _p('imu_timeout', 'double', 0.05, 's', 'angular velocity older than this is stale',
       CONTROLLER, check=_positive),
    _p('pose_ride_through', 'double', 0.5, 's',
       'a pose gap up to this long is flown through on the gyro-propagated attitude; longer: '
       'failsafe (0: failsafe at pose_timeout)', CONTROLLER, check=_nonnegative),
    _p('imu_ride_through', 'double', 0.25, 's',
       'an angular-velocity gap up to this long is flown through on rates from successive poses; '
       'longer: failsafe (0: failsafe at imu_timeout)', CONTROLLER, check=_nonnegative),
    _p('pose_rate_window', 'double', 0.05, 's',
       'time between the two poses that give the rate during an angular-velocity gap',
       CONTROLLER, check=lambda v: None if 0.0 < v <= 0.5 else 'must be in (0, 0.5] s'),
    _p('max_angular_velocity', 'double', 100.0, 'rad/s',
       'gyro readings faster than this are refused', CONTROLLER, check=_positive),
    _p('setpoint_schedule.times', 'double_array', [], 's',
       'optional: times after arming at which the scheduled set points take over', CONTROLLER),
    _p('setpoint_schedule.quaternions', 'double_array', [], '-',
       'optional: the scheduled set points, 4 values (x, y, z, w) per time', CONTROLLER),
    _p('frame_id', 'string', 'base_link', '-', 'body frame id on stamped outputs', BOTH),
    # Physical model, read by the controller (its model) and the simulator (the truth).
    _p('inertia', 'double_array', LAB_INERTIA, 'kg m^2',
       'inertia about the centre of mass, 9 values row-major', BOTH, length=9, check=_inertia),
    _p('mass', 'double', 1.26, 'kg', 'mass', BOTH, check=_positive),
    _p('cog_offset', 'double_array', [0.0, 0.0, 0.1], 'm',
       'pivot -> centre of mass, body frame (z up: above the pivot)', BOTH, length=3),
    _p('gravity', 'double_array', [0.0, 0.0, -9.81], 'm/s^2', 'gravity vector, world frame',
       BOTH, length=3),
    # Airframe: rotor geometry (controller: allocation; sim: the true rotors).
    _p('rotors.layout', 'string', 'tilted_ring', '-',
       'tilted_ring (from the five parameters below) or custom (rotors.positions/axes/spins)',
       BOTH, choices=('tilted_ring', 'custom')),
    _p('rotors.count', 'integer', 6, '-', 'tilted_ring: number of rotors, numbered clockwise '
       'from above', BOTH, check=lambda v: None if 3 <= v <= 12 else 'must be 3 to 12'),
    _p('rotors.arm_length', 'double', 0.31, 'm', 'tilted_ring: centre of mass to rotor', BOTH,
       check=_positive),
    _p('rotors.tilt_deg', 'double', 15.0, 'deg', 'tilted_ring: tangential tilt of each thrust '
       'axis, alternating with the spin', BOTH,
       check=lambda v: None if 0.0 <= v < 60.0 else 'must be in [0, 60) degrees'),
    _p('rotors.first_azimuth_deg', 'double', 0.0, 'deg', 'tilted_ring: azimuth of rotor 1 from '
       'the nose, counter-clockwise from above', BOTH),
    _p('rotors.height', 'double', 0.0, 'm', 'tilted_ring: rotor plane above the centre of mass',
       BOTH),
    _p('rotors.positions', 'double_array', _RING_POSITIONS, 'm',
       'custom: rotor positions from the centre of mass, 3 per rotor', BOTH),
    _p('rotors.axes', 'double_array', _RING_AXES, '-',
       'custom: rotor thrust axes (normalised), 3 per rotor', BOTH),
    _p('rotors.spins', 'integer_array', _RING_SPINS, '-',
       'custom: +1 counter-clockwise (seen along the thrust axis), -1 clockwise', BOTH,
       check=lambda v: None if v and all(x in (-1, 1) for x in v) else 'each must be 1 or -1'),
    _p('rotors.yaw_coefficient', 'double', 0.1, 'm',
       'reaction moment per newton of thrust', BOTH, check=_nonnegative),
    _p('rotors.failed', 'integer_array', [], '-', 'rotor numbers (1-based) to treat as dead',
       BOTH),
    # Motors: thrust curve f = a x^2 + b x + c, x = voltage_scale * command.
    _p('motor.a', 'double_array', [6.0252e-5], 'N', 'thrust curve a (1 value, or 1 per rotor)',
       BOTH),
    _p('motor.b', 'double_array', [8.4086e-3], 'N', 'thrust curve b (1 value, or 1 per rotor)',
       BOTH),
    _p('motor.c', 'double_array', [-2.5194e-2], 'N', 'thrust curve c (1 value, or 1 per rotor)',
       BOTH),
    _p('motor.voltage_scale', 'double', 1.1261, '-',
       'battery-voltage scale of the command (12.5 V / 11.1 V)', BOTH, check=_positive),
    _p('motor.command_max', 'integer', 240, '-', 'largest ESC command', BOTH,
       check=lambda v: None if 1 <= v <= 65535 else 'must be in 1..65535'),
    _p('thrust_min', 'double', 0.2, 'N', 'least thrust per rotor while armed', CONTROLLER,
       check=_nonnegative),
    _p('thrust_max', 'double', 6.5, 'N', 'most thrust per rotor (<= the curve at command_max)',
       CONTROLLER, check=_positive),
    _p('collective_thrust', 'double', 0.0, 'N',
       'thrust along body z to hold while armed; 0 = m * |gravity|', CONTROLLER,
       check=_nonnegative),
    # Simulator.
    _p('actuation', 'string', 'rotors', '-', 'rotors (commands through the motors) or torque '
       '(the controller\'s moment, ideal)', SIM, choices=('rotors', 'torque')),
    _p('motor_time_constant', 'double', 0.04, 's', 'first-order lag of each rotor\'s thrust',
       SIM, check=_positive),
    _p('noise.attitude_deg', 'double', 0.0, 'deg',
       'std dev of measured-attitude noise per axis (motion capture)', SIM, check=_nonnegative),
    _p('noise.angular_velocity', 'double', 0.0, 'rad/s',
       'std dev of gyro noise per axis', SIM, check=_nonnegative),
    _p('noise.gyro_bias', 'double_array', [0.0, 0.0, 0.0], 'rad/s', 'constant gyro bias', SIM,
       length=3),
    _p('noise.seed', 'integer', 0, '-', 'random seed of the noise', SIM),
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
    _p('pose_rate_hz', 'double', 200.0, 'Hz', 'sim node: rate of pose (motion capture)', SIM,
       check=_rate),
    _p('imu_rate_hz', 'double', 100.0, 'Hz', 'sim node: rate of imu', SIM, check=_rate),
    _p('publish_clock', 'bool', False, '-', 'sim node: publish /clock (for use_sim_time)', SIM),
    _p('real_time_factor', 'double', 1.0, '-', 'sim node: simulated seconds per wall second',
       SIM, check=lambda v: None if 0.0 < v <= 20.0 else 'must be in (0, 20]'),
    _p('command_timeout', 'double', 0.1, 's',
       'sim node: motors stop when motor_commands are older than this', SIM, check=_positive),
    _p('world_frame_id', 'string', 'world', '-', 'world frame id of pose messages', SIM),
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
CONE_KEY = re.compile(r'^cones\.([^.]+)\.(axis|half_angle_deg)$')
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
    elif t == 'integer':
        if isinstance(value, bool) or not isinstance(value, int):
            return None, 'expected an integer, got %s' % _describe(value)
        out = value
    elif t == 'integer_array':
        if not isinstance(value, (list, tuple)) or not all(
                isinstance(v, int) and not isinstance(v, bool) for v in value):
            return None, 'expected an array of integers, got %s' % _describe(value)
        out = list(value)
        if p.length and len(out) != p.length:
            return None, 'expected %d values, got %d' % (p.length, len(out))
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
def resolve(node, overrides, staged_cones=False):
    """Merge overrides (flat dict) into node's defaults and check everything.

    Returns a flat dict of converted values (cone keys included). Raises ConfigError listing every
    problem: wrong types, failed checks, unknown parameters, cones without their parameters.
    staged_cones accepts parameters of cones not (yet) in cones.names, as a running node must while
    a user adds a cone one parameter at a time; files are read without it, to catch typos.
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
        m = CONE_KEY.match(key)
        if m:
            if node == CONTROLLER and m.group(1) not in names and not staged_cones:
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


@dataclass
class ControllerSetup:
    """Everything a controller (node or headless) builds from its parameters."""

    config: ControllerConfig
    mixer: object                # geoctl_ros.airframe.Mixer
    setpoint: np.ndarray         # R_d
    schedule: object             # geoctl_ros.safety.SetpointSchedule
    values: dict


def controller_setup(values):
    """Build and cross-check a controller from resolved parameters; ConfigError on any problem,
    including a set point (or scheduled one) that puts the sensor in a cone."""
    from geoctl_ros.control import AttitudeController
    from geoctl_ros.safety import SetpointSchedule
    config = controller_config(values)
    mix = mixer(values)
    probe = AttitudeController(config)
    errors = []
    R_d = setpoint_rotation(values)
    problem = probe.setpoint_problem(R_d)
    if problem:
        errors.append(('setpoint', problem))
    times, quats = values['setpoint_schedule.times'], values['setpoint_schedule.quaternions']
    rotations = []
    if quats.size != 4 * times.size:
        errors.append(('setpoint_schedule.quaternions', 'expected 4 values per time (%d times), '
                       'got %d' % (times.size, quats.size)))
    elif np.any(np.diff(times) <= 0.0) or (times.size and times[0] < 0.0):
        errors.append(('setpoint_schedule.times', 'must be increasing and not negative'))
    else:
        for k, q in enumerate(quats.reshape(-1, 4)):
            reason = _unit_quaternion(q)
            R = so3.quat_to_rot(q) if reason is None else None
            reason = reason or probe.setpoint_problem(R)
            if reason:
                errors.append(('setpoint_schedule.quaternions', 'set point %d: %s' % (k + 1, reason)))
            rotations.append(R)
    for stream, timeout in (('pose', 'pose_timeout'), ('imu', 'imu_timeout')):
        limit = values[stream + '_ride_through']
        if 0.0 < limit < values[timeout]:
            errors.append((stream + '_ride_through', 'must be 0 or at least %s (%g s)'
                           % (timeout, values[timeout])))
    if errors:
        raise ConfigError(errors)
    return ControllerSetup(config, mix, R_d, SetpointSchedule(times, rotations), values)


def airframe(values):
    """(RotorGeometry, ThrustCurve, failed rotor numbers) of resolved parameters; raises
    ConfigError naming the parameter for a layout or curve that does not fit together."""
    from geoctl_ros.airframe import RotorGeometry, ThrustCurve, tilted_ring
    errors = []
    if values['rotors.layout'] == 'tilted_ring':
        geometry = tilted_ring(values['rotors.count'], values['rotors.arm_length'],
                               values['rotors.tilt_deg'], values['rotors.first_azimuth_deg'],
                               values['rotors.height'], values['rotors.yaw_coefficient'])
    else:
        spins = np.array(values['rotors.spins'], dtype=float)
        n = len(spins)
        pos, axes = values['rotors.positions'], values['rotors.axes']
        for name, arr in (('rotors.positions', pos), ('rotors.axes', axes)):
            if arr.size != 3 * n:
                errors.append((name, 'expected 3 values per rotor (%d rotors in rotors.spins), '
                               'got %d' % (n, arr.size)))
        if errors:
            raise ConfigError(errors)
        axes = axes.reshape(n, 3)
        norms = np.linalg.norm(axes, axis=1)
        if np.any(norms < 1e-9):
            raise ConfigError([('rotors.axes', 'rotor %d has a zero thrust axis'
                                % (int(np.argmin(norms)) + 1))])
        geometry = RotorGeometry(pos.reshape(n, 3), axes / norms[:, None], spins,
                                 values['rotors.yaw_coefficient'])
    n = geometry.count
    for v in values['rotors.failed']:
        if not 1 <= v <= n:
            errors.append(('rotors.failed', 'rotor %d does not exist (1..%d)' % (v, n)))
    coeffs = {}
    for k in 'abc':
        arr = values['motor.' + k]
        if arr.size not in (1, n):
            errors.append(('motor.' + k, 'expected 1 value or %d (one per rotor), got %d'
                           % (n, arr.size)))
        coeffs[k] = np.broadcast_to(arr, (n,)).copy() if arr.size in (1, n) else None
    if not errors and np.any(coeffs['a'] <= 0.0):
        errors.append(('motor.a', 'must be > 0 (thrust must grow with the command)'))
    if errors:
        raise ConfigError(errors)
    curve = ThrustCurve(coeffs['a'], coeffs['b'], coeffs['c'], values['motor.voltage_scale'],
                        values['motor.command_max'])
    return geometry, curve, sorted(set(values['rotors.failed']))


def mixer(values):
    """The Mixer (allocation + thrust curve) of resolved controller parameters."""
    from geoctl_ros.airframe import AirframeError, Allocator, Mixer
    geometry, curve, failed = airframe(values)
    top = float(np.min(curve.max_thrust()))
    if values['thrust_max'] > top:
        raise ConfigError([('thrust_max', '%.3g N is more than the thrust curve gives at '
                            'motor.command_max (%.3g N)' % (values['thrust_max'], top))])
    if values['thrust_min'] >= values['thrust_max']:
        raise ConfigError([('thrust_min', 'must be below thrust_max (%g)' % values['thrust_max'])])
    try:
        allocator = Allocator(geometry, values['cog_offset'], values['thrust_min'],
                              values['thrust_max'], failed)
    except AirframeError as e:
        raise ConfigError([('rotors', str(e))]) from None
    collective = values['collective_thrust'] or values['mass'] * float(
        np.linalg.norm(values['gravity']))
    return Mixer(allocator, curve, collective)


def testbed_sim(values):
    """The TestbedSim of resolved sim parameters, at its initial state."""
    from geoctl_ros.testbed import RotorActuator, TestbedSim
    actuator = None
    if values['actuation'] == 'rotors':
        geometry, curve, failed = airframe(values)
        actuator = RotorActuator(geometry, values['cog_offset'], curve,
                                 values['motor_time_constant'], failed)
    return TestbedSim(plant_config(values), so3.quat_to_rot(values['initial_attitude']),
                      values['initial_angular_velocity'], actuator,
                      math.radians(values['noise.attitude_deg']),
                      values['noise.angular_velocity'], values['noise.gyro_bias'],
                      values['noise.seed'])


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
    try:
        with open(path) as f:
            doc = yaml.safe_load(f) or {}
    except OSError as e:
        raise ConfigError([(str(path), 'cannot be read (%s)' % (e.strerror or e))]) from None
    except yaml.YAMLError as e:
        mark, context = getattr(e, 'problem_mark', None), getattr(e, 'context_mark', None)
        where = ' at line %d, column %d' % (mark.line + 1, mark.column + 1) if mark else ''
        if context is not None and getattr(e, 'context', None):
            where += ' (%s at line %d)' % (e.context, context.line + 1)
        what = getattr(e, 'problem', None) or str(e).splitlines()[0]
        raise ConfigError([(str(path), 'not valid YAML%s: %s' % (where, what))]) from None
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
              if k in own or (node == CONTROLLER and CONE_KEY.match(k))
              or k not in BY_NAME and not CONE_KEY.match(k)}
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
