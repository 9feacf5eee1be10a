"""Do the sensors agree? The motion capture's attitude against the IMU's gyro and accelerometer.

A wrong convention (``core.sensors.frames``), an unaligned marker set, a rotated IMU or a gyro bias
put the cones where they are not, and the controller would fly the real sensor into the real
obstacle with every figure saying it is clear. Two pairs of measurements see such errors:

- **gravity**: at rest, the IMU's specific force is the reaction to gravity, f = -R^T g. Its
  direction must agree with the "up" of the poses, R^T e_up: a wrong body convention (FRD for
  FLU: 180 deg), a wrong world (NED or Y up), a tilted marker set or a tilted IMU shows as an
  angle between them. A yaw error of the IMU's mounting or of the marker set does not show while
  the vehicle rests level (gravity lies along the yaw axis); it shows in proportion to the tilt.
- **rate**: the gyro's mean over a window must agree with the rate of the poses over it (the
  least-squares slope of log(R_0^T R_k) against the poses' stamps, in the body). At rest this is
  the gyro's bias; moving, it sees every rotation error, the yaw ones too. A yaw error turns the
  rates' horizontal parts (x, y) and leaves their z alone; over a flight the windows' horizontal
  rates measure that yaw (``core.sensors.yaw_offset``), which names a mounting turned in yaw
  long before the difference of one window exceeds its tolerance.

The tolerances are derived from the sensors' noise figures (one standard deviation per axis and
sample: ``attitude_noise``, ``gyro_noise``, ``accelerometer_noise``) and the samples each window
holds: ``SIGMAS`` standard deviations of the difference, so that a false refusal is about 1e-5
per window (a chi distribution of 2 or 3 degrees of freedom beyond 5), plus, for gravity, the
``alignment_tolerance`` a calibrated installation keeps. In flight the rate window is short and
the vehicle accelerates, so the tolerance adds ``FLIGHT_SHARE`` of the rate and
``FLIGHT_FLOOR`` (the streams' clocks and their stamps' offset, the log's curvature over a turning
window): a mismatch must exceed about a third of the motion, for ``FLIGHT_WINDOWS`` windows in a
row; the failsafe names the cause the first of them shows. The flight's yaw is named beyond
``YAW_FLOOR_DEG`` by ``SIGMAS`` of its standard error, for ``FLIGHT_WINDOWS`` windows in a row.

Only windows that both streams sample are judged: a hole (a step in a stream's stamps longer
than ``GAP_SHARE`` of a window) neither agrees nor disagrees. When both streams pause together
the window ends at the pause, judged if it spans ``MIN_SHARE`` of a window; a hole in one stream
while the other goes on loses the window (``_Accumulator``). At arming, a slow window in which
the vehicle moves (the poses turn beyond the rate's tolerance, or the gyro's samples spread
beyond its noise) is told from a bias (a steady gyro rate while the poses stand still).

``SensorAgreement`` takes the converted samples (``core.sensors.frames.InputFrames``) as they come
and closes a window on the pose that ends it; it computes (and allocates) only then.
"""
from dataclasses import dataclass
import math
from typing import List, NamedTuple, Optional, Tuple

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import FloatArray
from geoctl_ros.core.geometry.sphere import angle_between_deg
from geoctl_ros.core.sensors.frames import (
    BODY_FRAMES,
    WORLD_FRAMES,
    Y_UP_BODY_DEG,
    InputFrames,
    matrix_rpy,
    rpy_matrix,
)
from geoctl_ros.core.sensors.yaw_offset import YawOffset

SIGMAS = 5.0              # standard deviations of the difference a check allows
REST_WINDOW = 0.5         # s of poses per arming window
FLIGHT_WINDOW = 0.1       # s of poses per in-flight window
FLIGHT_SHARE = 0.35       # in flight, the rate may disagree by this share of the motion,
FLIGHT_FLOOR = 0.1        # rad/s, and this
FLIGHT_WINDOWS = 2        # windows in a row (0.2 s) before a mismatch is a failsafe
REST_RATE = 0.05          # rad/s: the poses turn slower than this at rest
FORCE_SHARE = 0.25        # |f| within this share of |g| at rest (else no accelerometer data)
LATE = 3.0                # a window older than this many windows does not count for arming
RESOLVED_RAD = 1.0        # a window whose poses (or gyro) turn more than this is not judged
GAP_SHARE = 0.25          # a hole: a step in a stream's stamps longer than this share of a
                          # window (25 ms in flight, 0.125 s at rest)
MIN_SHARE = 0.5           # a window a pause of both streams ends early is judged if it spans
                          # at least this share of a window
YAW_FLOOR_DEG = 10.0      # a yaw between the gyro and the poses beyond this (by SIGMAS of its
                          # standard error) is a mounting error, named in flight
YAW_STEP_DEG = 5.0        # the yaw a sentence names: the nearest multiple of 45 deg within
                          # this, else rounded to this


@dataclass(frozen=True)
class AgreementSettings:
    """The checks' settings, typed at configuration (``params.build``)."""

    enabled: bool
    attitude_noise: float        # rad per axis and pose (1 sigma)
    gyro_noise: float            # rad/s per axis and sample
    accelerometer_noise: float   # m/s^2 per axis and sample
    alignment_tolerance: float   # rad: the angle a calibrated installation keeps
    gravity: FloatArray          # the world's gravity (m/s^2)


class Window(NamedTuple):
    """One closed window: the means and what they disagree by."""

    end: float                   # receipt of the pose that closed it (the loop's clock)
    gyro: FloatArray             # the gyro's mean (rad/s, body)
    poses_rate: FloatArray       # the poses' rate (rad/s, body)
    rate_tolerance: float        # rad/s: SIGMAS sigmas of their difference
    up: FloatArray               # the poses' mean up, R^T e_up
    force: Optional[FloatArray]  # the IMU's mean specific force (None: none came)
    tilt_tolerance: float        # rad: SIGMAS sigmas of the angle between up and force
    poses: int
    gyros: int
    resolved: bool               # the poses turned less than RESOLVED_RAD over it (else the
                                 # slope of the logarithm says nothing: not judged)
    gyro_sigma: float            # rad/s: one standard deviation per axis of the gyro's mean
    poses_sigma: float           # rad/s: of the poses' rate
    gyro_spread: float           # rad/s: the gyro's samples about their mean, rms per axis
    spread_tolerance: float      # rad/s: the spread noise alone stays under (SIGMAS sigmas of
                                 # its chi-square)

    @property
    def disagreement(self) -> float:
        """|gyro - poses' rate| (rad/s)."""
        return _norm(self.gyro - self.poses_rate)

    @property
    def turning(self) -> float:
        """|poses' rate| (rad/s)."""
        return _norm(self.poses_rate)

    @property
    def moving(self) -> bool:
        """The vehicle moved over the window: the poses turn beyond the rate's tolerance, or the
        gyro's rate varies beyond its noise. A bias is a steady gyro rate while the poses stand
        still: neither.
        """
        return self.turning > self.rate_tolerance or self.gyro_spread > self.spread_tolerance


def _norm(v: FloatArray) -> float:
    """|v| of a 3-vector, in floats (no BLAS kernel's rounding)."""
    return math.sqrt(float(so3.dot(v, v)))


def _yaw_between(a: FloatArray, b: FloatArray) -> float:
    """The yaw psi (deg) that turns a's horizontal part (x, y) onto b's: Rz(psi) a ~ b."""
    ax, ay, bx, by = float(a[0]), float(a[1]), float(b[0]), float(b[1])
    return math.degrees(math.atan2(ax * by - ay * bx, ax * bx + ay * by))


def _log_stack(M: FloatArray) -> FloatArray:
    """Rotation vectors of a stack of rotations (n, 3, 3), each turned by less than pi (a
    window's own motion: ``so3.log``'s formula away from pi, for the stack at once).
    """
    skew = 0.5 * np.stack([M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0],
                           M[:, 1, 0] - M[:, 0, 1]], axis=1)
    sin_t = np.sqrt(so3.dot(skew, skew))
    theta = np.arctan2(sin_t, 0.5 * (M[:, 0, 0] + M[:, 1, 1] + M[:, 2, 2] - 1.0))
    scale = np.where(sin_t > 1e-12, theta / np.where(sin_t > 1e-12, sin_t, 1.0), 1.0)
    return skew * scale[:, None]


class _Closing(NamedTuple):
    """A window as the pose that closed it left it, to be worked out by ``_Accumulator.settle``
    (its poses' buffers, handed over whole, and the IMU's sums).
    """

    receipt: float
    span: float
    Rs: FloatArray
    ts: FloatArray
    n: int
    t0: float
    r0: float
    w: FloatArray
    ww: float
    f: FloatArray
    nw: int
    nf: int
    gyro_r0: float
    gyro_receipt: float


class _Accumulator:
    """One window of poses (kept, by their stamps, in preallocated buffers: the hot path stores
    a pose and adds an IMU sample, nothing more) and the sums of the IMU's samples; the window's
    figures are computed once, after a pose closes it: by ``settle``, which the loop runs once
    the tick's motor command is out (so that a closing pose does not delay the next command),
    and which reading ``last`` runs too.

    A window is judged only where both streams sample it: across a hole the gyro's mean and the
    poses' slope weigh different stretches of the motion, and differ wherever it accelerates. A
    hole is a step in a stream's stamps longer than ``gap``; whether the other stream paused too
    is told by the receipts (the one clock both share). When both paused together (a stalled
    source, the sim stopped), the window ends at the hole and is judged if it spans at least
    ``MIN_SHARE`` of a window; a hole in one stream while the other went on loses the window.
    So does an IMU that did not sample the window's start or end (its first or last sample
    received more than ``gap`` from the window's first or closing pose).
    """

    CAPACITY = 1024          # poses a window holds (a full one closes early)

    def __init__(self, span: float, settings: AgreementSettings, spread: bool = False):
        self.span = span
        self.gap = GAP_SHARE * span
        self.spread = spread             # sum the gyro's squares (the arming window's motion)
        self.configure(settings)
        self.Rs = np.zeros((self.CAPACITY, 3, 3))
        self.ts = np.zeros(self.CAPACITY)
        self.n = 0
        self.t0 = self.t_last = 0.0      # the window's first and last poses' stamps
        self.r0 = self.pose_receipt = 0.0    # and their receipts
        self.w = np.zeros(3)
        self.ww = 0.0                    # the sum of the gyro's |w|^2
        self.f = np.zeros(3)
        self.nw = self.nf = 0
        self.gyro_r0 = self.gyro_receipt = 0.0   # receipts of its first and last gyro samples
        self.cut = False                 # a hole in the IMU's samples while the poses went on
        self.imu_stamp: Optional[float] = None   # the last IMU sample's stamp
        self._last: Optional[Window] = None
        self._closing: Optional[_Closing] = None  # a window closed, not yet worked out
        self._spare = (np.zeros((self.CAPACITY, 3, 3)), np.zeros(self.CAPACITY))

    @property
    def last(self) -> Optional[Window]:
        """The last window worked out (a closed one first: ``settle``)."""
        self.settle()
        return self._last

    @last.setter
    def last(self, window: Optional[Window]) -> None:
        self.settle()
        self._last = window

    def configure(self, settings: AgreementSettings) -> None:
        """Take new settings (a reconfiguration: the next window closes with them)."""
        self.settings = settings
        self.up_world = -settings.gravity / _norm(settings.gravity)

    def _restart(self, R: FloatArray, stamp: float, receipt: float) -> None:
        self.Rs[0] = R
        self.ts[0] = stamp
        self.n, self.t0, self.t_last = 1, stamp, stamp
        self.r0 = self.pose_receipt = receipt
        self.w[:] = 0.0
        self.ww = 0.0
        self.f[:] = 0.0
        self.nw = self.nf = 0
        self.cut = False

    def imu(self, w: FloatArray, f: Optional[FloatArray], stamp: float, receipt: float) -> None:
        """A gyro sample w and specific force f (or None) of stamp, received at receipt."""
        last, self.imu_stamp = self.imu_stamp, stamp
        if not self.n or self.cut:
            return
        if last is not None and stamp - last > self.gap and (self.nw or self.n > 1):
            if receipt - self.pose_receipt <= self.gap:     # the poses went on through it
                self.cut = True
            return                       # (both paused: the pose after the hole ends it)
        if not self.nw:
            self.gyro_r0 = receipt
        self.gyro_receipt = receipt
        self.w += w
        if self.spread:
            x, y, z = w.tolist()
            self.ww += x * x + y * y + z * z
        self.nw += 1
        if f is not None:
            self.f += f
            self.nf += 1

    def pose(self, R: FloatArray, stamp: float, receipt: float) -> None:
        """A pose of stamp, received at receipt; one that closes the window hands it to
        ``settle``.
        """
        if not self.n or stamp < self.t0 or self.cut:
            self._restart(R, stamp, receipt)
            return
        if stamp - self.t_last > self.gap:          # a hole in the poses
            if (receipt - self.gyro_receipt > self.gap           # the IMU paused too
                    and self.t_last - self.t0 >= MIN_SHARE * self.span):
                self._hand_over(self.pose_receipt, self.t_last - self.t0)
            self._restart(R, stamp, receipt)
            return
        k = self.n
        self.Rs[k] = R
        self.ts[k] = stamp
        self.n = k + 1
        self.t_last, self.pose_receipt = stamp, receipt
        tau = stamp - self.t0
        if tau < self.span and self.n < self.CAPACITY:
            return
        self._hand_over(receipt, tau)
        self._restart(R, stamp, receipt)

    def _hand_over(self, receipt: float, span: float) -> None:
        """Close the window: its buffers and sums go to ``settle`` (the spare buffers take the
        next window's poses). A window still waiting is worked out first.
        """
        self.settle()
        self._closing = _Closing(receipt, span, self.Rs, self.ts, self.n, self.t0, self.r0,
                                 self.w.copy(), self.ww, self.f.copy(), self.nw, self.nf,
                                 self.gyro_r0, self.gyro_receipt)
        self.Rs, self.ts = self._spare
        self._spare = (self._closing.Rs, self._closing.ts)

    def settle(self) -> Optional[Window]:
        """Work out the window a pose closed, if one waits: the window (None where it cannot be
        judged, or none waits). ``last`` becomes it where it can be judged.
        """
        closing, self._closing = self._closing, None
        if closing is None:
            return None
        window = self._close(closing)
        if window is not None:
            self._last = window
        return window

    def _close(self, c: _Closing) -> Optional[Window]:
        n, s, nw, receipt, span = c.n, self.settings, c.nw, c.receipt, c.span
        if (not nw or c.gyro_r0 - c.r0 > self.gap
                or receipt - c.gyro_receipt > self.gap):     # the IMU missed its start or end
            return None
        Rs, t = c.Rs[:n], c.ts[:n] - c.t0
        theta = _log_stack(so3.matmul(Rs[0].T, Rs))
        st, stt = float(t.sum()), float((t * t).sum())
        spread = n * stt - st * st
        if spread <= 0.0:
            return None
        slope = (n * (t[:, None] * theta).sum(axis=0) - st * theta.sum(axis=0)) / spread
        poses_sigma = s.attitude_noise * math.sqrt(n / spread)
        gyro_sigma = s.gyro_noise / math.sqrt(nw)
        force = c.f / c.nf if c.nf else None
        g = _norm(s.gravity)
        sigma_tilt = math.hypot(s.attitude_noise / math.sqrt(n),
                                s.accelerometer_noise / (g * math.sqrt(max(c.nf, 1))))
        gyro = c.w / nw
        if self.spread and nw > 1:   # the samples' spread, against a chi-square of 3 (nw - 1)
            dof = 3 * (nw - 1)
            gyro_spread = math.sqrt(max(c.ww - nw * float(so3.dot(gyro, gyro)), 0.0) / dof)
            spread_tolerance = s.gyro_noise * math.sqrt(1.0 + SIGMAS * math.sqrt(2.0 / dof))
        else:
            gyro_spread, spread_tolerance = 0.0, math.inf
        turned = float(np.max(so3.dot(theta, theta)))
        resolved = turned < RESOLVED_RAD ** 2 and _norm(gyro) * span < RESOLVED_RAD
        up = so3.vecmat(self.up_world, Rs).mean(axis=0)     # the mean of R^T e_up
        return Window(receipt, gyro, slope, SIGMAS * math.hypot(poses_sigma, gyro_sigma),
                      up, force, SIGMAS * sigma_tilt, n, nw, resolved, gyro_sigma,
                      poses_sigma, gyro_spread, spread_tolerance)


# the conventions a mismatch is checked against, to name its likely cause:
# (words, pose world, body, marker set rpy deg)
_POSE_GUESSES = [
    ('the poses look NED/FRD and the IMU FRD (pose_world_frame ned, body_frame frd)',
     'ned', 'frd', (0.0, 0.0, 0.0)),
    ('the poses look Y-up (pose_world_frame y_up, and a Y-up rigid body: marker_rotation_deg '
     '[90, 0, 0], which calibrate measures)', 'y_up', 'flu', Y_UP_BODY_DEG),
    ('the poses look NED (pose_world_frame ned)', 'ned', 'flu', (0.0, 0.0, 0.0)),
]


class SensorAgreement:
    """The checks over the converted samples (module docstring)."""

    def __init__(self, settings: AgreementSettings, frames: InputFrames):
        self.settings = settings
        self.frames = frames          # the InputFrames in effect (to name a likely cause)
        self.rest = _Accumulator(REST_WINDOW, settings, spread=True)
        self.flight = _Accumulator(FLIGHT_WINDOW, settings)
        self.mismatches = 0           # in-flight windows in a row that disagree
        self._first: Optional[Tuple[Window, float]] = None   # the first of them, its limit
        self.yaw = YawOffset()        # the yaw between the gyro and the poses since arming
        self.yaw_named = 0            # in-flight windows in a row after which it is named
        self.flight_note: Optional[str] = None    # why, once FLIGHT_WINDOWS in a row did
        self.rest_problems: Optional[List[str]] = None   # the last rest window's verdict
        self.raw_pose: Optional[FloatArray] = None    # the newest pose as the source streamed it

    def imu(self, w: FloatArray, f: Optional[FloatArray], stamp: float, receipt: float) -> None:
        """A converted gyro sample and specific force (None: the IMU gave none) of stamp (s,
        the IMU's clock: only the time between its samples is used), received at receipt (the
        loop's clock).
        """
        self.rest.imu(w, f, stamp, receipt)
        self.flight.imu(w, f, stamp, receipt)

    def pose(self, R: FloatArray, stamp: float, receipt: float,
             raw: Optional[FloatArray] = None) -> None:
        """A converted pose R of stamp (s), received at receipt (the loop's clock); raw: the
        pose as the source streamed it (to name a likely cause).
        """
        self.raw_pose = raw
        self.settle()                   # (a window still waiting: the tick did not run)
        self.rest.pose(R, stamp, receipt)
        self.flight.pose(R, stamp, receipt)

    def settle(self) -> None:
        """Work out and judge the windows the last poses closed (``_Accumulator.settle``): the
        loop runs this once the tick's motor command is out, so a window's verdict
        (``flight_note``) is in force from the next tick on.
        """
        self.rest.settle()
        closed = self.flight.settle()
        if closed is not None and closed.resolved:
            self.yaw.add(closed.gyro, closed.poses_rate, closed.gyro_sigma, closed.poses_sigma)
            self._judge_rate(closed)
            self._judge_yaw()

    def _judge_rate(self, w: Window) -> None:
        """The in-flight rate check of a window: the gyro against the poses' rate. The cause is
        named from the first window that disagreed (while the motion was still the pilot's), a
        yaw by the flight's estimate once it is beyond doubt.
        """
        motion = max(_norm(w.gyro), w.turning)
        limit = w.rate_tolerance + FLIGHT_FLOOR + FLIGHT_SHARE * motion
        if w.disagreement <= limit:
            self.mismatches = 0
            return
        self.mismatches += 1
        if self.mismatches == 1:        # (judged while the motion is still the pilot's)
            self._first = (w, limit)
        if self.mismatches >= FLIGHT_WINDOWS and self.flight_note is None:
            first, allowed = self._first or (w, limit)
            self.flight_note = (
                'the gyro and the poses disagree by %.2f rad/s (over %.2f rad/s; %d windows of '
                '%.1f s in a row): %s' % (first.disagreement, allowed, self.mismatches,
                                          FLIGHT_WINDOW, self._rate_cause(first, True)))

    def _judge_yaw(self) -> None:
        """The in-flight yaw check: the flight's windows so far name a yaw between the gyro and
        the poses beyond YAW_FLOOR_DEG (by SIGMAS standard errors) after FLIGHT_WINDOWS windows
        in a row.
        """
        yaw = self.yaw
        if not yaw.beyond(YAW_FLOOR_DEG, SIGMAS):
            self.yaw_named = 0
            return
        self.yaw_named += 1
        if self.yaw_named >= FLIGHT_WINDOWS and self.flight_note is None:
            self.flight_note = (
                'the gyro and the poses disagree in yaw by %.1f deg (%.0f sigma %.1f deg, '
                'allowed %.0f; %d windows of %.1f s since arming): %s'
                % (yaw.deg, SIGMAS, SIGMAS * yaw.sigma_deg, YAW_FLOOR_DEG, yaw.windows,
                   FLIGHT_WINDOW, self._yaw_cause(yaw.deg)))

    def configure(self, settings: AgreementSettings) -> None:
        """Take new settings (``ControlLoop.reconfigure``), in both windows too."""
        self.settings = settings
        self.rest.configure(settings)
        self.flight.configure(settings)

    def reset_flight(self) -> None:
        """At arming: the in-flight verdicts start again."""
        self.mismatches, self.flight_note = 0, None
        self.yaw.reset()
        self.yaw_named = 0

    # --- at arming -----------------------------------------------------------------------
    def arm_problems(self, now: float) -> List[str]:
        """Why the sensors' agreement forbids arming now (empty: it allows it).

        At rest (the poses turn slower than REST_RATE) both checks judge the last window. A
        turning vehicle (re-armed after a failsafe, say) is judged by the rate check with the
        in-flight tolerance, and by the gravity and bias checks of the last window it rested in
        (the conventions cannot change while the node runs): it must have rested once. A slow
        window in which the vehicle moves (``Window.moving``) and the gyro and the poses differ
        beyond the rest tolerance is refused as moving, not as a bias, and is no rest: the last
        rest's verdict stays.
        """
        if not self.settings.enabled:
            return []
        self.settle()
        w = self.rest.last
        if w is None or now - w.end > LATE * REST_WINDOW:
            return ['the sensor checks have no recent window (%.1f s of poses and IMU '
                    'samples; docs/sensors.md)' % REST_WINDOW]
        turning = w.turning
        if turning > REST_RATE or not w.resolved:
            motion = max(turning, _norm(w.gyro))
            limit = w.rate_tolerance + FLIGHT_FLOOR + FLIGHT_SHARE * motion
            if w.resolved and w.disagreement > limit:
                return ['the gyro and the poses disagree by %.2f rad/s while turning at %.2f '
                        '(allowed %.2f): %s' % (w.disagreement, turning, limit,
                                                self._rate_cause(w))]
            if self.rest_problems is None:
                return ['the vehicle turns at %.2f rad/s and has not rested since start: arm it '
                        'at rest (the gravity check)' % turning]
            return list(self.rest_problems)
        if w.moving and w.disagreement > w.rate_tolerance:
            return ["the vehicle is moving (the poses turn at %.3f rad/s, the gyro's rate "
                    'varies by %.3f rad/s rms about %.3f, its noise %.3f; they differ by %.3f, '
                    'allowed %.3f at rest): arm it when it rests'
                    % (turning, w.gyro_spread, _norm(w.gyro), self.settings.gyro_noise,
                       w.disagreement, w.rate_tolerance)]
        self.rest_problems = self._rest_problems(w, turning)
        return list(self.rest_problems)

    def _rest_problems(self, w: Window, turning: float) -> List[str]:
        """The checks of a window at rest: the gyro against zero, gravity against the poses."""
        problems = []
        if w.disagreement > w.rate_tolerance:
            problems.append(
                'the gyro reads %.3f rad/s at rest (the poses %.3f; allowed %.3f): a gyro '
                "bias (run calibrate, which writes gyro_bias) or the gyro's axes wrong"
                % (_norm(w.gyro), turning, w.rate_tolerance))
        g = _norm(self.settings.gravity)
        if w.force is None:
            problems.append('the IMU sends no specific force (linear_acceleration): the gravity '
                            'check cannot run (consistency_checks false arms without it)')
            return problems
        size = _norm(w.force)
        if abs(size - g) > FORCE_SHARE * g:
            problems.append("the IMU's specific force is %.2f m/s^2 at rest, not about %.2f: "
                            'no accelerometer data in linear_acceleration, or its units wrong'
                            % (size, g))
            return problems
        angle = angle_between_deg(w.force, w.up)
        allowed = math.degrees(self.settings.alignment_tolerance + w.tilt_tolerance)
        if angle > allowed:
            problems.append("the IMU's gravity is %.1f deg from the poses' (allowed %.1f): %s"
                            % (angle, allowed, self._gravity_cause(w, angle, allowed)))
        return problems

    def _gravity_cause(self, w: Window, angle: float, allowed: float) -> str:
        """The likely causes of a gravity mismatch, in words: every other convention or IMU
        mounting that would make gravity agree (at rest, level, several may), or the tilt. A yaw
        of the mounting is measured: the yaw that turns the force's horizontal part onto the
        poses' up's (resting tilted; level, both are about zero and none fits).
        """
        fr = self.frames
        fits = []
        if self.raw_pose is not None and w.force is not None:
            up_world = self.rest.up_world
            raw_f = fr.source_vector(w.force)      # the window's mean, as the IMU gave it
            other = 'frd' if fr.body == 'flu' else 'flu'
            as_other = fr.imu_rotation @ BODY_FRAMES[other].T @ raw_f
            if angle_between_deg(as_other, w.up) <= allowed:
                fits.append('the IMU looks %s while body_frame says %s'
                            % (other.upper(), fr.body))
            for words, world, body, marker in _POSE_GUESSES:
                if (world, body) == (fr.world, fr.body) and marker == (0.0, 0.0, 0.0):
                    continue
                T, B = WORLD_FRAMES[world], BODY_FRAMES[body]
                R = T @ self.raw_pose @ B @ rpy_matrix(marker).T
                f = fr.imu_rotation @ B.T @ raw_f
                if R[2, 2] > 0.0 and angle_between_deg(f, R.T @ up_world) <= allowed:
                    fits.append(words + ', while the parameters say %s/%s'
                                % (fr.world, fr.body))
            yaw = _yaw_between(w.force, w.up)
            turned = so3.matvec(rpy_matrix((0.0, 0.0, yaw)), w.force)
            if abs(yaw) >= YAW_FLOOR_DEG and angle_between_deg(turned, w.up) <= allowed:
                fits.append(self._yaw_cause(yaw))
        if fits:
            return '; or '.join(fits)
        if angle < 30.0:
            return ('a tilted marker set or IMU mounting (about %.0f deg): run calibrate '
                    '(marker_rotation_deg, imu_rotation_deg; docs/sensors.md)' % angle)
        return ('the frames wrong: pose_world_frame, body_frame, marker_rotation_deg or '
                'imu_rotation_deg (docs/sensors.md)')

    def _rate_cause(self, w: Window, in_flight: bool = False) -> str:
        """The likely cause of a rate mismatch, in words: a yaw between the gyro and the poses,
        if turning the gyro by it makes them agree; in flight the flight's yaw once it is beyond
        doubt (``YawOffset``), else the window's own.
        """
        if in_flight and self.yaw.beyond(YAW_FLOOR_DEG, SIGMAS):
            yaw = self.yaw.deg
        else:
            yaw = _yaw_between(w.gyro, w.poses_rate)
        turned = so3.matvec(rpy_matrix((0.0, 0.0, yaw)), w.gyro)
        if abs(yaw) >= YAW_FLOOR_DEG and _norm(turned - w.poses_rate) <= (
                w.rate_tolerance + FLIGHT_FLOOR + 0.5 * FLIGHT_SHARE * w.turning):
            return self._yaw_cause(yaw)
        return "the IMU's mounting, the marker set or the pose frame wrong (docs/sensors.md)"

    def _yaw_cause(self, yaw_deg: float) -> str:
        """The cause a yaw between the gyro and the poses names: the IMU's mounting turned by it
        (the nearest multiple of 45 deg within YAW_STEP_DEG, as mountings mostly are, else
        rounded to YAW_STEP_DEG), with the imu_rotation_deg that undoes it, or the marker set.
        """
        named = 45.0 * round(yaw_deg / 45.0)
        if abs(named - yaw_deg) > YAW_STEP_DEG:
            named = YAW_STEP_DEG * round(yaw_deg / YAW_STEP_DEG)
        if named <= -180.0:
            named += 360.0
        mounting = np.round(matrix_rpy(so3.matmul(rpy_matrix((0.0, 0.0, named)),
                                                   self.frames.imu_rotation)), 1) + 0.0
        return ('the IMU looks mounted about %.0f deg off in yaw: set imu_rotation_deg [%.1f, '
                '%.1f, %.1f] (or the marker set is off as much in yaw: calibrate --heading-deg '
                'measures it)' % (named, mounting[0], mounting[1], mounting[2]))
