"""PRIOR: decoupled prioritized planning in space-time (van den Berg & Overmars, IROS 2005).

Robots are planned one after another. Each one treats the robots planned before it as moving
obstacles (each parked on its goal for ever after arriving) and the robots not planned yet as discs
parked on their starts (the "garage" assumption of the paper). One robot is planned with safe-interval
path planning (SIPP, Phillips & Likhachev 2011) over the 8-connected grid of cell centres its disc
fits on (no corner cutting: the swept disc of every move is clear of obstacles). It drives from
centre to centre at its top speed and may wait wherever it is safe; it only accepts its goal at a
time from which the goal stays free for ever.

Everything is exact in continuous time: every trajectory is piecewise linear, so

* the times at which a disc standing on a point overlaps a linear piece of another trajectory form
  one interval (a quadratic in t): the complement gives the point's *safe intervals*;
* the departure times at which a move overlaps a linear piece of another trajectory form one
  interval as well (the projection of a convex set, :func:`_bad_departures`): the earliest safe
  departure jumps from interval end to interval end, no time step involved.

The keep-out distance of a pair is ``r_i + r_j + margin`` (less where the scenario itself puts two
robots closer, e.g. adjacent starts), so rounding never turns a touch into an overlap. Planned
pieces live in per-cell buckets, padded so that a query looks at one bucket only. Every planned
path is re-checked against its neighbours with the plain closest-approach formula before it is
accepted.

SIPP leaves every node as early as it can, so it waits right before each conflict, often in an
aisle; the found path is then re-timed backwards so that each wait moves as far back along the path
as it can (to the start, mostly) without a later arrival.

Repairs, when a robot cannot be planned: a robot not planned yet whose start blocks the way stops
being an obstacle (it will have to leave in time); a planned robot that then drives over that start
before its owner can leave has to keep off it longer (and is planned again); a planned robot parked
on its goal in the way (or crossing our goal too late) gets the blocked robot just ahead of it.
Planning resumes from the earliest changed position; the robots ahead of it keep their paths.
"""
from __future__ import annotations

import heapq
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, dijkstra

from ..budget import Budget
from ..geometry import segment_point_distance_xy
from ..grid import GridMap
from ..model import Plan, PlanningError, RobotSpec, TimedPath
from .base import Planner, Progress, incremental_problem

ORDERS = ("given", "shortest", "longest")

_INF = math.inf
_DIRS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))
#: a search that expands this many states without reaching its goal gives up
_MAX_EXPANSIONS = 200_000
#: safe intervals shorter than this are dropped (a robot would have to hit them exactly)
_MIN_INTERVAL = 1e-9

# a piece of a trajectory: (t_a, t_b, x, y, vx, vy, owner, x_min, y_min, x_max, y_max); position at
# t is (x, y) + v (t - t_a), or (x, y) when v == 0 (then t_a may be -inf and t_b +inf); the last four
# bound the positions
Piece = tuple[float, float, float, float, float, float, int, float, float, float, float]


def _piece(ta: float, tb: float, x: float, y: float, vx: float, vy: float, owner: int) -> Piece:
    if vx == 0.0 and vy == 0.0:
        return ta, tb, x, y, 0.0, 0.0, owner, x, y, x, y
    ex, ey = x + vx * (tb - ta), y + vy * (tb - ta)
    return ta, tb, x, y, vx, vy, owner, min(x, ex), min(y, ey), max(x, ex), max(y, ey)


class PriorPlanner(Planner):
    """Prioritized planning: SIPP per robot around the robots planned before it.

    ``order``: initial priority - "given" (as listed), "shortest" / "longest" (straight-line distance
    from start to goal, shortest / longest first). ``time_limit_s``: give up after this long (None:
    no limit). ``max_wait_s``: how much later than on an empty map a robot may arrive; the search of
    one robot is bounded by it. ``margin`` (m): added to each pair's sum of radii. ``max_reorders``:
    how often a blocked robot may be moved ahead of its blocker (default 4 N; 0 keeps the order).
    """

    name = "prior"

    def __init__(self, order: str = "given", time_limit_s: float | None = None, max_wait_s: float = 300.0,
                 margin: float = 0.02, max_reorders: int | None = None):
        if order not in ORDERS:
            raise ValueError(f"order: must be one of {', '.join(ORDERS)} (got {order!r})")
        if time_limit_s is not None and not time_limit_s > 0:
            raise ValueError(f"time_limit_s: must be > 0 or None (got {time_limit_s!r})")
        if not (max_wait_s > 0 and math.isfinite(max_wait_s)):
            raise ValueError(f"max_wait_s: must be a finite number > 0 (got {max_wait_s!r})")
        if not (margin >= 0 and math.isfinite(margin)):
            raise ValueError(f"margin: must be a finite number >= 0 (got {margin!r})")
        if max_reorders is not None and not max_reorders >= 0:
            raise ValueError(f"max_reorders: must be >= 0 or None (got {max_reorders!r})")
        self.order = order
        self.time_limit_s = time_limit_s
        self.max_wait_s = float(max_wait_s)
        self.margin = float(margin)
        self.max_reorders = max_reorders
        #: ``time_limit_s`` counts CPU seconds of this process (a :class:`~fleet_planner.budget.Budget`), not wall-clock
        #: seconds: md's route search for legs sets it, so that its legs do not depend on the load
        self.cpu_time = False
        self._roadmaps: dict[tuple, _Roadmap] = {}

    # ------------------------------------------------------------------------------------------
    def plan(self, grid: GridMap, robots: Sequence[RobotSpec], progress: Progress | None = None) -> Plan:
        t_start = time.perf_counter()
        robots = list(robots)
        session = _Session(self, grid, robots, [], 0.0)
        paths, order, reorders = session.run(self._initial_order(robots), progress)
        timed = [TimedPath(r.id, r.radius, _compress(paths[x])) for x, r in enumerate(robots)]
        return Plan("prior", timed, time.perf_counter() - t_start,
                    {"order": [robots[x].id for x in order], "reorders": reorders})

    def plan_incremental(self, grid: GridMap, robots: Sequence[RobotSpec], fixed: Sequence[TimedPath],
                         t0: float) -> list[TimedPath]:
        """Timed paths for ``robots``, each leaving its ``start`` (where it stands at ``t0``) no
        earlier than ``t0``, around the ``fixed`` trajectories (unchanged; each parked on its last
        waypoint for ever). Paths start with the waypoint ``(start, t0)``; raises
        :class:`PlanningError` like :meth:`plan`."""
        robots = incremental_problem(robots, fixed, t0)
        session = _Session(self, grid, robots, list(fixed), float(t0))
        paths, _, _ = session.run(self._initial_order(robots), None)
        return [TimedPath(r.id, r.radius, _compress(paths[x])) for x, r in enumerate(robots)]

    # ------------------------------------------------------------------------------------------
    def _initial_order(self, robots: list[RobotSpec]) -> list[int]:
        idx = list(range(len(robots)))
        if self.order == "given":
            return idx
        dist = [math.dist(r.start, r.goal) for r in robots]
        return sorted(idx, key=lambda x: dist[x], reverse=self.order == "longest")

    def _roadmap(self, grid: GridMap, radius: float) -> _Roadmap:
        """Roadmaps are cached by map content and radius (the delivery benchmark calls us often)."""
        lanes = getattr(grid, "lanes", None)   # a road map of directed lanes (fleet_planner.roadmap)
        key = (grid.blocked.shape, grid.resolution, hash(grid.blocked.tobytes()), float(radius),
               None if lanes is None else hash(lanes.allowed.tobytes()))
        rm = self._roadmaps.get(key)
        if rm is None:
            if len(self._roadmaps) > 16:
                self._roadmaps.clear()
            rm = self._roadmaps[key] = _build_roadmap(grid, radius)
        return rm


# ---------------------------------------------------------------------------------------------
# the static part: where a disc of one radius may stand and drive
# ---------------------------------------------------------------------------------------------
@dataclass
class _Roadmap:
    """Cell centres a disc fits on and the moves between them (cell index = row * width + col)."""

    free: np.ndarray                      # bool [row, col]
    nbrs: list[list[tuple[int, float]]]   # per cell: (neighbour cell, length in m)
    graph: csr_matrix                     # the same moves, for Dijkstra / BFS
    component: np.ndarray                 # per cell: label of its connected component


def _build_roadmap(grid: GridMap, radius: float) -> _Roadmap:
    """Exact on the grid: a move is allowed when no blocked cell (or the outside of the map) comes
    closer than ``radius`` to the moving centre, tested with one template per move direction."""
    res, h, w = grid.resolution, grid.height, grid.width
    rc = radius / res
    k = int(math.ceil(rc)) + 2
    padded = np.pad(grid.blocked, k, constant_values=True)

    def clear(geom) -> np.ndarray:
        ok = np.ones((h, w), dtype=bool)
        for dc in range(-k, k + 1):
            for dr in range(-k, k + 1):
                if shapely.distance(geom, shapely.box(dc, dr, dc + 1, dr + 1)) < rc - 1e-9:
                    ok &= ~padded[k + dr:k + dr + h, k + dc:k + dc + w]
        return ok

    free = clear(shapely.Point(0.5, 0.5))
    lanes = getattr(grid, "lanes", None)   # only the moves of its road map of directed lanes
    allowed = None if lanes is None else lanes.move_mask((h, w))
    src, dst, length = [], [], []
    for bit, (dc, dr) in enumerate(_DIRS):
        ok = free & clear(shapely.LineString([(0.5, 0.5), (0.5 + dc, 0.5 + dr)]))
        if allowed is not None:
            ok &= (allowed & (1 << bit)) > 0
        rows, cols = np.nonzero(ok)
        src.append(rows * w + cols)
        dst.append((rows + dr) * w + cols + dc)
        length.append(np.full(len(rows), math.hypot(dc, dr) * res))
    src_a, dst_a, len_a = np.concatenate(src), np.concatenate(dst), np.concatenate(length)
    nbrs: list[list[tuple[int, float]]] = [[] for _ in range(h * w)]
    for s, d, l in zip(src_a.tolist(), dst_a.tolist(), len_a.tolist()):
        nbrs[s].append((d, l))
    graph = csr_matrix((len_a, (src_a, dst_a)), shape=(h * w, h * w))
    return _Roadmap(free, nbrs, graph, connected_components(graph, directed=False)[1])


# ---------------------------------------------------------------------------------------------
# the dynamic part: pieces of planned trajectories, bucketed by cell
# ---------------------------------------------------------------------------------------------
class _Space:
    """Pieces of the trajectories planned so far (and of robots parked on their starts).

    A piece is put in the bucket of every cell whose centre lies within ``pad`` of the piece's
    bounding box, ``pad`` = its radius + the largest radius + margin + one diagonal cell: then any
    piece that can come within keep-out distance of a move (or a wait) that starts in a cell is in
    that cell's bucket, as the whole move stays within one diagonal of the cell's centre.
    """

    def __init__(self, grid: GridMap, radii: Sequence[float] | np.ndarray, reach: float):
        self.res, self.width, self.height = grid.resolution, grid.width, grid.height
        self.radii = list(radii)
        self.reach = reach
        self.buckets: list[list[Piece]] = [[] for _ in range(grid.width * grid.height)]
        self.where: dict[int, set[int]] = {}
        self.parked: dict[int, tuple[float, float, float]] = {}  # owner -> (x, y, since) parked for ever

    def add(self, piece: Piece) -> None:
        ta, tb, x, y, vx, vy, owner, x0, y0, x1, y1 = piece
        if vx == 0.0 and vy == 0.0 and tb == _INF:
            self.parked[owner] = (x, y, ta)
        pad = self.radii[owner] + self.reach
        res = self.res
        c0 = max(0, math.ceil((x0 - pad) / res - 0.5))
        c1 = min(self.width - 1, math.floor((x1 + pad) / res - 0.5))
        r0 = max(0, math.ceil((y0 - pad) / res - 0.5))
        r1 = min(self.height - 1, math.floor((y1 + pad) / res - 0.5))
        where = self.where.setdefault(owner, set())
        for row in range(r0, r1 + 1):
            base = row * self.width
            for col in range(c0, c1 + 1):
                self.buckets[base + col].append(piece)
                where.add(base + col)

    def remove(self, owner: int) -> None:
        for b in self.where.pop(owner, ()):
            self.buckets[b] = [p for p in self.buckets[b] if p[6] != owner]
        self.parked.pop(owner, None)

    def add_path(self, owner: int, wp: np.ndarray, t_from: float = -_INF,
                 reach: Sequence[tuple[float, float, float, float]] = ()) -> None:
        """A trajectory with the contract's meaning, cut into pieces at most one cell long; pieces
        that end before ``t_from`` are left out, and with ``reach`` ((x, y, speed, keep-out) of each
        robot to plan, which leaves (x, y) at ``t_from`` at the earliest) so are pieces none of them
        can come within keep-out distance of before the piece ends (out of reach: they cannot
        conflict with anything it may do)."""
        for piece in _pieces(wp, owner, self.res):
            if piece[1] >= t_from and (not reach or _reachable(piece, t_from, reach)):
                self.add(piece)


def _reachable(piece: Piece, t0: float, reach: Sequence[tuple[float, float, float, float]]) -> bool:
    """Some robot leaving (x, y) at ``t0`` at top speed comes within its keep-out distance of the
    piece's bounding box before the piece ends."""
    tb, x0, y0, x1, y1 = piece[1], piece[7], piece[8], piece[9], piece[10]
    for x, y, speed, keep in reach:
        d = math.hypot(max(x0 - x, 0.0, x - x1), max(y0 - y, 0.0, y - y1))
        if d - keep <= speed * (tb - t0) + 1e-9:
            return True
    return False


def _pieces(wp: np.ndarray, owner: int, max_len: float) -> list[Piece]:
    """The parked head, the segments (long ones cut into pieces) and the parked tail of a path."""
    wp = np.asarray(wp, dtype=float)
    out: list[Piece] = [_piece(-_INF, float(wp[0, 2]), float(wp[0, 0]), float(wp[0, 1]), 0.0, 0.0, owner)]
    for (xa, ya, ta), (xb, yb, tb) in zip(wp[:-1].tolist(), wp[1:].tolist()):
        if tb <= ta:
            continue
        if xa == xb and ya == yb:
            out.append(_piece(ta, tb, xa, ya, 0.0, 0.0, owner))
            continue
        vx, vy = (xb - xa) / (tb - ta), (yb - ya) / (tb - ta)
        n = max(1, math.ceil(math.hypot(xb - xa, yb - ya) / max_len))
        for k in range(n):
            t1 = ta + (tb - ta) * k / n
            t2 = tb if k == n - 1 else ta + (tb - ta) * (k + 1) / n
            out.append(_piece(t1, t2, xa + vx * (t1 - ta), ya + vy * (t1 - ta), vx, vy, owner))
    out.append(_piece(float(wp[-1, 2]), _INF, float(wp[-1, 0]), float(wp[-1, 1]), 0.0, 0.0, owner))
    return out


# ---------------------------------------------------------------------------------------------
# exact conflict geometry
# ---------------------------------------------------------------------------------------------
def _roots(a: float, b: float, c: float, lo: float, hi: float) -> tuple[float, float] | None:
    """The part of [lo, hi] where a x^2 + b x + c < 0 (a > 0), or None."""
    disc = b * b - 4.0 * a * c
    if disc <= 0.0:
        return None
    sq = math.sqrt(disc)
    x1 = (-b - sq) / (2.0 * a)
    x2 = (-b + sq) / (2.0 * a)
    if x1 < lo:
        x1 = lo
    if x2 > hi:
        x2 = hi
    return (x1, x2) if x1 < x2 else None


def _unsafe_times(px: float, py: float, piece: Piece, reach: float) -> tuple[float, float] | None:
    """When a disc standing on (px, py) is closer than ``reach`` to the piece (open interval)."""
    ta, tb, x, y, vx, vy = piece[:6]
    ex, ey = x - px, y - py
    if vx == 0.0 and vy == 0.0:
        return (ta, tb) if ex * ex + ey * ey < reach * reach else None
    span = _roots(vx * vx + vy * vy, 2.0 * (ex * vx + ey * vy), ex * ex + ey * ey - reach * reach, 0.0, tb - ta)
    return None if span is None else (ta + span[0], ta + span[1])


def _bad_departures(ax: float, ay: float, wx: float, wy: float, d: float, piece: Piece,
                    reach: float) -> tuple[float, float] | None:
    """Departure times tau for which the move ``(ax, ay) + w (t - tau)``, t in [tau, tau + d], comes
    closer than ``reach`` to the piece: one open interval (or None).

    With s = t - tau in [0, d] and u = t - t_a in [0, L] the relative position E + s w - u v is affine
    in (s, u); the set where its norm is <= reach is convex, so is its intersection with the
    rectangle, and so is the projection onto tau = t_a + u - s: an interval. Its ends are attained at
    points where the disc boundary meets the rectangle's edges, or at the disc boundary's own
    extreme points in the tau direction when they fall inside the rectangle.
    """
    ta, tb, x, y, vx, vy = piece[:6]
    ex, ey = ax - x, ay - y
    r2 = reach * reach
    aw = wx * wx + wy * wy
    if vx == 0.0 and vy == 0.0:
        span = _roots(aw, 2.0 * (ex * wx + ey * wy), ex * ex + ey * ey - r2, 0.0, d)
        return None if span is None else (ta - span[1], tb - span[0])
    length = tb - ta
    av = vx * vx + vy * vy
    lo, hi = _INF, -_INF
    for s in (0.0, d):                       # edges s = 0 and s = d: an interval of u
        fx, fy = ex + s * wx, ey + s * wy
        span = _roots(av, -2.0 * (fx * vx + fy * vy), fx * fx + fy * fy - r2, 0.0, length)
        if span is not None:
            lo, hi = min(lo, span[0] - s), max(hi, span[1] - s)
    for u in (0.0, length):                  # edges u = 0 and u = L: an interval of s
        fx, fy = ex - u * vx, ey - u * vy
        span = _roots(aw, 2.0 * (fx * wx + fy * wy), fx * fx + fy * fy - r2, 0.0, d)
        if span is not None:
            lo, hi = min(lo, u - span[1]), max(hi, u - span[0])
    det = vx * wy - wx * vy                  # of M = [w, -v], (s, u) -> s w - u v
    if abs(det) > 1e-12 * math.sqrt(aw * av):
        gx, gy = (vy - wy) / det, (wx - vx) / det    # M^-T (-1, 1): gradient of tau in relative position
        gn = math.hypot(gx, gy)
        for sign in (reach / gn, -reach / gn):
            yx, yy = sign * gx - ex, sign * gy - ey
            s = (-vy * yx + vx * yy) / det
            u = (-wy * yx + wx * yy) / det
            if -1e-12 <= s <= d + 1e-12 and -1e-12 <= u <= length + 1e-12:
                lo, hi = min(lo, u - s), max(hi, u - s)
    return (ta + lo, ta + hi) if lo < hi else None


def _min_gap(a: Piece, b: Piece, ra: float, rb: float) -> float:
    """Closest distance minus (ra + rb) of two pieces over their common time (inf if none)."""
    lo, hi = max(a[0], b[0]), min(a[1], b[1])
    if lo > hi:
        return _INF
    t = lo if math.isfinite(lo) else (hi if math.isfinite(hi) else 0.0)

    def at(p: Piece) -> tuple[float, float]:
        if p[4] == 0.0 and p[5] == 0.0:
            return p[2], p[3]
        return p[2] + p[4] * (t - p[0]), p[3] + p[5] * (t - p[0])

    (xa, ya), (xb, yb) = at(a), at(b)
    dx, dy = xa - xb, ya - yb
    vx, vy = a[4] - b[4], a[5] - b[5]
    vv = vx * vx + vy * vy
    if vv > 0.0:  # both ends finite: a moving piece is finite
        s = min(max(-(dx * vx + dy * vy) / vv, 0.0), hi - lo)
        dx, dy = dx + s * vx, dy + s * vy
    return math.hypot(dx, dy) - ra - rb


# ---------------------------------------------------------------------------------------------
# one planning call: the robots, the fixed trajectories, the order
# ---------------------------------------------------------------------------------------------
class _Fail(Exception):
    """A robot could not be planned: why, and what might be repaired, as (owner, kind, time):

    * "start": robot ``owner``, not planned yet, stands on its start in the way;
    * "goal": robot ``owner``, planned, parks on its goal in the way or crosses our goal too late;
    * "runover": robot ``owner``, planned, drives over our start at ``time`` before we can leave.
    """

    def __init__(self, reason: str, blockers: Sequence[tuple[int, str, float]] = (), fatal: bool = False):
        super().__init__(reason)
        self.reason = reason
        self.blockers = list(blockers)
        self.fatal = fatal


class _Session:
    """One planning call. Owners 0..n-1 are the robots to plan, n.. the fixed trajectories.

    A robot not planned yet is a disc on its start until ``garage_until`` (+inf at first: the
    garage assumption). When it stands in the way of a robot it drops to t0 (the others may pass,
    it will have to leave in time); when a robot then runs it over before it can leave, it is raised
    and the robots that crossed the start too early are planned again.
    """

    def __init__(self, planner: PriorPlanner, grid: GridMap, robots: list[RobotSpec],
                 fixed: list[TimedPath], t0: float):
        self.p, self.grid, self.robots, self.fixed, self.t0 = planner, grid, robots, fixed, t0
        self.budget = Budget(planner.time_limit_s, wall=not planner.cpu_time)
        self.n = n = len(robots)
        self.names = [r.id for r in robots] + [f.robot_id for f in fixed]
        self.radii = np.array([r.radius for r in robots] + [f.radius for f in fixed], dtype=float)
        # where everyone stands at t0 and where it parks for ever
        here = [r.start for r in robots] + [f.position(t0) for f in fixed]
        last = [r.goal for r in robots] + [tuple(f.waypoints[-1, :2]) for f in fixed]
        self.here = np.array(here, dtype=float).reshape(-1, 2)
        self.last = np.array(last, dtype=float).reshape(-1, 2)
        self._check_input()
        rmax = float(self.radii.max()) if len(self.radii) else 0.0
        self.space = _Space(grid, self.radii, rmax + planner.margin + math.sqrt(2) * grid.resolution + 1e-6)
        # a fixed trajectory's pieces that no robot to plan can reach before they end are left out
        # (a leg's cost follows its neighbourhood in space-time, not the fleet)
        rfix = max((f.radius for f in fixed), default=0.0)
        reach = [(float(r.start[0]), float(r.start[1]), float(r.max_speed), r.radius + rfix + planner.margin + 1e-6)
                 for r in robots] if fixed else []
        for k, f in enumerate(fixed):
            self.space.add_path(n + k, f.waypoints, t0, reach)
        self.garage_until = [_INF] * n
        for i in range(n):
            self._add_garage(i)

    # -- input -----------------------------------------------------------------------------
    def _check_input(self) -> None:
        ids = [r.id for r in self.robots]
        dup = {x for x in ids if ids.count(x) > 1}
        if dup:
            raise ValueError(f"robots: duplicate id(s) {sorted(dup)}")
        grid, problems, in_way = self.grid, {}, {}
        for r in self.robots:
            for what in ("start", "goal"):
                x, y = getattr(r, what)
                if not grid.disc_is_free(x, y, r.radius):
                    problems[r.id] = (f"{what} ({x:.6g}, {y:.6g}) is not in free space for radius "
                                      f"{r.radius:.6g} (clearance {grid.clearance(x, y):.6g} m)")
        for i in range(self.n):
            for what, pts, others in (("start", self.here, "position at t0" if self.fixed else "start"),
                                      ("goal", self.last, "goal")):
                dist = np.hypot(*(pts - pts[i]).T) - self.radii - self.radii[i]
                dist[i] = _INF
                j = int(np.argmin(dist))
                if dist[j] < -1e-9 and self.robots[i].id not in problems:
                    problems[self.robots[i].id] = f"its {what} disc overlaps the {others} of robot {self.names[j]!r}"
                    in_way[self.robots[i].id] = self.names[j]
        for r in self.robots:
            if r.id not in problems:
                why = self._static_problem(r)
                if why:
                    problems[r.id] = why
        if problems:
            raise PlanningError(problems, in_way)

    def _static_problem(self, robot: RobotSpec) -> str | None:
        """Why the robot cannot reach its goal even alone on the map (None if it can)."""
        grid, radius = self.grid, robot.radius
        rm = self.p._roadmap(grid, radius)
        cells = []
        for what, (x, y) in (("start", robot.start), ("goal", robot.goal)):
            col, row = grid.cell_of(x, y)
            if not rm.free[row, col]:
                return f"the centre of the cell of its {what} ({x:.6g}, {y:.6g}) is not free for radius {radius:.6g}"
            cx, cy = grid.centre(col, row)
            if (cx, cy) != (x, y) and shapely.distance(grid.obstacle_geometry,
                                                       shapely.LineString([(x, y), (cx, cy)])) < radius - 1e-9:
                return (f"cannot drive from its {what} ({x:.6g}, {y:.6g}) to its cell's centre without "
                        "touching an obstacle")
            cells.append(row * grid.width + col)
        if rm.component[cells[0]] != rm.component[cells[1]]:
            return f"no way from start to goal on this map for radius {radius:.6g}"
        return None

    def keep_out(self, i: int) -> list[float]:
        """Keep-out distance from robot i to every owner (-1 for itself): r_i + r_j + margin, the
        margin shrunk to half the gap where the scenario puts the two closer (start or goal)."""
        gap = np.minimum(np.hypot(*(self.here - self.here[i]).T), np.hypot(*(self.last - self.last[i]).T))
        gap -= self.radii + self.radii[i]
        margin = np.minimum(self.p.margin, np.maximum(gap, 0.0) / 2) - 1e-9
        out = self.radii + self.radii[i] + margin
        out[i] = -1.0
        return out.tolist()

    def _add_garage(self, i: int) -> None:
        if self.garage_until[i] > self.t0:
            x, y = self.robots[i].start
            self.space.add(_piece(-_INF, self.garage_until[i], float(x), float(y), 0.0, 0.0, i))

    def _set_garage(self, i: int, until: float) -> None:
        self.garage_until[i] = until
        self.space.remove(i)
        self._add_garage(i)

    # -- the priority loop -----------------------------------------------------------------
    def run(self, order: list[int], progress: Progress | None) -> tuple[dict[int, np.ndarray], list[int], int]:
        n = self.n
        budget = 4 * n if self.p.max_reorders is None else self.p.max_reorders
        paths: dict[int, np.ndarray] = {}
        tried: dict[tuple[int, int, str], int] = {}
        repairs, pos = 0, 0
        while pos < n:
            i = order[pos]
            try:
                wp = self._search(i)
            except _Fail as fail:
                restart = None if fail.fatal or repairs >= budget else self._repair(i, fail, order, pos, paths, tried)
                if restart is None:
                    why = fail.reason
                    if fail.blockers and not fail.fatal:
                        why += f" (gave up after {repairs} re-ordering(s))"
                    failures = {self.robots[i].id: why}
                    if fail.fatal:
                        failures.update({self.robots[x].id: "not planned: the planner stopped early"
                                         for x in order[pos + 1:]})
                    blockers = {self.robots[i].id: self.names[fail.blockers[0][0]]} if fail.blockers else {}
                    raise PlanningError(failures, blockers) from None
                repairs += 1
                for x in order[restart:]:
                    if x in paths:  # robots from the restart position on are planned again
                        del paths[x]
                        self.space.remove(x)
                        self._add_garage(x)
                pos = restart
                continue
            paths[i] = wp
            self.space.remove(i)
            self.space.add_path(i, wp)
            pos += 1
            if progress:
                progress(pos, n, self.robots[i].id)
        return paths, order, repairs

    def _repair(self, i: int, fail: _Fail, order: list[int], pos: int, paths: dict[int, np.ndarray],
                tried: dict[tuple[int, int, str], int]) -> int | None:
        """Change the problem so that robot i may succeed; the position to plan again from, or None."""
        for j, kind, when in fail.blockers:
            if j >= self.n or tried.get((i, j, kind), 0) >= (3 if kind == "runover" else 1):
                continue
            tried[(i, j, kind)] = tried.get((i, j, kind), 0) + 1
            if kind == "start":       # j, not planned yet, will have to get out of i's way
                self._set_garage(j, self.t0)
                return pos
            if kind == "goal":        # i goes just ahead of the planned j
                q = order.index(j)
                order.remove(i)
                order.insert(q, i)
                return q
            # runover: the others keep off i's start longer; re-plan those that came too early
            old = self.garage_until[i]
            until = when + max(when - self.t0, 1.0)
            self._set_garage(i, until)
            x, y = self.robots[i].start
            col, row = self.grid.cell_of(x, y)
            keep = self.keep_out(i)
            early = set()
            for piece in self.space.buckets[row * self.grid.width + col]:
                o = piece[6]
                span = _unsafe_times(x, y, piece, keep[o]) if o in paths else None
                if span is not None and span[0] < until and span[1] > old:
                    early.add(order.index(o))
            return min(early, default=pos)
        return None

    # -- one robot -------------------------------------------------------------------------
    def _search(self, i: int) -> np.ndarray:
        """SIPP for robot i; uncompressed waypoints (x, y, t) from (start, t0) or raises _Fail."""
        return _RobotSearch(self, i).run()

    def _verify(self, i: int, wp: np.ndarray) -> None:
        """Re-check a new path against its neighbours with the plain closest-approach formula (a
        guard against a bug in the search's interval geometry, never expected to fire)."""
        width = self.grid.width
        for piece in _pieces(wp, i, self.grid.resolution)[1:]:
            col, row = self.grid.cell_of(piece[2], piece[3])
            for other in self.space.buckets[row * width + col]:
                o = other[6]
                if o != i and _min_gap(piece, other, self.radii[i], self.radii[o]) < -1e-9:
                    raise AssertionError(f"prior: the path of {self.names[i]!r} overlaps robot "
                                         f"{self.names[o]!r}; this is a bug")

    def _culprits(self, p: tuple[float, float], bucket: int, keep: list[float], t: float) -> list[int]:
        """Owners whose discs a disc on p would overlap at time t (bounds included)."""
        out = set()
        for piece in self.space.buckets[bucket]:
            reach = keep[piece[6]]
            span = _unsafe_times(p[0], p[1], piece, reach) if reach > 0 else None
            if span is not None and span[0] <= t <= span[1]:
                out.add(piece[6])
        return sorted(out)

    def _way_blockers(self, i: int, path: list[int], rm: _Roadmap, keep: list[float],
                      kinds: tuple[str, ...]) -> list[tuple[int, str, float]] | None:
        """None if robot i can reach its goal around the discs parked for ever (on starts: "start",
        on goals: "goal"); else those of them that meet its free shortest path ``path`` (cells), in
        path order. A disc over robot i's own start is left out: that one runs it over."""
        width, res = self.grid.width, self.grid.resolution
        start = self.robots[i].start
        discs = [(o, x, y, keep[o]) for o, (x, y, since) in self.space.parked.items()
                 if keep[o] > 0 and ("start" if since == -_INF and o < self.n else "goal") in kinds
                 and math.dist((x, y), start) >= keep[o]]
        if not discs:
            return None
        cells = np.array(path)
        centres = np.column_stack([(cells % width + 0.5) * res, (cells // width + 0.5) * res])
        where = np.array([(x, y) for _, x, y, _ in discs])
        near = np.hypot(centres[:, None, 0] - where[None, :, 0], centres[:, None, 1] - where[None, :, 1])
        if not np.any(near < np.array([r for *_, r in discs]) + res):   # a move is within res/sqrt(2) of an end
            return None
        blocked: dict[tuple[int, int], list[int]] = {}   # move (cell, cell) -> discs on it
        for o, x, y, reach in discs:
            pad = reach + math.sqrt(2) * res
            c0, c1 = max(0, math.ceil((x - pad) / res - 0.5)), min(width - 1, math.floor((x + pad) / res - 0.5))
            r0 = max(0, math.ceil((y - pad) / res - 0.5))
            r1 = min(self.grid.height - 1, math.floor((y + pad) / res - 0.5))
            for row in range(r0, r1 + 1):
                for col in range(c0, c1 + 1):
                    ax, ay = (col + 0.5) * res, (row + 0.5) * res
                    for nb, _ in rm.nbrs[row * width + col]:
                        bx, by = (nb % width + 0.5) * res, (nb // width + 0.5) * res
                        if segment_point_distance_xy(ax, ay, bx, by, x, y) < reach:
                            blocked.setdefault((row * width + col, nb), []).append(o)
        on_path = [o for move in zip(path[:-1], path[1:]) for o in blocked.get(move, ())]
        if not on_path:
            return None
        graph = rm.graph.copy()
        for src, dst in blocked:
            out_of_src = slice(graph.indptr[src], graph.indptr[src + 1])
            graph.data[out_of_src][graph.indices[out_of_src] == dst] = 0.0
        graph.eliminate_zeros()
        if path[-1] in set(breadth_first_order(graph, path[0], return_predecessors=False).tolist()):
            return None
        kind_of = {o: "start" if self.space.parked[o][2] == -_INF and o < self.n else "goal" for o in on_path}
        return [(o, kind_of[o], -_INF) for o in dict.fromkeys(on_path)]

    def _check_garages(self, i: int, path: list[int], rm: _Roadmap, keep: list[float]) -> None:
        """Before searching: robots parked on their starts for ever must leave a way open."""
        blockers = self._way_blockers(i, path, rm, keep, ("start",))
        if blockers:
            raise _Fail("its way is blocked by " + _blocker_words(self.names, blockers), blockers)

    def _diagnose(self, i: int, reason: str, rm: _Roadmap, path: list[int], keep: list[float],
                  start_iv: tuple[float, float], goal_iv: list[tuple[float, float]], bound: float) -> _Fail:
        """Why the search failed: robots parked for ever in the way (on their starts or goals), a
        robot crossing the goal later than the search may wait, a robot running over the start;
        else just ``reason``."""
        blockers = self._way_blockers(i, path, rm, keep, ("start", "goal"))
        if blockers:
            return _Fail("its way is blocked by " + _blocker_words(self.names, blockers), blockers)
        spec = self.robots[i]
        last_start = goal_iv[-1][0]
        if last_start > bound:
            col, row = self.grid.cell_of(*spec.goal)
            who = self._culprits(spec.goal, row * self.grid.width + col, keep, last_start)
            return _Fail(f"its goal is crossed by {_names(self.names, who)} until t={last_start:.6g}, later "
                         f"than max_wait_s={self.p.max_wait_s:g} s allows", [(o, "goal", last_start) for o in who])
        if start_iv[1] < _INF:
            col, row = self.grid.cell_of(*spec.start)
            who = self._culprits(spec.start, row * self.grid.width + col, keep, start_iv[1])
            return _Fail(f"{reason}; {_names(self.names, who)} drives over its start at t={start_iv[1]:.6g}",
                         [(o, "runover", start_iv[1]) for o in who])
        return _Fail(reason)


# ---------------------------------------------------------------------------------------------
# one robot: safe-interval path planning around what is planned so far
# ---------------------------------------------------------------------------------------------
#: a search state: (node, index of one of the node's safe intervals)
_State = tuple[int, int]


class _RobotSearch:
    """SIPP for robot ``i`` of a session, around the pieces in the session's space.

    The graph: the roadmap's cells (node = cell index ``row * width + col``, at the cell's centre)
    and, where the robot's start or goal lies off its cell's centre, one extra node for it
    (``n_cells``: the start, ``n_cells + 1``: the goal) joined to the centre of that cell. A state
    is a node with one of its safe intervals; ``best`` holds the earliest arrival found at each
    state and ``parent`` the state it came from with the departure time from there. The heuristic
    is the time to drive the free shortest path (Dijkstra from the goal cell) at top speed.
    """

    def __init__(self, session: _Session, i: int):
        grid, spec = session.grid, session.robots[i]
        self.session, self.i, self.t0 = session, i, session.t0
        self.rm = session.p._roadmap(grid, spec.radius)
        self.res, self.width = res, width = grid.resolution, grid.width
        self.speed = speed = spec.max_speed
        self.keep = session.keep_out(i)
        self.buckets = session.space.buckets
        self.n_cells = n_cells = grid.width * grid.height

        (sx, sy), (gx, gy) = (float(v) for v in spec.start), (float(v) for v in spec.goal)
        self.start_xy, self.goal_xy = (sx, sy), (gx, gy)
        sc, sr = grid.cell_of(sx, sy)
        gc, gr = grid.cell_of(gx, gy)
        self.cs, self.cg = cs, cg = sr * width + sc, gr * width + gc
        self.s_off = s_off = math.hypot(sx - (sc + 0.5) * res, sy - (sr + 0.5) * res)
        self.g_off = g_off = math.hypot(gx - (gc + 0.5) * res, gy - (gr + 0.5) * res)
        self.start_node = n_cells if s_off > 0 else cs
        self.goal_node = self.start_node if (gx, gy) == (sx, sy) else n_cells + 1 if g_off > 0 else cg

        # distances to the goal: along the reversed moves (the same graph unless lanes are one-way)
        to_goal = self.rm.graph if getattr(grid, "lanes", None) is None else self.rm.graph.T.tocsr()
        self.dist, pred = dijkstra(to_goal, indices=cg, return_predecessors=True)  # reachable: checked up front
        self.free_path = [cs]
        while self.free_path[-1] != cg:
            self.free_path.append(int(pred[self.free_path[-1]]))
        self.h_start = (s_off + float(self.dist[cs]) + g_off) / speed
        self.bound = self.t0 + self.h_start + session.p.max_wait_s
        self.d_max = max(math.sqrt(2) * res, s_off, g_off) / speed   # the longest move, in seconds
        # pieces farther than this from a node cannot meet a move from it
        self.lim = max(self.keep) + self.d_max * speed
        self._safe: dict[int, list[tuple[float, float]]] = {}   # node -> its safe intervals
        self.best: dict[_State, float] = {}
        self.parent: dict[_State, tuple[_State, float] | None] = {}
        self.heap: list[tuple[float, float, int, int, int, float]] = []
        self.pushed = 0   # tie-breaker of the heap: first pushed, first popped

    # -- the graph -------------------------------------------------------------------------
    def pos(self, node: int) -> tuple[float, float]:
        if node == self.n_cells:
            return self.start_xy
        if node == self.n_cells + 1:
            return self.goal_xy
        width, res = self.width, self.res
        return (node % width + 0.5) * res, (node // width + 0.5) * res

    def cell(self, node: int) -> int:
        return self.cs if node == self.n_cells else self.cg if node == self.n_cells + 1 else node

    def heur(self, node: int) -> float:
        if node == self.goal_node:
            return 0.0
        if node == self.n_cells:
            return self.h_start
        return (float(self.dist[node]) + self.g_off) / self.speed

    def neighbours(self, node: int) -> list[tuple[int, float]]:
        if node >= self.n_cells:
            return [(self.cs, self.s_off)] if node == self.n_cells else [(self.cg, self.g_off)]
        out = self.rm.nbrs[node]
        if node == self.cg and self.goal_node != self.cg:
            out = out + [(self.goal_node, self.g_off)]
        return out

    def intervals(self, node: int) -> list[tuple[float, float]]:
        """The safe intervals of a node (computed once per search)."""
        iv = self._safe.get(node)
        if iv is None:
            px, py = self.pos(node)
            keep = self.keep
            unsafe = []
            for piece in self.buckets[self.cell(node)]:
                reach = keep[piece[6]]
                if (reach > 0 and piece[7] - reach < px < piece[9] + reach
                        and piece[8] - reach < py < piece[10] + reach):
                    span = _unsafe_times(px, py, piece, reach)
                    if span is not None:
                        unsafe.append(span)
            iv = self._safe[node] = _complement(unsafe)
        return iv

    # -- the search ------------------------------------------------------------------------
    def run(self) -> np.ndarray:
        """The earliest arrival on the goal for good, as waypoints; raises _Fail."""
        session, t0 = self.session, self.t0
        session._check_garages(self.i, self.free_path, self.rm, self.keep)
        start = self._start_state()
        self.best[start] = t0
        self.parent[start] = None
        self.heap.append((t0 + self.heur(self.start_node), -t0, 0, *start, t0))
        expansions = 0
        reason = f"no collision-free timing within max_wait_s={session.p.max_wait_s:g} s"
        while self.heap:
            _, _, _, u, ju, g = heapq.heappop(self.heap)
            if g > self.best[(u, ju)]:
                continue
            e_u = self.intervals(u)[ju][1]
            if u == self.goal_node and e_u == _INF:
                return self._waypoints((u, ju))
            expansions += 1
            if expansions % 512 == 0:
                if session.budget.passed():
                    raise _Fail(f"time limit of {session.p.time_limit_s:g} s reached", fatal=True)
                if expansions >= _MAX_EXPANSIONS:
                    reason = f"search gave up after {expansions} expansions"
                    break
            self._expand(u, ju, g, e_u)
        raise session._diagnose(self.i, reason, self.rm, self.free_path, self.keep,
                                self.intervals(self.start_node)[start[1]], self.intervals(self.goal_node), self.bound)

    def _start_state(self) -> _State:
        """Standing on the start at t0 must be safe: the state of the safe interval holding t0."""
        t0 = self.t0
        j0 = next((k for k, (s, e) in enumerate(self.intervals(self.start_node)) if s <= t0 <= e), None)
        if j0 is None:
            session = self.session
            who = session._culprits(self.start_xy, self.cs, self.keep, t0)
            raise _Fail(f"standing on its start at t={t0:.6g} it overlaps {_names(session.names, who)}", fatal=True)
        return self.start_node, j0

    def _expand(self, u: int, ju: int, g: float, e_u: float) -> None:
        """Every state reachable from node u, reached at g and safe until e_u, by one move: leave
        as early as the move is clear, arrive within a safe interval of the next node."""
        keep, speed, bound, best, parent = self.keep, self.speed, self.bound, self.best, self.parent
        ax, ay = self.pos(u)
        horizon = e_u + self.d_max
        lim = self.lim
        x0, x1, y0, y1 = ax - lim, ax + lim, ay - lim, ay + lim
        near = [p for p in self.buckets[self.cell(u)] if p[1] > g and p[0] < horizon and keep[p[6]] > 0
                and p[7] < x1 and p[9] > x0 and p[8] < y1 and p[10] > y0]
        for v, length in self.neighbours(u):
            d = length / speed
            hv = self.heur(v)
            bx, by = self.pos(v)
            wx, wy = (bx - ax) / d, (by - ay) / d
            for jv, (s_v, e_v) in enumerate(self.intervals(v)):
                if e_v < g + d:
                    continue
                lo = max(g, s_v - d)
                if lo > e_u or lo + d + hv > bound:
                    break
                hi = min(e_u, e_v - d)
                if lo > hi:
                    continue
                tau = _earliest(near, keep, ax, ay, wx, wy, d, lo, hi)
                if tau is None:
                    continue
                arrive = tau + d
                key = (v, jv)
                if arrive >= best.get(key, _INF):
                    continue
                best[key] = arrive
                parent[key] = ((u, ju), tau)
                self.pushed += 1
                heapq.heappush(self.heap, (arrive + hv, -arrive, self.pushed, v, jv, arrive))

    # -- the result ------------------------------------------------------------------------
    def _waypoints(self, key: _State) -> np.ndarray:
        """The found path as waypoints, its waits moved as early along it as they can go."""
        nodes, taus = [], []
        at: _State | None = key
        while at is not None:
            nodes.append(at[0])
            link = self.parent[at]
            if link is not None:
                taus.append(link[1])
            at = None if link is None else link[0]
        nodes.reverse()
        taus.reverse()
        taus = self._postpone(nodes, self.best[key]) or taus
        pos, speed = self.pos, self.speed
        t = self.t0
        wp = [(*pos(nodes[0]), t)]
        for prev, node, tau in zip(nodes[:-1], nodes[1:], taus):
            if tau > t:
                wp.append((*pos(prev), tau))
            t = tau + math.dist(pos(prev), pos(node)) / speed
            wp.append((*pos(node), t))
        out = np.array(wp, dtype=float)
        self.session._verify(self.i, out)
        return out

    def _postpone(self, nodes: list[int], arrival: float) -> list[float] | None:
        """Departure times along ``nodes``, each as late as possible for the same arrival, or None.

        SIPP leaves every node as early as it can and so waits just before each conflict, often in
        an aisle where it blocks the robots planned after it. Going backwards over the same nodes
        (latest departure from each safe interval that still makes the arrival) moves the waiting
        to where the robot already stands, its start first of all.
        """
        t0, pos, intervals, keep, speed = self.t0, self.pos, self.intervals, self.keep, self.speed
        latest = {len(intervals(nodes[-1])) - 1: arrival}   # safe interval -> latest time to leave it
        choices: list[dict[int, tuple[int, float]]] = []
        for u, v in zip(nodes[-2::-1], nodes[:0:-1]):
            (ax, ay), (bx, by) = pos(u), pos(v)
            d = math.hypot(bx - ax, by - ay) / speed
            wx, wy = (bx - ax) / d, (by - ay) / d
            near = [p for p in self.buckets[self.cell(u)] if p[1] > t0 and p[0] < arrival and keep[p[6]] > 0]
            iv_v = intervals(v)
            new: dict[int, float] = {}
            pick: dict[int, tuple[int, float]] = {}
            for iu, (s_u, e_u) in enumerate(intervals(u)):
                if e_u < t0 or s_u > arrival:
                    continue
                for jv, leave in latest.items():
                    lo, hi = max(s_u, iv_v[jv][0] - d, t0), min(e_u, leave - d)
                    tau = _latest(near, keep, ax, ay, wx, wy, d, lo, hi) if lo <= hi else None
                    if tau is not None and tau > new.get(iu, -_INF):
                        new[iu], pick[iu] = tau, (jv, tau)
            latest = new
            choices.append(pick)
        choices.reverse()
        at = next((k for k, (s, e) in enumerate(intervals(nodes[0])) if s <= t0 <= e), None)
        taus = []
        for pick in choices:
            if at not in pick:
                return None
            at, tau = pick[at]
            taus.append(tau)
        return taus


# ---------------------------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------------------------
def _earliest(near: list[Piece], keep: list[float], ax: float, ay: float, wx: float, wy: float, d: float,
              lo: float, hi: float) -> float | None:
    """The earliest departure in [lo, hi] of the move from (ax, ay) at velocity w for d seconds that
    keeps clear of all pieces, or None: jump to the end of every bad interval containing it."""
    tau = lo
    bx, by = ax + wx * d, ay + wy * d
    x0, x1, y0, y1 = min(ax, bx), max(ax, bx), min(ay, by), max(ay, by)
    moved = True
    while moved:
        moved = False
        end = tau + d
        for piece in near:
            if piece[1] <= tau or piece[0] >= end:
                continue
            reach = keep[piece[6]]
            if piece[7] >= x1 + reach or piece[9] <= x0 - reach or piece[8] >= y1 + reach or piece[10] <= y0 - reach:
                continue
            bad = _bad_departures(ax, ay, wx, wy, d, piece, reach)
            if bad is not None and bad[0] < tau < bad[1]:
                tau = bad[1]
                if tau > hi:
                    return None
                end = tau + d
                moved = True
    return tau


def _latest(near: list[Piece], keep: list[float], ax: float, ay: float, wx: float, wy: float, d: float,
            lo: float, hi: float) -> float | None:
    """The latest departure in [lo, hi] of the move (see :func:`_earliest`) that keeps clear, or None."""
    tau = hi
    bx, by = ax + wx * d, ay + wy * d
    x0, x1, y0, y1 = min(ax, bx), max(ax, bx), min(ay, by), max(ay, by)
    moved = True
    while moved:
        moved = False
        for piece in near:
            if piece[1] <= tau or piece[0] >= tau + d:
                continue
            reach = keep[piece[6]]
            if piece[7] >= x1 + reach or piece[9] <= x0 - reach or piece[8] >= y1 + reach or piece[10] <= y0 - reach:
                continue
            bad = _bad_departures(ax, ay, wx, wy, d, piece, reach)
            if bad is not None and bad[0] < tau < bad[1]:
                tau = bad[0]
                if tau < lo:
                    return None
                moved = True
    return tau


def _complement(unsafe: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Safe intervals [s, e] (closed) between the open unsafe ones, from -inf to +inf."""
    out = []
    t = -_INF
    for a, b in sorted(unsafe):
        if a > t + _MIN_INTERVAL:
            out.append((t, a))
        t = max(t, b)
    if t < _INF:
        out.append((t, _INF))
    return out


def _compress(wp: np.ndarray) -> np.ndarray:
    """Merge consecutive segments driven at the same velocity (straight runs) into one."""
    out = [wp[0]]
    for k in range(1, len(wp)):
        p = wp[k]
        if len(out) >= 2:
            a, b = out[-2], out[-1]
            dt1, dt2 = b[2] - a[2], p[2] - b[2]
            if dt1 > 0 and dt2 > 0:
                v1, v2 = (b[:2] - a[:2]) / dt1, (p[:2] - b[:2]) / dt2
                if np.any(v1 != 0) and np.all(np.abs(v1 - v2) <= 1e-9 * (1 + np.abs(v1))):
                    out[-1] = p
                    continue
        out.append(p)
    return np.array(out, dtype=float)


def _blocker_words(names: list[str], blockers: list[tuple[int, str, float]]) -> str:
    return ", ".join(f"the start of robot {names[o]!r} (not planned yet)" if kind == "start" else
                     f"robot {names[o]!r} parked on its goal" for o, kind, _ in blockers)


def _names(names: list[str], owners: Sequence[int]) -> str:
    if not owners:
        return "another robot"
    return ("robot " if len(owners) == 1 else "robots ") + ", ".join(repr(names[o]) for o in owners)
