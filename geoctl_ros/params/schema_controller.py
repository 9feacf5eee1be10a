"""The controller's own parameters: gains, law, model, envelope, set points, loop timing."""

from geoctl_ros.core.law.control import DISTURBANCE_MODELS
from geoctl_ros.core.law.laws import LAWS
from geoctl_ros.params.param import (
    BOTH,
    CONTROLLER,
    diagonal_weights,
    nonzero_vector,
    positive,
    unit_quaternion,
)
from geoctl_ros.params.param import declare as _p

PARAMS = [
    # Controller gains and shape (paper notation).
    _p('k_R', 'double', 0.4, 'N m', 'attitude gain k_R', CONTROLLER, check=positive,
       lo=0.001, hi=10.0),
    _p('k_Omega', 'double', 0.7, 'N m s', 'angular-velocity gain k_Omega', CONTROLLER,
       check=positive, lo=0.001, hi=10.0),
    _p('k_Delta', 'double', 0.05, '-', 'adaptation gain k_Delta', CONTROLLER, check=positive,
       lo=1e-06, hi=10.0),
    _p('k_Delta_cog', 'double', 0.0005, '(kg m)^2 / (N m s)',
       'adaptation gain of the m*rho estimate (constant+cog model): its regressor is about |g| '
       'times the constant one, so this is about k_Delta / |g|^2 for the same learning rate',
       CONTROLLER, check=positive, lo=1e-07, hi=1.0),
    _p('c', 'double', 0.1, '1/s', 'weight of e_R in the adaptive law (Prop. 5)', CONTROLLER,
       check=positive, lo=0.0001, hi=100.0),
    _p('alpha', 'double', 8.0, '-', 'barrier shape alpha (larger: barrier acts closer to a cone)',
       CONTROLLER, check=positive, lo=0.1, hi=1000.0),
    _p('G', 'double_array', [0.9, 1.1, 1.0], '-',
       'diagonal weights g1, g2, g3 of the attitude error A (distinct, positive)', CONTROLLER,
       length=3, check=diagonal_weights, lo=0.0, hi=10.0),
    _p('law', 'string', 'delay_robust', '-',
       'the control law: delay_robust (the barrier of Kulumani, Poole & Lee, each cone widened by '
       'the blind time: blind_guard_max_deg), paper (that barrier as published), geometric (the '
       'same gains, no barrier: a baseline that does not keep the cones) or cbf (geometric, '
       'filtered by a control-barrier-function QP per cone; docs/control-law.md, "Laws")',
       CONTROLLER, choices=tuple(LAWS)),
    _p('cbf_rate', 'double', 4.0, '1/s',
       "the cbf law: double pole lambda of h'' + 2 lambda h' + lambda^2 h >= 0 for each cone",
       CONTROLLER, check=positive, lo=0.1, hi=100.0),
    _p('cbf_moment_bound', 'double', 0.0, 'N m',
       'the unlearnt moment the robust terms hold against: the cbf law, each cone (a robust '
       "CBF: a_i . u >= beta_i + bound |a_i|), and the delay-robust law's approach brake "
       '(its sampled-data margin); 0 = the model taken as exact', CONTROLLER,
       lo=0.0, hi=10.0),
    _p('approach_brake', 'bool', False, '-',
       'the approach brake (docs/safety.md, "The approach brake"): every cone\'s sampled-data '
       "margin kept for the loop as it runs (blind time, hold, the rotors' lag, the unlearnt "
       "moment cbf_moment_bound), the cones joined in one QP within the rotors' reach",
       CONTROLLER),
    _p('brake_acceleration', 'double', 0.0, 'rad/s^2',
       "the deceleration the approach brake takes the rotors to make along any cone's opening "
       "direction: 0 = all the rotors can (their moment polytope less the gravity moment up to "
       "the joint's stops, computed at configuration); a value above that is refused",
       CONTROLLER, lo=0.0, hi=10000.0),
    _p('attitude_noise_deg', 'double', 0.1, 'deg',
       "the attitude measurement's noise (one standard deviation): the approach brake keeps 3 "
       'of them from each cone', CONTROLLER, lo=0.0, hi=5.0),
    _p('guidance_lookahead_deg', 'double', 0.0, 'deg',
       'guidance: the law flies to set points along a path planned round the cones to the goal, '
       'each at most this far ahead of the measured attitude (also bounding the moment and the '
       'speed far from the goal); 0 = off, the law flies straight to the goal '
       '(docs/control-law.md, "Guidance")', CONTROLLER, lo=0.0, hi=90.0),
    _p('guidance_clearance_deg', 'double', 8.0, 'deg',
       "guidance: the planned path keeps this far outside each cone's barrier (its half-angle "
       'plus cone_guard_deg); less where the start or the goal is nearer', CONTROLLER,
       lo=0.0, hi=30.0),
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
       'body-fixed sensor axis r (normalised)', CONTROLLER, length=3, check=nonzero_vector,
       lo=-1000.0, hi=1000.0),
    _p('measurement_delay', 'double', 0.0, 's',
       'latency of the pose and imu chain from capture to receipt, where the stamps do not give '
       'it (age_from_stamps); each tick predicts the measurements forward by their age with the '
       'model and the moments commanded since (docs/safety.md, "Delay")', CONTROLLER,
       lo=0.0, hi=0.05),
    # The inputs' conventions (core.sensors.frames), applied once as they come in; the sim emulates
    # the same conventions when it is given them (docs/sensors.md).
    _p('pose_world_frame', 'string', 'enu', '-',
       "the pose's world axes: enu (REP-103), ned (north-east-down) or y_up (x kept, y up); the "
       'cones and set points stay in ENU (docs/sensors.md)', BOTH, choices=('enu', 'ned', 'y_up')),
    _p('body_frame', 'string', 'flu', '-',
       'the body axes of the pose and of the IMU: flu (forward-left-up) or frd '
       '(forward-right-down)', BOTH, choices=('flu', 'frd')),
    _p('marker_rotation_deg', 'double_array', [0.0, 0.0, 0.0], 'deg',
       "the motion capture's body (its marker set) against the airframe: roll, pitch, yaw "
       '(z-y-x) of the rotation from the marker body to the airframe; calibrate measures it; a '
       'Y-up rigid body is [90, 0, 0]', BOTH, length=3, lo=-180.0, hi=180.0),
    _p('imu_rotation_deg', 'double_array', [0.0, 0.0, 0.0], 'deg',
       "the IMU's mounting: roll, pitch, yaw (z-y-x) of the rotation from its axes to the "
       "airframe's", BOTH, length=3, lo=-180.0, hi=180.0),
    _p('gyro_bias', 'double_array', [0.0, 0.0, 0.0], 'rad/s',
       "the gyro's bias in its own axes, subtracted from every reading (calibrate measures it)",
       CONTROLLER, length=3, lo=-1.0, hi=1.0),
    _p('consistency_checks', 'bool', True, '-',
       'arming needs the IMU and the poses to agree (gravity and rate at rest), and a sustained '
       'rate disagreement in flight is a failsafe (docs/sensors.md, "Consistency checks"); '
       'false: neither', CONTROLLER),
    _p('gyro_noise', 'double', 0.005, 'rad/s',
       "the gyro's noise per axis and sample (one standard deviation): the checks' tolerances",
       CONTROLLER, check=positive, lo=1e-6, hi=1.0),
    _p('accelerometer_noise', 'double', 0.05, 'm/s^2',
       "the accelerometer's noise per axis and sample (one standard deviation): the gravity "
       "check's tolerance", CONTROLLER, check=positive, lo=1e-6, hi=10.0),
    _p('alignment_tolerance_deg', 'double', 2.0, 'deg',
       "the angle between the IMU's gravity and the poses' that arming allows beyond the noise "
       '(a calibrated installation keeps well under it)', CONTROLLER, lo=0.0, hi=30.0),
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
       CONTROLLER, check=positive, lo=0.01, hi=10.0),
    _p('cones.names', 'string_array', [], '-',
       'names of the forbidden cones; each needs cones.<name>.axis and .half_angle_deg',
       CONTROLLER),
    _p('setpoint', 'double_array', [0.0, 0.0, 0.0, 1.0], '-',
       'desired attitude R_d as a quaternion (x, y, z, w), world frame: what an arming flies '
       'with arming_setpoint configured; set at run time (ros2 param set, the setpoint command, '
       "a ground station's SET_ATTITUDE_TARGET), it is flown at once, or refused with the reason "
       'and nothing changes', CONTROLLER, length=4, check=unit_quaternion, lo=-1.0, hi=1.0),
    _p('arming_setpoint', 'string', 'hold', '-',
       'what an arming flies once the rotors have spooled up: hold (the attitude measured at '
       "arming, held 5 deg inside the joint's stops where it rests on them, as PX4 and "
       'ArduPilot arm; the operator commands what comes next: the setpoint command, '
       'docs/interface.md) or configured (setpoint, then setpoint_schedule from the '
       'arming: an experiment). The headless runners (scenario, campaign, benchmark, falsify, '
       'tune) fly their set point whatever this says', CONTROLLER, choices=('hold', 'configured')),
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
       CONTROLLER, check=positive, lo=0.001, hi=0.5),
    _p('imu_timeout', 'double', 0.05, 's', 'angular velocity older than this is stale',
       CONTROLLER, check=positive, lo=0.001, hi=0.5),
    _p('pose_ride_through', 'double', 0.5, 's',
       'a pose gap up to this long is flown through on the gyro-propagated attitude; longer: '
       'failsafe (0: failsafe at pose_timeout)', CONTROLLER, lo=0.0, hi=1.0),
    _p('imu_ride_through', 'double', 0.25, 's',
       'an angular-velocity gap up to this long is flown through on rates from successive poses; '
       'longer: failsafe (0: failsafe at imu_timeout)', CONTROLLER, lo=0.0, hi=1.0),
    _p('pose_rate_window', 'double', 0.05, 's',
       'time between the two poses that give the rate during an angular-velocity gap',
       CONTROLLER, check=positive, lo=0.001, hi=0.5),
    _p('max_angular_velocity', 'double', 100.0, 'rad/s',
       'gyro readings faster than this are refused', CONTROLLER, check=positive,
       lo=0.1, hi=200.0),
    _p('setpoint_schedule.times', 'double_array', [], 's',
       'optional: times after arming at which the scheduled set points take over (with '
       'arming_setpoint configured)', CONTROLLER,
       lo=0.0, hi=3600.0),
    _p('setpoint_schedule.quaternions', 'double_array', [], '-',
       'optional: the scheduled set points, 4 values (x, y, z, w) per time', CONTROLLER,
       lo=-1.0, hi=1.0),
    _p('frame_id', 'string', 'base_link', '-', 'body frame id on stamped outputs', BOTH),
]
