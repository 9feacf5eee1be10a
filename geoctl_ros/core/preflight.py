"""The arming checks (a preflight): every reason the controller must not arm now, as sentences."""
import math
from typing import Any, List, Optional

import numpy as np

ARM_RATE_DISAGREE = 0.3      # rad/s (+ half the poses' rate): gyro against poses, at arming


def arm_problems(loop: Any, now: float, extra_problem: Optional[str] = None) -> List[str]:
    """Every reason not to arm now (sentences; empty: it may), as a preflight check names
    them: no configuration given, extra_problem (the caller's, e.g. another publisher of the
    motor commands), each stale input, and the measured sensor inside a cone or within its
    guard (the barrier's widening cone_guard_deg plus its floor band barrier_floor_deg).
    """
    problems = [p for p in (loop.unconfigured, extra_problem, loop.esc_report_problem(now)) if p]
    problems += [p for p in (s.staleness(now) for s in loop.supervisor.streams) if p]
    if loop.Omega is not None:
        w_poses = loop.bridge.pose_rate()
        # (judged only where the poses resolve the rate: at most 1 rad turned per window)
        if w_poses is not None and loop.bridge.rate_window * max(
                np.linalg.norm(loop.Omega), np.linalg.norm(w_poses)) < 1.0:
            gap = float(np.linalg.norm(loop.Omega - w_poses))
            # (the poses' rate is a mean over the window: it lags a turning vehicle)
            if gap > ARM_RATE_DISAGREE + 0.5 * float(np.linalg.norm(w_poses)):
                problems.append('the gyro and the poses disagree by %.2f rad/s (the imu '
                                'frame or axes wrong?)' % gap)
    setpoint = loop.controller.setpoint_problem(loop.controller.R_d)
    if setpoint:
        problems.append('set point: ' + setpoint)
    cones = loop.setup.config.cones
    if loop.R is not None and len(cones):
        guard = math.degrees(cones.guard + cones.floor)
        margins = cones.margins_deg(loop.R)
        for name, margin in zip(cones.names, margins):
            if margin <= 0.0:
                problems.append('sensor inside cone %r (%.2f deg in)' % (name, -margin))
            elif margin < guard:
                problems.append('sensor within the guard of cone %r (margin %.2f deg, '
                                'guard %.2f deg)' % (name, margin, guard))
    return problems
