"""What the stages of a control step pass each other (``core.law.control``): the step's terms
before any law's choice, what a law's filter knows of the model, a law itself (its configuration
error and its filter), and the step's output. A law is data and a pure function: it takes the
step's terms and the model, never the controller.
"""
from typing import Callable, Literal, NamedTuple, Optional, Union, cast

from geoctl_ros.core.geometry.flags import Flags
from geoctl_ros.core.geometry.so3 import FloatArray, Scalars
from geoctl_ros.core.law.brake import ApproachBrake, BrakeInputs
from geoctl_ros.core.law.cones import ConeEval
from geoctl_ros.core.law.controller_config import ControllerConfig


class StepTerms(NamedTuple):
    """What a step computes from the attitude before any law's choice (one per run of a batch)."""

    A: FloatArray        # attractive error A, with a trailing axis of 1
    e_RA: FloatArray     # its gradient
    cones: ConeEval      # the cones at R (widened by the blind time, if any)
    M_g: FloatArray      # the model's gravity moment
    W: Optional[FloatArray]   # the regressor W(R) (None for the constant model, W = I)


class ControlOutput(NamedTuple):
    """One control step's results."""

    u: FloatArray            # control moment about the pivot, body frame, N m
    e_R: FloatArray
    e_Omega: FloatArray
    psi: Scalars
    delta_bar: FloatArray    # estimate used for this u
    violated: Flags          # sensor on or inside a cone
    saturated: Flags         # some barrier in its floor band (repulsion saturated)
    adapting: Union[Literal[False], Flags]   # the estimate advances this step (a flag, per run
                                             # of a batch)
    cones: Optional[ConeEval] = None   # the ConeEval the step used
    half_angles_deg: Optional[FloatArray] = None
    braking: Union[bool, Flags] = False      # the approach brake changed the law's moment
    brake_unmet: Union[bool, Flags] = False  # no moment within the rotors' limits met the
                                             # brake's condition
    W: Optional[FloatArray] = None   # the regressor W(R) the step used (None for the constant
                                     # model, W = I): the adaptive law's (``adapted``)
    # (in a batch, each field has the batch axis first: psi, violated, ... one per run)

    @property
    def margins_deg(self) -> FloatArray:
        """Per cone: angle between the sensor and the cone's axis minus its half-angle, degrees
        (computed when asked: the node publishes the motor commands first).
        """
        return cast(ConeEval, self.cones).margins_deg(cast(FloatArray, self.half_angles_deg))


class LawModel(NamedTuple):
    """What a law's filter knows of the model: the configuration (gains, inertia about the pivot
    J, cones, the rotors' limits), J^-1, and the approach brake's bounds (None: the brake off).
    """

    config: ControllerConfig
    J_inv: FloatArray
    brake: Optional[ApproachBrake]


# A law's filter: (the geometric moment's output, the step's terms, R, Omega, the model, the
# approach brake's inputs of the tick or None) -> the output with the moment the law commands
LawFilter = Callable[[ControlOutput, StepTerms, FloatArray, FloatArray, LawModel,
                      Optional[BrakeInputs]], ControlOutput]


class Law(NamedTuple):
    """A control law (a row of ``core.law.laws.LAWS``): whether its configuration error carries
    the cones' log barrier (else the attractive error alone), whether each cone is widened by the
    blind time, and its filter of the geometric moment (None: it commands that moment).
    """

    barrier: bool
    widened: bool
    filter: Optional[LawFilter] = None
