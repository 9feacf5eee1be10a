"""The other nodes' and the headless runner's parameters: MAVLink bridge, recorder, view, ESCs,
scenario.
"""

from geoctl_ros.params.param import (
    ESC,
    MAVLINK,
    MOTOR_TEST_COMMAND_MAX,
    MOTOR_TEST_DURATION_MAX,
    RECORD,
    RECORD_TOPICS,
    SCENARIO,
    SIM,
    VIEW,
    i2c_addresses,
    positive,
)
from geoctl_ros.params.param import declare as _p

PARAMS = [
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
       check=positive, lo=0.01, hi=100.0),
    _p('mavlink.status_rate_hz', 'double', 1.0, 'Hz', 'SYS_STATUS rate', MAVLINK, check=positive,
       lo=0.01, hi=100.0),
    _p('mavlink.attitude_rate_hz', 'double', 10.0, 'Hz', 'ATTITUDE_QUATERNION and ATTITUDE_TARGET '
       'rate', MAVLINK, check=positive, lo=0.01, hi=100.0),
    _p('mavlink.actuator_rate_hz', 'double', 5.0, 'Hz', 'ACTUATOR_OUTPUT_STATUS rate', MAVLINK,
       check=positive, lo=0.01, hi=100.0),
    _p('mavlink.internals_rate_hz', 'double', 2.0, 'Hz', 'rate of Psi, cone margins and the '
       'estimate (NAMED_VALUE_FLOAT, DEBUG_FLOAT_ARRAY)', MAVLINK, check=positive,
       lo=0.01, hi=100.0),
    _p('mavlink.statustext_rate_hz', 'double', 2.0, 'Hz', 'most STATUSTEXT messages per second '
       '(controller warnings and errors)', MAVLINK, check=positive, lo=0.01, hi=100.0),
    _p('mavlink.autopilot_url', 'string', '', '-', 'optional link to a PX4/ArduPilot board used '
       'as IMU (empty: none)', MAVLINK),
    _p('mavlink.autopilot_imu_rate_hz', 'double', 100.0, 'Hz', 'HIGHRES_IMU rate requested from '
       'the autopilot', MAVLINK, check=positive, lo=1.0, hi=1000.0),
    # Flight recorder (geoctl_ros.nodes.recorder).
    _p('record.path', 'string', '', '-', 'the bag folder to create (empty: '
       'records/flight_<UTC date and time> under the working directory)', RECORD),
    _p('record.storage', 'string', 'mcap', '-', "the bag's storage: mcap (Jazzy's default) or "
       'sqlite3', RECORD,
       check=lambda v: None if v in ('mcap', 'sqlite3') else 'must be mcap or sqlite3'),
    _p('record.topics', 'string_array', list(RECORD_TOPICS), '-', 'the topics to record, '
       "by the package's names, of those it publishes and reads; a remapped one (pose, imu) is "
       'recorded under its real name (docs/records.md, "Flight records")', RECORD,
       check=lambda v: next(("unknown topic %r (one of %s; a driver's own topic is recorded "
                             'under its real name as /pose or /imu remapped: --ros-args -r '
                             'pose:=NAME)' % (t, ', '.join(RECORD_TOPICS))
                             for t in v if t not in RECORD_TOPICS), None)),
    _p('record.controller', 'string', 'controller', '-', 'the controller node whose parameters '
       '(cones, sensor axis) are stored in the bag for the report', RECORD),
    # Live 3D view (geoctl_ros.nodes.view).
    _p('view.rate_hz', 'double', 10.0, 'Hz', 'view/markers rate', VIEW,
       check=positive, lo=0.1, hi=50.0),
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
       check=i2c_addresses, lo=3, hi=0x77),
    _p('esc.resolution', 'integer', 8, 'bit', 'set point per write: 8 (one byte, 0..command_max) '
       'or 11 (two bytes, 8 times finer)', ESC,
       check=lambda v: None if v in (8, 11) else 'must be 8 or 11', lo=8, hi=11),
    _p('esc.timeout', 'double', 0.1, 's', 'motor_commands older than this (or malformed, or none '
       'yet) give zero on every ESC', ESC,
       check=positive, lo=0.001, hi=1.0),
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
       check=positive, lo=0.01, hi=MOTOR_TEST_DURATION_MAX),
    # Headless runner.
    _p('duration', 'double', 20.0, 's', 'simulated time of a scenario run', SCENARIO,
       check=positive, lo=0.01, hi=3600.0),
    _p('title', 'string', '', '-', "title for a scenario run's plots and summary", SCENARIO),
    _p('latency', 'double', 0.0, 's', 'measurement latency of a scenario run: the controller sees '
       'the state this long ago (a whole number of integration steps)', SCENARIO,
       lo=0.0, hi=0.2),
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
    _p('tick_jitter_seed', 'integer', -1, '-',
       "the seed of the control steps' lateness (tick_jitter); -1: noise.seed (runs fly "
       'together in a batch only with the same lateness)', SCENARIO, lo=-1, hi=2 ** 31 - 1),
    _p('start', 'string', 'held', '-',
       'how a scenario run starts: held (the vehicle held still at its initial attitude while '
       'the rotors spool up, and let go as the controller takes over, at t = 0) or resting '
       '(free from the arming on: on its stops, or wherever gravity takes it, while the rotors '
       'spool up)', SCENARIO, choices=('held', 'resting')),
]
