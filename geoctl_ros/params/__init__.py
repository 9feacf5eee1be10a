"""Parameters: one schema, ROS-strict validation, parameter files, and building the objects.

Where each piece lives (the names below are this package's public API):

    schema.py    the schema (``SCHEMA``, ``CONE_SCHEMA``), the node kinds, ``ConfigError``
    validate.py  ``check_value`` (ROS-strict types and checks) and ``resolve`` (a node's values)
    files.py     ROS 2 parameter files: ``load_parameter_file``, ``node_overrides``
    build.py     objects from resolved values: ``controller_setup``, ``mixer``, ``airframe``,
                 ``cone_set``, ``GainSet``, ... with the checks that span parameters
    testbed.py   the simulated testbed's typed set-up (``TestbedSetup``: plant, rotors, noise)
    scenario.py  a scenario file, loaded and validated (``Scenario``, ``ScenarioOptions``), and
                 what the runs of a batch share
    esc.py       the ESC node's typed set-up (``EscSetup``, ``EscConfig``) and the sim's
                 virtual ESCs
    readme.py    the parameter table (docs/parameters.md) (``python -m geoctl_ros.params.readme``)

Past this package nothing reads a parameter by its name: the other layers take these typed
set-ups (test_layers.py checks it on every module).

Nothing here imports rclpy: the nodes (``geoctl_ros.nodes.ros_params``) and the headless runner
use the same code.

build.py's names are imported on first use (``__getattr__`` below): build brings in the
controller's supervisor (its LoopSettings and SetpointSchedule), which the ESC node, reading only
the schema, does not load (test_layers.py checks it).
"""
from typing import TYPE_CHECKING, Any

from geoctl_ros.params.files import (
                                     flatten,
                                     load_parameter_file,
                                     node_overrides,
                                     write_parameter_file,
)
from geoctl_ros.params.param import (
                                     BOTH,
                                     CONTROLLER,
                                     ESC,
                                     LAB_INERTIA,
                                     MAVLINK,
                                     RECORD,
                                     SCENARIO,
                                     SIM,
                                     VIEW,
                                     ConfigError,
                                     Param,
)
from geoctl_ros.params.schema import (
                                     AIRFRAME_NAMES,
                                     BY_NAME,
                                     CHANGE_WHILE_ARMED,
                                     CONE_KEY,
                                     CONE_SCHEMA,
                                     ESC_LIVE,
                                     SCHEMA,
                                     cone_param,
                                     schema_for,
)
from geoctl_ros.params.validate import (
                                     change_problem,
                                     check_value,
                                     configuration_given,
                                     resolve,
)

__all__ = ['AIRFRAME_NAMES', 'BOTH', 'BY_NAME', 'CHANGE_WHILE_ARMED', 'CONE_KEY', 'CONE_SCHEMA',
           'CONTROLLER', 'ConfigError', 'ESC', 'ESC_LIVE', 'ControllerSetup', 'LAB_INERTIA',
           'MAVLINK', 'Param', 'RECORD', 'SCENARIO', 'SCHEMA', 'SIM', 'VIEW',
           'airframe', 'change_problem', 'check_value', 'cone_param',
           'configuration_given', 'cone_set',
           'controller_config', 'controller_setup', 'flatten', 'load_parameter_file', 'mixer',
           'node_overrides', 'resolve', 'write_parameter_file',
           'schema_for', 'SETPOINT', 'setpoint_change', 'setpoint_rotation', 'settings']

_BUILD = frozenset(['SETPOINT', 'ControllerSetup', 'airframe', 'cone_set', 'controller_config',
                    'controller_setup', 'mixer', 'setpoint_change', 'setpoint_rotation',
                    'settings'])

if TYPE_CHECKING:
    from geoctl_ros.params.build import (
                                         SETPOINT,
                                         ControllerSetup,
                                         airframe,
                                         cone_set,
                                         controller_config,
                                         controller_setup,
                                         mixer,
                                         setpoint_change,
                                         setpoint_rotation,
                                         settings,
    )


def __getattr__(name: str) -> Any:
    """One of build.py's names, imported from it on first use."""
    if name not in _BUILD:
        raise AttributeError('module %r has no attribute %r' % (__name__, name))
    from geoctl_ros.params import build  # noqa: PLC0415  (on first use: the ESC node needs none)
    value = getattr(build, name)
    globals()[name] = value
    return value
