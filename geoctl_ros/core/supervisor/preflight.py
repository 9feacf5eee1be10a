"""The arming checks (a preflight): every reason the controller must not arm now, as sentences."""
import math
from typing import List, Optional, Protocol

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.law.brake import opening
from geoctl_ros.core.law.control import AttitudeController
from geoctl_ros.core.sensors.consistency import SensorAgreement
from geoctl_ros.core.supervisor.control_tick import ControlTick
from geoctl_ros.core.supervisor.loop_types import Setup
from geoctl_ros.core.supervisor.safety import Stream, Supervisor


class LoopInputs(Protocol):
    """What the arming checks and the diagnostics (``core.supervisor.loop_status``) both read of
    the loop (``core.supervisor.loop.ControlLoop``, which imports them): its configuration, its
    input streams, its supervisor and the sensors' agreement.
    """

    unconfigured: Optional[str]
    supervisor: Supervisor
    agreement: SensorAgreement
    setup: Setup
    pose: Stream
    rate: Stream

    def esc_report_problem(self, now: float) -> Optional[str]: ...


class PreflightLoop(LoopInputs, Protocol):
    """What the arming checks read of the loop besides its inputs."""

    controller: AttitudeController
    R: Optional[FloatArray]
    Omega: Optional[FloatArray]
    step: ControlTick

    @property
    def holds_at_arming(self) -> bool: ...

    def hold_attitude(self) -> Optional[FloatArray]: ...


def arm_problems(loop: PreflightLoop, now: float,
                 extra_problem: Optional[str] = None) -> List[str]:
    """Every reason not to arm now (sentences; empty: it may), as a preflight check names
    them: no configuration given, extra_problem (the caller's, e.g. another publisher of the
    motor commands), each stale input, the sensors' disagreement (``core.sensors.consistency``),
    the set point an arming would fly (with ``arming_setpoint`` hold, the attitude now lifted off
    the joint's stops: ``ControlLoop.hold_attitude``),
    and the measured sensor inside a cone or within its
    guard (the barrier's widening cone_guard_deg plus its floor band barrier_floor_deg).
    """
    problems = [p for p in (loop.unconfigured, extra_problem, loop.esc_report_problem(now)) if p]
    problems += [p for p in (s.staleness(now) for s in loop.supervisor.streams) if p]
    problems += loop.agreement.arm_problems(now)
    if loop.holds_at_arming:     # the attitude now (off the stops) is what an arming flies
        R_hold = loop.hold_attitude()
        setpoint = None if R_hold is None else loop.controller.setpoint_problem(R_hold)
        if setpoint:
            problems.append('the attitude to hold: ' + setpoint)
    else:
        setpoint = loop.controller.setpoint_problem(loop.controller.R_d)
        if setpoint:
            problems.append('set point: ' + setpoint)
    cones = loop.setup.config.cones
    if loop.R is not None and len(cones):
        guard = cones.band_deg
        margins = cones.margins_deg(loop.R)
        for name, margin in zip(cones.names, margins):
            if margin <= 0.0:
                problems.append('sensor inside cone %r (%.2f deg in)' % (name, -margin))
            elif margin < guard:
                problems.append('sensor within the guard of cone %r (margin %.2f deg, '
                                'guard %.2f deg)' % (name, margin, guard))
        problems += takeover_problems(loop, now)
    return problems


def takeover_problems(loop: PreflightLoop, now: float) -> List[str]:
    """Where the approach brake could not keep a cone from the take-over after an arming now
    (``core.law.brake.rows``' margin of the state then, ``ControlTick.takeover_inputs``: the
    vehicle held or resting where it is while the rotors spool up, the gravity moment at its
    tilt that the spooled rotors do not yet hold, the unlearnt acceleration a_u over the
    measurements' age, the rotors' lag): a sentence per cone, naming the predicted closest
    approach.
    """
    controller = loop.controller
    R, Omega = loop.R, loop.Omega
    if controller.brake is None or R is None or Omega is None:
        return []                       # (no state yet: arm_problems names the missing input)
    ages = [s.capture_age(now) for s in (loop.pose, loop.rate) if s.last_receipt is not None]
    margin = loop.step.takeover_margins(R, Omega, max(ages, default=0.0),
                                        1.0 / loop.setup.loop.rate_hz)
    cones = controller.config.cones
    gap = np.degrees(opening(cones, R, Omega)[0])
    return ['the approach brake could not keep cone %r once the rotors have spooled up: '
            'predicted closest approach %.2f deg (from %.2f deg out, in the worst case of the '
            "spool-up and the brake's bounds): arm further from it, or level the vehicle"
            % (name, math.degrees(m), gap_i)
            for name, m, gap_i in zip(cones.names, np.ravel(margin), np.ravel(gap)) if m < 0.0]
