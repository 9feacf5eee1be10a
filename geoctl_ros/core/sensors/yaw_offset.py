"""The yaw between the gyro's axes and the poses' body: the rotation about the body's z axis that
turns the gyro's rate onto the poses' rate, estimated over many windows.

An IMU turned in yaw against its ``imu_rotation_deg`` (or a marker set turned in yaw against its
``marker_rotation_deg``) reads the body rate turned about z: Omega_gyro = Rz(-psi) Omega_poses.
The z component is untouched, so a turn about the body's z axis shows nothing; the roll and pitch
rates show the yaw psi as the angle between the two rates' horizontal parts (x, y). One window's
horizontal rates are short and noisy; over a manoeuvre they add up. With the horizontal rates as
complex numbers g and p, the sum Z = sum conj(g) p = D + i C (D the dot products, C the z of the
cross products) has the argument psi that maximises sum p . Rz(psi) g: the least-squares yaw.

Its standard error comes from the windows' noise (one standard deviation per axis of the gyro's
mean, sigma_g, and of the poses' rate, sigma_p): the part of the noise in Z across Z's direction
has the variance sum (sigma_g^2 |p_xy|^2 + sigma_p^2 |g_xy|^2 + 2 sigma_g^2 sigma_p^2), and the
angle's standard error is its square root over |Z|. Without horizontal motion |Z| is noise, the
error is of the order of a radian, and nothing is named.
"""
import math

from geoctl_ros.core.geometry.so3 import FloatArray


class YawOffset:
    """The yaw psi (deg) with Rz(psi) gyro ~ poses' rate, over the windows added since reset."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Start again (at arming: the flight's estimate)."""
        self.dot = 0.0           # D: sum of g_xy . p_xy (rad^2/s^2)
        self.cross = 0.0         # C: sum of (g_xy x p_xy)_z
        self.variance = 0.0      # of Z's part across its direction
        self.windows = 0

    def add(self, gyro: FloatArray, poses_rate: FloatArray, gyro_sigma: float,
            poses_sigma: float) -> None:
        """One window's mean gyro rate and poses' rate (body, rad/s), with their noise (one
        standard deviation per axis, rad/s).
        """
        gx, gy = float(gyro[0]), float(gyro[1])
        px, py = float(poses_rate[0]), float(poses_rate[1])
        self.dot += gx * px + gy * py
        self.cross += gx * py - gy * px
        sg2, sp2 = gyro_sigma * gyro_sigma, poses_sigma * poses_sigma
        self.variance += (sg2 * (px * px + py * py) + sp2 * (gx * gx + gy * gy)
                          + 2.0 * sg2 * sp2)
        self.windows += 1

    @property
    def deg(self) -> float:
        """The estimate of psi, in (-180, 180] deg (0 before any motion)."""
        return math.degrees(math.atan2(self.cross, self.dot))

    @property
    def sigma_deg(self) -> float:
        """The estimate's standard error (deg; infinite before any motion)."""
        size = math.hypot(self.cross, self.dot)
        if size == 0.0:
            return math.inf
        return math.degrees(math.sqrt(self.variance) / size)

    def beyond(self, floor_deg: float, sigmas: float) -> bool:
        """Whether |psi| exceeds floor_deg by sigmas standard errors: a yaw that noise does not
        explain.
        """
        return abs(self.deg) - sigmas * self.sigma_deg > floor_deg
