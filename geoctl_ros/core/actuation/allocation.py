"""Allocation (``Allocator``) serves the testbed: the spherical joint carries any net force except
the collective thrust along body z, so it solves for the collective thrust and the three moments
about the pivot (the minimum-norm thrusts when more rotors than that are alive), within
[thrust_min, thrust_max] per rotor. A feasible request is met exactly. An infeasible one is
degraded in strict priority: roll and pitch first, then yaw, then collective thrust, each scaled
down only as far as needed, and the moment not delivered is reported.
"""
from dataclasses import dataclass
import math
from typing import List, NamedTuple, Sequence, Tuple

import numpy as np

from geoctl_ros.core.actuation.airframe import AirframeError, check
from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.flags import Flags, all_flag
from geoctl_ros.core.geometry.so3 import FloatArray, Scalars, matvec, matvec_floats


class MomentPolytope(NamedTuple):
    """The moments the rotors make unsaturated (``Allocator.moment_polytope``): A M >= beta
    (A (m, 3), beta (m,)), and its vertices (k, 3).
    """

    A: FloatArray
    beta: FloatArray
    vertices: FloatArray


def polytope_vertices(A: FloatArray, beta: FloatArray) -> FloatArray:
    """The vertices of the bounded polytope A x >= beta in 3-D: every point where three of its
    planes meet and that keeps the others (to rounding), each once.
    """
    found: List[FloatArray] = []
    m = len(beta)
    for i in range(m):
        for j in range(i + 1, m):
            for k in range(j + 1, m):
                M = A[[i, j, k]]
                if abs(float(np.linalg.det(M))) < 1e-12:
                    continue
                x = so3.matvec(so3.inverse3(M), beta[[i, j, k]])
                if np.all(so3.matvec(A, x) >= beta - 1e-9 * (1.0 + np.abs(beta))) and not any(
                        np.allclose(x, y, rtol=0.0, atol=1e-12) for y in found):
                    found.append(x)
    return np.array(found).reshape(-1, 3)


@dataclass
class Allocation:
    """One allocation's result (for a batch of moments: each field with the batch axis first)."""

    thrusts: FloatArray        # N, one per rotor (failed rotors: 0)
    moment: FloatArray         # moment the thrusts produce about the pivot
    collective: Scalars        # thrust they produce along body z
    moment_lost: FloatArray    # requested minus produced moment
    saturated: Flags           # the request was not met exactly
    valid: Flags               # False: the request was not finite (thrusts at thrust_min)


class Allocator:
    """Thrusts for a desired moment (about the pivot) and collective thrust, within limits.

    It knows rotors only through their effectiveness matrix B (6 x n: thrusts -> [force; moment
    about the pivot], from ``effectiveness`` or written by hand), as PX4's control allocation
    receives its matrix from the airframe's ActuatorEffectiveness.
    """

    INSET = 1e-6      # N kept from either thrust limit in ``moment_polytope``

    def __init__(self, B: FloatArray, thrust_min: float, thrust_max: float,
                 failed: Sequence[int] = ()) -> None:
        B = np.asarray(B, dtype=float)
        n = B.shape[1]
        self.count: int = n
        self.alive = [i for i in range(n) if i + 1 not in set(failed)]
        self.B_full = B
        self.B = self.B_full[:, self.alive]
        self.health = check(self.B, [i + 1 for i in self.alive])
        if failed:
            self.health.warnings.insert(0, 'rotor(s) %s marked failed: flying on %s'
                                        % (sorted(failed), self.health.alive))
        self.B4 = self.B[2:]                                  # rows F_z, M_x, M_y, M_z
        P = so3.right_inverse(self.B4)                        # n_alive x 4, minimum norm
        self._d, self._p_rp, self._p_y = P[:, 0], P[:, 1:3], P[:, 3]
        self.base_share = self._d               # each alive rotor's thrust per N of collective
        self._p_moment = np.ascontiguousarray(P[:, 1:])
        self._p_moment_rows: List[List[float]] = self._p_moment.tolist()   # (one moment's)
        self._d_floats: List[float] = self._d.tolist()
        self._B_made = np.ascontiguousarray(self.B[2:])   # rows F_z, M_x, M_y, M_z
        self._B_made_rows: List[List[float]] = self._B_made.tolist()
        if np.any(self._d <= 1e-9):
            raise AirframeError('collective thrust would need rotor(s) %s to push the other way'
                                % [self.alive[i] + 1 for i in np.nonzero(self._d <= 1e-9)[0]])
        self.lo, self.hi = float(thrust_min), float(thrust_max)
        self._inv_d = 1.0 / self._d

    def moment_polytope(self, collective: float) -> 'MomentPolytope':
        """The moments the rotors make unsaturated at this collective thrust, as A M >= beta:
        thrust_min <= collective d_j + P_j M <= thrust_max for every alive rotor j (d, P the
        minimum-norm allocation's columns), two rows per rotor, each limit INSET inside (so that
        a moment on a face, as a QP leaves it, allocates unsaturated despite rounding), with its
        vertices.
        """
        P, base = self._p_moment, collective * self._d
        A = np.concatenate((P, -P))
        beta = np.concatenate((self.lo + self.INSET - base, base - self.hi + self.INSET))
        return MomentPolytope(A, beta, polytope_vertices(A, beta))

    def allocate(self, moment: FloatArray, collective: float) -> Allocation:
        """Allocation for the desired moment (3,) about the pivot and collective thrust (N); a
        stack of moments (batch, 3) gives one allocation per row.
        """
        moment = np.asarray(moment, dtype=float)
        valid: Flags                        # a flag, or one per row
        if moment.ndim == 1:                # one moment: its check in floats
            valid = np.bool_(math.isfinite(collective)
                             and all(map(math.isfinite, moment.tolist())))
        else:
            valid = np.isfinite(moment).all(axis=-1) & math.isfinite(collective)
        all_valid = all_flag(valid)
        m = moment if all_valid else np.where(np.asarray(valid)[..., None], moment, 0.0)
        # (entry by entry, one moment or a batch's rows: a run's bits do not depend on its batch
        # or on the CPU's BLAS kernel)
        if m.ndim == 1:                     # (one moment: the same sums, in floats)
            parts = matvec_floats(self._p_moment_rows, m.tolist())
            f_floats = [collective * d + p for d, p in zip(self._d_floats, parts)]
            f = np.array(f_floats)
            met = np.bool_(min(f_floats) >= self.lo and max(f_floats) <= self.hi)
        else:
            f = collective * self._d + matvec(self._p_moment, m)
            met = (f.min(axis=-1) >= self.lo) & (f.max(axis=-1) <= self.hi)
        if not all_flag(met):
            f_rp = matvec(self._p_rp, m[..., :2])
            f_y = self._p_y * m[..., 2:]
            # roll and pitch scaled first, then yaw (only when roll and pitch are whole), then the
            # collective thrust moved within what the rotors allow
            s_rp = self._max_scale(np.zeros_like(f_rp), f_rp)
            base = (f_rp.T * s_rp).T
            s_y = np.where(s_rp >= 1.0, self._max_scale(base, f_y), 0.0)
            base = base + (f_y.T * s_y).T
            t_lo, t_hi = self._t_interval(base)
            t = np.minimum(np.maximum(collective, t_lo), t_hi)
            degraded = np.minimum(np.maximum(np.multiply.outer(t, self._d) + base, self.lo),
                                  self.hi)                                        # round-off
            f = np.where(np.asarray(met)[..., None], f, degraded)
        if not all_valid:
            f = np.where(np.asarray(valid)[..., None], f, self.lo)
            moment = np.where(np.asarray(valid)[..., None], moment, 0.0)
        return self._result(f, moment, saturated=~met | ~valid, valid=valid)

    def _t_interval(self, base: FloatArray) -> Tuple[FloatArray, FloatArray]:
        """The collective levels t with lo <= t d + base <= hi for every rotor."""
        return (np.max((self.lo - base) * self._inv_d, axis=-1),
                np.min((self.hi - base) * self._inv_d, axis=-1))

    def _max_scale(self, base: FloatArray, a: FloatArray) -> FloatArray:
        """Largest s in [0, 1] such that some t gives lo <= t d + base + s a <= hi per rotor.

        Per rotor, L_i - s A_i <= t <= H_i - s A_i; some t exists iff for every pair (i, j)
        s (A_j - A_i) <= H_j - L_i. (0 when base itself is infeasible.)
        """
        L = (self.lo - base) * self._inv_d
        H = (self.hi - base) * self._inv_d
        A = a * self._inv_d
        D = A[..., None, :] - A[..., :, None]
        N = H[..., None, :] - L[..., :, None]
        ratio = np.divide(N, D, out=np.full(D.shape, np.inf), where=D > 1e-12).min(axis=(-2, -1))
        return np.where((N < -1e-12).any(axis=(-2, -1)), 0.0,
                        np.minimum(np.maximum(ratio, 0.0), 1.0))

    def _result(self, f_alive: FloatArray, moment: FloatArray, saturated: Flags,
                valid: Flags) -> Allocation:
        """The Allocation of the alive rotors' thrusts; moment is the request (0 where invalid)."""
        if len(self.alive) == self.count:
            thrusts = f_alive
        else:
            thrusts = np.zeros(f_alive.shape[:-1] + (self.count,))
            thrusts[..., self.alive] = f_alive
        made = (np.array(matvec_floats(self._B_made_rows, f_alive.tolist())) if f_alive.ndim == 1
                else matvec(self._B_made, f_alive))      # the collective thrust and the moment
        return Allocation(thrusts=thrusts, moment=made[..., 1:], collective=made[..., 0],
                          moment_lost=moment - made[..., 1:], saturated=saturated, valid=valid)
