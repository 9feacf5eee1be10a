"""The simulated testbed as its users see it: commands in, measurements out.

Composes the rigid body about the pivot (``geoctl_ros.sim.plant``), the actuation and the sensors:

- actuation ``rotors``: integer ESC commands -> thrust through the motors' thrust curve, a
  first-order lag per rotor (time constant ``motor_time_constant``, discretised exactly and held
  over each integration step), saturation at the curve's range, and the rotors' forces and reaction
  moments about the pivot (``geoctl_ros.core.actuation.airframe.effectiveness``) from the true
  geometry;
- actuation ``torque``: the commanded moment itself (ideal);
- sensors (``SensorNoise``, ``measured_attitude``, ``measured_rate``: the one place the batch's
  closed loop takes them from too): attitude R exp(hat(n)), n ~ N(0, sigma_R^2 I) (motion
  capture), and angular velocity Omega + bias + N(0, sigma_w^2 I) (gyro), and the specific force
  at the IMU (the sim node).

The sim node drives ``TestbedSim``. A batch (the scenario runner's and the campaign's closed
loop: ``geoctl_ros.sim.runs.Testbeds``) is the stack of the same typed set-ups
(``geoctl_ros.params.testbed``), flown with the same classes (a leading batch axis on the
plant's configuration and state and on the actuator's centre-of-mass offset) and the same
sensors' formulas, so the testbed and its noise are written once.
"""
import math
from typing import Optional

import numpy as np

from geoctl_ros.core.actuation.airframe import effectiveness
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import matvec
from geoctl_ros.core.sensors.frames import InputFrames
from geoctl_ros.params.testbed import SensorNoise, TestbedSetup, testbed_setup
from geoctl_ros.sim.plant import Plant


class RotorActuator:
    """Commands -> thrusts (lagged) -> moment about the pivot (rho (batch, 3): one per run)."""

    def __init__(self, geometry, rho, curve, time_constant, failed=()):
        self.curve = curve
        self.B_moment = effectiveness(geometry, rho)[..., 3:, :]
        self.time_constant = time_constant
        self.thrusts = np.zeros(self.B_moment.shape[:-2] + (geometry.count,))
        self._alive = np.ones(geometry.count)
        for i in failed:
            self._alive[i - 1] = 0.0
        self._h = None

    def moment(self, commands: np.ndarray, h: float) -> np.ndarray:
        """Advance the rotors by h with the commands held; the moment about the pivot."""
        if h != self._h:
            self._h, self._blend = h, 1.0 - math.exp(-h / self.time_constant)
        target = self.curve.thrust(commands) * self._alive
        self.thrusts += self._blend * (target - self.thrusts)
        return matvec(self.B_moment, self.thrusts)


class EscWatchdog:
    """The ESCs' command timeout: motors stop when no command has come for ``timeout`` seconds.

    Real ESCs watch the bus, and the bus keeps running while a simulator is descheduled or
    SIGSTOPped. A simulator that judged age by the wall clock after such a stall of its own would
    stop the motors for the whole catch-up it integrates next (the controller kept commanding; the
    simulator could not listen), an open-loop fall no vehicle would see. So the age is taken at the
    last moment the simulator was running: a tick more than ``stall`` after the previous one means
    the simulator itself stalled, and the command's age is judged as of that previous tick.
    Commands that really stopped are still caught: at the tick after the stall (the first one after
    the queued commands could arrive), the age is the wall clock's again.
    """

    def __init__(self, timeout, stall):
        self.timeout, self.stall = timeout, stall
        self.last_command = -math.inf
        self.last_tick = None

    def received(self, now: float) -> None:
        self.last_command = now

    def fresh(self, now: float) -> bool:
        """Whether the motors run for the integration due at ``now``; call once per tick."""
        stalled = self.last_tick is not None and now - self.last_tick > self.stall
        reference = self.last_tick if stalled else now
        self.last_tick = now
        return reference - self.last_command < self.timeout


def measured_attitude(R: np.ndarray, n_R: np.ndarray) -> np.ndarray:
    """What the motion capture measures of R (one or a stack) with the error n_R."""
    return so3.matmul(R, so3.exp(n_R))


def measured_rate(Omega: np.ndarray, bias: np.ndarray, n_w: np.ndarray) -> np.ndarray:
    """What the gyro reads of Omega (one or a stack) with its bias and the error n_w."""
    return Omega + bias + n_w


class TestbedSim:
    """Plant + actuation + sensors, integrated at a fixed step."""

    __test__ = False   # not a pytest test class

    def __init__(self, plant_config, R0, Omega0, actuator=None,
                 noise: Optional[SensorNoise] = None):
        self.plant = Plant(plant_config, R0, Omega0)
        self.actuator = actuator                  # None: ideal torque actuation
        self.noise = SensorNoise() if noise is None else noise
        self.rng = np.random.default_rng(self.noise.seed)   # (one sample at a time)

    def _error(self, sigma: float) -> np.ndarray:
        """A measurement's error, per axis normal with sigma (0: none, and nothing drawn)."""
        return sigma * self.rng.standard_normal(3) if sigma > 0.0 else np.zeros(3)

    def step(self, command: np.ndarray, h: float) -> None:
        """Advance by h: command is the integer ESC commands (rotors) or the moment (torque)."""
        tau = command if self.actuator is None else self.actuator.moment(command, h)
        self.plant.step(tau, h)

    def measure_attitude(self, R: Optional[np.ndarray] = None) -> np.ndarray:
        """Motion capture of the attitude now (or of R, a past one, for a delayed measurement)."""
        R = self.plant.R if R is None else R
        return measured_attitude(R, self._error(self.noise.attitude))

    def measure_angular_velocity(self, Omega: Optional[np.ndarray] = None,
                                 frames: Optional[InputFrames] = None) -> np.ndarray:
        """The gyro's reading now (or of Omega, a past angular velocity); with frames (an
        InputFrames), in the axes of an IMU of those conventions (the bias is in its axes).
        """
        w = self.plant.Omega if Omega is None else Omega
        if frames is not None:
            w = frames.source_vector(w)
        return measured_rate(w, self.noise.bias, self._error(self.noise.gyro))

    def specific_force(self, gravity: np.ndarray, position: np.ndarray,
                       alpha: np.ndarray) -> np.ndarray:
        """The specific force (body frame) at position (m from the pivot, body), with the angular
        acceleration alpha: a - g of that point, R^T(-g) + alpha x r + Omega x (Omega x r).
        """
        R, w = self.plant.R, self.plant.Omega
        return R.T @ -gravity + np.cross(alpha, position) + np.cross(w, np.cross(w, position))


def rotor_actuator(setup: TestbedSetup,
                   cog_offset: Optional[np.ndarray] = None) -> Optional[RotorActuator]:
    """The rotors' actuator of a testbed's set-up (None with torque actuation), about cog_offset
    (default: the plant's; a batch gives the stack of its runs').
    """
    r = setup.rotors
    if r is None:
        return None
    rho = setup.plant.cog_offset if cog_offset is None else cog_offset
    return RotorActuator(r.geometry, rho, r.curve, r.time_constant, r.failed)


def testbed_sim(values: dict) -> TestbedSim:
    """The TestbedSim of resolved sim parameters, at its initial state."""
    s = testbed_setup(values)
    return TestbedSim(s.plant, s.R0, s.Omega0, rotor_actuator(s), s.noise)
