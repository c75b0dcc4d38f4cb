"""The independent plan checker: the oracle every planner test and benchmark trusts.

It re-derives, from the plan contract of docs/ARCHITECTURE.md alone, whether a plan is valid, and shares
no code with the planners (no import of ``collision``, ``scheduler`` or ``planners``) so that a bug
there cannot hide itself here. A robot sits on its first waypoint until that waypoint's time,
moves in a straight line at constant speed between consecutive waypoints and sits on its last
waypoint for ever after.

Collisions are found exactly, without sampling: both robots of a pair move linearly between their
merged breakpoint times, so their relative position is linear in t on each such interval and the
closest approach has a closed form. Every trajectory is cut into space-time pieces (the parked
head ``(-inf, t0]``, one piece per segment, the parked tail ``[tn, +inf)``); a sort-and-sweep over
the pieces' bounding boxes keeps only the pairs of pieces that could touch, and the closed form is
evaluated for all of them at once with numpy.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from .grid import GridMap
from .model import Plan, RobotSpec, TimedPath

VIOLATION_KINDS = ("missing", "radius", "start", "goal", "time", "speed", "obstacle", "collision")

#: relative slack on the speed limit (on top of ``tol`` of rounding in every coordinate and time)
SPEED_SLACK = 1e-6

#: at most this many candidate piece pairs are held in memory at once by the sweep
_CHUNK_PAIRS = 2_000_000


@dataclass(frozen=True)
class Violation:
    """One reason a plan is invalid; ``detail`` says it in words, with the numbers."""

    kind: str
    robots: tuple[str, ...]
    time: float | None
    detail: str

    def __str__(self) -> str:
        when = "" if self.time is None else f" at t={self.time:.3f}"
        return f"[{self.kind}] {', '.join(self.robots)}{when}: {self.detail}"


# ---------------------------------------------------------------------------------------------
# space-time pieces and the exact closest approach
# ---------------------------------------------------------------------------------------------
@dataclass
class _Pieces:
    """Every robot's trajectory cut into linear space-time pieces (one row each)."""

    owner: np.ndarray  # robot index
    t0: np.ndarray     # piece start time (-inf for the parked head)
    t1: np.ndarray     # piece end time (+inf for the parked tail)
    p0: np.ndarray     # (n, 2) position at t0
    p1: np.ndarray     # (n, 2) position at t1
    radius: np.ndarray


def _pieces(waypoints: Sequence[np.ndarray], radii: Sequence[float]) -> _Pieces:
    owner, t0, t1, p0, p1, rad = [], [], [], [], [], []
    for idx, (wp, r) in enumerate(zip(waypoints, radii)):
        n = len(wp)
        owner.append(np.full(n + 1, idx))
        t0.append(np.concatenate([[-np.inf], wp[:, 2]]))
        t1.append(np.concatenate([wp[:, 2], [np.inf]]))
        p0.append(np.vstack([wp[:1, :2], wp[:, :2]]))
        p1.append(np.vstack([wp[:, :2], wp[-1:, :2]]))
        rad.append(np.full(n + 1, float(r)))
    cat = np.concatenate
    return _Pieces(cat(owner), cat(t0), cat(t1), cat(p0), cat(p1), cat(rad))


def _candidate_pairs(pc: _Pieces, margin: float):
    """Pairs (a, b) of pieces of different robots whose boxes, inflated by radius + margin/2, meet.

    Yields index arrays chunk by chunk (sort-and-sweep on x, then filters on y and t).
    """
    grow = pc.radius + margin / 2
    lo = np.minimum(pc.p0, pc.p1) - grow[:, None]
    hi = np.maximum(pc.p0, pc.p1) + grow[:, None]
    order = np.argsort(lo[:, 0], kind="stable")
    xlo = lo[order, 0]
    end = np.searchsorted(xlo, hi[order, 0], side="right")   # exclusive end of each sweep window
    count = np.maximum(end - np.arange(len(order)) - 1, 0)
    first = 0
    while first < len(order):
        csum = np.cumsum(count[first:])
        last = first + max(1, int(np.searchsorted(csum, _CHUNK_PAIRS, side="right")))
        cnt = count[first:last]
        total = int(cnt.sum())
        if total:
            i_sorted = np.repeat(np.arange(first, last), cnt)
            offsets = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            a, b = order[i_sorted], order[i_sorted + 1 + offsets]
            keep = ((pc.owner[a] != pc.owner[b])
                    & (lo[a, 1] <= hi[b, 1]) & (lo[b, 1] <= hi[a, 1])
                    & (pc.t0[a] <= pc.t1[b]) & (pc.t0[b] <= pc.t1[a]))
            yield a[keep], b[keep]
        first = last


def _position(pc: _Pieces, idx: np.ndarray, t: np.ndarray, at_end: bool) -> np.ndarray:
    """Positions of pieces ``idx`` at times ``t`` inside them.

    A piece of zero duration that still moves (an infinitely fast jump, reported as a speed
    violation) is taken to sweep its whole segment during that instant: its position is p0 at the
    start of the overlap and p1 at its end, so the sweep is checked too.
    """
    p0, p1 = pc.p0[idx], pc.p1[idx]
    t0, t1 = pc.t0[idx], pc.t1[idx]
    moving = np.any(p0 != p1, axis=1)
    dur = t1 - t0
    timed = moving & (dur > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(timed, (t - t0) / np.where(timed, dur, 1.0), 0.0)
    frac = np.where(moving & ~timed, 1.0 if at_end else 0.0, np.clip(frac, 0.0, 1.0))
    return p0 + frac[:, None] * (p1 - p0)


@dataclass
class _Approach:
    """Closest approach of each candidate piece pair."""

    a: np.ndarray       # robot index
    b: np.ndarray
    gap: np.ndarray     # closest distance minus (r_a + r_b)
    t_min: np.ndarray   # when the closest distance happens
    t_enter: np.ndarray  # first instant of the pair of pieces at which distance < r_a + r_b - tol


def _approach(pc: _Pieces, ia: np.ndarray, ib: np.ndarray, tol: float) -> _Approach:
    lo = np.maximum(pc.t0[ia], pc.t0[ib])
    hi = np.minimum(pc.t1[ia], pc.t1[ib])
    d0 = _position(pc, ia, lo, False) - _position(pc, ib, lo, False)
    d1 = _position(pc, ia, hi, True) - _position(pc, ib, hi, True)
    v = d1 - d0
    vv = np.einsum("ij,ij->i", v, v)
    dv = np.einsum("ij,ij->i", d0, v)
    dd = np.einsum("ij,ij->i", d0, d0)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(vv > 0, np.clip(-dv / np.where(vv > 0, vv, 1.0), 0.0, 1.0), 0.0)
    closest = d0 + s[:, None] * v
    reach = pc.radius[ia] + pc.radius[ib]
    gap = np.hypot(closest[:, 0], closest[:, 1]) - reach
    # first s with |d0 + s v| = reach - tol (0 when already overlapping at the start of the overlap)
    r_in = np.maximum(reach - tol, 0.0)
    disc = dv * dv - vv * (dd - r_in * r_in)
    with np.errstate(invalid="ignore", divide="ignore"):
        s_in = np.where(dd < r_in * r_in, 0.0,
                        np.where((vv > 0) & (disc >= 0),
                                 (-dv - np.sqrt(np.maximum(disc, 0.0))) / np.where(vv > 0, vv, 1.0), s))
    s_in = np.clip(s_in, 0.0, 1.0)

    def when(frac: np.ndarray) -> np.ndarray:
        # an infinite end only occurs where both pieces are parked (relative position constant):
        # the earliest instant then stands for all, -inf meaning "from the start" (callers clamp to 0)
        with np.errstate(invalid="ignore"):
            inner = lo + frac * (hi - lo)
        return np.where(np.isfinite(lo) & np.isfinite(hi), inner, lo)

    return _Approach(pc.owner[ia], pc.owner[ib], gap, when(s), when(s_in))


def _all_approaches(pc: _Pieces, margin: float, tol: float):
    for ia, ib in _candidate_pairs(pc, margin):
        if len(ia):
            yield _approach(pc, ia, ib, tol)


def min_separation(paths: Sequence[TimedPath]) -> tuple[float, str | None, str | None, float | None]:
    """Smallest ``distance - (r_a + r_b)`` over all pairs of robots and all time, parked included.

    Returns ``(gap, id_a, id_b, t)``; negative gap means the discs overlap. With fewer than two
    paths there is no pair: ``(inf, None, None, None)``. Exact: the sweep margin is doubled until a
    pair closer than the margin is found, so no pair outside the sweep can be closer.
    """
    if len(paths) < 2:
        return math.inf, None, None, None
    pc = _pieces([p.waypoints for p in paths], [p.radius for p in paths])
    extent = float(np.ptp(np.vstack([pc.p0, pc.p1]), axis=0).max())
    margin = max(float(pc.radius.max()), 1e-3)
    while True:
        best = (math.inf, -1, -1, 0.0)
        for ap in _all_approaches(pc, margin, 0.0):
            k = int(np.argmin(ap.gap))
            if ap.gap[k] < best[0]:
                best = (float(ap.gap[k]), int(ap.a[k]), int(ap.b[k]), float(ap.t_min[k]))
        if best[0] < margin or margin > 2 * extent + 4 * float(pc.radius.max()):
            gap, a, b, t = best
            return gap, paths[a].robot_id, paths[b].robot_id, max(t, 0.0)
        margin *= 2


# ---------------------------------------------------------------------------------------------
# per-robot checks
# ---------------------------------------------------------------------------------------------
def _check_path(spec: RobotSpec, path: TimedPath, tol: float) -> list[Violation]:
    rid = (spec.id,)
    out: list[Violation] = []
    wp = path.waypoints
    if abs(path.radius - spec.radius) > tol:
        out.append(Violation("radius", rid, None,
                             f"plan radius {path.radius:.6g} m differs from the scenario's {spec.radius:.6g} m"))
    if not np.all(np.isfinite(wp)):
        bad = int(np.nonzero(~np.all(np.isfinite(wp), axis=1))[0][0])
        out.append(Violation("time", rid, None, f"waypoint {bad} is not finite: {wp[bad].tolist()}"))
        return out
    d_start = math.dist(wp[0, :2], spec.start)
    if d_start > tol:
        out.append(Violation("start", rid, float(wp[0, 2]),
                             f"first waypoint ({wp[0, 0]:.6g}, {wp[0, 1]:.6g}) is {d_start:.6g} m from "
                             f"the start ({spec.start[0]:.6g}, {spec.start[1]:.6g})"))
    d_goal = math.dist(wp[-1, :2], spec.goal)
    if d_goal > tol:
        out.append(Violation("goal", rid, float(wp[-1, 2]),
                             f"last waypoint ({wp[-1, 0]:.6g}, {wp[-1, 1]:.6g}) is {d_goal:.6g} m from "
                             f"the goal ({spec.goal[0]:.6g}, {spec.goal[1]:.6g})"))
    if wp[0, 2] < -tol:
        out.append(Violation("time", rid, float(wp[0, 2]), f"first waypoint time {wp[0, 2]:.6g} s is before 0"))
    dt = np.diff(wp[:, 2])
    for k in np.nonzero(dt < 0)[0][:3]:
        out.append(Violation("time", rid, float(wp[k + 1, 2]),
                             f"waypoint {k + 1} at t={wp[k + 1, 2]:.6g} s comes before waypoint {k} "
                             f"at t={wp[k, 2]:.6g} s"))
    seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
    allowed = spec.max_speed * (1 + SPEED_SLACK) * (np.maximum(dt, 0) + 2 * tol) + 3 * tol
    for k in np.nonzero(seg > allowed)[0][:3]:
        speed = seg[k] / dt[k] if dt[k] > 0 else math.inf
        out.append(Violation("speed", rid, float(wp[k, 2]),
                             f"segment {k}->{k + 1}: {seg[k]:.6g} m in {dt[k]:.6g} s = {speed:.6g} m/s "
                             f"> max_speed {spec.max_speed:.6g} m/s"))
    return out


def _check_obstacles(grid: GridMap, specs: Sequence[RobotSpec], paths: Sequence[TimedPath],
                     tol: float) -> list[Violation]:
    """Every segment's swept disc (and every parked disc) must keep ``radius - tol`` from obstacles."""
    geoms, owner, first_wp = [], [], []
    for idx, (_spec, path) in enumerate(zip(specs, paths)):
        wp = path.waypoints
        if not np.all(np.isfinite(wp)):
            continue
        if len(wp) == 1:
            geoms.append(shapely.points(wp[0, :2]))
            owner.append(idx)
            first_wp.append(0)
            continue
        lines = shapely.linestrings(np.stack([wp[:-1, :2], wp[1:, :2]], axis=1))
        geoms.extend(lines)
        owner.extend([idx] * len(lines))
        first_wp.extend(range(len(lines)))
    if not geoms:
        return []
    geoms_arr = np.array(geoms, dtype=object)
    owner_arr = np.array(owner)
    reach = np.array([specs[i].radius for i in owner_arr]) - tol
    # plain distance, not the faster "dwithin" predicate: GEOS 3.14's dwithin misses zero-length
    # segments (holds), and the oracle must not share that blind spot
    dist = shapely.distance(grid.obstacle_geometry, geoms_arr)
    hit = dist < reach
    out: list[Violation] = []
    reported: set[int] = set()
    for g in np.nonzero(hit)[0]:
        idx = int(owner_arr[g])
        if idx in reported:
            continue
        reported.add(idx)
        spec, wp, k = specs[idx], paths[idx].waypoints, first_wp[g]
        where = (f"waypoint {k} ({wp[k, 0]:.6g}, {wp[k, 1]:.6g})" if len(wp) == 1 else
                 f"segment {k}->{k + 1} ({wp[k, 0]:.6g}, {wp[k, 1]:.6g})->({wp[k + 1, 0]:.6g}, {wp[k + 1, 1]:.6g})")
        out.append(Violation("obstacle", (spec.id,), float(wp[k, 2]),
                             f"{where} passes {dist[g]:.6g} m from an obstacle or the map edge, "
                             f"radius is {spec.radius:.6g} m"))
    return out


def _check_collisions(specs: Sequence[RobotSpec], paths: Sequence[TimedPath], tol: float) -> list[Violation]:
    """One violation per overlapping pair: first contact time, deepest overlap and when."""
    if len(paths) < 2:
        return []
    # the scenario's radius is the truth, whatever radius the plan claims
    pc = _pieces([p.waypoints for p in paths], [s.radius for s in specs])
    worst: dict[tuple[int, int], list[float]] = {}  # pair -> [first contact, min gap, t of min gap]
    for ap in _all_approaches(pc, 0.0, tol):
        bad = np.nonzero(ap.gap < -tol)[0]
        for k in bad:
            key = (int(min(ap.a[k], ap.b[k])), int(max(ap.a[k], ap.b[k])))
            rec = worst.setdefault(key, [math.inf, math.inf, 0.0])
            rec[0] = min(rec[0], float(ap.t_enter[k]))
            if ap.gap[k] < rec[1]:
                rec[1], rec[2] = float(ap.gap[k]), float(ap.t_min[k])
    out = []
    for (a, b), (t_in, gap, t_min) in sorted(worst.items(), key=lambda kv: kv[1][0]):
        reach = specs[a].radius + specs[b].radius
        out.append(Violation("collision", (specs[a].id, specs[b].id), max(t_in, 0.0),
                             f"discs overlap from t={max(t_in, 0.0):.6g} s; closest distance "
                             f"{gap + reach:.6g} m < {reach:.6g} m (= {specs[a].radius:.6g} + "
                             f"{specs[b].radius:.6g}) at t={max(t_min, 0.0):.6g} s"))
    return out


def check_plan(grid: GridMap, robots: Sequence[RobotSpec], plan: Plan, tol: float = 1e-6) -> list[Violation]:
    """Every way ``plan`` breaks the plan contract for these robots on this map; [] when valid.

    Checks: one path per robot and none for unknown robots, the plan radius equals the robot's,
    first waypoint = start and last = goal (within ``tol``), times finite, >= 0 and non-decreasing,
    no segment faster than ``max_speed`` (allowing ``tol`` of rounding), every swept disc in free
    space (clearance >= radius - tol), and no two discs closer than r_a + r_b - tol at any instant,
    parked robots included.
    """
    out: list[Violation] = []
    specs = {s.id: s for s in robots}
    seen: dict[str, TimedPath] = {}
    for path in plan.paths:
        if path.robot_id not in specs:
            out.append(Violation("missing", (path.robot_id,), None, "plan has a path for a robot not in the scenario"))
        elif path.robot_id in seen:
            out.append(Violation("missing", (path.robot_id,), None, "plan has more than one path for this robot"))
        else:
            seen[path.robot_id] = path
    for spec in robots:
        if spec.id not in seen:
            out.append(Violation("missing", (spec.id,), None, "plan has no path for this robot"))
    order = [s for s in robots if s.id in seen]
    paths = [seen[s.id] for s in order]
    for spec, path in zip(order, paths):
        out.extend(_check_path(spec, path, tol))
    out.extend(_check_obstacles(grid, order, paths, tol))
    finite = [i for i, p in enumerate(paths) if np.all(np.isfinite(p.waypoints))]
    out.extend(_check_collisions([order[i] for i in finite], [paths[i] for i in finite], tol))
    return out


__all__ = ["VIOLATION_KINDS", "Violation", "check_plan", "min_separation"]
