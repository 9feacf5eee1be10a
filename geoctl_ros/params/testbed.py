"""The simulated testbed's set-up, typed, from resolved sim parameters: its plant (``PlantConfig``,
``Disturbance``), initial state, rotors and sensors' noise (``SensorNoise``), written once for the
sim node, a scenario and every run of a batch (``testbed_setup``).
"""
from dataclasses import dataclass, field
import math
from typing import Any, Optional

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.law.mechanics import first_moment, pivot_inertia
from geoctl_ros.params.build import airframe


@dataclass(frozen=True)
class Disturbance:
    """Delta(t) = constant + amplitude * [sin wt, cos wt, (sin wt + cos wt)/2], body frame, N m."""

    constant: np.ndarray
    amplitude: np.ndarray
    frequency: float  # rad/s

    def __post_init__(self):
        object.__setattr__(self, '_varying', bool(np.any(self.amplitude)))

    def __call__(self, t):
        if not self._varying:
            return self.constant
        s, c = math.sin(self.frequency * t), math.cos(self.frequency * t)
        return self.constant + self.amplitude * np.array([s, c, 0.5 * (s + c)])  # (not batched)


@dataclass(frozen=True)
class PlantConfig:
    """Physical parameters of the testbed; built and validated by ``geoctl_ros.params``."""

    inertia: np.ndarray      # about the centre of mass, kg m^2
    mass: float              # kg
    cog_offset: np.ndarray   # pivot -> centre of mass, body frame, m
    gravity: np.ndarray      # world frame, m/s^2
    disturbance: Disturbance
    tilt_max: float = math.pi   # rad, the joint's stops: the body's z axis from upright, at most
    J: np.ndarray = field(init=False, repr=False)        # inertia about the pivot
    m_rho: np.ndarray = field(init=False, repr=False)    # mass times pivot -> centre of mass

    def __post_init__(self):
        object.__setattr__(self, 'J', pivot_inertia(self.inertia, self.mass, self.cog_offset))
        object.__setattr__(self, 'm_rho', first_moment(self.mass, self.cog_offset))


@dataclass(frozen=True)
class SensorNoise:
    """The sensors' errors of one testbed, written once for the sim node and a batch: the motion
    capture measures R exp(n_R) and the gyro Omega + bias + n_w (in the IMU's axes), with n_R and
    n_w normal, ``attitude`` (rad) and ``gyro`` (rad/s) per axis, drawn from ``seed``.
    """

    attitude: float = 0.0
    gyro: float = 0.0
    bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    seed: int = 0

    def drawn(self, steps: int) -> np.ndarray:
        """(n_R, n_w) of ``steps`` measurements taken together, (2, steps, 3), as a batch draws
        them: from the seed's stream, per measurement the attitude's 3 then the gyro's 3 (only
        those whose level is not 0; the others are 0).
        """
        sigmas = (self.attitude, self.gyro)
        drawn = [i for i, sigma in enumerate(sigmas) if sigma > 0.0]
        z = np.random.default_rng(self.seed).standard_normal((steps, len(drawn), 3))
        out = np.zeros((2, steps, 3))
        for slot, i in enumerate(drawn):
            out[i] = sigmas[i] * z[:, slot]
        return out


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
    itself), sensors' noise and integration rate; what the sim node's ``TestbedSim`` and a batch's
    ``geoctl_ros.sim.runs.Testbeds`` (the stack of its runs' set-ups) are built from.
    """

    __test__ = False   # not a pytest test class

    plant: PlantConfig
    R0: np.ndarray
    Omega0: np.ndarray
    rotors: Optional[Rotors]
    noise: SensorNoise
    integration_rate_hz: float   # the plant's integration step's rate


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
                                    values['noise.seed']),
                        values['integration_rate_hz'])


def plant_config(values: dict) -> PlantConfig:
    """PlantConfig from resolved sim parameters."""
    return PlantConfig(
        inertia=values['inertia'].reshape(3, 3), mass=values['mass'],
        cog_offset=values['cog_offset'], gravity=values['gravity'],
        disturbance=Disturbance(constant=values['disturbance.constant'],
                                amplitude=values['disturbance.amplitude'],
                                frequency=values['disturbance.frequency']),
        tilt_max=math.radians(values['joint_tilt_max_deg']))
