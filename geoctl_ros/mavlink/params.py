"""The controller's ROS parameters as MAVLink parameters: one table, ids of at most 16 characters.

Only scalars are offered (a ground station's parameter editor edits numbers); arrays, strings and
the cones stay ROS-only. Booleans travel as INT32 0/1. Every PARAM_SET is applied through the
controller's own ``set_parameters`` service, so it is validated exactly as ``ros2 param set`` is.
"""
from geoctl_ros.params.schema import BY_NAME

# (ROS name, MAVLink id, MAVLink type: 'REAL32' or 'INT32')
TABLE = [
    ('k_R', 'GC_K_R', 'REAL32'),
    ('k_Omega', 'GC_K_OMEGA', 'REAL32'),
    ('k_Delta', 'GC_K_DELTA', 'REAL32'),
    ('k_Delta_cog', 'GC_K_DELTA_COG', 'REAL32'),
    ('c', 'GC_C', 'REAL32'),
    ('alpha', 'GC_ALPHA', 'REAL32'),
    ('adaptive', 'GC_ADAPTIVE', 'INT32'),
    ('delta_bar_max', 'GC_DBAR_MAX', 'REAL32'),
    ('cog_estimate_max', 'GC_COG_EST_MAX', 'REAL32'),
    ('gravity_compensation', 'GC_GRAV_COMP', 'INT32'),
    ('barrier_floor_deg', 'GC_BAR_FLOOR', 'REAL32'),
    ('pose_timeout', 'GC_POSE_TO', 'REAL32'),
    ('imu_timeout', 'GC_IMU_TO', 'REAL32'),
    ('pose_ride_through', 'GC_POSE_RIDE', 'REAL32'),
    ('imu_ride_through', 'GC_IMU_RIDE', 'REAL32'),
    ('max_angular_velocity', 'GC_MAX_RATE', 'REAL32'),
    ('mass', 'GC_MASS', 'REAL32'),
    ('thrust_min', 'GC_THR_MIN', 'REAL32'),
    ('thrust_max', 'GC_THR_MAX', 'REAL32'),
    ('collective_thrust', 'GC_THR_COLL', 'REAL32'),
]
BY_ROS = {ros: (pid, t) for ros, pid, t in TABLE}
BY_ID = {pid: (ros, t) for ros, pid, t in TABLE}
assert all(len(pid) <= 16 for _, pid, _ in TABLE)


def to_mavlink(value):
    """A ROS value (float, int or bool) as the float a PARAM_VALUE carries."""
    return float(int(value)) if isinstance(value, bool) else float(value)


def to_ros(name, value):
    """A PARAM_SET float for the ROS parameter name, in its ROS type."""
    for ros, _, t in TABLE:
        if ros == name:
            break
    else:
        raise KeyError(name)
    kind = BY_NAME[name].type
    if kind == 'bool':
        return bool(round(value))
    if kind == 'integer':
        return int(round(value))
    return float(value)
