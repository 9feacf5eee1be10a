"""The approach brake: every cone's margin kept for the loop as it runs, sampled, held and delayed
(docs/safety.md, "The approach brake").

The loop. At a tick the controller has measurements T_b old (their age from capture); it
predicts the state at the tick by its model and the moments already commanded, then commands a
moment that is held for the hold h. The rotors follow with their first-order lag tau: the mixer's
compensation brings them to the command by the end of the hold where the command is within their
reach in one hold, and that reach is a shrunk copy of their moment polytope P round the moment
they make now, M_s: a M_s + (1 - a) P, a = exp(-h / tau) (``reachable``). So the moment the
rotors make moves monotonically from M_s to the command over the hold, and no faster than the
lag allows: from one hold to the next at most (1 - a) of the way to P's edge.

One cone, in one axis. Let g = phi - theta be the sensor's gap to the cone (its angle to the
axis less the half-angle), w = -dg/dt its approach rate, and D the deceleration of w that the
moment the rotors make gives by the brake's model (``brake_terms``: D = n . J^-1 (M + f) - kin,
n the cone's opening direction, f the model's moment besides the rotors' (gravity, the estimate,
the gyroscopic term, the observed model error), kin the approach's kinematic term). Then
dw/dt = -D + d with |d| <= a_u: a_u bounds what the model, frozen at the tick, does not know
over a hold. Bounds (numbers from the parameters; docs/safety.md has the testbed's):
- e, e_w: the attitude's and the gyro's measurement errors (3 standard deviations);
- a_u: the unknown acceleration (``cbf_moment_bound`` over the smallest pivot inertia);
- a_b: the deceleration the rotors' polytope gives along any opening direction, gravity at the
  joint's tilt limit counted (``brake_authority``).
The prediction is off by at most dw = e_w + e |Omega| / sin phi + a_u T_b in w (phi the
sensor's angle to the axis) and dg = e + (e_w + e |Omega| / sin phi) T_b + a_u T_b^2 / 2 in
g, so the brake takes the worst state in that box:
w0 = w + dw, G0 = g - dg.

The backup. From a tick with the rotors at D_s, braking as hard as the lag lets: over the first
hold the deceleration is at least min(D_s, D_1), D_1 = a D_s + (1 - a) a_b, and then rises as
a_b - (a_b - D_1) exp(-t / tau) (the compensated rotors asked for their most each hold follow
their lag exactly); it is concave, so its chord over each of ``BACKUP_SPANS`` (in time
constants) bounds it from below, and after them it is held at the level reached, for ever; a_u
pushes in throughout.
The peak of its worst-case travel towards the cone (``backup_travel``) within the gap is the
safe set: Phi = G0 - peak >= 0.

The condition. A command whose deceleration at the end of its hold is D keeps the state safe at
the next tick if the travel over its hold (deceleration at least min(D_s, D)) and the backup
from D after it peaks within G0 (``least_deceleration``: the least such D, from above). By
induction the true state stays in the safe set at every tick, and the sensor out of the cone
between them: the backup's own first command always meets the condition where Phi >= 0. Past
the curve (Phi < 0: at a take-over after a fall, after the bounds broke, or inside a cone) the
brake asks for the backup, the rotors' hardest deceleration within reach, until it is back.

Several cones are joined: each condition is a row on the moment, (J^-1 n_i) . u >= beta_i, and
the law's moment, where it breaks one, is replaced by the closest moment that meets every row
within the rotors' reach this hold (``core.law.projection.project``); where the rows conflict
(a narrow corridor between two cones, at speed), by the closest that meets them all relaxed by
the least common amount.

Assumptions (what "derived" covers): the bounds above hold over every hold (judged per step by
``covered``), the allocation is not saturated and the lag compensation not clipped (the rotors
make the moment commanded by the end of the hold), each command is held no longer than its
designed hold, and the state is safe (Phi >= 0) at the start.
"""
from dataclasses import dataclass
import functools
import math
from typing import Dict, List, NamedTuple, Optional, Sequence, Tuple, Union, cast

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.elementwise import (
    ARRAYS,
    FLOATS,
    Flag,
    Ops,
    Value,
    evaluate,
    matrix_parts,
    one_run,
    vector_parts,
)
from geoctl_ros.core.geometry.flags import Flags
from geoctl_ros.core.geometry.so3 import BoolArray, FloatArray, Scalars
from geoctl_ros.core.law.cones import ConeSet
from geoctl_ros.core.law.controller_config import ControllerConfig
from geoctl_ros.core.law.mechanics import Parts, Rows
from geoctl_ros.core.law.projection import TOL, Polytope, project, slack_of

# ``_worst``: per cone G0, w0, the rotors' deceleration, the backup's first command, Phi (and
# with a law's deceleration, the travel after it)
Worst = Tuple[Scalars, ...]

SIGMAS = 3.0      # the measurement errors are bounded at this many standard deviations
NET_SHARE_MIN = 0.25   # the backup must out-brake a_u by at least this share of a_b
BACKUP_SPANS = (0.25, 0.25, 0.5, 1.0, 2.0)   # the backup's rise, followed over these spans (in
                       # time constants; its chord over each): 4 of them, e^-4 of its deficit left
FALSI_STEPS = 10       # the least deceleration's regula falsi steps (within 1 rad/s^2 of the
                       # least: test_brake)


@dataclass(frozen=True)
class ApproachBrake:
    """The brake's bounds (see the module)."""

    authority: float        # rad/s^2, a_b: the deceleration the rotors can always make
    unmodelled: float       # rad/s^2, a_u: what the model does not know over a hold
    measurement: float      # rad, e: the attitude measurement's error
    rate_error: float       # rad/s, e_w: the gyro's error
    lag: float              # s, tau: the rotors' thrust time constant (0: none modelled)

    @classmethod
    def of(cls, config: ControllerConfig) -> Optional['ApproachBrake']:
        """The brake of a ControllerConfig, or None when it is off."""
        return cls.bounds_of(config) if config.approach_brake else None

    @classmethod
    def bounds_of(cls, config: ControllerConfig) -> 'ApproachBrake':
        """The brake's bounds of a ControllerConfig, whether or not its law brakes (what a
        flight is judged against: ``covered``).
        """
        return cls(config.brake_acceleration,
                   unmodelled_acceleration(config.cbf_moment_bound, config.J),
                   SIGMAS * config.attitude_noise, SIGMAS * config.gyro_noise,
                   config.motor_lag)

    def uncertainty(self, T_b: Scalars, spin: Scalars) -> Tuple[Scalars, Scalars]:
        """(dg, dw): how far the predicted gap (rad) and approach rate (rad/s) can be from the
        truth, with measurements T_b old (s) and spin = |Omega| / sin phi (rad/s; phi the
        sensor's angle to the cone's axis: an attitude error e turns the opening direction n by
        up to e / sin phi, so w = -n . Omega is off by up to e |Omega| / sin phi): the
        measurement errors, and a_u acting over T_b.
        """
        e_w = self.rate_error + self.measurement * spin
        return (self.measurement + e_w * T_b + 0.5 * self.unmodelled * T_b * T_b,
                e_w + self.unmodelled * T_b)

    def keep(self, hold: float) -> float:
        """a = exp(-h / tau): the share of the rotors' gap to a new command left after a hold
        (0 without a lag).
        """
        return math.exp(-hold / self.lag) if self.lag > 0.0 else 0.0


def unmodelled_acceleration(moment_bound: float, J: FloatArray) -> float:
    """a_u: the largest angular acceleration (rad/s^2) an unlearnt moment of moment_bound (N m)
    gives, over the smallest principal inertia of J.
    """
    return moment_bound / so3.symmetric_eigenvalues(J)[0]


def _stop(ops: Ops, turn: Flag, x: Value, w: Value, acc0: Value, c: Value, T: float) -> Value:
    """The travel at the stop within a phase that starts at travel x and rate w, its
    acceleration acc0 + 2 c t for t in [0, T] (where w falls through 0 within it, ``turn``:
    w > 0 > the rate at T; else x): the root of w + acc0 t + c t^2. (An ``elementwise``
    formula.)
    """
    disc = ops.maximum(acc0 * acc0 - 4.0 * c * w, 0.0)
    linear = (c < 1e-12) & (c > -1e-12)            # |c| < 1e-12
    root = ops.where(linear, -w / ops.where(acc0 < 0.0, acc0, -1.0),
                     (-acc0 - ops.sqrt(disc)) / ops.where(linear, 1.0, 2.0 * c))
    root = ops.where((root > 0.0) & (root < T), root, ops.where(
        linear, root, (-acc0 + ops.sqrt(disc)) / ops.where(linear, 1.0, 2.0 * c)))
    t = ops.minimum(ops.maximum(root, 0.0), T)
    return ops.where(turn, x + (w + (0.5 * acc0 + c * t / 3.0) * t) * t, x)


def _shares(spans: Tuple[float, ...]) -> Tuple[float, ...]:
    """The share of the backup's deficit left at the start of each span and after the last
    (exp of minus the spans so far, multiplied in turn).
    """
    shares = [1.0]
    for span in spans:
        shares.append(shares[-1] * math.exp(-span))
    return tuple(shares)


SHARES = _shares(BACKUP_SPANS)
_ANY_BRAKE = ApproachBrake(1.0, 0.0, 0.0, 0.0, 0.0)     # (``opening``'s: its terms need none)


class Phases(NamedTuple):
    """What the backup's travel integrates, the same at every tick of a flight: a_u, the
    phases' durations (the hold, then each of ``BACKUP_SPANS`` in time constants; s) and the
    share of the backup's deficit left at each span's ends (``SHARES``).
    """

    unmodelled: float
    durations: Tuple[float, ...]
    shares: Tuple[float, ...]
    total: float          # s, the phases' durations together


@functools.lru_cache(maxsize=64)
def phases(brake: 'ApproachBrake', hold: float) -> Phases:
    """The backup's ``Phases`` for a brake and a hold."""
    spans = BACKUP_SPANS if brake.lag > 0.0 else ()
    durations = (hold,) + tuple(span * brake.lag for span in spans)
    return Phases(brake.unmodelled, durations, SHARES[:len(spans) + 1], math.fsum(durations))


def _travel(ops: Ops, p: Phases, w0: Value, D_s: Value, D: Value, authority: Value) -> Value:
    """``backup_travel`` of one element (an ``elementwise`` formula)."""
    a_u = p.unmodelled
    low = a_u - ops.minimum(D_s, D)
    nil = 0.0 * low
    gap_left = authority - ops.minimum(D, authority)        # the backup's deficit to a_b
    level = [a_u - (authority - share * gap_left) for share in p.shares]  # at each span's ends
    w = w0 + nil
    x = 0.0 * w0 + nil
    best = x
    for k, T in enumerate(p.durations):
        acc0 = low if k == 0 else level[k - 1] + nil
        acc1 = low if k == 0 else level[k] + nil
        c = 0.5 * (acc1 - acc0) / T
        x_T = x + (w + (0.5 * acc0 + c * T / 3.0) * T) * T
        w_T = w + (acc0 + c * T) * T
        turn = (w > 0.0) & (w_T < 0.0)           # (a stop within it: its travel there)
        peak = ops.maximum(_stop(ops, turn, x, w, acc0, c, T) if ops.some(turn) else x, x_T)
        best = peak if k == 0 else ops.maximum(best, peak)
        w, x = w_T, x_T
    best = ops.maximum(best, 0.0 * w0)
    final = level[-1]                                       # (< 0: see NET_SHARE_MIN)
    rising = ops.maximum(w, 0.0)
    return ops.maximum(best, x + rising * rising / (2.0 * ops.maximum(-final, 1e-9)))


TRAVEL_SURE = 1e-6    # rad: a travel bounded this far within the gap is within it, whatever the
                      # rounding of its exact working out (``_surely_met``)


def _travel_bound(ops: Ops, p: Phases, w0: Value, D_s: Value, D: Value, authority: Value) -> Value:
    """An upper bound of ``_travel`` of the same arguments, in a few operations (an
    ``elementwise`` formula). Over every phase the acceleration towards the cone is at most
    A = a_u - min(D_s, D) (the hold's; the backup's levels after it only fall), so by the end of
    the phases (their total T) the rate is at most w+ + A+ T and the travel, and every peak on
    the way, at most w+ T + A+ T^2 / 2 (w+ = max(w0, 0), A+ = max(A, 0)); after them the
    deceleration is the last level's, as ``_travel`` takes it, so its tail is at most
    (w+ + A+ T)^2 / (2 max(-final, 1e-9)). It does not rise with D.
    """
    a_u = p.unmodelled
    A = ops.maximum(a_u - ops.minimum(D_s, D), 0.0)
    w = ops.maximum(w0, 0.0)
    T = p.total
    final = a_u - (authority - p.shares[-1] * (authority - ops.minimum(D, authority)))
    rising = w + A * T
    return w * T + 0.5 * A * T * T + rising * rising / (2.0 * ops.maximum(-final, 1e-9))


def backup_travel(brake: ApproachBrake, w0: Scalars, D_s: Scalars, D: Scalars, authority: Scalars,
                  hold: float) -> Scalars:
    """The farthest (rad) the sensor travels towards the cone in the worst case from a tick with
    the approach w0 (rad/s) and the rotors at D_s: a command reaching D at the end of its hold
    (the deceleration over it at least min(D_s, D)), then the backup (see the module) to
    ``authority`` (a_b; per cone), a_u pushing in throughout. After the hold the backup's
    deceleration rises as a_b - (a_b - D) exp(-t / tau) (the compensated rotors asked for their
    most each hold follow their lag exactly), so over each of ``BACKUP_SPANS`` its chord is a
    lower bound of it; after them it stays at the level reached. Floats or arrays alike.

    The phases (the hold, then the spans) are integrated in turn: each phase's acceleration
    goes linearly from acc0 to acc1 over its T, so its rate and travel at its end are the
    start's plus (acc0 + c T) T and (w + (acc0 / 2 + c T / 3) T) T (c = (acc1 - acc0) / 2 T),
    and the farthest point is a phase's end or the stop within one (``_stop``).
    """
    p = phases(brake, hold)
    return evaluate(lambda ops, *v: _travel(ops, p, *v), w0, D_s, D, authority)


def backup_margin(brake: ApproachBrake, gap: Scalars, w: Scalars, D_s: Scalars, authority: Scalars,
                  hold: float) -> Scalars:
    """Phi (rad): the gap left when the backup stops an approach w (rad/s) with the rotors at
    D_s now (taken at most a_b): >= 0 on the safe set.
    """
    Ds = np.minimum(D_s, authority)
    first = backup_first(brake, Ds, authority, hold)
    return gap - backup_travel(brake, w, Ds, first, authority, hold)


def backup_first(brake: ApproachBrake, D_s: Scalars, authority: Scalars, hold: float) -> Scalars:
    """D_1: where the backup's first command takes the rotors by the end of the hold, a D_s +
    (1 - a) a_b (their reach in one hold towards a_b).
    """
    keep = brake.keep(hold)
    return keep * D_s + (1.0 - keep) * authority


def _worst_box(ops: Ops, brake: ApproachBrake, keep: float, gap: Value, w: Value, D_s: Value,
               age: Value, spin: Value, authority: Value) -> Tuple[Value, Value, Value, Value]:
    """The worst state of the uncertainty box of one element (an ``elementwise`` formula): G0,
    w0, the rotors' deceleration now taken at most a_b, the backup's first command.
    """
    dg, dw = brake.uncertainty(age, spin)
    Ds = ops.minimum(D_s, authority)
    return gap - dg, w + dw, Ds, keep * Ds + (1.0 - keep) * authority     # (backup_first)


def _worst_state(ops: Ops, brake: ApproachBrake, p: Phases, keep: float, gap: Value, w: Value,
                 D_s: Value, age: Value, spin: Value, authority: Value) -> Worst:
    """``_worst`` of one element without a law (an ``elementwise`` formula)."""
    G0, w0, Ds, first = _worst_box(ops, brake, keep, gap, w, D_s, age, spin, authority)
    return G0, w0, Ds, first, G0 - _travel(ops, p, w0, Ds, first, authority)


def _worst_with_law(ops: Ops, brake: ApproachBrake, p: Phases, keep: float, gap: Value,
                    w: Value, D_s: Value, age: Value, spin: Value, authority: Value,
                    law: Value) -> Tuple[Union[Value, Flag], ...]:
    """``_worst`` of one element with the law's deceleration, and whether the law meets the
    condition there (``_met``; an ``elementwise`` formula).
    """
    G0, w0, Ds, first = _worst_box(ops, brake, keep, gap, w, D_s, age, spin, authority)
    return _with_law(ops, p, G0, w0, Ds, first, authority, law)


def _with_law(ops: Ops, p: Phases, G0: Value, w0: Value, Ds: Value, first: Value,
              authority: Value, law: Value) -> Tuple[Union[Value, Flag], ...]:
    """``_worst_with_law`` from the worst state of the uncertainty box."""
    backup, travel = ops.both(lambda D: _travel(ops, p, w0, Ds, D, authority), first, law)
    margin = G0 - backup
    return G0, w0, Ds, first, margin, travel, _met(margin, first, law, travel, G0)


def _surely_met(ops: Ops, p: Phases, G0: Value, w0: Value, Ds: Value, first: Value,
                authority: Value, law: Value) -> Flag:
    """Where the law's deceleration surely meets the condition (an ``elementwise`` formula):
    the travel's bound (``_travel_bound``) at the lesser of the law's and the backup's first
    command is within the gap by TRAVEL_SURE. Then both travels are within G0, so the margin
    is not negative and the law's travel within G0: ``_met`` is true, without working either
    out (a cone far from the sensor, or approached slowly).
    """
    return _travel_bound(ops, p, w0, Ds, ops.minimum(law, first), authority) <= G0 - TRAVEL_SURE


def _worst(brake: ApproachBrake, gap: Scalars, w: Scalars, D_s: Scalars, age: Scalars,
           spin: Scalars, authority: Scalars, hold: float,
           law: Optional[Scalars] = None) -> Worst:
    """The worst state of the uncertainty box and the backup from it, per cone: (G0, w0, the
    rotors' deceleration now taken at most a_b, the backup's first command, Phi); with law (a
    deceleration per cone: the law's), also the worst-case travel after a command reaching it
    and whether the law meets the condition (``_met``).
    """
    p, keep = phases(brake, hold), brake.keep(hold)
    if law is None:
        return evaluate(lambda ops, *v: _worst_state(ops, brake, p, keep, *v), gap, w, D_s, age,
                        spin, authority)
    return cast(Worst, evaluate(lambda ops, *v: _worst_with_law(ops, brake, p, keep, *v), gap,
                                w, D_s, age, spin, authority, law))      # (its last: flags)


def _met(margin: Value, first: Value, D: Value, travel: Value, G0: Value) -> Flag:
    """``meets`` from the worst state's margin, the backup's first command, D and the
    worst-case travel after a command reaching D (an ``elementwise`` formula: past the curve,
    Phi < 0, D at least the backup's first; else the travel within G0).
    """
    return ((margin < 0.0) & (D >= first)) | ((margin >= 0.0) & (travel <= G0))


def _least(ops: Ops, p: Phases, G0: Value, w0: Value, Ds: Value, first: Value, margin: Value,
           authority: Value) -> Value:
    """``least_deceleration``'s D of one element (an ``elementwise`` formula)."""
    past = margin < 0.0
    # regula falsi (Illinois) between a deceleration that does not meet the condition and one
    # that does (the backup's own first), keeping the one that does
    lo = ops.minimum(Ds, 0.0) - 4.0 * authority
    hi = first
    f_lo, f_hi = ops.both(lambda D: _travel(ops, p, w0, Ds, D, authority) - G0, lo, hi)
    fine = f_lo <= 0.0                     # (even the low end meets it: a far cone)
    hi = ops.where(fine, lo, hi)
    fixed = fine | past                    # (past: the backup's first, whatever the search)
    if not ops.every(fixed):               # (where fixed, the steps leave hi as it is)
        f_lo, f_hi = ops.where(fixed, 1.0, f_lo), ops.where(fixed, -1.0, f_hi)
        for _ in range(FALSI_STEPS):
            mid = ops.where(fixed, hi, hi - f_hi * (hi - lo) / ops.minimum(f_hi - f_lo, -1e-12))
            f_mid = _travel(ops, p, w0, Ds, mid, authority) - G0
            ok = f_mid <= 0.0
            f_lo = ops.where(ok, f_lo * 0.5, f_mid)
            lo = ops.where(ok, lo, mid)
            f_hi = ops.where(ok, f_mid, f_hi)
            hi = ops.where(ok, mid, hi)
    return ops.where(past, first, hi)


def least_deceleration(brake: ApproachBrake, gap: Scalars, w: Scalars, D_s: Scalars, age: Scalars,
                       spin: Scalars, authority: Scalars, hold: float,
                       worst: Optional[Worst] = None) -> Tuple[Scalars, Scalars]:
    """(D, Phi) per cone: the least deceleration D (rad/s^2) the command must reach at the end of
    its hold for the condition, and the backup's margin Phi (rad) now. Where Phi < 0, D is the
    backup's own first command (past the curve: brake as hard as the lag lets).

    The worst state (w0, G0) of the uncertainty box; the rotors' deceleration now taken at most
    a_b. The travel falls as D grows, so D is found by regula falsi (``FALSI_STEPS``) between
    a deceleration far below and the backup's first command, returning the end that meets the
    condition: never less than the least. Each cone's answer is its own, whatever the others'
    (a run alone and in a batch alike). worst: ``_worst`` of the same arguments, where already
    computed.
    """
    G0, w0, Ds, first, margin = (_worst(brake, gap, w, D_s, age, spin, authority, hold)
                                 if worst is None else worst)[:5]
    p = phases(brake, hold)
    D = evaluate(lambda ops, *v: _least(ops, p, *v), G0, w0, Ds, first, margin, authority)
    return D, margin


def meets(brake: ApproachBrake, gap: Scalars, w: Scalars, D_s: Scalars, age: Scalars,
          spin: Scalars, authority: Scalars, hold: float, D: Scalars) -> Scalars:
    """Per cone, whether a command reaching the deceleration D (rad/s^2) at the end of its hold
    meets the condition (``least_deceleration``'s, without its search): its worst-case travel
    peaks within the gap or, past the curve, D is at least the backup's own first command.
    """
    return _worst(brake, gap, w, D_s, age, spin, authority, hold, D)[-1]


class BrakeRows(NamedTuple):
    """The brake's condition for every cone at a tick, as rows on the moment u:
    A u >= beta (``A`` (..., cones, 3), ``beta`` (..., cones)); ``margin``: each cone's Phi
    (rad; < 0 past the curve); ``weak``: where the backup's authority is too weak for the
    derivation (``BrakeTerms.weak``).
    """

    A: FloatArray
    beta: FloatArray
    margin: FloatArray
    weak: BoolArray


class BrakeInputs(NamedTuple):
    """What the brake needs of a tick besides the law's moment (one per run of a batch where
    arrays): the state predicted at the tick (R, Omega: not the lead the law flies on), the
    measurements' age T_b (s), the hold the command is designed for (s), the moment the rotors
    make at the tick (about the pivot, N m) and the model's moment besides the rotors' there
    (f: gravity, the estimate, the gyroscopic term, the observed error; N m), its gravity
    moment alone (N m), and where the rotors' thrusts are now within their polytope's frame
    (``Mixer.thrust_offsets``; None: no lag model).
    """

    R: FloatArray
    Omega: FloatArray
    age: Scalars
    hold: float
    rotors: FloatArray
    f: FloatArray
    gravity: FloatArray
    thrusts: Optional[FloatArray] = None


def _opening(ops: Ops, R: Rows, Omega: Parts, r: Parts, r_cols: Rows, v: Parts,
             theta: Value) -> Tuple[Value, Value, List[Value], Value, Value, Value]:
    """``opening`` of one cone by components (an ``elementwise`` formula): (s, gap, n, w, kin,
    |Omega|^2), the products in index order as ``ConeSet.terms``' and
    ``ConeSet.axes_in_body``'s.
    """
    P = [[R[k][0] * r_cols[0][j] + R[k][1] * r_cols[1][j] + R[k][2] * r_cols[2][j]
          for j in range(4)] for k in range(3)]                      # R [r, hat(r)]
    s, c0, c1, c2 = (v[0] * P[0][j] + v[1] * P[1][j] + v[2] * P[2][j] for j in range(4))
    inv = 1.0 / ops.maximum(ops.sqrt(c0 * c0 + c1 * c1 + c2 * c2), 1e-9)
    n = [c0 * inv, c1 * inv, c2 * inv]
    w = -(n[0] * Omega[0] + n[1] * Omega[1] + n[2] * Omega[2])
    b = [v[0] * R[0][j] + v[1] * R[1][j] + v[2] * R[2][j] for j in range(3)]    # R^T v
    spin = Omega[0] * Omega[0] + Omega[1] * Omega[1] + Omega[2] * Omega[2]
    kin = ((b[0] * Omega[0] + b[1] * Omega[1] + b[2] * Omega[2])
           * (r[0] * Omega[0] + r[1] * Omega[1] + r[2] * Omega[2]) - s * (spin - w * w)) * inv
    gap = ops.arccos(ops.minimum(ops.maximum(s, -1.0), 1.0)) - theta
    return s, gap, n, w, kin, spin


def _cone_terms(ops: Ops, brake: ApproachBrake, J_inv: Rows, n: Parts, kin: Value, f: Parts,
                gravity: Parts, rotors: Parts) -> Tuple[List[Value], Value, Value, Value, Flag]:
    """``brake_terms``' rest for one cone by components (an ``elementwise`` formula): (A,
    f_along, D_s, authority, weak).
    """
    A = [n[0] * J_inv[0][j] + n[1] * J_inv[1][j] + n[2] * J_inv[2][j] for j in range(3)]
    f_along = A[0] * f[0] + A[1] * f[1] + A[2] * f[2]
    # the backup's authority here: a_b, less what of the model's other terms (the estimate,
    # the gyroscopic term, the observed error: a_b counts gravity) and of the kinematic term
    # works against it now
    authority = brake.authority + ops.minimum(
        f_along - (A[0] * gravity[0] + A[1] * gravity[1] + A[2] * gravity[2]) - kin, 0.0)
    # the backup must out-brake a_u by a share of a_b at least: where the model's other terms
    # leave less (a model error past the bounds, learnt by the observer), the derivation does
    # not hold (``weak``), and the brake takes that share all the same
    floor = brake.unmodelled + NET_SHARE_MIN * brake.authority
    weak = authority < floor
    authority = ops.maximum(authority, floor)
    D_s = A[0] * rotors[0] + A[1] * rotors[1] + A[2] * rotors[2] + f_along - kin
    return A, f_along, D_s, authority, weak


Column = Union[Value, Flag, Parts]    # one of ``_cone``'s results: a number, a flag or a vector
# ``_cone``'s results in their order, by name: the terms (``BrakeTerms``'s fields), the worst
# state (``Worst``) and whether the law meets the condition
_TERMS = ('gap', 'n', 'w', 'kin', 'A', 'f_along', 'D_s', 'authority', 'weak')
_WORST = ('G0', 'w0', 'Ds', 'first', 'margin')
_AT = {name: k for k, name in enumerate(_TERMS + _WORST + ('met',))}
_FLAGS = (_AT['weak'], _AT['met'])                    # the results of one flag
_VECTORS = (_AT['n'], _AT['A'])                       # ... of a vector
_FIGURES = tuple(k for k in _AT.values() if k not in _FLAGS + _VECTORS)   # ... of one number


class _View:
    """The brake's per-cone view of a tick (``_cones_at``): its terms, and with the law's
    moment, whether the law meets each cone's condition and the worst state there. One run's
    arrays are built only when asked for (the usual tick needs its two flags alone).
    """

    def __init__(self, cols: Sequence[Sequence[Column]], shape: Tuple[int, ...],
                 one: bool) -> None:
        self._cols, self._shape, self._one = cols, shape, one
        self._built: Optional[Dict[int, FloatArray]] = None

    def _flag(self, k: int, every: bool) -> Flags:
        """Per run, whether every cone's flag k is set (every) or any is."""
        if self._one:
            flags = cast('Sequence[bool]', self._cols[k])
            value = all(flags) if every else any(flags)
            return np.array([value]) if self._shape[:-1] else np.bool_(value)
        flags_all = self._arrays()[k]
        return cast(Flags, np.all(flags_all, axis=-1) if every else np.any(flags_all, axis=-1))

    @property
    def weak(self) -> Flags:
        """Per run, whether any cone's bounds are too weak for the derivation."""
        return self._flag(_AT['weak'], every=False)

    @property
    def met(self) -> Flags:
        """Per run, whether the law's moment meets every cone's condition."""
        return self._flag(_AT['met'], every=True)

    @property
    def whole(self) -> bool:
        """Whether every cone's margin was worked out (not left out by ``_cone``'s quick)."""
        if len(self._cols) == len(_TERMS):
            return True
        margins = self._cols[_AT['margin']]
        if self._one:
            return not any(math.isnan(cast(float, m)) for m in margins)
        return not bool(np.isnan(cast(FloatArray, margins[0])).any())

    @property
    def terms(self) -> 'BrakeTerms':
        out = self._arrays()
        return BrakeTerms._make(out[_AT[name]] for name in _TERMS)

    @property
    def worst(self) -> Optional[Worst]:
        """The worst state of every cone (``_worst``; None without the law's moment)."""
        if len(self._cols) == len(_TERMS):
            return None
        out = self._arrays()
        return tuple(out[_AT[name]] for name in _WORST)

    def _arrays(self) -> Dict[int, FloatArray]:
        """Every result as an array (one run's: three calls at once)."""
        if self._built is not None:
            return self._built
        cols, shape, got = self._cols, self._shape, range(len(self._cols))
        if self._one:
            lead = shape[:-1]
            figures = np.array([cols[k] for k in _FIGURES if k in got], dtype=float)
            flags = np.array([cols[k] for k in _FLAGS if k in got], dtype=bool)
            vectors = np.array([cols[k] for k in _VECTORS], dtype=float)
            if lead:                              # (a batch of one)
                figures, flags, vectors = figures[:, None], flags[:, None], vectors[:, None]
            out = {k: figures[i] for i, k in enumerate(k for k in _FIGURES if k in got)}
            out.update((k, flags[i]) for i, k in enumerate(k for k in _FLAGS if k in got))
            out.update((k, vectors[i]) for i, k in enumerate(_VECTORS))
        else:
            out = {k: np.broadcast_to(np.asarray(cols[k][0],
                                                 dtype=bool if k in _FLAGS else float),
                                      shape).copy() for k in got if k not in _VECTORS}
            out.update((k, np.stack(np.broadcast_arrays(*cast(Sequence[FloatArray], cols[k][0]),
                                                        np.zeros(shape))[:3], axis=-1))
                       for k in _VECTORS)
        self._built = out
        return out


class _TickParts(NamedTuple):
    """A tick's values by components for ``_cone``: one run's floats, or a batch's arrays with
    an axis for the cones (runs, 1).
    """

    R: Rows
    Omega: Parts
    f: Parts
    gravity: Parts
    rotors: Parts
    u: Optional[Parts]
    age: Value

    @classmethod
    def of(cls, x: 'BrakeInputs', u: Optional[FloatArray], one: bool) -> '_TickParts':
        if one:
            return cls(matrix_parts(x.R, True), vector_parts(x.Omega, True),
                       vector_parts(x.f, True), vector_parts(x.gravity, True),
                       vector_parts(x.rotors, True), None if u is None else vector_parts(u, True),
                       float(np.asarray(x.age).reshape(-1)[0]))

        def per_run(a: FloatArray) -> List[Value]:
            return [a[..., k, None] for k in range(3)]
        return cls([[x.R[..., i, j, None] for j in range(3)] for i in range(3)],
                   per_run(x.Omega), per_run(x.f), per_run(x.gravity), per_run(x.rotors),
                   None if u is None else per_run(u),
                   np.asarray(x.age, dtype=float)[..., None] if np.ndim(x.age)
                   else float(x.age))


def _cone(ops: Ops, brake: ApproachBrake, p: Phases, keep: float, J_inv: Rows, r: Parts,
          r_cols: Rows, x: _TickParts, worst: bool, quick: bool, v: Parts,
          theta: Value) -> Tuple[Column, ...]:
    """One cone's ``_View`` at a tick by components (an ``elementwise`` formula): gap, n, w,
    kin, A, f_along, D_s, authority, weak; with worst or the law's moment u also the worst state
    (G0, w0, Ds, first, margin: ``_worst``), and with u whether the law meets the condition.
    quick (with u): where the law surely meets it (``_surely_met``, for every element), the
    margin is not worked out (NaN: ``_View.whole`` says so).
    """
    s, gap, n, w, kin, spin = _opening(ops, x.R, x.Omega, r, r_cols, v, theta)
    A, f_along, D_s, authority, weak = _cone_terms(ops, brake, J_inv, n, kin, x.f, x.gravity,
                                                   x.rotors)
    out: Tuple[Column, ...] = (gap, n, w, kin, A, f_along, D_s, authority, weak)
    u = x.u
    if u is None and not worst:
        return out
    # |Omega| / sin phi (``ApproachBrake.uncertainty``)
    spin_rate = ops.sqrt(spin) / ops.maximum(ops.sin(gap + theta), SIN_PHI_MIN)
    if u is None:
        return out + _worst_state(ops, brake, p, keep, gap, w, D_s, x.age, spin_rate, authority)
    law = A[0] * u[0] + A[1] * u[1] + A[2] * u[2] + f_along - kin
    G0, w0, Ds, first = _worst_box(ops, brake, keep, gap, w, D_s, x.age, spin_rate, authority)
    if quick and ops.every(_surely_met(ops, p, G0, w0, Ds, first, authority, law)):
        return out + (G0, w0, Ds, first, G0 * math.nan, True)
    worst_state = _with_law(ops, p, G0, w0, Ds, first, authority, law)
    return out + worst_state[:5] + worst_state[6:]


def _cones_at(brake: ApproachBrake, cones: ConeSet, J_inv: FloatArray, x: 'BrakeInputs',
              u: Optional[FloatArray] = None, worst: bool = False, quick: bool = False) -> _View:
    """The brake's view of every cone at the tick of x (``_cone``): one run's cones one by one
    in floats, a batch's in whole arrays (runs, cones); with worst, the worst state of each;
    with the law's moment u, that and whether the law meets every cone's condition (quick: a
    cone the law surely keeps without its margin, ``_cone``).
    """
    one = one_run(x.R) and len(cones) > 0
    consts = (brake, phases(brake, x.hold), brake.keep(x.hold),
              cast('List[List[Value]]', J_inv.reshape(3, 3).tolist()),
              cast('List[Value]', cones.r_floats),
              cast('List[List[Value]]', cones.r_cols_floats), _TickParts.of(x, u, one), worst,
              quick)
    if one:
        theta = cones.theta.reshape(-1)
        per_cone = list(zip(*(_cone(FLOATS, *consts, v, t) for v, t in
                              zip(cones.V.reshape(-1, 3).tolist(), theta.tolist()))))
        return _View(per_cone, x.R.shape[:-2] + theta.shape, True)
    V, theta = cones.V, cones.theta
    whole = _cone(ARRAYS, *consts, [V[..., k] for k in range(3)], theta)
    return _View([[c] for c in whole], np.broadcast_shapes(x.R.shape[:-2] + (1,), theta.shape),
                 False)


def opening(cones: ConeSet, R: FloatArray,
            Omega: FloatArray) -> Tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per cone at (R, Omega): (gap (rad, phi - theta), n (the opening direction, body, unit),
    w (the approach rate, rad/s), kin (the approach's kinematic term, rad/s^2)): with
    b = R^T v, c = b x r, n = c / |c|, w = -n . Omega, and dw/dt = kin - n . Omega' where
    kin = -(dn/dt) . Omega = ((b . Omega)(r . Omega) - s (|Omega|^2 - w^2)) / |c|
    (dc/dt = s Omega - b (r . Omega), n . b = 0; dot products only). (``_opening``, for every
    cone.)
    """
    zero = np.zeros(3)
    t = _cones_at(_ANY_BRAKE, cones, np.eye(3),
                  BrakeInputs(R, Omega, 0.0, 0.0, zero, zero, zero)).terms
    return t.gap, t.n, t.w, t.kin


class BrakeTerms(NamedTuple):
    """The brake's view of every cone at a tick (arrays (..., cones)): the gap (rad), the
    opening direction n (body, unit; (..., cones, 3)), the approach rate w (rad/s) and its
    kinematic term kin (rad/s^2), the rows A = (J^-1 n)^T
    (..., cones, 3) that give the rotors' part of the deceleration (A u), the model's other
    part n . J^-1 f, the rotors' deceleration now D_s, the backup's authority here (rad/s^2),
    and where that is too weak for the derivation (``NET_SHARE_MIN``).
    """

    gap: FloatArray
    n: FloatArray
    w: FloatArray
    kin: FloatArray
    A: FloatArray
    f_along: FloatArray
    D_s: FloatArray
    authority: FloatArray
    weak: BoolArray

    def model_rate_change(self, moment: FloatArray) -> FloatArray:
        """dw/dt by the brake's model, frozen at the tick, under the rotors' moment."""
        return self.kin - so3.dot(self.A, moment[..., None, :]) - self.f_along


def brake_terms(brake: ApproachBrake, cones: ConeSet, J_inv: FloatArray,
                x: BrakeInputs) -> BrakeTerms:
    """``BrakeTerms`` at the tick of x (see the module; ``_cone`` for each cone)."""
    return _cones_at(brake, cones, J_inv, x).terms


def rows(brake: ApproachBrake, cones: ConeSet, J_inv: FloatArray, x: BrakeInputs,
         terms: Optional[BrakeTerms] = None, worst: Optional[Worst] = None) -> BrakeRows:
    """The brake's condition at a tick for every cone (``BrakeRows``; see the module); terms:
    ``brake_terms`` of x, worst: the worst state of each cone there (``_worst``), where
    already computed (the two together, or neither).
    """
    if terms is None or worst is None:
        view = _cones_at(brake, cones, J_inv, x, worst=True)
        terms, worst = view.terms, view.worst
    t = terms
    D, margin = least_deceleration(brake, t.gap, t.w, t.D_s, 0.0, 0.0, t.authority, x.hold,
                                   worst)
    return BrakeRows(t.A, D - t.f_along + t.kin, cast(FloatArray, margin), t.weak)


SIN_PHI_MIN = math.sin(math.radians(5.0))   # sin phi below which the rate error is taken at
                                            # this (deep inside a cone, or opposite it)


def brake_authority(vertices: FloatArray, J_inv: FloatArray, m_rho: FloatArray,
                    gravity: FloatArray, tilt_max: float, r: FloatArray,
                    directions: int = 720) -> float:
    """a_b (rad/s^2): the least, over the opening directions n (every unit n perpendicular to
    the sensor axis r: a cone is opened by turning r), of the deceleration along n that the
    rotors' moment polytope (its vertices) gives, less the gravity moment working against it at
    any attitude within tilt_max (rad) of upright: min over n of [max over vertices of
    (J^-1 n) . u - max over the tilts of -(J^-1 n) . M_g]. With c = J^-1 n, -c . (m rho x g_b)
    = g_b . (m rho x c), and gravity in the body frame g_b ranges over the cap of half-angle
    tilt_max round -e3 (|g_b| = g): its most is g |k| cos(max(0, angle(k, -e3) - tilt_max)) for
    k = m rho x c. The directions are sampled finely; the support and the cap are exact.
    """
    r = np.asarray(r, dtype=float)
    e1 = np.cross(r, np.eye(3)[int(np.argmin(np.abs(r)))])
    e1 /= math.sqrt(so3.dot(e1, e1))
    e2 = np.cross(r, e1)
    t = np.linspace(0.0, 2.0 * math.pi, directions, endpoint=False)
    n = np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2            # (N, 3)
    c = so3.matvec(J_inv, n)                                          # J^-1 n
    support = so3.dot(c[:, None, :], vertices[None, :, :]).max(axis=1)
    g = math.sqrt(so3.dot(gravity, gravity))
    k = so3.cross(np.broadcast_to(m_rho, c.shape), c)
    size = np.sqrt(so3.dot(k, k))
    down = -k[:, 2] / np.maximum(size, 1e-300)                         # cos angle(k, -e3)
    off = np.maximum(np.arccos(np.clip(down, -1.0, 1.0)) - tilt_max, 0.0)
    worst = np.maximum(g * size * np.cos(np.minimum(off, math.pi)), 0.0)
    return float((support - worst).min())


def covered(ok: BoolArray, safe: BoolArray, lead: int) -> BoolArray:
    """(steps, runs) bool: whether the derivation speaks of each control step: some step j at
    or before it had a safe state (``safe``: Phi >= 0 of the true state, every cone) and the
    bounds held (``ok``) at every step from ``lead`` steps before j (the measurements j used)
    up to it. Per step and run (arrays (steps, runs)).
    """
    steps = ok.shape[0]
    broken = np.concatenate([np.zeros((1,) + ok.shape[1:]), np.cumsum(~ok, axis=0)])
    k = np.arange(steps)
    lead_ok = (broken[k + 1] - broken[np.maximum(k - lead, 0)]) == 0
    out = np.zeros(ok.shape, dtype=bool)
    prev = np.zeros(ok.shape[1:], dtype=bool)
    for i in range(steps):
        prev = ok[i] & (prev | (safe[i] & lead_ok[i]))
        out[i] = prev
    return out


class Braked(NamedTuple):
    """The brake stage's result: the moment, and per run whether the brake changed the law's
    (``braking``) and whether its condition could not be met for every cone within the rotors'
    reach this hold, or its bounds were too weak for it (``unmet``: outside the derivation).
    """

    u: FloatArray
    braking: Flags
    unmet: Flags


def reachable(polytope: Polytope, keep: float,
              offsets: Optional[FloatArray]) -> Tuple[FloatArray, FloatArray]:
    """The moments the lagged rotors reach by the end of a hold from where they are now, within
    their polytope A M >= beta (each rotor j between its limits: lo <= base_j + P_j M <= hi):
    each rotor's thrust reaches a f0_j + (1 - a) [lo, hi] (keep: a = exp(-h / tau)), so
    A M >= (1 - a) beta + a [f0 - base, base - f0] (offsets: f0 - base per alive rotor, one row
    per run of a batch; None: no lag model, the whole polytope). Returns (A, beta (per run)).
    """
    if offsets is None or keep <= 0.0:
        return polytope.A, polytope.beta
    return polytope.A, (1.0 - keep) * polytope.beta + keep * np.concatenate(
        (offsets, -offsets), axis=-1)


def braked(brake: ApproachBrake, cones: ConeSet, J_inv: FloatArray, polytope: Polytope,
           x: BrakeInputs, u: FloatArray,
           extra: Optional[Tuple[FloatArray, FloatArray]] = None) -> Braked:
    """The brake stage: u (the law's moment; one per run of a batch) where it meets every cone's
    condition (``rows``) within the rotors' reach this hold (``reachable``), else the closest
    moment that does (``core.law.projection.project``); where none does, the closest that meets
    the cones' rows relaxed by the least common amount (``_compromise``). extra: more rows
    (A, beta) the moment must meet with the brake's (the cbf law's pointing constraints), or
    None.
    """
    view = _cones_at(brake, cones, J_inv, x, None if extra is not None else u, worst=True,
                     quick=extra is None)
    weak = view.weak
    A_p, beta_p = reachable(polytope, brake.keep(x.hold), x.thrusts)
    # (a moment the rotors cannot reach this hold, which the lag compensation would clip, needs
    # the projection too: the derivation's rotors reach every command, the law's too)
    unreached = (slack_of(A_p, u, beta_p) < -TOL).any(axis=-1)
    if extra is None:
        # whether the law's moment meets every cone's condition (``meets``, on the law's own
        # deceleration along each cone; no search), and the worst state of every cone there
        # (for the rows)
        braking = ~view.met
        if not (braking | unreached).any():
            return Braked(u, braking, weak)
        if not view.whole:                 # (the rows need every cone's worst state whole)
            view = _cones_at(brake, cones, J_inv, x, u, worst=True)
    r = rows(brake, cones, J_inv, x, view.terms, view.worst)
    A, beta = r.A, r.beta
    if extra is not None:
        A = np.concatenate((extra[0], A), axis=-2)
        beta = np.concatenate((extra[1], beta), axis=-1)
        braking = np.any(slack_of(A, u, beta) < -TOL, axis=-1)
    need = braking | unreached
    if not np.any(need):
        return Braked(u, braking, weak)
    out = np.array(u, dtype=float, copy=True)
    unmet = np.array(weak, copy=True)
    for i in zip(*np.nonzero(need)) if out.ndim > 1 else [()]:
        A_i = np.concatenate((A[i], A_p))
        beta_i = np.concatenate((beta[i], beta_p[i] if beta_p.ndim > 1 else beta_p))
        v, ok = project(u[i], A_i, beta_i)
        if not ok:
            v = _compromise(u[i], A_i, beta_i, len(beta[i]), x.rotors[i])
            unmet[i] = True
        out[i] = v
    return Braked(out, braking, unmet)


def _compromise(u: FloatArray, A: FloatArray, beta: FloatArray, rows_: int,
                rotors: FloatArray, iterations: int = 30) -> FloatArray:
    """Where the first ``rows_`` rows (the cones') cannot all be met within the rest (the
    rotors' reach): the moment closest to u that meets them all relaxed by the least common
    amount e (rad/s^2 of deceleration: A_i u >= beta_i - e), found by bisection on e, so that no
    cone is given up for another (two cones' rows conflict where the sensor runs fast down a
    narrow corridor between them).
    """
    soft = np.zeros(len(beta))
    soft[:rows_] = 1.0
    # (relaxed by the most any row asks beyond the rotors' moment now, every row is met there,
    # and the reach holds it)
    lo = 0.0
    hi = max(float(np.max(beta[:rows_] - slack_of(A[:rows_], rotors, np.zeros(rows_)))),
             0.0) + 1.0
    best = None
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        v, ok = project(u, A, beta - mid * soft)
        if ok:
            hi, best = mid, v
        else:
            lo = mid
    if best is None:
        best, _ = project(u, A[rows_:], beta[rows_:])
    return best
