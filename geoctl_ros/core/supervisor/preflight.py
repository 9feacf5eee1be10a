"""The arming checks (a preflight): every reason the controller must not arm now, as sentences."""
import math
from typing import Any, List, Optional


def arm_problems(loop: Any, now: float, extra_problem: Optional[str] = None) -> List[str]:
    """Every reason not to arm now (sentences; empty: it may), as a preflight check names
    them: no configuration given, extra_problem (the caller's, e.g. another publisher of the
    motor commands), each stale input, the sensors' disagreement (``core.sensors.consistency``),
    and the measured sensor inside a cone or within its
    guard (the barrier's widening cone_guard_deg plus its floor band barrier_floor_deg).
    """
    problems = [p for p in (loop.unconfigured, extra_problem, loop.esc_report_problem(now)) if p]
    problems += [p for p in (s.staleness(now) for s in loop.supervisor.streams) if p]
    problems += loop.agreement.arm_problems(now)
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
