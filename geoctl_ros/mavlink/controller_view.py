"""What the bridge knows of the controller (``ControllerView``, fed from its topics) and the names
its figures go to a ground station under.
"""
from dataclasses import dataclass, field
import math

import numpy as np

from geoctl_ros.core.actuation.esc_wire import motor_commands_problem
from geoctl_ros.core.supervisor.safety import angular_velocity_problem, attitude_of
from geoctl_ros.core.telemetry.diagnostics import Status

# DEBUG_FLOAT_ARRAY / NAMED_VALUE_FLOAT names (at most 10 characters; docs/mavlink.md, "MAVLink").
NAME_PSI = 'GC_PSI'            # configuration error Psi
NAME_MARGIN = 'GC_MARGIN'      # smallest cone margin, deg
NAME_MARGINS = 'GC_MARGINS'    # DEBUG_FLOAT_ARRAY: every cone margin, deg, in cones.names order
NAME_DBAR = 'GC_DBAR'          # DEBUG_FLOAT_ARRAY: the disturbance estimate Delta_bar


@dataclass
class ControllerView:
    """What the bridge knows of the controller (ROS frames), updated as messages arrive."""

    R: np.ndarray = None                 # attitude ENU <- FLU (from pose)
    omega: np.ndarray = None             # body rate FLU (from imu)
    R_d: np.ndarray = None               # set point
    commands: list = field(default_factory=list)   # normalised motor commands
    psi: float = math.nan
    margins: list = field(default_factory=list)
    dbar: list = field(default_factory=list)
    diagnostics: Status = None           # the controller's last diagnostics (typed figures)
    params: dict = field(default_factory=dict)     # ROS name -> value

    # What arrives is checked here: a zero or NaN quaternion, a non-finite vector, never reaches
    # a frame conversion or a ground station. Each returns why it refused the value, or None.
    def take_attitude(self, q, setpoint=False):
        """A pose's (or, setpoint, the active set point's) quaternion (x, y, z, w)."""
        R, problem = attitude_of(q)
        if problem is None:
            if setpoint:
                self.R_d = R
            else:
                self.R = R
        return problem

    def take_rate(self, w):
        problem = angular_velocity_problem(w, math.inf)
        if problem is None:
            self.omega = np.asarray(w, dtype=float)
        return problem

    def take_commands(self, data):
        problem = motor_commands_problem(data, len(data))
        if problem is None:
            self.commands = list(data)
        return problem

    def take_psi(self, x):
        if not math.isfinite(x):
            return 'configuration error is not finite'
        self.psi = float(x)
        return None

    def take_array(self, name, data):
        """'margins' or 'dbar'."""
        if not all(math.isfinite(x) for x in data):
            return '%s not finite' % name
        setattr(self, name, list(data))
        return None

