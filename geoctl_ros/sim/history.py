"""Every control step of a flight, kept for its history.csv and figures (``closed_loop.fly`` with
history=True): the true state, the step's output, what the controller does not model, the cone
angles and, with rotors, the commands, thrusts and the moment the allocation lost.
"""
from typing import List

import numpy as np

from geoctl_ros.core.actuation.motors import MotorOutput
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.control import ControlOutput
from geoctl_ros.core.law.mechanics import gravity_moment


class History:
    """Per-step arrays with a leading step axis and a run axis: (steps, runs, ...)."""

    def __init__(self, steps, bed):
        """bed: the batch's controller and testbeds (``geoctl_ros.sim.runs.Testbeds``)."""
        self._bed = bed
        controller, plant, actuator = bed.controller, bed.plant, bed.actuator
        runs = len(bed.cones.V)
        self._controller, self._plant, self._actuator = controller, plant, actuator
        cfg = controller.config
        self.cone_names = list(cfg.cones.names)
        n_params = cfg.n_params
        rotors = 0 if actuator is None else actuator.thrusts.shape[-1]
        m_rho_model = cfg.m_rho if cfg.gravity_compensation else np.zeros(3)
        self._m_rho_error = np.broadcast_to(plant.config.m_rho - m_rho_model, (runs, 3))
        self.arrays = {
            't': np.empty(steps),
            'q': np.empty((steps, runs, 4)),
            'w': np.empty((steps, runs, 3)),
            'eR': np.empty((steps, runs, 3)),
            'psi': np.empty((steps, runs)),
            'u': np.empty((steps, runs, 3)),
            'dbar': np.empty((steps, runs, n_params)),
            'dtrue': np.empty((steps, runs, n_params)),
            'angle': np.empty((steps, runs, len(self.cone_names))),
            'cmd': np.empty((steps, runs, rotors)),
            'thrust': np.empty((steps, runs, rotors)),
            'moment_lost': np.empty((steps, runs)),
        }

    def add(self, k: int, t: float, out: ControlOutput, motors: MotorOutput) -> None:
        """Step k at time t: the plant's state now, the step's ControlOutput and MotorOutput."""
        a, plant = self.arrays, self._plant
        R, Omega = self._bed.state()
        a['t'][k] = t
        a['q'][k] = [so3.rot_to_quat(Ri) for Ri in R]
        a['w'][k] = Omega
        a['eR'][k], a['psi'][k], a['u'][k], a['dbar'][k] = out.e_R, out.psi, out.u, out.delta_bar
        # what the controller does not model: the disturbance plus the uncompensated gravity
        # moment, or (with the constant + centre-of-mass model) the two separately
        pcfg = plant.config
        disturbance = np.broadcast_to(pcfg.disturbance(plant.t), R.shape[:-1])
        if a['dtrue'].shape[-1] == 3:
            a['dtrue'][k] = disturbance + gravity_moment(R, self._m_rho_error, pcfg.gravity)
        else:
            a['dtrue'][k] = np.concatenate((disturbance, self._m_rho_error), axis=-1)
        a['angle'][k] = self._controller.config.cones.angles_deg(R)
        if self._actuator is not None:
            a['cmd'][k] = motors.commands
            a['thrust'][k] = self._actuator.thrusts
            lost = motors.allocation.moment_lost
            a['moment_lost'][k] = np.sqrt(so3.dot(lost, lost))

    def columns(self) -> List[str]:
        """The history.csv's column names."""
        a = self.arrays
        rotors = a['cmd'].shape[-1]
        return (['t', 'qx', 'qy', 'qz', 'qw', 'wx', 'wy', 'wz', 'eR_x', 'eR_y', 'eR_z', 'psi',
                 'u_x', 'u_y', 'u_z']
                + ['dbar_%d' % i for i in range(a['dbar'].shape[-1])]
                + ['dtrue_%d' % i for i in range(a['dtrue'].shape[-1])]
                + ['angle_%s' % n for n in self.cone_names]
                + ['cmd_%d' % (i + 1) for i in range(rotors)]
                + ['thrust_%d' % (i + 1) for i in range(rotors)]
                + (['moment_lost'] if rotors else []))

    def table(self, run: int = 0) -> np.ndarray:
        """One run's history: a row per step, in the columns' order."""
        a = self.arrays
        steps = len(a['t'])
        parts = [a['t'][:, None]] + [a[key][:, run].reshape(steps, -1) for key in (
            'q', 'w', 'eR', 'psi', 'u', 'dbar', 'dtrue', 'angle', 'cmd', 'thrust')]
        if a['cmd'].shape[-1]:
            parts.append(a['moment_lost'][:, run, None])
        return np.concatenate(parts, axis=1)
