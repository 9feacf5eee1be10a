"""The moment closest to a law's that meets linear constraints, A u >= beta: the QP
min |u - u0|^2 that the cbf law's filter and the approach brake (``core.law.brake``) solve, with
the rotors' moment polytope (``Allocator.moment_polytope``) among the rows.

Solved exactly by Goldfarb and Idnani's dual active-set method, in floats (a few rows of three
numbers: numpy's overhead, and BLAS's CPU-dependent rounding, cost more than the arithmetic).
"""
import math
from typing import List, Optional, Protocol, Sequence, Tuple

import numpy as np

from geoctl_ros.core.geometry.so3 import FloatArray


class Polytope(Protocol):
    """The moments A M >= beta (A (m, 3), beta (m,)), also as (A, beta, ...): what the law
    knows of ``core.actuation.allocation.MomentPolytope`` (actuation is above the law).
    """

    @property
    def A(self) -> FloatArray: ...

    @property
    def beta(self) -> FloatArray: ...

    def __getitem__(self, i: int) -> FloatArray: ...

    def __len__(self) -> int: ...

TOL = 1e-9


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _solve(G: List[List[float]], rhs: List[float]) -> List[float]:
    """x with G x = rhs for a small nonsingular G (Gaussian elimination, partial pivoting)."""
    q = len(rhs)
    M = [row[:] + [v] for row, v in zip(G, rhs)]
    for c in range(q):
        p = max(range(c, q), key=lambda i: abs(M[i][c]))
        M[c], M[p] = M[p], M[c]
        for i in range(c + 1, q):
            k = M[i][c] / M[c][c]
            M[i] = [x - k * y for x, y in zip(M[i], M[c])]
    x = [0.0] * q
    for i in range(q - 1, -1, -1):
        acc = M[i][q]
        for j in range(i + 1, q):
            acc -= M[i][j] * x[j]
        x[i] = acc / M[i][i]
    return x


def project(u0: FloatArray, A: FloatArray, beta: FloatArray,
            tol: float = TOL) -> Tuple[FloatArray, bool]:
    """The point closest to u0 with A u >= beta (one run: u0 (3,), A (m, 3), beta (m,)),
    exactly, by Goldfarb and Idnani's dual active-set method (Math. Programming 27, 1983) with
    the identity for its Hessian: from u0, the most violated constraint is added at a time, each
    step moving u along the part of its normal the active ones leave free, and an active
    constraint whose multiplier would turn negative is dropped. Every iterate keeps the
    multipliers of the active set nonnegative, so when no constraint is violated u is the
    optimum. Returns (u, True), or (u0, False) when the constraints contradict each other.
    """
    rows = np.asarray(A, dtype=float).tolist()
    b = np.asarray(beta, dtype=float).tolist()
    start = np.asarray(u0, dtype=float).tolist()
    u = start[:]
    active: List[int] = []
    lam: List[float] = []
    m = len(b)
    for _ in range(4 * m + 8):               # (finite: each full step adds, no set recurs)
        slack = [_dot(rows[i], u) - b[i] for i in range(m)]
        p = min(range(m), key=slack.__getitem__)
        if slack[p] >= -tol:
            return np.array(u), True
        n_p = rows[p]
        lam_p = 0.0
        while True:
            if active:
                N = [rows[j] for j in active]
                r = _solve([[_dot(x, y) for y in N] for x in N], [_dot(x, n_p) for x in N])
                z = [n_p[c] - sum(r[j] * N[j][c] for j in range(len(N))) for c in range(3)]
            else:
                r, z = [], n_p
            # partial step: the first active multiplier to reach zero
            t1, k = math.inf, -1
            for j in range(len(active)):
                if r[j] > tol and lam[j] / r[j] < t1:
                    t1, k = lam[j] / r[j], j
            zz = _dot(z, n_p)
            # (a normal the active ones leave (nearly) no part of: a dual step only)
            t2 = (-(_dot(n_p, u) - b[p]) / zz if zz > 1e-10 * _dot(n_p, n_p) else math.inf)
            t = min(t1, t2)
            if t == math.inf:                      # the constraints contradict each other
                return np.array(start), False
            lam = [lj - t * rj for lj, rj in zip(lam, r)]
            lam_p += t
            if t2 < math.inf:
                u = [u[c] + t * z[c] for c in range(3)]
            if t == t2:                            # full step: p joins the active set
                active.append(p)
                lam.append(lam_p)
                break
            del active[k]                          # partial step: k leaves
            del lam[k]
    return np.array(start), False


def closest_admissible(u0: FloatArray, A: FloatArray, beta: FloatArray,
                       limits: Optional[Polytope] = None) -> FloatArray:
    """The moment closest to u0 with A u >= beta (``project``) and, given limits =
    (A_m, beta_m), within the moments the rotors make unsaturated
    (``Allocator.moment_polytope``). u0 itself where it is admissible. Where the rows and the
    rotors' contradict each other, the rows alone (the allocation then saturates); where the
    rows contradict each other, the most violated one alone. A batch solves each run on its own,
    so a run gets the same bits alone and in a batch.
    """
    if limits is not None:
        A_m, beta_m = limits[0], limits[1]
        A = np.concatenate((A, np.broadcast_to(A_m, A.shape[:-2] + A_m.shape)), axis=-2)
        beta = np.concatenate((beta, np.broadcast_to(beta_m, beta.shape[:-1] + beta_m.shape)),
                              axis=-1)
    slack = slack_of(A, u0, beta)
    ok = np.all(slack >= -TOL, axis=-1)
    if np.all(ok):
        return u0
    own = A.shape[-2] - (0 if limits is None else len(limits[1]))
    out = np.array(u0, dtype=float, copy=True)
    for i in zip(*np.nonzero(~np.asarray(ok))) if out.ndim > 1 else [()]:
        u, feasible = project(u0[i], A[i], beta[i])
        if not feasible and limits is not None:
            u, feasible = project(u0[i], A[i][:own], beta[i][:own])
        if not feasible:                        # the most violated constraint alone
            j = int(np.argmin(slack[i][:own]))
            a = A[i][j]
            u = u0[i] + a * (max(-slack[i][j], 0.0) / max(_dot(a, a), 1e-12))
        out[i] = u
    return out


def slack_of(A: FloatArray, u: FloatArray, beta: FloatArray) -> FloatArray:
    """A u - beta, entry by entry (the same bits for a run alone and in a batch)."""
    u = u[..., None, :]
    return A[..., 0] * u[..., 0] + A[..., 1] * u[..., 1] + A[..., 2] * u[..., 2] - beta
