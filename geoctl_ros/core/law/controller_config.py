"""The controller's configuration (``ControllerConfig``): everything the control law needs, built
and validated by ``geoctl_ros.params``; notation as ``geoctl_ros.core.law.control``'s.
"""
from dataclasses import dataclass, field
import math
from typing import Optional

from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.mechanics import first_moment, pivot_inertia
from geoctl_ros.core.law.projection import Polytope

# Disturbance models: name -> number of estimated parameters (the columns of W).
#   constant:      W = I,                     Delta = a constant moment (the paper's case)
#   constant+cog:  W = [I, -hat(R^T g_w)],    Delta = [constant moment; error of m * rho]
DISTURBANCE_MODELS = {'constant': 3, 'constant+cog': 6}


@dataclass(frozen=True)
class ControllerConfig:
    """Everything the control law needs; built and validated by ``geoctl_ros.params``."""

    k_R: float
    k_Omega: float
    k_Delta: float
    c: float
    G: FloatArray                    # (3,) diagonal weights g1, g2, g3
    cones: ConeSet
    inertia: FloatArray              # (3, 3) about the centre of mass, kg m^2
    mass: float                      # kg
    cog_offset: FloatArray           # pivot -> centre of mass, body frame, m
    gravity: FloatArray              # world frame, m/s^2
    adaptive: bool = True
    gravity_compensation: bool = True
    disturbance_model: str = 'constant'
    delta_bar_max: float = 0.0       # bound on |constant estimate| (N m); 0 = none
    cog_estimate_max: float = 0.0    # bound on |m rho estimate| (kg m); 0 = none
    unmodelled_moment_max: float = 0.0   # what a set point must be held against (N m); 0 = none
    blind_guard_max: float = 0.0     # rad, the most a blind loop widens a cone's barrier
    law: str = 'delay_robust'        # the control law, a key of LAWS
    cbf_rate: float = 4.0            # 1/s, the cbf law's double pole
    cbf_moment_bound: float = 0.0    # N m, the unlearnt moment the cbf law's filter holds against
    k_Delta_cog: float = 0.0         # adaptation gain of the m*rho block (constant+cog model)
    guidance_lookahead: float = 0.0  # rad, guidance's set point at most this far ahead; 0 = off
    guidance_clearance: float = 0.0  # rad, guidance's path this far outside each cone's barrier
    approach_brake: bool = False      # the approach brake on (``core.law.brake``)
    brake_acceleration: float = 0.0   # rad/s^2, a_b: the deceleration the rotors can always
                                      # make (``core.law.brake.brake_authority``; set with the
                                      # rotors by ``params.controller_setup``)
    attitude_noise: float = 0.0       # rad, the attitude measurement's standard deviation
    gyro_noise: float = 0.0           # rad/s, the gyro's standard deviation
    tilt_max: float = math.pi         # rad, the joint's tilt limit (its stops)
    motor_lag: float = 0.0            # s, the rotors' thrust time constant the mixer models
    moment_limits: Optional[Polytope] = None   # the moments the rotors make unsaturated
                                          # (``Allocator.moment_polytope``); the brake and the
                                          # cbf law's QP keep them
    J: FloatArray = field(init=False, repr=False)        # inertia about the pivot
    m_rho: FloatArray = field(init=False, repr=False)    # mass times pivot -> centre of mass

    def __post_init__(self) -> None:
        object.__setattr__(self, 'J', pivot_inertia(self.inertia, self.mass, self.cog_offset))
        object.__setattr__(self, 'm_rho', first_moment(self.mass, self.cog_offset))

    @property
    def n_params(self) -> int:
        """Number of estimated disturbance parameters (length of Delta_bar)."""
        return DISTURBANCE_MODELS[self.disturbance_model]
