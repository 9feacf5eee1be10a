"""The simulated testbed from resolved sim parameters (``geoctl_ros.params.resolve``), once:
``testbed_setup`` is the typed set-up of one testbed, which the sim node's ``TestbedSim`` and a
batch's ``geoctl_ros.sim.runs.Testbeds`` (the stack of its runs' set-ups) are built from.
"""
from dataclasses import dataclass
import math
from typing import Any, Optional

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.params import airframe
from geoctl_ros.sim.plant import Disturbance, PlantConfig
from geoctl_ros.sim.testbed import RotorActuator, SensorNoise, TestbedSim


@dataclass(frozen=True)
class Rotors:
    """The rotors' actuation: the airframe (``params.airframe``) and the motors' lag."""

    geometry: Any
    curve: Any
    failed: list
    time_constant: float


@dataclass(frozen=True)
class TestbedSetup:
    """One simulated testbed: its plant, initial state, actuation (None: the commanded moment
    itself) and sensors' noise.
    """

    __test__ = False   # not a pytest test class

    plant: PlantConfig
    R0: np.ndarray
    Omega0: np.ndarray
    rotors: Optional[Rotors]
    noise: SensorNoise

    def actuator(self, cog_offset: Optional[np.ndarray] = None) -> Optional[RotorActuator]:
        """The rotors' actuator (None with torque actuation), about cog_offset (default: the
        plant's; a batch gives the stack of its runs').
        """
        r = self.rotors
        if r is None:
            return None
        rho = self.plant.cog_offset if cog_offset is None else cog_offset
        return RotorActuator(r.geometry, rho, r.curve, r.time_constant, r.failed)


def testbed_setup(values: dict) -> TestbedSetup:
    """The TestbedSetup of resolved sim parameters."""
    rotors = None
    if values['actuation'] == 'rotors':
        geometry, curve, failed = airframe(values)
        rotors = Rotors(geometry, curve, failed, values['motor_time_constant'])
    return TestbedSetup(plant_config(values), so3.quat_to_rot(values['initial_attitude']),
                        values['initial_angular_velocity'], rotors,
                        SensorNoise(math.radians(values['noise.attitude_deg']),
                                    values['noise.angular_velocity'],
                                    np.asarray(values['noise.gyro_bias'], dtype=float),
                                    values['noise.seed']))


def testbed_sim(values: dict) -> TestbedSim:
    """The TestbedSim of resolved sim parameters, at its initial state."""
    s = testbed_setup(values)
    return TestbedSim(s.plant, s.R0, s.Omega0, s.actuator(), s.noise)


def plant_config(values: dict) -> PlantConfig:
    """PlantConfig from resolved sim parameters."""
    return PlantConfig(
        inertia=values['inertia'].reshape(3, 3), mass=values['mass'],
        cog_offset=values['cog_offset'], gravity=values['gravity'],
        disturbance=Disturbance(constant=values['disturbance.constant'],
                                amplitude=values['disturbance.amplitude'],
                                frequency=values['disturbance.frequency']))

