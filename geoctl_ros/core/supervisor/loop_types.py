"""The controller loop's typed values: its settings (built once at configuration) and one tick's
result; and the period of a step that a sample starts.
"""
from dataclasses import dataclass
from typing import Generic, Optional, Protocol, Tuple, TypeVar, Union

from geoctl_ros.core.actuation.motors import Mixer, MotorOutput
from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.law.controller_config import ControllerConfig
from geoctl_ros.core.law.step_types import ControlOutput
from geoctl_ros.core.sensors.consistency import AgreementSettings
from geoctl_ros.core.sensors.frames import InputFrames
from geoctl_ros.core.supervisor.gaps import AttitudeSource, RateSource
from geoctl_ros.core.supervisor.safety import SetpointSchedule


def step_period(since: float, period: float) -> float:
    """The dt of a step started by a sample (``step_on``): the time since the last step, within
    half to twice the control period. A burst of samples must not make a step of almost no time:
    the mixer's lag compensation would then command the extreme thrust, and the motors would hold
    it for the whole wait until the next sample.
    """
    return min(max(since, 0.5 * period), 2.0 * period)


# the type of the stamps a loop's caller gives offer_pose in its own form (``stamp_as_given``) and
# gets back on the ticks: the node's message header stamps; tests give none (the float stamp)
StampT = TypeVar('StampT')


@dataclass(frozen=True)
class LoopSettings:
    """The loop's and the node's settings, typed, built once from the parameters at configuration
    (``geoctl_ros.params.controller_setup``); nothing on the hot path reads the parameter dict.
    """

    rate_hz: float                 # the control timer
    step_on: str                   # 'timer', 'pose' or 'imu': what starts a control step
    pose_timeout: float            # s: a pose older than this is stale
    pose_ride_through: float       # s: how long a stale pose is ridden through (0: not at all)
    imu_timeout: float
    imu_ride_through: float
    pose_rate_window: float        # s: the poses a rate is differenced from during an imu gap
    max_angular_velocity: float    # rad/s: an imu sample faster than this is refused
    measurement_delay: float       # s: the inputs' latency when their stamps do not give it
    age_from_stamps: bool          # the inputs' ages from their capture stamps (synced clocks)
    allow_default_configuration: bool   # may arm without a parameter file (the opt-in)
    arming_setpoint: str           # 'hold': an arming holds the attitude measured then;
                                   # 'configured': it flies the set point and the schedule
    frame_id: str                  # the body frame of the published vectors
    world_frame_id: str


@dataclass
class LoopTick(Generic[StampT]):
    """One control tick's results: everything the node publishes and logs."""

    control: Optional[ControlOutput]   # None before the first pose and rate
    motors: MotorOutput      # zero commands unless armed
    armed: bool
    # stamp of the pose the step used, as offer_pose was given it (the node's header stamp, for
    # exact-time matching; the float stamp when given none; None before the first pose)
    stamp: Union[float, StampT, None]
    pose_receipt: Optional[float]   # when that pose was received, on the loop's clock (or None)
    state: str               # the supervisor's state: 'armed', or why not
    failed: bool             # disarmed by a failsafe
    sources: Tuple[AttitudeSource, RateSource]   # (attitude source, rate source): POSE/GYRO, or
                                                 # a gap's stand-ins
    setpoint: FloatArray     # R_d being flown (the same object until a new one is adopted)
    bridging: bool = False   # a gap is being ridden through (see geoctl_ros.core.supervisor.gaps)
    # (R, Omega) the step flew on, in the package's frames (a gap's stand-ins while bridging), or
    # None before the first
    measured: Optional[Tuple[FloatArray, FloatArray]] = None



class Setup(Protocol):
    """What the loop takes of a controller's setup (``geoctl_ros.params.build.ControllerSetup``,
    which params builds: params is above core).
    """

    config: ControllerConfig
    mixer: Mixer
    setpoint: FloatArray
    schedule: SetpointSchedule
    loop: LoopSettings
    frames: InputFrames
    agreement: AgreementSettings
