"""The simulated testbed from resolved sim parameters (``geoctl_ros.params.resolve``): the
``sim`` node's and the scenario runner's one way to build it.
"""
import math

from geoctl_ros.core.geometry import so3
from geoctl_ros.params import airframe
from geoctl_ros.sim.plant import Disturbance, PlantConfig
from geoctl_ros.sim.testbed import RotorActuator, TestbedSim


def testbed_sim(values: dict) -> TestbedSim:
    """The TestbedSim of resolved sim parameters, at its initial state."""
    actuator = None
    if values['actuation'] == 'rotors':
        geometry, curve, failed = airframe(values)
        actuator = RotorActuator(geometry, values['cog_offset'], curve,
                                 values['motor_time_constant'], failed)
    return TestbedSim(plant_config(values), so3.quat_to_rot(values['initial_attitude']),
                      values['initial_angular_velocity'], actuator,
                      math.radians(values['noise.attitude_deg']),
                      values['noise.angular_velocity'], values['noise.gyro_bias'],
                      values['noise.seed'])


def plant_config(values: dict) -> PlantConfig:
    """PlantConfig from resolved sim parameters."""
    return PlantConfig(
        inertia=values['inertia'].reshape(3, 3), mass=values['mass'],
        cog_offset=values['cog_offset'], gravity=values['gravity'],
        disturbance=Disturbance(constant=values['disturbance.constant'],
                                amplitude=values['disturbance.amplitude'],
                                frequency=values['disturbance.frequency']))

