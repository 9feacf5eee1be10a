"""What the controller's diagnostics say, composed from the loop's state (``ControlLoop.status``):
the level, the message's sentences and the typed figures, and the per-window counts they use.
"""
from dataclasses import dataclass
import math
from typing import Dict, List, Optional, Protocol, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry.flags import Flags
from geoctl_ros.core.geometry.so3 import Scalars
from geoctl_ros.core.supervisor.control_tick import BLIND_BOUND_S, SUSTAINED_BLIND_BOUND_S
from geoctl_ros.core.supervisor.gaps import GYRO, POSE, GapBridge
from geoctl_ros.core.supervisor.loop_types import LoopTick, StampT
from geoctl_ros.core.supervisor.preflight import LoopInputs
from geoctl_ros.core.telemetry.diagnostics import (
    ERROR,
    OK,
    WARN,
    Counts,
    Figures,
    Gaps,
    Status,
    Unlearnt,
)
from geoctl_ros.core.telemetry.stats import WindowStats

NEAR_CONE_DEG = 2.0           # a cone margin below this is reported (WARN)


@dataclass
class Window:
    """Counts over one diagnostics window (``end_window`` starts a new one)."""

    ticks: int = 0
    saturated: int = 0            # armed ticks with the allocation saturated
    bridging: int = 0             # armed ticks riding through a gap
    armed_ticks: int = 0
    blind_ms: int = 0             # the longest blind time of an armed tick
    steady_blind_ms: int = 0      # the shortest blind time of an armed tick (a sustained latency)
    gain_pct: int = 100           # the lowest degraded-mode gain scale of an armed tick
    unlearnt: float = 0.0         # rad/s^2: the largest acceleration the model did not know
    unlearnt_over: int = 0        # rate samples with it past the approach brake's a_u

    def note_unlearnt(self, residual: Optional[float], bound: float) -> bool:
        """A rate sample's acceleration the model did not know (None: no sample taught it this
        tick); whether it was past the bound.
        """
        if residual is None:
            return False
        self.unlearnt = max(self.unlearnt, residual)
        over = residual > bound
        self.unlearnt_over += over
        return over

    def note(self, armed: bool, saturated: Flags, bridging: bool, blind_s: Scalars,
             gain_scale: Scalars) -> None:
        """One tick: armed or not, its allocation saturated, riding a gap, its blind time (s)
        and the degraded mode's gain scale.
        """
        self.ticks += 1
        self.saturated += bool(armed and saturated)
        self.bridging += bool(armed and bridging)
        if armed:
            blind_ms = int(1e3 * blind_s)
            gain_pct = int(round(100.0 * float(gain_scale)))
            first = not self.armed_ticks
            self.blind_ms = max(self.blind_ms, blind_ms)
            self.steady_blind_ms = blind_ms if first else min(self.steady_blind_ms, blind_ms)
            self.gain_pct = gain_pct if first else min(self.gain_pct, gain_pct)
            self.armed_ticks += 1


class StatusLoop(LoopInputs, Protocol[StampT]):
    """What the diagnostics read of the loop besides its inputs (``LoopInputs``;
    ``core.supervisor.loop.ControlLoop``, which imports this module).
    """

    bridge: GapBridge
    last_tick: Optional[LoopTick[StampT]]
    entry: Optional[Tuple[str, float]]
    cone_entries: int
    window: Window
    pose_age: WindowStats
    rate_age: WindowStats
    gaps: Dict[str, List[float]]
    unlearnt_bound: float
    unlearnt_over: int
    setpoint_note: Optional[str]


def gap_notes(loop: StatusLoop[StampT], now: float) -> List[str]:
    """Sentences for the gaps being ridden through (empty in normal flight)."""
    notes = []
    b = loop.bridge
    if b.attitude_source is not POSE:
        notes.append('pose gap: attitude %s (pose %.3f s old, failsafe at %.3f s)'
                     % (b.attitude_source.value, loop.pose.age(now), loop.pose.limit))
    if b.rate_source is not GYRO:
        notes.append('angular velocity gap: rate %s (imu %.3f s old, failsafe at %.3f s)'
                     % (b.rate_source.value, loop.rate.age(now), loop.rate.limit))
    return notes


def status(loop: StatusLoop[StampT], now: float,
           other_commanders: Optional[str] = None) -> Status:
    """The diagnostics: level, message and figures. other_commanders is the node's sentence
    when another node publishes the motor commands (an error while armed).
    """
    errors: List[str] = []
    warnings: List[str] = []
    sup = loop.supervisor
    if not sup.armed:
        (errors if sup.failed else warnings).append(sup.reason)
        if loop.unconfigured:
            warnings.append(loop.unconfigured)
        stale = sup.input_problem(now)
        if stale:
            warnings.append(stale)
        escs = loop.esc_report_problem(now)
        if escs:
            warnings.append(escs)
        # what the sensor checks would refuse now (a ground station shows it before arming)
        warnings += ['sensor check: ' + p for p in loop.agreement.arm_problems(now)
                     if 'no recent window' not in p]
    else:
        lost = sup.input_loss(now)
        if lost:
            errors.append(lost)
        warnings += gap_notes(loop, now)
    for s in (loop.pose, loop.rate):
        reasons = s.take_refusals()
        if reasons:
            warnings.append('%s refused: %s (%d so far)' % (s.name, ' | '.join(reasons),
                                                             s.refused))
        untrusted = s.stamp_note()
        if untrusted:
            warnings.append(untrusted)
    tick = loop.last_tick
    out = tick.control if tick else None
    if sup.armed and loop.entry is not None:
        errors.append('sensor entered cone %r, %.2f deg deep (%d entr%s since arming)'
                      % (loop.entry[0], loop.entry[1], loop.cone_entries,
                         'y' if loop.cone_entries == 1 else 'ies'))
    cones = loop.setup.config.cones
    # (the last tick's cones: a reconfiguration since may have changed them until the next tick)
    margin: Optional[float]     # the closest cone's margin (deg); then the figures' least
    if out is not None and len(cones) and len(out.margins_deg) == len(cones):
        name, margin = cones.closest(out.margins_deg)
        near = max(NEAR_CONE_DEG, cones.band_deg)
        if out.violated:
            errors.append('sensor inside cone %r (margin %.2f deg)' % (name, margin))
        elif margin < near:
            warnings.append('near cone %r (margin %.2f deg)' % (name, margin))
    w = loop.window
    if sup.armed and w.steady_blind_ms > 1e3 * SUSTAINED_BLIND_BOUND_S:
        warnings.append('loop blind at least %d ms at every tick of the window (a sustained '
                        'latency): beyond the %.0f ms of the envelope tested and attacked '
                        '(docs/safety.md)'
                        % (w.steady_blind_ms, 1e3 * SUSTAINED_BLIND_BOUND_S))
    elif sup.armed and w.blind_ms > 1e3 * BLIND_BOUND_S:
        warnings.append('loop blind up to %d ms (inputs up to %.0f ms old by receipt, plus '
                        'their delay to receipt and late steps): beyond the %.0f ms of the '
                        'envelope tested and attacked (docs/safety.md)' % (w.blind_ms, 1e3 * max(
                            np.max(loop.pose_age.samples(), initial=0.0),
                            np.max(loop.rate_age.samples(), initial=0.0)),
                            1e3 * BLIND_BOUND_S))
    if sup.armed and w.unlearnt_over:
        warnings.append('the model did not know up to %.1f rad/s^2 of the acceleration at %d '
                        "rate samples (%d since the take-over), past the approach brake's a_u "
                        'of %.1f rad/s^2: its derivation does not hold (docs/safety.md); a '
                        'moment the model lacks (a disturbance, a wrong mass, centre of mass or '
                        'inertia)' % (w.unlearnt, w.unlearnt_over, loop.unlearnt_over,
                                      loop.unlearnt_bound))
    if sup.armed and w.armed_ticks and w.gain_pct < 100:
        warnings.append('degraded: feedback gains down to %d %% of their bandwidth while '
                        'blind past the bound' % w.gain_pct)
    if w.saturated:
        warnings.append('allocation saturated in %d of %d ticks'
                        % (w.saturated, w.ticks))
    if loop.setpoint_note:
        warnings.append(loop.setpoint_note)
    if other_commanders:
        (errors if sup.armed else warnings).append(other_commanders)
    level = ERROR if errors else WARN if warnings else OK
    margin = None
    if out is not None and len(out.margins_deg):
        margin = float(np.min(out.margins_deg))
    figures = Figures(
        armed=sup.armed, failsafe=sup.failed and not sup.armed, state=sup.reason,
        pose_age=loop.pose.age(now), imu_age=loop.rate.age(now),
        pose_counts=Counts(loop.pose.accepted, loop.pose.refused),
        imu_counts=Counts(loop.rate.accepted, loop.rate.refused),
        pose_age_at_tick=loop.pose_age.window(), imu_age_at_tick=loop.rate_age.window(),
        pose_delay=loop.pose.delays.window(), imu_delay=loop.rate.delays.window(),
        pose_stamps=loop.pose.stamps(), imu_stamps=loop.rate.stamps(),
        # (a gap record is [count, longest]: its count an int, which List[float] does not say)
        pose_gaps=Gaps(*cast(Tuple[int, float], loop.gaps['pose'])),
        imu_gaps=Gaps(*cast(Tuple[int, float], loop.gaps['angular velocity'])),
        ticks_bridging=w.bridging, ticks=w.ticks, cone_entries=loop.cone_entries,
        psi=None if out is None else float(out.psi), min_cone_margin_deg=margin,
        # (out is the last tick's control: not None, there is a last tick)
        motor_commands=None if out is None else tuple(
            int(c) for c in cast(LoopTick[StampT], tick).motors.commands),
        unlearnt=(Unlearnt(w.unlearnt, loop.unlearnt_bound, w.unlearnt_over,
                           loop.unlearnt_over)
                  if sup.armed and math.isfinite(loop.unlearnt_bound) else None))
    message = '; '.join(errors + warnings) or 'armed, all inputs fresh'
    return Status(level, message, figures)
