r"""Rotor geometry, the effectiveness matrix and the airframe's health check.

Frames: ROS body frame (REP-103: x forward, y left, z up), origin at the centre of mass for the
rotor positions; moments are taken about the pivot, which is at -rho from the centre of mass.

Rotor i (1-based) has a position p_i (from the centre of mass), a unit thrust axis n_i, a spin
direction s_i (+1: counter-clockwise about n_i, seen from above) and the airframe's yaw-reaction
coefficient k (moment per newton of thrust). Its thrust f_i >= 0 gives the force f_i n_i and the
moment about the pivot f_i ((rho + p_i) x n_i - s_i k n_i): a rotor spinning counter-clockwise
pushes the body clockwise.

The lab's hexrotor (``tilted_ring`` layout, the defaults), seen from above, nose up the page:

                 x (forward)
                 ^
           6     |     2            rotor i at azimuth -(i - 1) 60 deg, i.e. numbered clockwise
            \    1    /             from the nose, as in the lab's forward-right-down code
             \   |   /              (the lab's rotor i is this rotor i and ESC address 0x28 + i)
     y <------ (pivot)              arm 0.31 m; each thrust axis tilted 15 deg tangentially;
             /       \              odd rotors spin counter-clockwise (s = +1), even clockwise;
            /    4    \             each tilt leans towards the rotor's direction of travel
           5           3            ... (so that tilt and reaction moments add up in yaw)
"""
from dataclasses import dataclass
import math
from typing import List, Sequence

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray


class AirframeError(ValueError):
    """A rotor layout that cannot produce every moment (with the reason)."""


@dataclass(frozen=True)
class RotorGeometry:
    """Per-rotor geometry (n rotors): positions (n, 3) from the centre of mass, unit axes (n, 3),
    spins (n,) of +-1, and the yaw-reaction coefficient (m).
    """

    positions: FloatArray
    axes: FloatArray
    spins: FloatArray
    yaw_coefficient: float

    @property
    def count(self) -> int:
        return len(self.spins)


def tilted_ring(count: int = 6, arm_length: float = 0.31, tilt_deg: float = 15.0,
                first_azimuth_deg: float = 0.0, height: float = 0.0,
                yaw_coefficient: float = 0.1) -> RotorGeometry:
    """The usual layout: rotors numbered clockwise seen from above, alternating spin and tilt."""
    i = np.arange(count)
    azimuth = np.radians(first_azimuth_deg) - 2.0 * np.pi * i / count     # clockwise from above
    radial = np.column_stack((np.cos(azimuth), np.sin(azimuth), np.zeros(count)))
    tangential = np.column_stack((-np.sin(azimuth), np.cos(azimuth), np.zeros(count)))  # CCW
    spins = np.where(i % 2 == 0, 1.0, -1.0)
    # A CCW rotor's reaction pushes the body clockwise (-z); tilting its thrust towards -tangential
    # (clockwise travel) gives a moment arm x axis with the same sign: the two add in yaw.
    tilt = math.radians(tilt_deg)
    axes = (math.cos(tilt) * np.array([0.0, 0.0, 1.0])[None, :]
            - math.sin(tilt) * spins[:, None] * tangential)
    positions = arm_length * radial + np.array([0.0, 0.0, height])[None, :]
    return RotorGeometry(positions, axes, spins, float(yaw_coefficient))


def effectiveness(geometry: RotorGeometry, rho: FloatArray) -> FloatArray:
    """The 6 x n matrix mapping rotor thrusts to [force; moment about the pivot] (body frame);
    a stack of them for a stack of centre-of-mass offsets rho (batch, 3).
    """
    arms = geometry.positions + np.asarray(rho, dtype=float)[..., None, :]    # from the pivot
    moments = (np.cross(arms, geometry.axes)
               - (geometry.spins * geometry.yaw_coefficient)[:, None] * geometry.axes)
    forces = np.broadcast_to(geometry.axes.T, moments.shape[:-2] + geometry.axes.T.shape)
    return np.concatenate((forces, np.swapaxes(moments, -1, -2)), axis=-2)


@dataclass
class AirframeHealth:
    """What the start-up check found."""

    rank: int               # of the 6 x n effectiveness (6: fully actuated)
    moment_rank: int        # of its moment rows (must be 3)
    condition: float        # of the allocated rows [F_z; M]
    alive: List[int]        # 1-based numbers of the rotors in use
    warnings: List[str]


def check(B: FloatArray, alive: Sequence[int]) -> 'AirframeHealth':
    """Check an effectiveness matrix (6 x n_alive); raises AirframeError when a moment cannot be
    produced, returns AirframeHealth with warnings for what is merely degraded.
    """
    rank = int(np.linalg.matrix_rank(B))
    moment_rank = int(np.linalg.matrix_rank(B[3:]))
    if moment_rank < 3:
        raise AirframeError('the rotors %s cannot produce every moment (moment rank %d of 3)'
                            % (alive, moment_rank))
    B4 = B[2:]
    if np.linalg.matrix_rank(B4) < 4:
        raise AirframeError('the rotors %s cannot produce collective thrust independently of the '
                            'moments' % (alive,))
    s = np.linalg.svd(B4, compute_uv=False)
    warnings = []
    if rank < 6:
        warnings.append('not fully actuated (effectiveness rank %d of 6): lateral forces '
                        'follow from the moments, which the joint absorbs' % rank)
    cond = float(s[0] / s[-1])
    if cond > 100.0:
        warnings.append('poorly conditioned allocation (condition number %.0f)' % cond)
    return AirframeHealth(rank, moment_rank, cond, list(alive), warnings)
