"""Riding through short input gaps: the attitude and rate the controller uses when a stream is
late.

Motion capture comes over WiFi and the IMU over a serial link; either can go quiet for a few
hundred milliseconds (a busy DDS participant, a WiFi retry, a scheduler hiccup) while the vehicle
is perfectly flyable. Dropping the motors then is the worse choice on a joint with the centre of
mass above the pivot. So, while a stream is stale but not yet lost
(``geoctl_ros.core.supervisor.safety.Stream``):

- **pose gap** (gyro fresh): the attitude is propagated from the last pose with the gyro,
  R <- R exp(hat(Omega) dt) at every control tick (the rate held over the tick). Its error grows
  like the gyro's error times the gap: 0.005 rad/s of white noise at 100 Hz costs at most 0.07 deg
  in 0.4 s (200 trials); a 0.005 rad/s bias would cost 0.11 deg.
- **rate gap** (pose fresh): the angular velocity is taken from two poses ``rate_window`` apart
  (by their stamps): Omega = log(R_old^T R_new) / (t_new - t_old), the mean body rate over the
  window (so it lags by about half the window). With 0.1 deg of motion-capture noise and a 50 ms
  window its noise alone is about sqrt(2) 0.1 deg / 50 ms = 0.05 rad/s; over the testbed's
  manoeuvre, lag included, the error is 0.088 rad/s RMS, 0.17 p99, 0.33 max
  (docs/safety-behaviour.md, "Input gaps").
- **both**: the last rate in use is held and the attitude propagated with it.

When a stream is fresh its measurement is used as it is: nothing here changes normal flight.
"""
from enum import Enum
from typing import Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import FloatArray

POSE_HISTORY = 64    # poses kept for the rate estimate (320 ms at 200 Hz)


class AttitudeSource(Enum):
    """Where the attitude in use comes from (the value is how the diagnostics say it)."""

    POSE = 'pose'
    PROPAGATED = 'propagated with the gyro'


class RateSource(Enum):
    """Where the body rate in use comes from (the value is how the diagnostics say it)."""

    GYRO = 'gyro'
    FROM_POSES = 'from successive poses'
    HELD = 'held'


POSE, PROPAGATED = AttitudeSource.POSE, AttitudeSource.PROPAGATED
GYRO, FROM_POSES, HELD = RateSource.GYRO, RateSource.FROM_POSES, RateSource.HELD


class GapBridge:
    """The attitude and body rate the controller uses, from the latest measurements."""

    def __init__(self, rate_window: float) -> None:
        self.rate_window = float(rate_window)
        self._t = np.full(POSE_HISTORY, -np.inf)      # pose stamps, a ring
        self._R = np.zeros((POSE_HISTORY, 3, 3))
        self._head = -1
        self._R_meas: Optional[FloatArray] = None
        self._pose_receipt: Optional[float] = None
        self._w_meas: Optional[FloatArray] = None
        self.R: Optional[FloatArray] = None       # the attitude in use
        self.Omega: Optional[FloatArray] = None   # the body rate in use
        self._R_time: Optional[float] = None      # the time R refers to
        self.attitude_source = POSE
        self.rate_source = GYRO

    def pose(self, R: FloatArray, stamp: float, receipt: float) -> None:
        """An accepted pose."""
        self._head = (self._head + 1) % POSE_HISTORY
        self._t[self._head] = stamp
        self._R[self._head] = R
        self._R_meas = R
        self._pose_receipt = receipt

    def gyro(self, w: FloatArray) -> None:
        """An accepted angular velocity."""
        self._w_meas = w

    def pose_rate(self) -> Optional[FloatArray]:
        """Body rate from the newest pose and the one closest to rate_window before it, or None
        when no such pair exists (fewer than two poses, or none within 3 windows).
        """
        if self._head < 0:
            return None
        t1 = self._t[self._head]
        dt = t1 - self._t
        ok = (dt > 0.0) & (dt <= 3.0 * self.rate_window)
        if not ok.any():
            return None
        k = int(np.argmin(np.where(ok, np.abs(dt - self.rate_window), np.inf)))
        return cast(FloatArray,
                    so3.log(so3.matmul(so3.transpose(self._R[k]), self._R[self._head])) / dt[k])

    def update(self, now: float, pose_fresh: bool,
               gyro_fresh: bool) -> Optional[Tuple[FloatArray, FloatArray]]:
        """The (R, Omega) to use at time now, given which streams are fresh; None before the first
        pose and the first rate (gyro or poses).
        """
        if gyro_fresh and self._w_meas is not None:
            self.Omega, self.rate_source = self._w_meas, GYRO
        else:
            w = self.pose_rate() if pose_fresh else None
            if w is not None:
                self.Omega, self.rate_source = w, FROM_POSES
            elif self.Omega is not None or self._w_meas is not None:
                self.Omega = self.Omega if self.Omega is not None else self._w_meas
                self.rate_source = HELD
        if self._R_meas is None or self.Omega is None:
            return None
        if pose_fresh or self.R is None:
            self.R, self._R_time, self.attitude_source = self._R_meas, self._pose_receipt, POSE
        else:
            self.R = so3.matmul(self.R, so3.exp(self.Omega * (now - cast(float, self._R_time))))
            self._R_time, self.attitude_source = now, PROPAGATED
        return self.R, self.Omega

    @property
    def bridging(self) -> bool:
        """True while either the attitude or the rate is not the fresh measurement."""
        return self.attitude_source is not POSE or self.rate_source is not GYRO
