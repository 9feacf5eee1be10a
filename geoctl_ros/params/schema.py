"""The one parameter schema: every parameter any part of geoctl_ros reads, declared once.

Each ``Param`` has its ROS 2 type, default, unit, one-line doc, the nodes that read it and a check
(a function returning a reason, or None). The nodes declare their parameters from it
(``geoctl_ros.nodes.ros_params``), the headless runner reads files through it
(``geoctl_ros.params.files``) and the parameter table (docs/parameters.md) is generated from it
(``geoctl_ros.params.readme``). Cones are parameters too: ``cones.names: [a, b]`` plus
``cones.<name>.axis`` and ``cones.<name>.half_angle_deg`` per name (``CONE_SCHEMA``).
"""
from dataclasses import replace
import re
from typing import List

from geoctl_ros.params import schema_controller, schema_testbed, schema_tools
from geoctl_ros.params.param import CONTROLLER, Param, half_angle, nonzero_vector
from geoctl_ros.params.param import declare as _p

SCHEMA = schema_controller.PARAMS + schema_testbed.PARAMS + schema_tools.PARAMS
AIRFRAME_NAMES = schema_testbed.AIRFRAME


# Per-cone parameters; <name> is one of cones.names.
CONE_SCHEMA = [
    _p('cones.<name>.axis', 'double_array', None, '-', 'cone axis v_i, world frame (normalised)',
       CONTROLLER, length=3, check=nonzero_vector, lo=-1000.0, hi=1000.0),
    _p('cones.<name>.half_angle_deg', 'double', None, 'deg', 'cone half-angle theta_i',
       CONTROLLER, check=half_angle, lo=0.0, hi=90.0),
]

# What may change while the controller is armed: its gains and its goals. The envelope (cones,
# sensor axis, guards), the model and the airframe, the input checks and the loop's timing are
# refused while armed, with the reason (docs/safety.md, "Parameters").
CHANGE_WHILE_ARMED = ('k_R', 'k_Omega', 'k_Delta', 'k_Delta_cog', 'c', 'alpha', 'G',
                      'delta_bar_max', 'cog_estimate_max', 'unmodelled_moment_max', 'setpoint',
                      'setpoint_schedule.times', 'setpoint_schedule.quaternions')
# What esc_i2c applies at run time; the rest of its parameters take effect at start only, and a
# change of them at run time is refused.
ESC_LIVE = ('motor_test.rotor', 'motor_test.command', 'motor_test.duration',
            'esc.temperature_warn', 'esc.temperature_error')

BY_NAME = {p.name: p for p in SCHEMA}
CONE_KEY = re.compile(r'^cones\.([^.]+)\.(axis|half_angle_deg)$')
CONE_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')


def schema_for(node: str) -> List[Param]:
    """The parameters node ('controller', 'sim' or 'scenario') reads, in schema order."""
    return [p for p in SCHEMA if node in p.nodes]


def cone_param(name: str, field_: str) -> Param:
    """The schema entry for cones.<name>.<field_> (field_ is 'axis' or 'half_angle_deg')."""
    template = {'axis': CONE_SCHEMA[0], 'half_angle_deg': CONE_SCHEMA[1]}[field_]
    return replace(template, name=template.name.replace('<name>', name))



