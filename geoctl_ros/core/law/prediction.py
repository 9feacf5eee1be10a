"""Delay compensation: the attitude and rate at the control tick from measurements that are some
time old, by the controller's own model of the testbed and the moments it has already commanded
(``predict``, its state an ``Observer``; after the predictor-based designs for input and
measurement delay, e.g. Molnar, Kiss, Ames & Orosz, arXiv 2112.08445).

A measurement captured ``age`` seconds before the tick shows the vehicle as it was then; since
then the rotors have been told to produce the moments of the ticks in between, each held until
the next. The predictor integrates the model's rigid-body dynamics about the pivot over that
window, piece by piece, with the moment in force at each instant (``CommandHistory``):

    J Omega' = M_cmd(t) + M_g(R) + W Delta_bar - Omega x J Omega - J a_slow,   R' = R hat(Omega)

a_slow is the slow part of the model's own error (the low-passed model acceleration at the
measurements: at rest the true acceleration is zero, while the model's is J^-1 times the moment
not yet learnt). Predicting with a constant rate, or with only the last moment, is what let a
50 ms delay tip the testbed over (docs/safety.md, "Delay").
"""
import bisect
import math
from typing import List, NamedTuple, Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry.elementwise import (
    ARRAYS,
    FLOATS,
    joined,
    joined_matrix,
    matrix_parts,
    one_run,
    vector_parts,
)
from geoctl_ros.core.geometry.so3 import FloatArray, Scalars, exp_parts, matmul_parts
from geoctl_ros.core.law.dynamics import Dynamics
from geoctl_ros.core.law.mechanics import Parts, Rows

PREDICT_SLOW_S = 0.25    # s, the observer's low-pass of the model's error
OBSERVE_GAP_MAX_S = 0.05  # s, the longest interval between rate samples the observer learns from
SUBSTEP_MAX_S = 0.01      # s, the longest piece of the prediction's integration


class CommandHistory:
    """The moments the rotors were told to produce, with the time each command was sent: a ring
    of the last ``size`` ticks (one moment per run of a batch).

    With a motor lag (the rotors' first-order thrust time constant ``lag``, s) a command does not
    act at once: each entry holds the moment the rotors produced when it was sent (``start``) and
    the one it asks for (``end``), and the moment in force a time s after sending is
    end + exp(-s / lag) (start - end). Without one, start = end. ``at(t)`` is the moment in force
    at t: zero before the first entry, and the oldest one's for a time older than a full ring.

    Only the times move at a push (``size`` floats, kept sorted for the lookup); the moments stay
    in their slots: the k-th oldest entry is in slot (newest + 1 + k) % size.
    """

    def __init__(self, size: int, lag: float = 0.0) -> None:
        self.size = int(size)
        self.lag = float(lag)
        self.times = np.full(self.size, -math.inf)    # oldest first; -inf: empty
        self._times = self.times.tolist()             # the same as floats (one run's lookup)
        self.start: Optional[FloatArray]         # (the two are set together)
        self.end: Optional[FloatArray]
        self.start = self.end = None
        self._newest = -1                             # the slot of the newest entry
        self.count = 0                                # entries held
        # one run's moments as floats too, slot by slot (its lookups by components: ``parts_at``)
        self._end_floats: List[List[float]] = []
        self._start_floats: List[List[float]] = []

    def clear(self) -> None:
        """Forget every command (at arming: the rotors were off, the vehicle on its stops)."""
        self.times[:] = -math.inf
        self._times = self.times.tolist()
        self.count = 0
        if self.end is not None:
            cast(FloatArray, self.start)[:] = 0.0
            self.end[:] = 0.0
        self._end_floats = [[0.0] * 3 for _ in self._end_floats]
        self._start_floats = [[0.0] * 3 for _ in self._start_floats]

    @property
    def first(self) -> float:
        """When the oldest command held was sent (inf: none yet)."""
        return self.times[-self.count] if self.count else math.inf

    def push(self, t: float, end: FloatArray, start: Optional[FloatArray] = None) -> None:
        end = np.asarray(end, dtype=float)
        if self.end is None or self.end.shape[1:] != end.shape:
            self.start = np.zeros((self.size,) + end.shape)
            self.end = np.zeros((self.size,) + end.shape)
            self.times[:] = -math.inf
            self._times = self.times.tolist()
            one = end.size == 3
            self._end_floats = [[0.0] * 3 for _ in range(self.size)] if one else []
            self._start_floats = [[0.0] * 3 for _ in range(self.size)] if one else []
        self._newest = w = (self._newest + 1) % self.size
        self.count = min(self.count + 1, self.size)
        self.end[w] = end
        cast(FloatArray, self.start)[w] = end if start is None else start
        if self._end_floats:
            self._end_floats[w] = made = end.ravel().tolist()
            self._start_floats[w] = made if start is None else np.ravel(start).tolist()
        self.times[:-1] = self.times[1:]
        self.times[-1] = t
        del self._times[0]
        self._times.append(float(t))

    def parts_at(self, t: Scalars, one: bool) -> Parts:
        """``at(t)`` by components (``elementwise.vector_parts``): one run's floats, looked up
        without arrays (the same operations as ``at``'s), or a batch's arrays.
        """
        if not (one and self._end_floats and isinstance(t, float)):
            return vector_parts(self.at(t), one)
        slot, decay = self._in_force(t)
        end = self._end_floats[slot]
        if decay is None:
            return list(end)
        start = self._start_floats[slot]
        return [end[0] + decay * (start[0] - end[0]), end[1] + decay * (start[1] - end[1]),
                end[2] + decay * (start[2] - end[2])]

    def _in_force(self, t: float) -> Tuple[int, Optional[float]]:
        """The slot of the command in force at one time t, and how much of its start is left
        then, exp(-(t - sent) / lag) (None without a lag). (Before the first entry: an empty
        slot, all zeros, of time -inf; before a full ring's oldest: that oldest.)
        """
        k = max(bisect.bisect_right(self._times, t) - 1, 0)
        slot = (self._newest + 1 + k) % self.size
        if self.lag <= 0.0:
            return slot, None
        return slot, float(np.exp(-max(t - self._times[k], 0.0) / self.lag))

    def at(self, t: Scalars) -> FloatArray:
        """The moment in force at times t (a scalar, or one per run of a batch: (N,))."""
        start: FloatArray
        end: FloatArray
        if self.end is None:
            return np.zeros(3)
        # (before the first entry: an empty slot, all zeros, of time -inf; before a full ring's
        # oldest: i = -1, that oldest)
        if isinstance(t, float) or np.ndim(t) == 0:    # one time (the node's; a batch's tick)
            slot, decay = self._in_force(float(t))
            start, end = cast(FloatArray, self.start)[slot], self.end[slot]
            return end if decay is None else end + decay * (start - end)
        i = np.maximum(np.searchsorted(self.times, t, side='right') - 1, 0)
        slots = (self._newest + 1 + i) % self.size
        runs = np.arange(len(slots))                         # each run its own entry
        start, end = cast(FloatArray, self.start)[slots, runs], self.end[slots, runs]
        if self.lag <= 0.0:
            return end
        decays: FloatArray = np.exp(-np.maximum(t - self.times[i], 0.0) / self.lag)
        return end + (decays * (start - end).T).T


class Observer(NamedTuple):
    """The prediction's state: an observer of the model's error (one run, or a batch: then one
    value per run).

    The model's acceleration is wrong by what it does not know (the moment not yet learnt, a
    wrong mass or centre of mass). The observer measures that error where it can be measured: at
    the rate samples themselves. Between two samples, the measured mean acceleration
    (Omega_k - Omega_{k-1}) / (t_k - t_{k-1}) is compared with the model's at the interval's
    middle, under the moment in force then; the difference, low-passed over ``PREDICT_SLOW_S``,
    is taken off every piece of the prediction. At rest this is the whole model acceleration (the
    true one is zero); while manoeuvring, only the model's error, so a vehicle that really
    accelerates is predicted to. After a reset (``Observer()``: at the take-over, what held the
    vehicle on its stops or in a hand is not its error) the low-pass starts as the mean of the
    samples learnt so far (its time constant is the time learnt, up to PREDICT_SLOW_S): the
    take-over's error (a wrong m rho spooled into the rotors' gravity compensation) is known from
    the first sample learnt, not a time constant later (docs/safety.md, "The take-over").
    """

    acc_error: Scalars = 0.0   # rad/s^2: model minus measured acceleration, low-passed
    learnt: Scalars = 0.0      # s: the time learnt since the reset (one per run)
    last: Optional[Tuple[Scalars, FloatArray]] = None   # (capture time, Omega) of the last
                                                        # rate sample


class Learnt(NamedTuple):
    """``observe``'s result: the observer after the sample; R, Omega and the estimate by
    components (``elementwise``) where it took them to learn, else None; and the sample's
    |acceleration the model and the observer did not know| (rad/s^2; one run alone, where the
    sample taught something, else None).
    """

    observer: Observer
    taken: Optional[Tuple[Rows, Parts, Parts]]
    residual: Optional[float]


def observe(observer: Observer, model: Dynamics, R: FloatArray, Omega: FloatArray,
            captured: Scalars, history: 'CommandHistory') -> Learnt:
    """Learn the model's error (``Observer``) from a rate sample captured at ``captured`` (a
    time on the history's clock; one per run of a batch), given the model's dynamics with the
    estimate in force. A sample no newer than the last (a stall repeats it), one more than
    ``OBSERVE_GAP_MAX_S`` after it, or an interval that starts before the first command held
    teaches nothing.
    """
    last = observer.last
    if last is None:
        return Learnt(Observer(observer.acc_error, observer.learnt, (captured, Omega)), None, None)
    one = one_run(R)
    alone = np.ndim(captured) == 0          # one run (the node's tick)
    before, captured_at = last[0], captured
    if one and not alone:                   # a batch of one: its times as floats
        before, captured_at = (float(np.asarray(v).reshape(-1)[0])
                               for v in (before, captured_at))
    scalar = one or alone
    ops = FLOATS if scalar else ARRAYS
    interval: Scalars = (float(captured_at) - float(before) if scalar
                         else captured_at - before)
    usable = (interval > 1e-6) & (interval <= OBSERVE_GAP_MAX_S) & (before >= history.first)
    if not ops.some(usable):
        return Learnt(Observer(observer.acc_error, observer.learnt, (captured, Omega)), None, None)
    span = ops.where(usable, interval, 1.0)
    taken = (matrix_parts(R, one), vector_parts(Omega, one),
             vector_parts(model.delta_bar, one))
    now_, then = taken[1], vector_parts(last[1], one)
    modelled = model.acceleration_parts(
        taken[0], [0.5 * (now_[i] + then[i]) for i in range(3)],
        history.parts_at(before + 0.5 * span, one), taken[2])
    error = observer.acc_error
    e = [error] * 3 if isinstance(error, float) else vector_parts(error, one)
    innovation = [modelled[i] - (now_[i] - then[i]) / span - e[i] for i in range(3)]
    weight = ops.where(usable, span / (ops.minimum(observer.learnt, PREDICT_SLOW_S) + span),
                       0.0)
    residual = None
    if alone and one:                       # (the node's: its unlearnt moment's watch)
        x, y, z = (cast(float, v) for v in innovation)
        residual = math.sqrt(x * x + y * y + z * z)
    return Learnt(Observer(joined([e[i] + innovation[i] * weight for i in range(3)],
                                  R.shape[:-2], one),
                           observer.learnt + ops.where(usable, span, 0.0), (captured, Omega)),
                  taken, residual)


class Prediction(NamedTuple):
    """``predict``'s result: the observer after the tick's rate sample, the attitude and rate
    at the tick and at the tick plus the lead ((R, Omega) each), and the sample's residual
    (``Learnt``).
    """

    observer: Observer
    at_now: Tuple[FloatArray, FloatArray]
    at_lead: Tuple[FloatArray, FloatArray]
    residual: Optional[float]


def predict(observer: Observer, model: Dynamics, R: FloatArray, Omega: FloatArray,
            age_R: Scalars, age_Omega: Scalars, history: CommandHistory, now: float,
            lead: float = 0.0) -> Prediction:
    """The attitude and rate at ``now`` and at ``now + lead`` (``Prediction``), from
    measurements age_R and age_Omega seconds old at ``now`` (scalars, or one per run of a
    batch), given the observer (``Observer``, which first learns from this rate sample:
    ``observe``), the model's dynamics with the estimate in force (``Dynamics``) and the moments
    commanded before now (a CommandHistory on the same clock as now). Ages and lead of 0 return
    the measurements unchanged.

    Only the part of the window since the first command held is predicted (none at the first
    tick after the take-over). The window from the older measurement to now is integrated in S
    equal pieces of at most SUBSTEP_MAX_S (each with the moment in force at its midpoint; the
    rate is advanced only in the part of the window after its own capture, the attitude only
    after its own, with the mean of the rates at either end of the piece), and the lead after
    it in pieces of its own.
    """
    horizon: Scalars
    captured = now - age_Omega               # when the rate sample was captured
    observer, taken, residual = observe(observer, model, R, Omega, captured, history)
    # nothing is predicted from before the first command held: what moved the vehicle then
    # (its stops, a hand) is not in the model
    known = max(now - history.first, 0.0)
    if known <= 0.0:
        return Prediction(observer, (R, Omega), (R, Omega), residual)
    scalar = np.ndim(age_R) == 0 and np.ndim(age_Omega) == 0
    if scalar:                      # (one run: plain floats, np.minimum's value)
        age_R, age_Omega = float(age_R), float(age_Omega)
        age_R = known if known < age_R else age_R
        age_Omega = known if known < age_Omega else age_Omega
        horizon = max(age_R, age_Omega)
        latest = horizon
    else:
        age_R = np.minimum(np.asarray(age_R, dtype=float), known)
        age_Omega = np.minimum(np.asarray(age_Omega, dtype=float), known)
        horizon = np.maximum(age_R, age_Omega)
        latest = float(np.max(horizon))
    at_now = (R, Omega)
    if lead <= 0.0 and latest <= 0.0:
        return Prediction(observer, at_now, at_now, residual)
    # (by components from here on, made once, or as the observer took them)
    one, shape = one_run(R), R.shape[:-2]
    Rp, Wp, d = taken if taken is not None else (
        matrix_parts(R, one), vector_parts(Omega, one), vector_parts(model.delta_bar, one))
    error = observer.acc_error
    if latest > 0.0:
        # (the moment then, before any clipping)
        moment_now = history.parts_at(captured, one)
        acc0 = model.acceleration_parts(Rp, Wp, moment_now, d)
        Rp, Wp = _integrate(error, model, Rp, Wp, d, one, now - age_R, now - age_Omega,
                            history, now - horizon, horizon, (acc0, moment_now), scalar)
        at_now = (joined_matrix(Rp, shape, one), joined(Wp, shape, one))
    if lead <= 0.0:
        return Prediction(observer, at_now, at_now, residual)
    Rp, Wp = _integrate(error, model, Rp, Wp, d, one, now, now, history, now, lead, None, True)
    return Prediction(observer, at_now, (joined_matrix(Rp, shape, one), joined(Wp, shape, one)),
                      residual)


def _integrate(error: Scalars, model: Dynamics, Rp: Rows, Wp: Parts, d: Parts, one: bool,
               moved_R: Scalars, moved_Omega: Scalars, history: CommandHistory,
               start: Scalars, span: Scalars, first: Optional[Tuple[Parts, Parts]],
               scalar: bool) -> Tuple[Rows, Parts]:
    """Integrate the model from ``start`` over ``span`` (s; one per run of a batch unless
    scalar) in equal pieces of at most SUBSTEP_MAX_S, each under the moment in force at its
    midpoint, less the observed error (``Observer.acc_error``): the rate only after
    moved_Omega, the attitude only after moved_R (their capture times). first: (the model's
    acceleration at the start, the moment then) to save the first piece's evaluation, or None.
    The state (Rp, Wp) and the estimate d come and go by components (one run's floats, or a
    batch's arrays).

    One formula by components for one run (floats) and a batch (arrays; each run in its
    own number of equal pieces, so a run's prediction does not depend on the other runs of
    its batch: a run with fewer pieces than the most idles, h = 0).
    """
    if one and not scalar:                   # a batch of one: its times as floats
        start, span, moved_R, moved_Omega = (float(np.asarray(v).reshape(-1)[0]) for v in
                                             (start, span, moved_R, moved_Omega))
        scalar = True
    ops = FLOATS if scalar else ARRAYS
    e = [error] * 3 if isinstance(error, float) else vector_parts(error, one)
    if scalar:
        pieces: Scalars = float(max(math.ceil(span / SUBSTEP_MAX_S - 1e-9), 1))
        count = int(pieces)
    else:
        pieces = np.maximum(np.ceil(span / SUBSTEP_MAX_S - 1e-9), 1.0)
        count = int(np.max(pieces))
    h_run = span / pieces
    for j in range(count):
        h = ops.where(j < pieces, h_run, 0.0)
        mid = start + (j + 0.5) * h_run
        moment = history.parts_at(mid, one)
        if j == 0 and first is not None:
            # the first piece starts at the measured state, where the acceleration is acc0
            # under moment_now: under another moment it differs by J^-1 times the
            # difference (it is linear in the moment), which saves a model evaluation
            acc0, moment_now = first
            change = model.J_inv_times([moment[i] - moment_now[i] for i in range(3)])
            acc = [acc0[i] + change[i] for i in range(3)]
        else:
            acc = model.acceleration_parts(Rp, Wp, moment, d)
        acc = [acc[i] - e[i] for i in range(3)]
        # each measurement moves only after its own capture time
        moves_Omega, moves_R = mid > moved_Omega, mid > moved_R
        W_next = Wp
        if ops.some(moves_Omega):
            hw = ops.where(moves_Omega, h, 0.0)
            W_next = [Wp[i] + acc[i] * hw for i in range(3)]
        if ops.some(moves_R):
            hr = ops.where(moves_R, h, 0.0)
            Rp = matmul_parts(Rp, exp_parts(*((0.5 * (Wp[i] + W_next[i])) * hr
                                               for i in range(3))))
        Wp = W_next
    return Rp, Wp
