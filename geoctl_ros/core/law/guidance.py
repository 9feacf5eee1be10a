"""Guidance: the way round the cones, planned on the sphere, and the set point fed along it.

The paper's law is a gradient flow of Psi = A (1 + sum_i (B_i - 1)). Where the goal lies behind
a cone, that flow has a saddle in front of it: the straight 90 deg yaw of the testbed lingers
there for half a minute (it needs noise to fall off the ridge) and the lab stepped through
hand-made set points round the cone. Guidance does that by itself, for any start, goal and cones:

1. **The sensor's path** (``sensor_path``): the shortest way on the unit sphere from where the
   sensor points to where the goal points it, keeping every cone's guarded half-angle plus
   ``clearance`` away: a visibility graph of the start, the goal and points on each cone's
   widened rim, searched by Dijkstra. (Cones near the start or the goal are widened less, down
   to the barrier's own rim, so that a start or goal close to a cone still has a way out.)
2. **The attitudes along it** (``attitude_path``): each step turns the body by the shortest
   rotation that takes the sensor from one point of the path to the next (parallel transport),
   and the turn about the sensor axis that is left at the end (the goal's twist) is spread
   along the way in proportion to the arc; the last attitude is the goal itself.
3. **The set point** (``Guidance.carrot``): from the path's point nearest the vehicle (by the
   sensor's direction), the furthest attitude of the path within the lookahead of the measured
   one that this point sees (the straight way to it keeps each cone's barrier rim plus half the
   point's own gap to it away: no corner cut into a cone). The lookahead is ``lookahead``, and
   near a cone LOOKAHEAD_PER_GAP times the sensor's gap to that cone's barrier rim (at least
   LOOKAHEAD_MIN). So the law always chases a set point at most that far away: that bounds the
   attractive error A, and with it the moment and the speed, however far away the goal is, and
   slows the sensor as it nears a cone (where a fast approach bounced off the barrier's stiff
   rim under latency). The last set point is the goal, held as the paper's law holds any
   constant set point. A vehicle pushed more than twice ``lookahead`` off its set point gets a
   new plan from where it is.

The barrier of the law stays whole between the set points. The law's proof covers each constant
set point; the switches between them are not covered by it (docs/control-law.md, "Guidance").
A batch plans its runs' ways at once (at a set point's start only; each the same as planned
alone) and picks every run's set point at once.
"""
import math
from typing import Dict, List, Optional, Tuple, cast

import numpy as np

from geoctl_ros.core.geometry import so3
from geoctl_ros.core.geometry.so3 import BoolArray, FloatArray, IntArray, Scalars
from geoctl_ros.core.law.cones import ConeSet

RIM_POINTS = 48             # points on each cone's widened rim (7.5 deg apart)
RIM_SLACK = math.radians(1.0)   # the rim's points lie this far outside the widened cone, so that
                                # the arc between two neighbours (its sag 0.15 deg) clears it
PATH_STEP = math.radians(2.0)   # the path's attitudes at most this far apart (sensor arc)
REPLAN_FACTOR = 2.0         # a set point this many lookaheads away from the vehicle: plan again
LOOKAHEAD_MIN = math.radians(5.0)   # the lookahead near a cone, at least
LOOKAHEAD_PER_GAP = 2.0     # near a cone the lookahead is at most this many times the gap to it
CAP_SLACK = math.radians(0.5)   # a joint cap keeps this far from a path's end inside it
CAP_CLEARANCE = math.radians(2.0)   # the path keeps this far from the joint's caps
SIGHT_CHUNK = 8             # the set point's sight is worked out this many places ahead at a time
BOUND_SURE = 1e-6           # rad: a way judged by a bound has this much to spare (far more than
                            # the rounding of the exact judgement it stands for)


def arc_clearance(a: FloatArray, b: FloatArray, axes: FloatArray) -> FloatArray:
    """The smallest angle (rad) between each axis and the short great-circle arc from a to b:
    a and b unit vectors (..., 3) that broadcast together, axes unit (..., C, 3) broadcasting
    against them; returns (..., C).

    The great circle through a and b has the unit normal n; its point nearest an axis v is v's
    projection on its plane, at arcsin |v . n| from v. Where that point lies outside the arc,
    the nearer end is the nearest point.
    """
    a, b = np.broadcast_arrays(a, b)
    n = so3.cross(a, b)
    norm = np.sqrt(so3.dot(n, n))[..., None]
    n = np.where(norm > 1e-12, n / np.maximum(norm, 1e-12), 0.0)
    a, b, n = a[..., None, :], b[..., None, :], n[..., None, :]
    vn = so3.dot(axes, n)                                              # (..., C)
    p = axes - vn[..., None] * n
    # (a x p) . n >= 0 and (p x b) . n >= 0: p lies between a and b on the great circle
    inside = ((so3.dot(so3.cross(a, p), n) >= 0.0) & (so3.dot(so3.cross(p, b), n) >= 0.0)
              & (norm > 1e-12))
    mid = np.arcsin(np.clip(np.abs(vn), 0.0, 1.0))
    ends = np.minimum(np.arccos(np.clip(so3.dot(a, axes), -1.0, 1.0)),
                      np.arccos(np.clip(so3.dot(b, axes), -1.0, 1.0)))
    return cast(FloatArray, np.where(inside, mid, ends))


_RIM_PHI = np.linspace(0.0, 2.0 * math.pi, RIM_POINTS, endpoint=False)
_RIM_COS, _RIM_SIN = np.cos(_RIM_PHI)[:, None], np.sin(_RIM_PHI)[:, None]   # (made once)


def _rim(axis: FloatArray, radius: float) -> FloatArray:
    """RIM_POINTS points at angle radius round the unit axis."""
    e1 = so3.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    e1 /= math.sqrt(so3.dot(e1, e1))
    e2 = so3.cross(axis, e1)
    return math.cos(radius) * axis + math.sin(radius) * (_RIM_COS * e1 + _RIM_SIN * e2)


def sensor_path(d0: FloatArray, d1: FloatArray, axes: FloatArray, rims: FloatArray,
                clearance: Scalars) -> Optional[List[FloatArray]]:
    """The shortest way on the sphere from d0 to d1 that keeps every cone i (unit axis axes[i],
    the barrier's half-angle rims[i]) at least rims[i] + clearance away (one clearance, or one
    per cone): the corner points, d0
    first and d1 last. Where d0 or d1 is nearer a cone than that, the cone is widened only up to
    halfway from its rim to the nearer of them. None where no such way exists (the cones close
    round the start or the goal). (``sensor_paths`` of one run.)
    """
    axes = np.asarray(axes, dtype=float).reshape(-1, 3)
    return sensor_paths(np.asarray(d0)[None], np.asarray(d1)[None], axes[None],
                        np.asarray(rims, dtype=float).reshape(1, len(axes)), clearance)[0]


PLAN_ENTRIES = 1 << 16      # the visibility graphs of this many (pair, cone) entries at a time


def sensor_paths(d0: FloatArray, d1: FloatArray, axes: FloatArray, rims: FloatArray,
                 clearance: Scalars) -> List[Optional[List[FloatArray]]]:
    """``sensor_path`` for each of n runs: d0 and d1 (n, 3), axes (n, C, 3), rims (n, C),
    clearance one, or one per cone (C,). A visibility graph of the start, the goal and
    RIM_POINTS points on each cone's widened rim, searched by Dijkstra, for every run at once
    (PLAN_ENTRIES at a time), entry by entry: each run's way is the same to the bit as alone.
    """
    n, C = rims.shape
    if not C:
        return [[a, b] for a, b in zip(d0, d1)]
    N = 2 + C * RIM_POINTS
    first, second = np.triu_indices(N)
    chunk = max(1, PLAN_ENTRIES // (len(first) * C))
    out: List[Optional[List[FloatArray]]] = []
    for lo in range(0, n, chunk):
        part = slice(lo, lo + chunk)
        out += _visible_ways(d0[part], d1[part], axes[part], rims[part], clearance, first,
                             second)
    return out


def _visible_ways(d0: FloatArray, d1: FloatArray, axes: FloatArray, rims: FloatArray,
                  clearance: Scalars, first: IntArray,
                  second: IntArray) -> List[Optional[List[FloatArray]]]:
    """``sensor_paths`` of a chunk of runs (first, second: the graph's pairs of nodes)."""
    ends = np.stack([d0, d1], axis=1)                                          # (n, 2, 3)
    gap = np.arccos(np.clip(_cosines(ends, axes), -1.0, 1.0)).min(axis=-2) - rims   # (n, C)
    keep = rims + np.clip(np.minimum(clearance, 0.5 * gap), 0.0, None)        # widened radii
    X = _graph_nodes(ends, axes, keep)
    n, N = X.shape[:2]
    angles = np.arccos(np.clip(_cosines(X, axes), -1.0, 1.0))         # (n, N, C): to each axis
    need = keep[:, None] - 1e-9                                            # (n, 1, C)
    # a point of one rim inside another widened cone is no way
    inside = np.any(angles < need, axis=-1)
    length = np.arccos(np.clip(_cosines(X, X), -1.0, 1.0))
    clear = _clear_ways(X, axes, angles, need, length, inside, first, second)
    clear &= ~inside[:, :, None] & ~inside[:, None, :]
    previous = _dijkstra(np.where(clear, length, np.inf), 0)
    ways: List[Optional[List[FloatArray]]] = []
    for x, before in zip(X, previous.tolist()):
        if before[1] < 0:
            ways.append(None)
            continue
        way, i = [], 1
        while i != 0:
            way.append(x[i])
            i = before[i]
        ways.append([x[0]] + way[::-1])
    return ways


def _graph_nodes(ends: FloatArray, axes: FloatArray, keep: FloatArray) -> FloatArray:
    """The visibility graphs' nodes (n, N, 3): each run's start and goal (ends (n, 2, 3)), then
    RIM_POINTS points on each cone's rim (axes (n, C, 3)), RIM_SLACK outside its widened radius
    keep (n, C).
    """
    return np.concatenate([ends, np.array([np.concatenate(
        [_rim(v, k + RIM_SLACK) for v, k in zip(V, K)]) for V, K in zip(axes, keep)]
        ).reshape(len(ends), -1, 3)], axis=1)


def _clear_ways(X: FloatArray, axes: FloatArray, angles: FloatArray, need: FloatArray,
                length: FloatArray, inside: BoolArray, first: IntArray,
                second: IntArray) -> BoolArray:
    """(n, N, N): whether the arc between each pair of the nodes X (n, N, 3) keeps every cone
    (axes (n, C, 3)) at least need (n, 1, C) away (``arc_clearance``); angles: each node's to each
    axis, length: the pairs' arcs, inside: the nodes inside a cone (their ways are none anyway).
    The way between two points is the same both ways, to the bit (arc_clearance's terms only
    change sign), so each pair (first, second) is worked out once. Most are judged by bounds, by
    BOUND_SURE: clear where each end's angle to every axis, less half the arc, is beyond need
    (every point of the arc lies within half its length of an end); not clear where the arc's
    middle lies inside a cone. Only the rest is worked out whole (``arc_clearance`` against
    need), and so every pair is judged as that would judge it.
    """
    n, N = X.shape[:2]
    half = 0.5 * length[:, first, second, None]                               # (n, P, 1)
    sure = np.all(np.minimum(angles[:, first], angles[:, second]) - half >= need + BOUND_SURE,
                  axis=-1)
    middle = X[:, first] + X[:, second]
    size = np.sqrt(so3.dot(middle, middle))[..., None]
    cut = np.any(_cosines(middle, axes) > size * np.cos(np.maximum(need - BOUND_SURE, 0.0)),
                 axis=-1) & (size[..., 0] > 1e-6)
    ways = sure & ~(inside[:, first] | inside[:, second])
    runs, pairs = np.nonzero(~(sure | cut | inside[:, first] | inside[:, second]))
    if len(runs):
        ways[runs, pairs] = np.all(arc_clearance(X[runs, first[pairs]], X[runs, second[pairs]],
                                                 axes[runs]) >= need[runs, 0], axis=-1)
    clear = np.empty((n, N, N), dtype=bool)
    clear[:, first, second] = clear[:, second, first] = ways
    return clear


def _cosines(X: FloatArray, Y: FloatArray) -> FloatArray:
    """X Y^T for unit vectors X (..., N, 3) and Y (..., C, 3): (..., N, C), entry by entry (not
    through BLAS, whose kernels round by the CPU: a plan, and every decision on it, would differ
    by machine).
    """
    return so3.dot(X[..., :, None, :], Y[..., None, :, :])


def _dijkstra(cost: FloatArray, start: int) -> IntArray:
    """The predecessor of each node on its shortest way from start (-1: no way) on the dense
    cost matrices (..., n, n) (inf: no edge), one graph per leading index, all searched at once.
    The nodes are settled nearest first, the lower index first among equally near ones (a heap
    of (distance, index) would settle them so too); with as few nodes as a plan has (some 50),
    a scan of the distances beats the heap.
    """
    n = cost.shape[-1]
    graphs = cost.reshape(-1, n, n)
    m = len(graphs)
    dist = np.full((m, n), np.inf)
    previous = np.full((m, n), -1)
    done = np.zeros((m, n), dtype=bool)
    waiting = np.full((m, n), np.inf)   # the distances of the nodes reached, not yet settled
    dist[:, start] = waiting[:, start] = 0.0
    every = np.arange(m)
    for _ in range(n):
        i = np.argmin(waiting, axis=-1)
        d = waiting[every, i]
        if not np.any(d < np.inf):      # (a graph with none left reached changes no more)
            break
        done[every, i] = True
        waiting[every, i] = np.inf
        through = d[:, None] + graphs[every, i]
        better = (through < dist) & ~done
        dist[better] = waiting[better] = through[better]
        previous[better] = np.broadcast_to(i[:, None], better.shape)[better]
    previous[:, start] = start
    return cast(IntArray, previous.reshape(cost.shape[:-1]))


def upright(d: FloatArray, r: FloatArray, up: FloatArray) -> FloatArray:
    """The attitudes that point the body-fixed r along each unit d (K, 3) with the body's z axis
    as near up as it can be (R r = d, R e3 on the cone of half-angle angle(r, e3) round d, on the
    side of up): (K, 3, 3). Each one's tilt is |elevation of d - elevation of r in the body|, the
    least any attitude pointing r along d has. (Entry by entry the operations of one attitude's
    floats: the same bits for a direction alone and among others.)
    """
    (rx, ry, rz), (ux, uy, uz) = (np.asarray(v, dtype=float).tolist() for v in (r, up))
    zb = [-rz * rx, -rz * ry, 1.0 - rz * rz]            # body z, less its part along r
    nb = math.sqrt(zb[0] * zb[0] + zb[1] * zb[1] + zb[2] * zb[2])
    if nb < 1e-9:                                      # r along the body's z: any turn will do
        zb = so3.cross_floats([rx, ry, rz], np.eye(3)[int(np.argmin(np.abs(r)))].tolist())
        nb = math.sqrt(zb[0] * zb[0] + zb[1] * zb[1] + zb[2] * zb[2])
    zb = [v / nb for v in zb]
    yb = so3.cross_floats([rx, ry, rz], zb)
    d = np.asarray(d, dtype=float)
    dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
    dot_ud = ux * dx + uy * dy + uz * dz
    zw = [ux - dot_ud * dx, uy - dot_ud * dy, uz - dot_ud * dz]   # towards up, across d
    nw = np.sqrt(zw[0] * zw[0] + zw[1] * zw[1] + zw[2] * zw[2])
    for k in np.flatnonzero(nw < 1e-9):                # d straight up or down
        other = so3.cross_floats(d[k].tolist(), np.eye(3)[int(np.argmin(np.abs(d[k])))].tolist())
        for i in range(3):
            zw[i][k] = other[i]
        nw[k] = math.sqrt(other[0] * other[0] + other[1] * other[1] + other[2] * other[2])
    zw = [v / nw for v in zw]
    yw = [dy * zw[2] - dz * zw[1], dz * zw[0] - dx * zw[2], dx * zw[1] - dy * zw[0]]  # d x z_w
    # R = W B^T with the columns B = (r, z_b, r x z_b) and W = (d, z_w, d x z_w)
    B, W = ([rx, ry, rz], zb, yb), ([dx, dy, dz], zw, yw)
    out = np.empty((len(d), 3, 3))
    for i in range(3):
        for j in range(3):
            out[:, i, j] = W[0][i] * B[0][j] + W[1][i] * B[1][j] + W[2][i] * B[2][j]
    return out


def _turn_about(d: FloatArray, R: FloatArray, base: FloatArray) -> float:
    """The angle psi (rad, in (-pi, pi]) with R = exp(psi d) base, for attitudes R and base that
    both point the sensor along d (their difference is a turn about d).
    """
    w = so3.log(so3.matmul(R, so3.transpose(base)))
    return float(so3.dot(w, d))


def attitude_path(R0: FloatArray, R_goal: FloatArray, r: FloatArray,
                  corners: List[FloatArray], up: FloatArray,
                  tilt_max: float = math.pi) -> FloatArray:
    """The attitudes along the sensor's path through corners (unit vectors, R0 r first and
    R_goal r last), at most PATH_STEP apart: (K, 3, 3), R0 first and R_goal last. At each point
    the most upright attitude (``upright``), turned about the sensor by the start's turn from
    its own upright one blended into the goal's by arc length, and at the points between the
    ends by no more than keeps the body's z axis CAP_CLEARANCE inside the joint's stops
    (tilt_max, rad, from up; ``twist_within``): a start resting on the stops is lifted off them
    at once, and no point of the path lies past them (where the path keeps out of their caps).
    """
    points = [corners[0]]
    for a, b in zip(corners[:-1], corners[1:]):
        angle = math.acos(min(1.0, max(-1.0, float(so3.dot(a, b)))))
        k = max(1, int(math.ceil(angle / PATH_STEP)))
        if angle < 1e-12:
            continue
        axis = so3.cross(a, b)
        if not so3.dot(axis, axis) > 0.0:    # the same or opposite to the bit: by any great
            if angle < 0.5 * math.pi:        # circle through them (before: a NaN axis)
                continue
            axis = so3.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        axis /= math.sqrt(so3.dot(axis, axis))
        turned = so3.exp(axis[None, :] * (angle * np.arange(1, k + 1) / k)[:, None])
        points += list(so3.matvec(turned, a))
    d = np.array(points)
    arc = np.concatenate([[0.0], np.cumsum(np.arccos(np.clip(
        so3.dot(d[:-1], d[1:]), -1.0, 1.0)))])
    bases = upright(d, r, up)
    first, last = _turn_about(d[0], R0, bases[0]), _turn_about(d[-1], R_goal, bases[-1])
    if len(points) == 1:               # the sensor does not move: turn about it in steps
        twist = last - first
        k = max(1, int(math.ceil(abs(twist) / PATH_STEP)))
        turns = first + twist * np.arange(k + 1) / k
        path = so3.matmul(so3.exp(d[0][None, :] * turns[:, None]), bases[0])
    else:
        share = arc / arc[-1] if arc[-1] > 0.0 else np.linspace(0.0, 1.0, len(points))
        turns = first + (last - first) * share
        if tilt_max < math.pi - 1e-9:
            limit = twist_within(bases, d, up, tilt_max - CAP_CLEARANCE)
            turns[1:-1] = np.clip(turns[1:-1], -limit[1:-1], limit[1:-1])
        path = so3.matmul(so3.exp(d * turns[:, None]), bases)
    path[0], path[-1] = R0, R_goal
    return _filled(path)


def _filled(path: FloatArray) -> FloatArray:
    """The path with attitudes put in, PATH_STEP apart at most, along the shortest turn between
    neighbours more than twice that apart (where the stops' limit on the turn about the sensor
    changes the turn faster than the sensor moves: the lift off the stops at the start), so that
    the set point, which looks LOOKAHEAD_MIN ahead near a cone, always has a next one in reach.
    """
    # (the neighbours' turns all at once, a little generously: only those that may be more
    # than twice PATH_STEP apart are worked out one by one, as before)
    turns = so3.angle(so3.matmul(so3.transpose(path[:-1]), path[1:]))
    far = np.flatnonzero(turns > 2.0 * PATH_STEP * (1.0 - 1e-9))
    if not len(far):
        return path
    out = [path[:far[0] + 1]]
    for n, m in enumerate(far):
        a, b = path[m], path[m + 1]
        w = so3.log(so3.matmul(so3.transpose(a), b))
        angle = math.sqrt(so3.dot(w, w))
        k = int(math.ceil(angle / PATH_STEP)) if angle > 2.0 * PATH_STEP else 1
        out.append(np.array([so3.matmul(a, so3.exp(w * (i / k))) for i in range(1, k)]
                            ).reshape(-1, 3, 3))
        out.append(path[m + 1:far[n + 1] + 1 if n + 1 < len(far) else len(path)])
    return np.concatenate(out)


def twist_within(bases: FloatArray, d: FloatArray, up: FloatArray,
                 tilt: float) -> FloatArray:
    """The largest turn psi (rad, >= 0) about each sensor direction d[k] that keeps the body's
    z axis of exp(+-psi d[k]) bases[k] within tilt (rad) of up; 0 where even the upright
    attitude bases[k] (``upright``) is tilted further. With z = bases[k] e3 split into a part
    a along d and b across it (b towards up: the upright attitude), up . z(psi) = a + b cos psi
    falls with |psi| on [0, pi], so the bound is arccos((cos tilt - a) / b).
    """
    z = np.ascontiguousarray(bases[:, :, 2])
    along = so3.dot(z, d)[:, None] * d
    a = so3.dot(along, up[None, :])
    b = so3.dot(z - along, up[None, :])
    gap = math.cos(tilt) - a
    # (b = 0: d along up, the tilt the same at every turn: any turn, or none)
    c = np.where(b > 1e-12, gap / np.maximum(b, 1e-12), np.where(gap <= 0.0, -1.0, 1.0))
    return cast(FloatArray, np.arccos(np.clip(c, -1.0, 1.0)))


def joint_caps(up: FloatArray, r: FloatArray, tilt_max: float,
               ends: FloatArray) -> Tuple[FloatArray, FloatArray]:
    """The sensor directions the joint's stops keep the body from (its z axis at most tilt_max
    from up): above the elevation of r in the body plus tilt_max and below it less tilt_max, as
    two cones round up and down for the planner ((axes (k, 3), half-angles (k,)); none where the
    stops allow every direction). Each is narrowed to keep the path's ends (a vehicle resting on
    its stops) just outside it.
    """
    if tilt_max >= math.pi - 1e-9:
        return np.zeros((0, 3)), np.zeros(0)
    rise = math.asin(max(-1.0, min(1.0, float(r[2]))))    # r's elevation in the body
    axes, rims = [], []
    for axis, half in ((up, 0.5 * math.pi - rise - tilt_max),
                       (-up, 0.5 * math.pi + rise - tilt_max)):
        nearest = float(np.arccos(np.clip(so3.dot(ends, axis[None, :]), -1.0, 1.0)).min())
        half = min(half, nearest - CAP_SLACK)
        if half > 0.0:
            axes.append(axis)
            rims.append(half)
    return np.array(axes).reshape(-1, 3), np.array(rims)


def plan(R0: FloatArray, R_goal: FloatArray, r: FloatArray, axes: FloatArray,
         rims: FloatArray, clearance: float, up: Optional[FloatArray] = None,
         tilt_max: float = math.pi) -> FloatArray:
    """The attitudes from R0 to R_goal round the cones (``sensor_path``, ``attitude_path``) and
    within the joint's stops (``joint_caps``: up, the world's up; tilt_max, rad); where no way
    round exists, the goal alone (the law's barrier then decides). (``plans`` of one run.)
    """
    axes = np.asarray(axes, dtype=float).reshape(-1, 3)
    return plans(R0[None], R_goal[None], r, axes[None],
                 np.asarray(rims, dtype=float).reshape(1, len(axes)), clearance, up,
                 tilt_max)[0]


def plans(R0: FloatArray, R_goal: FloatArray, r: FloatArray, axes: FloatArray,
          rims: FloatArray, clearance: float, up: Optional[FloatArray] = None,
          tilt_max: float = math.pi) -> List[FloatArray]:
    """``plan`` for each of n runs: R0 and R_goal (n, 3, 3), axes (n, C, 3), rims (n, C); the
    sensor's ways of all runs at once (``sensor_paths``), each the same as alone.
    """
    up = np.array([0.0, 0.0, 1.0]) if up is None else up
    d0, d1 = so3.matvec(R0, r), so3.matvec(R_goal, r)
    corners = sensor_paths(d0, d1, axes, rims, clearance)
    # the way round the cones that goes past the stops: round the stops' caps too (planned
    # only then: the caps make the graph half as large again), the runs with as many caps
    # together
    again: Dict[int, List[Tuple[int, FloatArray, FloatArray]]] = {}
    for i, way in enumerate(corners):
        cap_axes, cap_rims = joint_caps(up, r, tilt_max, np.stack([d0[i], d1[i]]))
        if way is not None and len(cap_rims) and _enters(way, cap_axes, cap_rims):
            again.setdefault(len(cap_rims), []).append((i, cap_axes, cap_rims))
    for caps, runs in again.items():
        index = [i for i, _, _ in runs]
        ways = sensor_paths(
            d0[index], d1[index],
            np.array([np.concatenate((axes[i], cap_axes)) for i, cap_axes, _ in runs]),
            np.array([np.concatenate((rims[i], cap_rims)) for i, _, cap_rims in runs]),
            np.concatenate((np.full(rims.shape[-1], clearance), np.full(caps, CAP_CLEARANCE))))
        for i, way in zip(index, ways):
            corners[i] = way
    return [R_goal[i][None].copy() if way is None
            else attitude_path(R0[i], R_goal[i], r, way, up, tilt_max)
            for i, way in enumerate(corners)]


def _enters(corners: List[FloatArray], axes: FloatArray, rims: FloatArray) -> bool:
    """Whether the way through corners passes within CAP_CLEARANCE of a cap (axes, half-angles
    rims): each leg's closest approach to each cap's axis (``arc_clearance``).
    """
    a, b = np.array(corners[:-1]), np.array(corners[1:])
    return bool(np.any(arc_clearance(a[:, None], b[:, None], axes[None]) < rims + CAP_CLEARANCE))


_ONE_RUN = np.zeros(1, dtype=int)
_ONE_RUN.flags.writeable = False


class Guidance:
    """The set point fed along the planned path, for one run or a batch (see the module)."""

    def __init__(self, lookahead: float, clearance: float, up: Optional[FloatArray] = None,
                 tilt_max: float = math.pi):
        """lookahead: rad, how far ahead of the vehicle the set point may be; clearance: rad,
        how far outside each cone's barrier the path keeps; up: the world's up (unit); tilt_max:
        rad, the joint's stops (the body's z axis from up), which the path keeps within.
        """
        self.lookahead = lookahead
        self.clearance = clearance
        self.up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=float)
        self.tilt_max = tilt_max
        self.cos_replan = math.cos(min(math.pi, REPLAN_FACTOR * lookahead))
        # the path's points within the lookahead lie at most this many places ahead (its steps
        # turn the sensor at least PATH_STEP / 2, and the body at least as far)
        self.window = 2 * int(math.ceil(lookahead / PATH_STEP)) + 2
        self._around = np.arange(-self.window, self.window + 1)[None, :]   # (the places looked
        self._ahead = np.arange(self.window)[None, :]                      # at, made once)
        self.paths: Optional[FloatArray] = None   # (runs, K, 3, 3), each padded with its goal
        self.sensor: Optional[FloatArray] = None  # (runs, K, 3): the sensor's direction on it
        self.last: Optional[IntArray] = None      # (runs,): the goal's place on each path
        self.sight: Optional[IntArray] = None     # (runs, K): the furthest point each one sees
        self.index: Optional[IntArray] = None     # (runs,), the set point's place on its path

    def reset(self) -> None:
        """Forget the plan: the next set point is planned from where the vehicle is then."""
        self.paths = self.sensor = self.last = self.sight = self.index = None

    def carrot(self, R: FloatArray, R_goal: FloatArray, cones: ConeSet) -> FloatArray:
        """The set point for the measured attitude R (one (3, 3) or a stack), with the goal
        R_goal and the ConeSet cones: from the path's point nearest the vehicle (its sensor's),
        the furthest point within the lookahead that the path's point sees (``_sight``), so that
        the set point never cuts a corner into a cone.
        """
        single = R.ndim == 2
        Rs = R[None] if single else R
        goals = R_goal[None] if single else R_goal
        if self.paths is None:
            self._plan(Rs, goals, cones, np.arange(len(Rs)))
        assert self.paths is not None and self.index is not None
        if len(Rs) == 1:                # one run, or a batch of one
            P = self._carrot_of_one(Rs, goals, cones)
            return P if single else P[None]
        runs = np.arange(len(Rs))
        P = self.paths[runs, self.index]
        cos_now = 0.5 * (np.einsum('nij,nij->n', P, Rs) - 1.0)     # cos of the angle R to P
        far = np.flatnonzero(cos_now < self.cos_replan)
        if len(far):
            self._plan(Rs, goals, cones, far)
        # (the others hold their goal)
        moving = np.flatnonzero(self.index < cast(IntArray, self.last))
        if len(moving):
            self._advance(Rs[moving], moving, cones)
        P = self.paths[runs, self.index]
        return P[0] if single else P

    def _carrot_of_one(self, Rs: FloatArray, goals: FloatArray, cones: ConeSet) -> FloatArray:
        """``carrot`` for one run (Rs and goals (1, 3, 3)): the same steps, without the batch's
        indexing; its set point (3, 3).
        """
        assert self.paths is not None and self.index is not None and self.last is not None
        P = self.paths[0, self.index[0]]
        if 0.5 * (np.einsum('nij,nij->n', P[None], Rs)[0] - 1.0) < self.cos_replan:
            self._plan(Rs, goals, cones, _ONE_RUN)
        if self.index[0] < self.last[0]:
            self._advance(Rs, _ONE_RUN, cones)
        return cast(FloatArray, self.paths[0, self.index[0]].copy())

    def _advance(self, Rs: FloatArray, runs: IntArray, cones: ConeSet) -> None:
        """Move the set points of the runs (indices) along their paths (see ``carrot``). Near a
        cone the lookahead shrinks to LOOKAHEAD_PER_GAP times the sensor's gap to the cone's
        barrier rim (down to LOOKAHEAD_MIN): the pull, and with it the speed, falls as the sensor
        nears a cone.
        """
        assert self.paths is not None and self.sensor is not None and self.index is not None
        assert self.sight is not None
        K, W = self.paths.shape[1], self.window
        m = np.arange(len(runs))
        # (np.minimum and np.maximum for np.clip: the same values, without its checks' cost)
        around = np.minimum(np.maximum(self.index[runs, None] + self._around, 0), K - 1)
        # (one run's in floats: the stack's bits)
        d = so3.matvec(Rs[0], cones.r)[None] if len(Rs) == 1 else so3.matvec(Rs, cones.r)
        V, rims = _cone_rows(cones, runs)
        gap = np.min(np.arccos(np.minimum(np.maximum(np.einsum('nck,nk->nc', V, d), -1.0), 1.0))
                     - rims, axis=-1, initial=np.inf)
        cos_lookahead = np.cos(np.minimum(np.maximum(LOOKAHEAD_PER_GAP * gap, LOOKAHEAD_MIN),
                                          self.lookahead))
        near = around[m, np.argmax(np.einsum('nwk,nk->nw', self.sensor[runs[:, None], around],
                                             d), axis=1)]             # the nearest path point
        ahead = np.minimum(near[:, None] + self._ahead, K - 1)
        within = 0.5 * (np.einsum('nkij,nij->nk', self.paths[runs[:, None], ahead], Rs)
                        - 1.0) >= cos_lookahead[:, None]
        within[:, 0] = True
        furthest = ahead[m, W - 1 - np.argmax(within[:, ::-1], axis=1)]
        # (never past its own goal, into the padding up to the batch's longest path: a shorter
        # plan of another run would leave it off the end)
        self.index[runs] = np.minimum(np.minimum(furthest, self.sight[runs, near]),
                                      cast(IntArray, self.last)[runs])

    def _plan(self, Rs: FloatArray, goals: FloatArray, cones: ConeSet,
              runs: IntArray) -> None:
        """Plan the paths of the runs (indices) from the attitudes Rs to their goals."""
        V, rims = _cone_rows(cones, np.arange(len(Rs)))
        new = dict(zip(runs.tolist(), plans(Rs[runs], goals[runs], cones.r, V[runs], rims[runs],
                                            self.clearance, self.up, self.tilt_max)))
        old = [] if self.paths is None else [self.paths[i, :cast(IntArray, self.last)[i] + 1]
                                             for i in range(len(Rs))]
        paths = [new[i] if i in new else old[i] for i in range(len(Rs))]
        K = max(len(p) for p in paths)
        self.paths = np.array([np.concatenate([p, np.repeat(p[-1:], K - len(p), axis=0)])
                               for p in paths])
        self.sensor = so3.matvec(self.paths, cones.r)
        self.last = np.array([len(p) - 1 for p in paths])
        runs = np.asarray(runs)
        sight = np.full((len(Rs), K), K - 1)
        if self.sight is not None:              # (the others' as they were)
            keep = min(K, self.sight.shape[1])
            sight[:, :keep] = np.minimum(self.sight[:, :keep], K - 1)
        sight[runs] = _sight(self.sensor[runs], V[runs], rims[runs], self.window,
                             self.clearance)
        self.sight = sight
        index = np.zeros(len(Rs), dtype=int) if self.index is None else self.index.copy()
        index[runs] = 0
        self.index = index


def _sight(D: FloatArray, V: FloatArray, rims: FloatArray, window: int,
           clearance: float) -> IntArray:
    """Per run and path point k (D: the paths' sensor directions, (n, K, 3)), the furthest point
    j of the path within window places that k sees: the straight way from k to each point up to
    j keeps every cone (axes V (n, C, 3), barrier half-angles rims (n, C)) at its rim plus half
    k's own gap to it (at most the clearance) away.
    """
    n, K = D.shape[:2]
    ahead = np.minimum(np.arange(K)[:, None] + np.arange(1, window)[None, :], K - 1)
    gap = np.arccos(np.clip(np.einsum('nkx,ncx->nkc', D, V), -1.0, 1.0)) - rims[:, None]
    need = rims[:, None] + np.clip(0.5 * gap, 0.0, clearance)                  # (n, K, C)
    # Most ways are clear by the triangle inequality: every point of the arc from k to j lies
    # within the arc's length of k, and that length is at most the path's from k to j; so the
    # arc keeps a cone at least k's angle to its axis less that away. Only the rest, near a
    # cone, is worked out whole (arc_clearance), with the same comparison as before.
    steps = np.arccos(np.clip(so3.dot(D[:, :-1], D[:, 1:]), -1.0, 1.0))     # (n, K - 1)
    along = np.concatenate([np.zeros((n, 1)), np.cumsum(steps, axis=-1)], axis=-1)
    length = along[:, ahead] - along[:, :, None]                                # (n, K, W-1)
    room = np.min(gap + rims[:, None] - need, axis=-1, initial=np.inf)         # (n, K)
    clear = length <= (room - BOUND_SURE)[:, :, None]                          # (n, K, W-1)
    # and only up to the first way that is not clear: the points after it are not seen
    # whatever their ways (SIGHT_CHUNK places ahead at a time)
    looking = np.ones((n, K), dtype=bool)
    for first in range(0, window - 1, SIGHT_CHUNK):
        part = clear[:, :, first:first + SIGHT_CHUNK]
        runs, k, m = np.nonzero(looking[:, :, None] & ~part)
        if len(runs):
            part[runs, k, m] = np.all(arc_clearance(D[runs, k], D[runs, ahead[k, first + m]],
                                                    V[runs]) >= need[runs, k] - 1e-9, axis=-1)
        looking &= np.all(part, axis=-1)
        if not looking.any():
            break
    blocked = np.cumsum(~clear, axis=-1) > 0          # from the first point it does not see
    seen = np.sum(~blocked, axis=-1)                  # how many points ahead it sees
    return cast(IntArray, np.minimum(np.arange(K)[None, :] + np.maximum(seen, 1), K - 1))


def _cone_rows(cones: ConeSet, runs: IntArray) -> Tuple[FloatArray, FloatArray]:
    """The cones' axes (m, C, 3) and barrier half-angles (m, C) of the runs (indices) of a
    batched ConeSet, or of its one set for each.
    """
    C = cones.V.shape[-2] if cones.V.ndim >= 2 else 0
    V = cones.V.reshape(-1, C, 3) if C else np.zeros((1, 0, 3))
    rims = np.asarray(cones.theta_b).reshape(V.shape[0], C)
    if V.shape[0] == 1:
        if len(runs) == 1:                  # (one run: the set itself)
            return V, rims
        return np.repeat(V, len(runs), axis=0), np.repeat(rims, len(runs), axis=0)
    return V[runs], rims[runs]
