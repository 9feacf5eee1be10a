"""The testbed's parameters: the physical model (the controller's model, the simulator's truth),
the airframe, the motors and the simulator; ``AIRFRAME``, the names that say what is flown.
"""

from geoctl_ros.params.param import (
    BOTH,
    CONTROLLER,
    ESC,
    LAB_INERTIA,
    SIM,
    VIEW,
    inertia_matrix,
    positive,
    unit_quaternion,
)
from geoctl_ros.params.param import declare as _p

# Physical model, read by the controller (its model) and the simulator (the truth).
BODY = [
    _p('inertia', 'double_array', LAB_INERTIA, 'kg m^2',
       'inertia about the centre of mass, body frame, 9 values row-major (default: the lab '
       "hexrotor's, docs/testbed.md)", BOTH, length=9, check=inertia_matrix, lo=-10.0, hi=10.0),
    _p('mass', 'double', 1.26, 'kg', "mass (default: the lab hexrotor's)", BOTH, check=positive,
       lo=0.01, hi=100.0),
    _p('cog_offset', 'double_array', [0.0, 0.0, 0.1], 'm',
       'pivot -> centre of mass, body frame (z up: above the pivot)', BOTH, length=3,
       lo=-1.0, hi=1.0),
    _p('gravity', 'double_array', [0.0, 0.0, -9.81], 'm/s^2', 'gravity vector, world frame',
       BOTH, length=3, lo=-20.0, hi=20.0),
    _p('joint_tilt_max_deg', 'double', 180.0, 'deg',
       "the spherical joint's stops: the body's z axis tilts at most this far from upright (the "
       'sim rests on them; the approach brake counts the gravity moment up to them); 180 = no '
       'stops', BOTH, lo=1.0, hi=180.0),
]
# Airframe: rotor geometry (controller: allocation; sim: the true rotors).
ROTORS = [
    _p('rotors.layout', 'string', 'tilted_ring', '-',
       'tilted_ring (from the five parameters below) or custom (rotors.positions/axes/spins)',
       BOTH, choices=('tilted_ring', 'custom')),
    _p('rotors.count', 'integer', 6, '-', 'tilted_ring: number of rotors, numbered clockwise '
       'from above', BOTH, lo=3, hi=12),
    _p('rotors.arm_length', 'double', 0.31, 'm', 'tilted_ring: centre of mass to rotor', BOTH,
       check=positive, lo=0.01, hi=2.0),
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
]
# Motors: thrust curve f = a x^2 + b x + c, x = voltage_scale * command; the rotors' limits.
MOTORS = [
    _p('motor.a', 'double_array', [6.0252e-5], 'N', 'thrust curve a (1 value, or 1 per rotor)',
       BOTH, lo=-10.0, hi=10.0),
    _p('motor.b', 'double_array', [8.4086e-3], 'N', 'thrust curve b (1 value, or 1 per rotor)',
       BOTH, lo=-10.0, hi=10.0),
    _p('motor.c', 'double_array', [-2.5194e-2], 'N', 'thrust curve c (1 value, or 1 per rotor)',
       BOTH, lo=-10.0, hi=10.0),
    _p('motor.voltage_scale', 'double', 1.1261, '-',
       'battery-voltage scale of the command (12.5 V / 11.1 V)', BOTH, check=positive,
       lo=0.01, hi=10.0),
    _p('motor.command_max', 'integer', 240, '-', 'largest ESC command (the set point of a '
       'normalised command of 1)', (CONTROLLER, SIM, ESC), lo=1, hi=65535),
    _p('thrust_min', 'double', 0.2, 'N', 'least thrust per rotor while armed', CONTROLLER,
       lo=0.0, hi=50.0),
    _p('thrust_max', 'double', 6.5, 'N', 'most thrust per rotor (<= the curve at command_max)',
       CONTROLLER, check=positive, lo=0.01, hi=50.0),
    _p('collective_thrust', 'double', 0.0, 'N',
       'thrust along body z to hold while armed; 0 = m * |gravity|', CONTROLLER, lo=0.0, hi=500.0),
]
# Simulator.
SIMULATOR = [
    _p('actuation', 'string', 'rotors', '-', 'rotors (commands through the motors) or torque '
       "(the controller's moment, ideal)", SIM, choices=('rotors', 'torque')),
    _p('motor_time_constant', 'double', 0.04, 's', "first-order lag of each rotor's thrust",
       SIM, check=positive, lo=0.0001, hi=1.0),
    _p('noise.attitude_deg', 'double', 0.0, 'deg',
       'std dev of measured-attitude noise per axis (motion capture)', SIM, lo=0.0, hi=10.0),
    _p('noise.angular_velocity', 'double', 0.0, 'rad/s',
       'std dev of gyro noise per axis', SIM, lo=0.0, hi=1.0),
    _p('noise.gyro_bias', 'double_array', [0.0, 0.0, 0.0], 'rad/s', 'constant gyro bias', SIM,
       length=3, lo=-1.0, hi=1.0),
    _p('noise.specific_force', 'double', 0.0, 'm/s^2',
       "std dev of the accelerometer's noise per axis", SIM, lo=0.0, hi=10.0),
    _p('imu_position', 'double_array', [0.0, 0.0, 0.0], 'm',
       'where the IMU sits, from the pivot in the body frame: its specific force includes the '
       'acceleration of that point', SIM, length=3, lo=-1.0, hi=1.0),
    _p('noise.seed', 'integer', 0, '-', 'random seed of the noise', SIM, lo=0, hi=2 ** 32 - 1),
    _p('integration_rate_hz', 'double', 1000.0, 'Hz', 'simulator integration rate (RKMK4)', SIM,
       check=positive, lo=1.0, hi=10000.0),
    _p('initial_attitude', 'double_array', [0.0, 0.0, 0.0, 1.0], '-',
       'initial attitude quaternion (x, y, z, w)', SIM, length=4, check=unit_quaternion,
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
       check=positive, lo=1.0, hi=1000.0),
    _p('imu_rate_hz', 'double', 100.0, 'Hz', 'sim node: rate of imu', SIM, check=positive,
       lo=1.0, hi=1000.0),
    _p('publish_clock', 'bool', False, '-', 'sim node: publish /clock (for use_sim_time)', SIM),
    _p('real_time_factor', 'double', 1.0, '-', 'sim node: simulated seconds per wall second',
       SIM, check=positive, lo=0.01, hi=20.0),
    _p('command_timeout', 'double', 0.1, 's',
       'sim node: motors stop when motor_commands are older than this', SIM, check=positive,
       lo=0.001, hi=1.0),
    _p('world_frame_id', 'string', 'world', '-', 'world frame id (sim: of pose messages; '
       'controller: of active_setpoint; view: of its markers)', (CONTROLLER, SIM, VIEW)),
]
PARAMS = BODY + ROTORS + MOTORS + SIMULATOR

# The airframe: what the body, its rotors and its motors are (the simulator's truth and the
# controller's model of it), the rotors' lag and the controller's compensation of it. A flight
# "on a file's airframe" takes these from that file (the tuner's latency rows: docs/campaigns.md,
# "Gain tuning"); everything else (gains, cones, set points, noise, timing) from its own.
AIRFRAME = tuple(p.name for p in BODY + ROTORS + MOTORS) + (
    'motor_time_constant', 'motor_lag_compensation')
