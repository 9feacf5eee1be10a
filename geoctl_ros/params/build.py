"""Building the core's and the simulator's objects from resolved parameters, with the checks
that span several parameters (a set point against the cones, a thrust limit against the curve, an
airframe that must produce every moment).
"""
import collections
from dataclasses import dataclass, fields, replace
import math
from typing import Any, Dict, List, Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.actuation.airframe import (
    AirframeError,
    RotorGeometry,
    effectiveness,
    tilted_ring,
)
from geoctl_ros.core.actuation.allocation import Allocator
from geoctl_ros.core.actuation.motors import Mixer, ThrustCurve
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.quaternions import quaternion_problem
from geoctl_ros.core.law.brake import brake_authority, unmodelled_acceleration
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.control import AttitudeController, ControllerConfig
from geoctl_ros.core.sensors.consistency import AgreementSettings
from geoctl_ros.core.sensors.frames import InputFrames
from geoctl_ros.core.supervisor.loop_types import LoopSettings
from geoctl_ros.core.supervisor.safety import SetpointSchedule
from geoctl_ros.params.param import ConfigError
from geoctl_ros.params.schema import BY_NAME
from geoctl_ros.params.validate import check_value

MOTOR_A_MIN = 1e-12     # N: the thrust curve's a, at least (a denormal overflowed its inverse)


def cone_set(values: dict) -> ConeSet:
    """The ConeSet described by resolved controller parameters."""
    names = values['cones.names']
    return ConeSet(values['sensor_axis'],
                   [values['cones.%s.axis' % n] for n in names] or np.zeros((0, 3)),
                   np.radians([values['cones.%s.half_angle_deg' % n] for n in names]),
                   values['alpha'], math.radians(values['barrier_floor_deg']), names,
                   math.radians(values['cone_guard_deg']))


def cone_values(cones: Any) -> dict:
    """The controller parameters of cones [(axis, half-angle deg)], named c1, c2, ...: what
    ``cone_set`` reads back.
    """
    names = ['c%d' % (i + 1) for i in range(len(cones))]
    values: Dict[str, Any] = {'cones.names': names}
    for name, (axis, half_angle) in zip(names, cones):
        values['cones.%s.axis' % name] = axis
        values['cones.%s.half_angle_deg' % name] = half_angle
    return values


@dataclass(frozen=True)
class GainSet:
    """The gains a tuning searches (``geoctl_ros.campaign.tune``), as controller parameters."""

    k_R: float
    k_Omega: float
    c: float
    k_Delta: float
    k_Delta_cog: float
    guidance_lookahead_deg: float

    @classmethod
    def names(cls) -> Tuple[str, ...]:
        """Their parameters' names."""
        return tuple(f.name for f in fields(cls))

    def overrides(self) -> Dict[str, float]:
        """The controller parameters they set."""
        return {f.name: float(getattr(self, f.name)) for f in fields(self)}


def gain_set(values: dict) -> GainSet:
    """The GainSet of (resolved or overriding) controller parameters."""
    return GainSet(*(float(values[name]) for name in GainSet.names()))


def controller_config(values: dict) -> ControllerConfig:
    """ControllerConfig from resolved controller parameters (see ``resolve``)."""
    return ControllerConfig(
        k_R=values['k_R'], k_Omega=values['k_Omega'], k_Delta=values['k_Delta'], c=values['c'],
        k_Delta_cog=values['k_Delta_cog'],
        G=values['G'], cones=cone_set(values), inertia=values['inertia'].reshape(3, 3),
        mass=values['mass'], cog_offset=values['cog_offset'], gravity=values['gravity'],
        adaptive=values['adaptive'], gravity_compensation=values['gravity_compensation'],
        disturbance_model=values['disturbance_model'], delta_bar_max=values['delta_bar_max'],
        cog_estimate_max=values['cog_estimate_max'],
        unmodelled_moment_max=values['unmodelled_moment_max'],
        blind_guard_max=math.radians(values['blind_guard_max_deg']), law=values['law'],
        cbf_rate=values['cbf_rate'], cbf_moment_bound=values['cbf_moment_bound'],
        approach_brake=values['approach_brake'],
        brake_acceleration=values['brake_acceleration'],
        attitude_noise=math.radians(values['attitude_noise_deg']),
        gyro_noise=values['gyro_noise'], tilt_max=math.radians(values['joint_tilt_max_deg']),
        motor_lag=values['motor_lag_compensation'],
        guidance_lookahead=math.radians(values['guidance_lookahead_deg']),
        guidance_clearance=math.radians(values['guidance_clearance_deg']))


_RECORDS: dict = {}


def settings(values: dict, prefix: str = '') -> Any:
    """Resolved parameters as a read-only record with one attribute per parameter (dots as
    underscores, ``prefix`` such as 'mavlink.' dropped): what a node reads once, at
    configuration, by name instead of by indexing the parameter dict. The names are the schema's,
    so there is no second list of them.
    """
    names = tuple(k[len(prefix):] if k.startswith(prefix) else k for k in values)
    record = _RECORDS.get(names)
    if record is None:
        record = _RECORDS[names] = collections.namedtuple(
            'Settings', [n.replace('.', '_') for n in names])
    return record(*values.values())


def loop_settings(values: dict) -> LoopSettings:
    """The LoopSettings of resolved controller parameters."""
    return LoopSettings(**{f.name: values[f.name] for f in fields(LoopSettings)})


def input_frames(values: dict) -> InputFrames:
    """The inputs' conventions (core.sensors.frames) of resolved controller (or sim) parameters;
    the sim's have no gyro_bias (its bias is the truth, noise.gyro_bias).
    """
    return InputFrames.of(values['pose_world_frame'], values['body_frame'],
                          values['marker_rotation_deg'], values['imu_rotation_deg'],
                          values.get('gyro_bias', (0.0, 0.0, 0.0)))


@dataclass(frozen=True)
class EmulatedImu:
    """The IMU (and motion capture) the sim emulates: their conventions, where the IMU sits (m
    from the pivot, body) and its accelerometer's noise (m/s^2), and the world's gravity.
    """

    frames: InputFrames
    position: np.ndarray
    force_noise: float
    gravity: np.ndarray


def emulated_imu(values: dict) -> EmulatedImu:
    """The EmulatedImu of resolved sim parameters."""
    return EmulatedImu(input_frames(values), np.array(values['imu_position'], dtype=float),
                       float(values['noise.specific_force']),
                       np.array(values['gravity'], dtype=float))


def agreement_settings(values: dict) -> AgreementSettings:
    """The sensor checks' settings (core.sensors.consistency) of resolved controller parameters."""
    return AgreementSettings(values['consistency_checks'],
                             math.radians(values['attitude_noise_deg']), values['gyro_noise'],
                             values['accelerometer_noise'],
                             math.radians(values['alignment_tolerance_deg']),
                             np.array(values['gravity'], dtype=float))


def input_timeouts(values: dict) -> Tuple[float, float]:
    """(imu_timeout, pose_timeout) (s) of controller parameters as far as they are known (a
    ground station's view of them), the schema's defaults for the rest.
    """
    imu, pose = BY_NAME['imu_timeout'], BY_NAME['pose_timeout']
    return (float(values.get(imu.name, imu.default)), float(values.get(pose.name, pose.default)))


def setpoint_rotation(values: dict) -> np.ndarray:
    """R_d of the resolved controller parameters."""
    return so3.quat_to_rot(values['setpoint'])


# The parameter a set point is sent as at run time (the setpoint command, a ground station's
# SET_ATTITUDE_TARGET through the bridge): the controller takes it alone as a set point.
SETPOINT = 'setpoint'


def setpoint_change(values: dict, changed: set) -> Optional[np.ndarray]:
    """A run-time change of the ``setpoint`` parameter alone (a command's, a ground station's):
    its quaternion (x, y, z, w) checked by the schema (raises ConfigError with the reason); None
    when the change names any other parameter (it is a reconfiguration).
    """
    if changed != {SETPOINT}:
        return None
    q, problem = check_value(BY_NAME[SETPOINT], values[SETPOINT])
    if problem:
        raise ConfigError([(SETPOINT, problem)])
    return q


@dataclass
class ControllerSetup:
    """Everything a controller (node or headless) builds from its parameters."""

    config: ControllerConfig
    mixer: Mixer
    setpoint: np.ndarray         # R_d
    schedule: SetpointSchedule
    loop: LoopSettings           # the loop's and the node's own settings
    frames: InputFrames          # the inputs' conventions
    agreement: AgreementSettings   # the sensor checks


def controller_setup(values: dict) -> 'ControllerSetup':
    """Build and cross-check a controller from resolved parameters; ConfigError on any problem,
    including a set point (or scheduled one) that puts the sensor in a cone.
    """
    mix = mixer(values)
    config = controller_config(values)
    errors = []
    polytope = mix.allocator.moment_polytope(mix.collective_thrust)
    authority = brake_authority(polytope.vertices, so3.inverse3(config.J), config.m_rho,
                                config.gravity, config.tilt_max, config.cones.r)
    asked = values['brake_acceleration']
    if authority <= 0.0:
        errors.append(('brake_acceleration', "the rotors cannot decelerate along every cone's "
                       "opening direction with gravity at the joint's stops (%.1f rad/s^2 at "
                       'best): thrust limits, mass or centre of mass out of reach'
                       % authority))
    elif asked > authority:
        errors.append(('brake_acceleration', '%.1f rad/s^2 is more than the rotors can make along '
                       "every cone's opening direction with gravity at the joint's stops "
                       '(%.1f rad/s^2)' % (asked, authority)))
    config = replace(config, moment_limits=polytope, brake_acceleration=asked or authority)
    a_u = unmodelled_acceleration(config.cbf_moment_bound, config.J)
    if config.approach_brake and config.brake_acceleration <= a_u:
        errors.append(('cbf_moment_bound', 'the approach brake needs the rotors to out-brake the '
                       'unlearnt moment: a_u %.1f rad/s^2 against %.1f'
                       % (a_u, config.brake_acceleration)))
    probe = AttitudeController(config)
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
            reason = quaternion_problem(q)
            R = None
            if reason is None:
                R = so3.quat_to_rot(q)
                reason = probe.setpoint_problem(R)
            if reason:
                errors.append(('setpoint_schedule.quaternions',
                               'set point %d: %s' % (k + 1, reason)))
            rotations.append(R)
    for stream, timeout in (('pose', 'pose_timeout'), ('imu', 'imu_timeout')):
        limit = values[stream + '_ride_through']
        if 0.0 < limit < values[timeout]:
            errors.append((stream + '_ride_through', 'must be 0 or at least %s (%g s)'
                           % (timeout, values[timeout])))
    if errors:
        raise ConfigError(errors)
    # (every rotation is one here: a set point without one raised ConfigError above)
    return ControllerSetup(config, mix, R_d,
                           SetpointSchedule(times, cast(List[so3.FloatArray], rotations)),
                           loop_settings(values), input_frames(values),
                           agreement_settings(values))


def airframe(values: dict) -> Tuple[RotorGeometry, ThrustCurve, List[int]]:
    """(RotorGeometry, ThrustCurve, failed rotor numbers) of resolved parameters; raises
    ConfigError naming the parameter for a layout or curve that does not fit together.
    """
    errors = []
    if values['rotors.layout'] == 'tilted_ring':
        geometry = tilted_ring(values['rotors.count'], values['rotors.arm_length'],
                               values['rotors.tilt_deg'], values['rotors.first_azimuth_deg'],
                               values['rotors.height'], values['rotors.yaw_coefficient'])
    else:
        spins = np.array(values['rotors.spins'], dtype=float)
        n = len(spins)
        if n == 0:
            raise ConfigError([('rotors.spins', 'rotors.layout custom needs rotors.positions, '
                                'rotors.axes and rotors.spins (one spin per rotor)')])
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
    coeffs: Dict[str, Any] = {}
    for k in 'abc':
        arr = values['motor.' + k]
        if arr.size not in (1, n):
            errors.append(('motor.' + k, 'expected 1 value or %d (one per rotor), got %d'
                           % (n, arr.size)))
        coeffs[k] = np.broadcast_to(arr, (n,)).copy() if arr.size in (1, n) else None
    if not errors and np.any(coeffs['a'] < MOTOR_A_MIN):
        errors.append(('motor.a', 'must be at least %g (thrust must grow with the command; the '
                       "curve's inverse divides by it)" % MOTOR_A_MIN))
    if errors:
        raise ConfigError(errors)
    curve = ThrustCurve(coeffs['a'], coeffs['b'], coeffs['c'], values['motor.voltage_scale'],
                        values['motor.command_max'])
    return geometry, curve, sorted(set(values['rotors.failed']))


def mixer(values: dict) -> Mixer:
    """The Mixer (allocation + thrust curve) of resolved controller parameters."""
    geometry, curve, failed = airframe(values)
    top = float(np.min(curve.max_thrust()))
    if values['thrust_max'] > top:
        raise ConfigError([('thrust_max', '%.3g N is more than the thrust curve gives at '
                            'motor.command_max (%.3g N)' % (values['thrust_max'], top))])
    if values['thrust_min'] >= values['thrust_max']:
        raise ConfigError([('thrust_min', 'must be below thrust_max (%g)' % values['thrust_max'])])
    try:
        allocator = Allocator(effectiveness(geometry, values['cog_offset']), values['thrust_min'],
                              values['thrust_max'], failed)
    except AirframeError as e:
        raise ConfigError([('rotors', str(e))]) from None
    collective = values['collective_thrust'] or values['mass'] * float(
        np.linalg.norm(values['gravity']))
    # the rotors must carry the collective thrust with no moment at all (else they make no
    # moment unsaturated: the moment polytope is empty)
    shares = collective * allocator.base_share
    if (shares.max() > allocator.hi - allocator.INSET
            or shares.min() < allocator.lo + allocator.INSET):
        raise ConfigError([('thrust_max' if shares.max() > allocator.hi - allocator.INSET
                            else 'thrust_min',
                            'the rotors cannot carry the collective thrust %.3g N within '
                            'thrust_min..thrust_max (%.3g..%.3g N): their shares of it are '
                            '%.3g..%.3g N' % (collective, allocator.lo, allocator.hi,
                                              shares.min(), shares.max()))])
    return Mixer(allocator, curve, collective, values['motor_lag_compensation'])
