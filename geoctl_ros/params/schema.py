"""The one parameter schema: every parameter any part of geoctl_ros reads, declared once.

Each ``Param`` has its ROS 2 type, default, unit, one-line doc, the nodes that read it and a check
(a function returning a reason, or None). The nodes declare their parameters from it
(``geoctl_ros.nodes.ros_params``), the headless runner reads files through it
(``geoctl_ros.params.files``) and the parameter table (docs/parameters.md) is generated from it
(``geoctl_ros.params.readme``). Cones are parameters too: ``cones.names: [a, b]`` plus
``cones.<name>.axis`` and ``cones.<name>.half_angle_deg`` per name (``CONE_SCHEMA``).
"""
from dataclasses import dataclass, replace
import re

import numpy as np

from geoctl_ros.core.control import DISTURBANCE_MODELS, LAWS
from geoctl_ros.core.safety import quaternion_problem
from geoctl_ros.records.bag import TOPICS as _RECORDED

CONTROLLER, SIM, SCENARIO, MAVLINK, RECORD, VIEW, ESC = (
    'controller', 'sim', 'scenario', 'mavlink_bridge', 'record', 'view', 'esc_i2c')
BOTH = (CONTROLLER, SIM)
MOTOR_TEST_COMMAND_MAX = 0.3       # the largest motor-test command (normalised)
MOTOR_TEST_DURATION_MAX = 10.0     # s, the longest motor test
RECORD_TOPICS = tuple(t.name for t in _RECORDED)

# The lab's inertia about the centre of mass is given in its code's forward-right-down body frame;
# in this package's forward-left-up frame (F = diag(1, -1, -1), J_FLU = F J_FRD F) the products
# J12 and J13 change sign and J23 does not.
LAB_INERTIA = [5.5710e-3, -6.1766e-5, 2.5028e-5,
               -6.1766e-5, 5.5757e-3, 1.0068e-5,
               2.5028e-5, 1.0068e-5, 1.0505e-2]


class ConfigError(ValueError):
    """One or more invalid parameters; ``errors`` lists (parameter, reason) pairs."""

    def __init__(self, errors):
        self.errors = list(errors)
        super().__init__('invalid parameters:\n' + '\n'.join(
            '  %s: %s' % (name, reason) for name, reason in self.errors))


# --- checks: each returns a reason (str) or None ------------------------------------------------
def _positive(v):
    return None if v > 0.0 else 'must be > 0 (got %r)' % v


def _nonzero_vector(v):
    # (the largest element, not the norm: a norm of 1e200 overflows)
    return None if np.abs(v).max() > 1e-9 else 'must not be the zero vector'


def _unit_quaternion(q):
    problem = quaternion_problem(q)
    return None if problem is None else 'must be a unit quaternion (x, y, z, w): ' + problem


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


def _addresses(v):
    if not len(v) or any(not 0x03 <= a <= 0x77 for a in v):
        return 'must be 7-bit addresses 0x03 to 0x77'
    return None if len(set(v)) == len(v) else 'must be different'


@dataclass(frozen=True)
class Param:
    """One parameter: ROS type ('double', 'double_array', 'bool', 'string', 'string_array'),
    array length (0: any), default, unit, one-line doc, the nodes that read it, and a check.
    """

    name: str
    type: str
    default: object
    unit: str
    doc: str
    nodes: tuple
    length: int = 0
    check: object = None
    choices: tuple = ()
    lo: object = None       # the least value (of each element, for arrays); None: not a number
    hi: object = None       # the greatest

    @property
    def range_text(self):
        """The documented range, as docs/parameters.md shows it ('' for non-numbers)."""
        if self.lo is None:
            return ''
        return '[%s, %s]' % (_number(self.lo), _number(self.hi))


def _number(x):
    return '%d' % x if isinstance(x, int) else '%g' % x


def _p(name, type_, default, unit, doc, nodes, length=0, check=None, choices=(), lo=None,
       hi=None):
    return Param(name, type_, default, unit, doc, nodes if isinstance(nodes, tuple) else (nodes,),
                 length, check, choices, lo, hi)


SCHEMA = [
    # Controller gains and shape (paper notation).
    _p('k_R', 'double', 0.4, 'N m', 'attitude gain k_R', CONTROLLER, check=_positive,
       lo=0.001, hi=10.0),
    _p('k_Omega', 'double', 0.7, 'N m s', 'angular-velocity gain k_Omega', CONTROLLER,
       check=_positive, lo=0.001, hi=10.0),
    _p('k_Delta', 'double', 0.05, '-', 'adaptation gain k_Delta', CONTROLLER, check=_positive,
       lo=1e-06, hi=10.0),
    _p('c', 'double', 0.1, '1/s', 'weight of e_R in the adaptive law (Prop. 5)', CONTROLLER,
       check=_positive, lo=0.0001, hi=100.0),
    _p('alpha', 'double', 8.0, '-', 'barrier shape alpha (larger: barrier acts closer to a cone)',
       CONTROLLER, check=_positive, lo=0.1, hi=1000.0),
    _p('G', 'double_array', [0.9, 1.1, 1.0], '-',
       'diagonal weights g1, g2, g3 of the attitude error A (distinct, positive)', CONTROLLER,
       length=3, check=_weights, lo=0.0, hi=10.0),
    _p('law', 'string', 'paper', '-',
       'the control law: paper (the barrier of Kulumani, Poole & Lee), geometric (the same '
       'gains, no barrier: a baseline that does not keep the cones) or cbf (geometric, filtered '
       'by a control-barrier-function QP per cone)', CONTROLLER, choices=tuple(LAWS)),
    _p('cbf_rate', 'double', 4.0, '1/s',
       "the cbf law: double pole lambda of h'' + 2 lambda h' + lambda^2 h >= 0 for each cone",
       CONTROLLER, check=_positive, lo=0.1, hi=100.0),
    _p('adaptive', 'bool', True, '-', 'run the adaptive law (else Delta_bar stays 0)', CONTROLLER),
    _p('disturbance_model', 'string', 'constant', '-',
       'regressor W: constant (W = I) or constant+cog (also estimates the error in m*rho)',
       CONTROLLER, choices=tuple(DISTURBANCE_MODELS)),
    _p('delta_bar_max', 'double', 1.0, 'N m',
       'bound on |constant disturbance estimate| (projection); 0 = unbounded', CONTROLLER,
       lo=0.0, hi=10.0),
    _p('cog_estimate_max', 'double', 0.1, 'kg m',
       'bound on |m*rho estimate| of the constant+cog model; 0 = unbounded', CONTROLLER,
       lo=0.0, hi=1.0),
    _p('gravity_compensation', 'bool', True, '-',
       'subtract the modelled gravity moment of the centre-of-mass offset', CONTROLLER),
    _p('sensor_axis', 'double_array', [1.0, 0.0, 0.0], '-',
       'body-fixed sensor axis r (normalised)', CONTROLLER, length=3, check=_nonzero_vector,
       lo=-1000.0, hi=1000.0),
    _p('measurement_delay', 'double', 0.0, 's',
       'latency of the pose and imu chain from capture to receipt, where the stamps do not give '
       'it (age_from_stamps); each tick predicts the measurements forward by their age with the '
       'model and the moments commanded since (docs/safety.md, "Delay")', CONTROLLER,
       lo=0.0, hi=0.05),
    _p('age_from_stamps', 'bool', True, '-',
       "each input's age from its header stamp against this computer's clock (the motion-capture "
       'host and the IMU driver must stamp capture time on a clock synchronised with this one, '
       'e.g. by chrony or PTP, to a few ms); a stamp ahead of this clock by more than 10 ms or '
       'older than 0.5 s at receipt counts as measurement_delay old instead (docs/safety.md, '
       '"Delay"); false: always measurement_delay', CONTROLLER),
    _p('cone_guard_deg', 'double', 0.0, 'deg',
       'the barrier acts on every cone widened by this (margins and violations are still those of '
       'the real cones; set points must clear the widened cone)', CONTROLLER, lo=0.0, hi=10.0),
    _p('blind_guard_max_deg', 'double', 10.0, 'deg',
       'the most the barrier widens a cone for a blind loop (inputs old, or steps later than the '
       'control period): each cone is widened by what the sensor travels towards it in that '
       'time (docs/safety.md, "Delay"); 0 = never', CONTROLLER, lo=0.0, hi=30.0),
    _p('motor_lag_compensation', 'double', 0.0, 's',
       "the motors' thrust time constant the mixer compensates (commands the thrust that brings "
       'a model of the lagged rotors to the allocated thrust by the next step; '
       'docs/campaigns.md, "Safety campaign"); 0 = none', CONTROLLER, lo=0.0, hi=0.5),
    _p('unmodelled_moment_max', 'double', 0.0, 'N m',
       'the moment the controller may have to hold without having learnt it (disturbance plus '
       "model errors); set points whose cones' barriers cannot hold it near the goal are refused "
       '(docs/campaigns.md, "Safety campaign"); 0 = no check', CONTROLLER, lo=0.0, hi=10.0),
    _p('barrier_floor_deg', 'double', 0.25, 'deg',
       'within this angle of a cone boundary the barrier is extended linearly (saturated)',
       CONTROLLER, check=_positive, lo=0.01, hi=10.0),
    _p('cones.names', 'string_array', [], '-',
       'names of the forbidden cones; each needs cones.<name>.axis and .half_angle_deg',
       CONTROLLER),
    _p('setpoint', 'double_array', [0.0, 0.0, 0.0, 1.0], '-',
       'desired attitude R_d as a quaternion (x, y, z, w), world frame', CONTROLLER, length=4,
       check=_unit_quaternion, lo=-1.0, hi=1.0),
    _p('rate_hz', 'double', 100.0, 'Hz', 'control rate', CONTROLLER, lo=1.0, hi=1000.0),
    _p('allow_default_configuration', 'bool', False, '-',
       'arm even when started with no parameter file and no override, on these built-in '
       'defaults (no cones): for deliberate bench use only; otherwise every arm request is '
       'refused', CONTROLLER),
    _p('step_on', 'string', 'timer', '-',
       'what starts a control step: the rate_hz timer, or each accepted imu or pose sample (the '
       'least latency; set rate_hz to that sample rate: the timer then steps only when no sample '
       'came for 1.5 periods, so stale inputs still fail safe)', CONTROLLER,
       choices=('timer', 'imu', 'pose')),
    _p('pose_timeout', 'double', 0.1, 's', 'pose older than this (by receipt) is stale',
       CONTROLLER, check=_positive, lo=0.001, hi=0.5),
    _p('imu_timeout', 'double', 0.05, 's', 'angular velocity older than this is stale',
       CONTROLLER, check=_positive, lo=0.001, hi=0.5),
    _p('pose_ride_through', 'double', 0.5, 's',
       'a pose gap up to this long is flown through on the gyro-propagated attitude; longer: '
       'failsafe (0: failsafe at pose_timeout)', CONTROLLER, lo=0.0, hi=1.0),
    _p('imu_ride_through', 'double', 0.25, 's',
       'an angular-velocity gap up to this long is flown through on rates from successive poses; '
       'longer: failsafe (0: failsafe at imu_timeout)', CONTROLLER, lo=0.0, hi=1.0),
    _p('pose_rate_window', 'double', 0.05, 's',
       'time between the two poses that give the rate during an angular-velocity gap',
       CONTROLLER, check=_positive, lo=0.001, hi=0.5),
    _p('max_angular_velocity', 'double', 100.0, 'rad/s',
       'gyro readings faster than this are refused', CONTROLLER, check=_positive,
       lo=0.1, hi=200.0),
    _p('setpoint_schedule.times', 'double_array', [], 's',
       'optional: times after arming at which the scheduled set points take over', CONTROLLER,
       lo=0.0, hi=3600.0),
    _p('setpoint_schedule.quaternions', 'double_array', [], '-',
       'optional: the scheduled set points, 4 values (x, y, z, w) per time', CONTROLLER,
       lo=-1.0, hi=1.0),
    _p('frame_id', 'string', 'base_link', '-', 'body frame id on stamped outputs', BOTH),
    # Physical model, read by the controller (its model) and the simulator (the truth).
    _p('inertia', 'double_array', LAB_INERTIA, 'kg m^2',
       'inertia about the centre of mass, 9 values row-major', BOTH, length=9, check=_inertia,
       lo=-10.0, hi=10.0),
    _p('mass', 'double', 1.26, 'kg', 'mass', BOTH, check=_positive, lo=0.01, hi=100.0),
    _p('cog_offset', 'double_array', [0.0, 0.0, 0.1], 'm',
       'pivot -> centre of mass, body frame (z up: above the pivot)', BOTH, length=3,
       lo=-1.0, hi=1.0),
    _p('gravity', 'double_array', [0.0, 0.0, -9.81], 'm/s^2', 'gravity vector, world frame',
       BOTH, length=3, lo=-20.0, hi=20.0),
    # Airframe: rotor geometry (controller: allocation; sim: the true rotors).
    _p('rotors.layout', 'string', 'tilted_ring', '-',
       'tilted_ring (from the five parameters below) or custom (rotors.positions/axes/spins)',
       BOTH, choices=('tilted_ring', 'custom')),
    _p('rotors.count', 'integer', 6, '-', 'tilted_ring: number of rotors, numbered clockwise '
       'from above', BOTH, lo=3, hi=12),
    _p('rotors.arm_length', 'double', 0.31, 'm', 'tilted_ring: centre of mass to rotor', BOTH,
       check=_positive, lo=0.01, hi=2.0),
    _p('rotors.tilt_deg', 'double', 15.0, 'deg', 'tilted_ring: tangential tilt of each thrust '
       'axis, alternating with the spin', BOTH, lo=0.0, hi=60.0),
    _p('rotors.first_azimuth_deg', 'double', 0.0, 'deg', 'tilted_ring: azimuth of rotor 1 from '
       'the nose, counter-clockwise from above', BOTH, lo=-360.0, hi=360.0),
    _p('rotors.height', 'double', 0.0, 'm', 'tilted_ring: rotor plane above the centre of mass',
       BOTH, lo=-1.0, hi=1.0),
    _p('rotors.positions', 'double_array', [], 'm',
       'custom (required): rotor positions from the centre of mass, 3 per rotor', BOTH,
       lo=-2.0, hi=2.0),
    _p('rotors.axes', 'double_array', [], '-',
       'custom (required): rotor thrust axes (normalised), 3 per rotor', BOTH,
       lo=-1000.0, hi=1000.0),
    _p('rotors.spins', 'integer_array', [], '-',
       'custom (required): +1 counter-clockwise (seen along the thrust axis), -1 clockwise', BOTH,
       check=lambda v: None if all(x in (-1, 1) for x in v) else 'each must be 1 or -1',
       lo=-1, hi=1),
    _p('rotors.yaw_coefficient', 'double', 0.1, 'm',
       'reaction moment per newton of thrust', BOTH, lo=0.0, hi=1.0),
    _p('rotors.failed', 'integer_array', [], '-', 'rotor numbers (1-based) to treat as dead',
       BOTH, lo=1, hi=12),
    # Motors: thrust curve f = a x^2 + b x + c, x = voltage_scale * command.
    _p('motor.a', 'double_array', [6.0252e-5], 'N', 'thrust curve a (1 value, or 1 per rotor)',
       BOTH, lo=-10.0, hi=10.0),
    _p('motor.b', 'double_array', [8.4086e-3], 'N', 'thrust curve b (1 value, or 1 per rotor)',
       BOTH, lo=-10.0, hi=10.0),
    _p('motor.c', 'double_array', [-2.5194e-2], 'N', 'thrust curve c (1 value, or 1 per rotor)',
       BOTH, lo=-10.0, hi=10.0),
    _p('motor.voltage_scale', 'double', 1.1261, '-',
       'battery-voltage scale of the command (12.5 V / 11.1 V)', BOTH, check=_positive,
       lo=0.01, hi=10.0),
    _p('motor.command_max', 'integer', 240, '-', 'largest ESC command (the set point of a '
       'normalised command of 1)', (CONTROLLER, SIM, ESC), lo=1, hi=65535),
    _p('thrust_min', 'double', 0.2, 'N', 'least thrust per rotor while armed', CONTROLLER,
       lo=0.0, hi=50.0),
    _p('thrust_max', 'double', 6.5, 'N', 'most thrust per rotor (<= the curve at command_max)',
       CONTROLLER, check=_positive, lo=0.01, hi=50.0),
    _p('collective_thrust', 'double', 0.0, 'N',
       'thrust along body z to hold while armed; 0 = m * |gravity|', CONTROLLER, lo=0.0, hi=500.0),
    # Simulator.
    _p('actuation', 'string', 'rotors', '-', 'rotors (commands through the motors) or torque '
       "(the controller's moment, ideal)", SIM, choices=('rotors', 'torque')),
    _p('motor_time_constant', 'double', 0.04, 's', "first-order lag of each rotor's thrust",
       SIM, check=_positive, lo=0.0001, hi=1.0),
    _p('noise.attitude_deg', 'double', 0.0, 'deg',
       'std dev of measured-attitude noise per axis (motion capture)', SIM, lo=0.0, hi=10.0),
    _p('noise.angular_velocity', 'double', 0.0, 'rad/s',
       'std dev of gyro noise per axis', SIM, lo=0.0, hi=1.0),
    _p('noise.gyro_bias', 'double_array', [0.0, 0.0, 0.0], 'rad/s', 'constant gyro bias', SIM,
       length=3, lo=-1.0, hi=1.0),
    _p('noise.seed', 'integer', 0, '-', 'random seed of the noise', SIM, lo=0, hi=2 ** 32 - 1),
    _p('integration_rate_hz', 'double', 1000.0, 'Hz', 'simulator integration rate (RKMK4)', SIM,
       check=_positive, lo=1.0, hi=10000.0),
    _p('initial_attitude', 'double_array', [0.0, 0.0, 0.0, 1.0], '-',
       'initial attitude quaternion (x, y, z, w)', SIM, length=4, check=_unit_quaternion,
       lo=-1.0, hi=1.0),
    _p('initial_angular_velocity', 'double_array', [0.0, 0.0, 0.0], 'rad/s',
       'initial body angular velocity', SIM, length=3, lo=-100.0, hi=100.0),
    _p('disturbance.constant', 'double_array', [0.0, 0.0, 0.0], 'N m',
       'constant disturbance moment, body frame', SIM, length=3, lo=-10.0, hi=10.0),
    _p('disturbance.amplitude', 'double_array', [0.0, 0.0, 0.0], 'N m',
       'amplitudes of [sin wt, cos wt, (sin wt + cos wt)/2] added to it', SIM, length=3,
       lo=-10.0, hi=10.0),
    _p('disturbance.frequency', 'double', 0.0, 'rad/s', 'w of the sinusoidal disturbance', SIM,
       lo=0.0, hi=1000.0),
    _p('pose_rate_hz', 'double', 200.0, 'Hz', 'sim node: rate of pose (motion capture)', SIM,
       check=_positive, lo=1.0, hi=1000.0),
    _p('imu_rate_hz', 'double', 100.0, 'Hz', 'sim node: rate of imu', SIM, check=_positive,
       lo=1.0, hi=1000.0),
    _p('publish_clock', 'bool', False, '-', 'sim node: publish /clock (for use_sim_time)', SIM),
    _p('real_time_factor', 'double', 1.0, '-', 'sim node: simulated seconds per wall second',
       SIM, check=_positive, lo=0.01, hi=20.0),
    _p('command_timeout', 'double', 0.1, 's',
       'sim node: motors stop when motor_commands are older than this', SIM, check=_positive,
       lo=0.001, hi=1.0),
    _p('world_frame_id', 'string', 'world', '-', 'world frame id (sim: of pose messages; '
       'controller: of active_setpoint; view: of its markers)', (CONTROLLER, SIM, VIEW)),
    # MAVLink bridge (geoctl_ros.nodes.mavlink_bridge).
    _p('mavlink.url', 'string', 'udpout:127.0.0.1:14550', '-',
       'ground-station link, as pymavlink takes it (udpout:HOST:PORT, udpin:IP:PORT, '
       'tcp:HOST:PORT, '
       'DEVICE,BAUD)', MAVLINK),
    _p('mavlink.signing_key_file', 'string', '', '-',
       'MAVLink 2 signing key file: 64 hex digits (the key), or a passphrase (the key is its '
       'SHA-256, as ground stations derive it); refused when group or others may read it. Empty: '
       'no signing, and anyone on the link can arm the vehicle', MAVLINK),
    _p('mavlink.signing_link_id', 'integer', 0, '-', 'link id in the signatures the bridge sends',
       MAVLINK, lo=0, hi=255),
    _p('mavlink.signing_timestamp_file', 'string', '', '-',
       'where the outgoing signing timestamp is kept across restarts (empty: the key file '
       "followed by .timestamp); the incoming streams' last timestamps go beside it, in the "
       'same name followed by .streams', MAVLINK),
    _p('mavlink.system_id', 'integer', 1, '-', 'MAVLink system id of the vehicle (component 1)',
       MAVLINK, lo=1, hi=255),
    _p('mavlink.controller', 'string', 'controller', '-', 'name of the controller node to bridge',
       MAVLINK),
    _p('mavlink.esc', 'string', 'esc_i2c', '-', 'name of the ESC node that carries out '
       'MAV_CMD_DO_MOTOR_TEST', MAVLINK),
    _p('mavlink.heartbeat_rate_hz', 'double', 1.0, 'Hz', 'HEARTBEAT rate', MAVLINK,
       check=_positive, lo=0.01, hi=100.0),
    _p('mavlink.status_rate_hz', 'double', 1.0, 'Hz', 'SYS_STATUS rate', MAVLINK, check=_positive,
       lo=0.01, hi=100.0),
    _p('mavlink.attitude_rate_hz', 'double', 10.0, 'Hz', 'ATTITUDE_QUATERNION and ATTITUDE_TARGET '
       'rate', MAVLINK, check=_positive, lo=0.01, hi=100.0),
    _p('mavlink.actuator_rate_hz', 'double', 5.0, 'Hz', 'ACTUATOR_OUTPUT_STATUS rate', MAVLINK,
       check=_positive, lo=0.01, hi=100.0),
    _p('mavlink.internals_rate_hz', 'double', 2.0, 'Hz', 'rate of Psi, cone margins and the '
       'estimate (NAMED_VALUE_FLOAT, DEBUG_FLOAT_ARRAY)', MAVLINK, check=_positive,
       lo=0.01, hi=100.0),
    _p('mavlink.statustext_rate_hz', 'double', 2.0, 'Hz', 'most STATUSTEXT messages per second '
       '(controller warnings and errors)', MAVLINK, check=_positive, lo=0.01, hi=100.0),
    _p('mavlink.autopilot_url', 'string', '', '-', 'optional link to a PX4/ArduPilot board used '
       'as IMU (empty: none)', MAVLINK),
    _p('mavlink.autopilot_imu_rate_hz', 'double', 100.0, 'Hz', 'HIGHRES_IMU rate requested from '
       'the autopilot', MAVLINK, check=_positive, lo=1.0, hi=1000.0),
    # Flight recorder (geoctl_ros.nodes.recorder).
    _p('record.path', 'string', '', '-', 'the bag folder to create (empty: '
       'records/flight_<UTC date and time> under the working directory)', RECORD),
    _p('record.storage', 'string', 'mcap', '-', "the bag's storage: mcap (Jazzy's default) or "
       'sqlite3', RECORD,
       check=lambda v: None if v in ('mcap', 'sqlite3') else 'must be mcap or sqlite3'),
    _p('record.topics', 'string_array', list(RECORD_TOPICS), '-', 'the topics to record, '
       'of those the package publishes and reads (docs/records.md, "Flight records")', RECORD,
       check=lambda v: next(('unknown topic %r (one of %s)' % (t, ', '.join(RECORD_TOPICS))
                             for t in v if t not in RECORD_TOPICS), None)),
    _p('record.controller', 'string', 'controller', '-', 'the controller node whose parameters '
       '(cones, sensor axis) are stored in the bag for the report', RECORD),
    # Live 3D view (geoctl_ros.nodes.view).
    _p('view.rate_hz', 'double', 10.0, 'Hz', 'view/markers rate', VIEW,
       check=_positive, lo=0.1, hi=50.0),
    _p('view.trail_s', 'double', 3.0, 's', 'how long a trail of sensor directions is drawn',
       VIEW, lo=0.0, hi=60.0),
    _p('view.warning_deg', 'double', 5.0, 'deg', 'a cone turns red while the sensor is this close '
       'to it (or inside)', VIEW, lo=0.0, hi=90.0),
    _p('view.controller', 'string', 'controller', '-', 'the controller node whose cones are '
       'drawn', VIEW),
    # ESCs on I2C (geoctl_ros.nodes.esc_i2c; docs/esc.md, "ESCs on I2C").
    _p('esc.bus', 'integer', 1, '-', 'the I2C bus: /dev/i2c-<bus>', ESC, lo=0, hi=255),
    _p('esc.addresses', 'integer_array', [0x29, 0x2A, 0x2B, 0x2C, 0x2D, 0x2E], '-',
       "7-bit I2C address of each rotor's ESC, in rotor order (the lab's 0x29-0x2E)", (ESC, SIM),
       check=_addresses, lo=3, hi=0x77),
    _p('esc.resolution', 'integer', 8, 'bit', 'set point per write: 8 (one byte, 0..command_max) '
       'or 11 (two bytes, 8 times finer)', ESC,
       check=lambda v: None if v in (8, 11) else 'must be 8 or 11', lo=8, hi=11),
    _p('esc.timeout', 'double', 0.1, 's', 'motor_commands older than this (or malformed, or none '
       'yet) give zero on every ESC', ESC,
       check=_positive, lo=0.001, hi=1.0),
    _p('esc.rate_hz', 'double', 100.0, 'Hz', 'least write rate: each ESC gets its set point on '
       'every command and at least this often', ESC, lo=10.0, hi=1000.0),
    _p('esc.telemetry_rate_hz', 'double', 20.0, 'Hz', 'ESC reads per second (one ESC at a time, '
       'in turn), for esc/telemetry and the diagnostics', ESC, lo=0.0, hi=200.0),
    _p('esc.retries', 'integer', 2, '-', 'retries of a failed transfer within a write cycle',
       ESC, lo=0, hi=10),
    _p('esc.ignore', 'integer_array', [], '-', 'rotors (1-based) whose ESC may be missing at '
       'start-up: then never written', ESC, lo=1, hi=12),
    _p('esc.probe_timeout', 'double', 3.0, 's', 'at start-up, how long every ESC has to answer',
       ESC, lo=0.0, hi=60.0),
    _p('esc.temperature_warn', 'double', 80.0, 'deg C', 'an ESC this hot is reported WARN', ESC,
       lo=0.0, hi=150.0),
    _p('esc.temperature_error', 'double', 100.0, 'deg C', 'an ESC this hot is reported ERROR',
       ESC, lo=0.0, hi=150.0),
    _p('esc.controller', 'string', 'controller', '-', 'the controller node this node follows: '
       "its <name>/armed state and the session on its motor_commands (others' are refused; the "
       'motor test is refused while it is armed)', ESC),
    _p('esc.virtual_bus', 'string', '', '-', 'a virtual ESC bus file (e.g. /dev/shm/geoctl_esc): '
       'esc_i2c writes it instead of /dev/i2c-<bus>, and the sim reads its set points instead '
       'of motor_commands (empty: none)', (ESC, SIM)),
    _p('motor_test.rotor', 'integer', 1, '-', "the motor test's rotor (1-based)", ESC,
       lo=1, hi=12),
    _p('motor_test.command', 'double', 0.1, '-', "the motor test's normalised command",
       ESC, lo=0.0, hi=MOTOR_TEST_COMMAND_MAX),
    _p('motor_test.duration', 'double', 2.0, 's', 'how long the motor test runs', ESC,
       check=_positive, lo=0.01, hi=MOTOR_TEST_DURATION_MAX),
    # Headless runner.
    _p('duration', 'double', 20.0, 's', 'simulated time of a scenario run', SCENARIO,
       check=_positive, lo=0.01, hi=3600.0),
    _p('title', 'string', '', '-', "title for a scenario run's plots and summary", SCENARIO),
    _p('latency', 'double', 0.0, 's', 'measurement latency of a scenario run: the controller sees '
       'the state this long ago (a whole number of integration steps)', SCENARIO,
       lo=0.0, hi=0.1),
    _p('stalls.start', 'double_array', [], 's',
       'input stalls of a scenario run: when each begins (the controller then gets no new '
       'sample, as behind a starved executor, and flies on the last one, older by the stall)',
       SCENARIO, lo=0.0, hi=3600.0),
    _p('stalls.duration', 'double_array', [], 's',
       'how long each input stall lasts (one per stalls.start; at most 40 ms, within the imu '
       "timeout: a longer one is an input gap, which the campaign's batches do not model)",
       SCENARIO, lo=0.0, hi=0.04),
    _p('tick_jitter', 'double', 0.0, 's',
       "lateness of a scenario run's control steps: each comes a "
       'random 0..tick_jitter (uniform, whole integration steps, seeded by noise.seed) more than '
       'a period after the one before, as on a busy machine; a command is held until the next',
       SCENARIO, lo=0.0, hi=0.2),
]

# Per-cone parameters; <name> is one of cones.names.
CONE_SCHEMA = [
    _p('cones.<name>.axis', 'double_array', None, '-', 'cone axis v_i, world frame (normalised)',
       CONTROLLER, length=3, check=_nonzero_vector, lo=-1000.0, hi=1000.0),
    _p('cones.<name>.half_angle_deg', 'double', None, 'deg', 'cone half-angle theta_i',
       CONTROLLER, check=_half_angle, lo=0.0, hi=90.0),
]

# What may change while the controller is armed: its gains and its goals. The envelope (cones,
# sensor axis, guards), the model and the airframe, the input checks and the loop's timing are
# refused while armed, with the reason (docs/safety.md, "Parameters").
CHANGE_WHILE_ARMED = ('k_R', 'k_Omega', 'k_Delta', 'c', 'alpha', 'G', 'delta_bar_max',
                      'cog_estimate_max', 'unmodelled_moment_max', 'setpoint',
                      'setpoint_schedule.times', 'setpoint_schedule.quaternions')
# What esc_i2c applies at run time; the rest of its parameters take effect at start only, and a
# change of them at run time is refused.
ESC_LIVE = ('motor_test.rotor', 'motor_test.command', 'motor_test.duration',
            'esc.temperature_warn', 'esc.temperature_error')

BY_NAME = {p.name: p for p in SCHEMA}
CONE_KEY = re.compile(r'^cones\.([^.]+)\.(axis|half_angle_deg)$')
CONE_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')


def schema_for(node):
    """The parameters node ('controller', 'sim' or 'scenario') reads, in schema order."""
    return [p for p in SCHEMA if node in p.nodes]


def cone_param(name, field_):
    """The schema entry for cones.<name>.<field_> (field_ is 'axis' or 'half_angle_deg')."""
    template = {'axis': CONE_SCHEMA[0], 'half_angle_deg': CONE_SCHEMA[1]}[field_]
    return replace(template, name=template.name.replace('<name>', name))


