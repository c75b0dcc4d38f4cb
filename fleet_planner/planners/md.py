"""The (M,D) collision-model planner of paper 001, with what we measured it needs (FINDINGS 1-3).

1. Safe paths: each robot's path avoids the start discs of lower-priority robots and the goal discs
   of higher-priority robots where the map allows (falling back to goals only, then to nothing).
2. The (M,D) network over those paths and priority-ordered departure delays (Eq. 3).
3. Where a delay cannot help (a higher robot parks on its goal in the way, or passes a lower
   robot's start while it is still parked), the blocked robot is moved just ahead of its blocker,
   only the paths whose avoidance changed are re-planned, only their collision regions recomputed
   and only the robots from the moved one on re-scheduled.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..collision import CollisionModel
from ..grid import GridMap
from ..model import Plan, PlanningError, RobotSpec, TimedPath, timed_path_from_polyline
from ..scheduler import MODES, Blocked, DelayScheduler, Network
from .base import Planner, Progress

ORDERS = ("given", "shortest", "longest")


@dataclass
class Schedule:
    """Result of scheduling fixed paths: delays by robot index, the network, the final order."""

    order: list[int]
    delays: np.ndarray
    network: Network
    blocked: Blocked | None


def schedule_paths(ids: Sequence[str], paths: Sequence[np.ndarray], radii: Sequence[float],
                   speeds: Sequence[float], order: Sequence[int] | None = None,
                   margin: float = 0.0, mode: str = "box") -> Schedule:
    """Departure delays for robots on the given paths (no re-planning): the bare method of the paper.

    ``order`` lists robot indices from highest to lowest priority (default: as given); ``mode`` is
    "box" (the paper's collision boxes) or "exact" (the regions themselves, see the scheduler)."""
    order = list(range(len(ids))) if order is None else list(order)
    model = CollisionModel(paths, radii, margin, speeds)
    sched = DelayScheduler(model, speeds, mode)
    blocked = sched.schedule(order)
    return Schedule(order, sched.delays.copy(), sched.network(order, ids), blocked)


class MDPlanner(Planner):
    """Central planner: safe paths, (M,D) network, departure delays, re-ordering on deadlock.

    ``margin`` (m) is added to every pair's sum of radii; ``order`` is the initial priority
    ("given": as listed; "shortest"/"longest": by straight-line distance to the goal);
    ``max_reorders`` bounds the re-ordering attempts (default 4 N); ``mode`` picks the collision
    test: "exact" (default; robots may follow each other) or "box" (paper 001 as written)."""

    name = "md"

    def __init__(self, margin: float = 0.02, order: str = "given", max_reorders: int | None = None,
                 mode: str = "exact"):
        if mode not in MODES:
            raise ValueError(f"mode: must be one of {', '.join(MODES)} (got {mode!r})")
        self.mode = mode
        if order not in ORDERS:
            raise ValueError(f"order: must be one of {', '.join(ORDERS)} (got {order!r})")
        if not margin >= 0:
            raise ValueError(f"margin: must be >= 0 (got {margin!r})")
        self.margin = float(margin)
        self.order = order
        self.max_reorders = max_reorders

    # ------------------------------------------------------------------------------------------
    def plan(self, grid: GridMap, robots: Sequence[RobotSpec], progress: Progress | None = None) -> Plan:
        t_start = time.perf_counter()
        robots = list(robots)
        n = len(robots)
        _check_endpoints(robots, self.margin)
        order = self._initial_order(robots)
        rank = {x: k for k, x in enumerate(order)}
        finder = _Finders(grid)

        paths: list[np.ndarray | None] = [None] * n
        for k, x in enumerate(order):
            paths[x] = self._safe_path(finder, robots, x, rank)
            if progress:
                progress(k + 1, n, "paths")
        missing = {robots[x].id: "no path from start to goal on this map for its radius"
                   for x in range(n) if paths[x] is None}
        if missing:
            raise PlanningError(missing)

        speeds = [r.max_speed for r in robots]
        model = CollisionModel(paths, [r.radius for r in robots], self.margin, speeds)
        sched = DelayScheduler(model, speeds, self.mode)
        blocked = sched.schedule(order)
        reorders = 0
        swaps: dict[tuple[int, int], int] = {}
        limit = 4 * n if self.max_reorders is None else self.max_reorders
        while blocked is not None:
            j, i = blocked.j, blocked.blocker
            swaps[(j, i)] = swaps.get((j, i), 0) + 1
            if reorders >= limit or swaps[(j, i)] > 2:
                raise PlanningError({robots[j].id: f"blocked by {robots[i].id}, which {blocked.why}; "
                                                   f"re-ordering did not help after {reorders} attempt(s)"})
            reorders += 1
            old_j, pos_i = rank[j], rank[i]
            order.pop(old_j)
            order.insert(pos_i, j)
            rank = {x: k for k, x in enumerate(order)}
            # robots between the blocker and j now have j above them: those crossing j's goal re-plan
            replan = [j] + [x for x in order[pos_i + 1:old_j + 1]
                            if _passes_near(paths[x], robots[j].goal,
                                            robots[j].radius + robots[x].radius + self.margin)]
            changed = {}
            for x in replan:
                new = self._safe_path(finder, robots, x, rank)
                if new is None:
                    raise PlanningError({robots[x].id: "no path from start to goal on this map for its radius"})
                paths[x] = changed[x] = new
            model.set_paths(changed)
            blocked = sched.schedule(order, start_at=pos_i)
            if progress:
                progress(reorders, limit, "re-ordering")

        network = sched.network(order, [r.id for r in robots])
        timed = [timed_path_from_polyline(r.id, r.radius, paths[x], r.max_speed, float(sched.delays[x]))
                 for x, r in enumerate(robots)]
        return Plan("md", timed, time.perf_counter() - t_start,
                    {"network": network.to_dict(), "mode": self.mode, "reorders": reorders,
                     "regions": model.region_count})

    # ------------------------------------------------------------------------------------------
    def plan_incremental(self, grid: GridMap, robots: Sequence[RobotSpec], fixed: Sequence[TimedPath],
                         t0: float) -> list[TimedPath]:
        """Plan new legs for ``robots`` (starting at ``t0`` from their ``start``) around trajectories
        that are already being driven and stay as they are (``fixed``, absolute times; a robot on
        its last waypoint stays there). The fixed robots rank above the new ones, so only the new
        ones are delayed; new robots are re-ordered among themselves if needed. Returns timed paths
        in absolute time, or raises PlanningError (with ``blockers``) naming who is in the way."""
        robots = list(robots)
        kept = [_remaining(tp, t0) for tp in fixed]
        nf, n = len(kept), len(kept) + len(robots)
        specs = [RobotSpec(tp.robot_id, tp.radius, speed, tuple(poly[0]), tuple(poly[-1]))
                 for tp, (poly, _, speed) in zip(fixed, kept)] + robots
        _check_endpoints(specs[nf:], self.margin)
        order = list(range(nf)) + [nf + x for x in self._initial_order(robots)]
        rank = {x: k for k, x in enumerate(order)}
        finder = _Finders(grid)
        paths: list[np.ndarray | None] = [poly for poly, _, _ in kept] + [None] * len(robots)
        for x in order[nf:]:
            paths[x] = self._safe_path(finder, specs, x, rank)
            if paths[x] is None:
                raise PlanningError({specs[x].id: "no path from start to goal on this map for its radius"})
        speeds = [s.max_speed for s in specs]
        model = CollisionModel(paths, [s.radius for s in specs], self.margin, speeds)
        sched = DelayScheduler(model, speeds, self.mode)
        sched.delays[:nf] = [delay for _, delay, _ in kept]
        blocked = sched.schedule(order, start_at=nf)
        swaps: dict[tuple[int, int], int] = {}
        while blocked is not None:
            j, i = blocked.j, blocked.blocker
            swaps[(j, i)] = swaps.get((j, i), 0) + 1
            if i < nf or swaps[(j, i)] > 2 or sum(swaps.values()) > 4 * n:
                raise PlanningError({specs[j].id: f"blocked by {specs[i].id}, which {blocked.why}"},
                                    {specs[j].id: specs[i].id})
            old_j, pos_i = rank[j], rank[i]
            order.insert(pos_i, order.pop(old_j))
            rank = {x: k for k, x in enumerate(order)}
            changed = {}
            for x in [j] + [x for x in order[pos_i + 1:old_j + 1]
                            if _passes_near(paths[x], specs[j].goal, specs[j].radius + specs[x].radius + self.margin)]:
                paths[x] = changed[x] = self._safe_path(finder, specs, x, rank)
                if paths[x] is None:
                    raise PlanningError({specs[x].id: "no path from start to goal on this map for its radius"})
            model.set_paths(changed)
            blocked = sched.schedule(order, start_at=pos_i)
        out = []
        for x in range(nf, n):
            tp = timed_path_from_polyline(specs[x].id, specs[x].radius, paths[x], speeds[x], float(sched.delays[x]))
            tp.waypoints[:, 2] += t0
            out.append(tp)
        return out

    def _initial_order(self, robots: list[RobotSpec]) -> list[int]:
        idx = list(range(len(robots)))
        if self.order == "given":
            return idx
        dist = [float(np.hypot(r.goal[0] - r.start[0], r.goal[1] - r.start[1])) for r in robots]
        return sorted(idx, key=lambda x: dist[x], reverse=self.order == "longest")

    def _safe_path(self, finder: "_Finders", robots: list[RobotSpec], x: int, rank: dict[int, int]):
        """FINDINGS 1: avoid lower robots' starts and higher robots' goals; else goals only; else none."""
        me = robots[x]
        starts, goals = [], []
        for y, other in enumerate(robots):
            if y == x:
                continue
            keep_out = me.radius + other.radius + self.margin
            if rank[y] > rank[x]:
                starts.append((other.start, keep_out))
            else:
                goals.append((other.goal, keep_out))
        pf = finder.get(me.radius)
        for avoid in (starts + goals, goals, []):
            path = pf.find(me.start, me.goal, avoid=avoid)
            if path is not None:
                return path
        return None


class _Finders:
    """One path finder per distinct radius (its inflated map is computed once)."""

    def __init__(self, grid: GridMap):
        self.grid = grid
        self._by_radius: dict[float, object] = {}

    def get(self, radius: float):
        from ..paths import PathFinder

        if radius not in self._by_radius:
            self._by_radius[radius] = PathFinder(self.grid, radius)
        return self._by_radius[radius]


def _remaining(tp: TimedPath, t0: float) -> tuple[np.ndarray, float, float]:
    """The part of a hold-then-drive timed path still ahead at ``t0``: (polyline from the robot's
    position at t0, delay from t0 until it moves, its speed). A path that holds again after it has
    started moving is not of this form and is refused (the md planner never makes one)."""
    wp = tp.waypoints
    seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
    dt = np.diff(wp[:, 2])
    moving = seg > 1e-9
    if not moving.any():
        return wp[-1:, :2].copy(), 0.0, 1.0
    first, last = int(np.argmax(moving)), len(moving) - 1 - int(np.argmax(moving[::-1]))
    if not moving[first:last + 1].all():
        raise ValueError(f"fixed path of {tp.robot_id!r}: holds after it starts moving; cannot be kept as is")
    speeds = seg[first:last + 1] / np.maximum(dt[first:last + 1], 1e-12)
    speed = float(np.median(speeds))
    if np.max(np.abs(speeds - speed)) > 1e-6 * max(speed, 1.0):
        raise ValueError(f"fixed path of {tp.robot_id!r}: speed varies along the path; cannot be kept as is")
    depart = float(wp[first, 2])
    if t0 <= depart:
        return wp[first:last + 2, :2].copy(), depart - t0, speed
    if t0 >= wp[last + 1, 2]:
        return wp[last + 1:last + 2, :2].copy(), 0.0, speed
    k = int(np.searchsorted(wp[:, 2], t0, side="right"))   # next vertex ahead of t0
    here = np.array(tp.position(t0))
    return np.vstack([here, wp[k:last + 2, :2]]), 0.0, speed


def _passes_near(path: np.ndarray, point: tuple[float, float], dist: float) -> bool:
    """True if some point of the polyline is closer than ``dist`` to ``point``."""
    p = np.asarray(point, dtype=float)
    a, b = path[:-1], path[1:]
    if len(a) == 0:
        return bool(np.hypot(*(path[0] - p)) < dist)
    ab = b - a
    denom = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.where(denom > 0, denom, 1.0), 0.0, 1.0)
    closest = a + ab * t[:, None]
    return bool(np.min(np.hypot(*(closest - p).T)) < dist)


def _check_endpoints(robots: list[RobotSpec], margin: float) -> None:
    """Two robots whose start discs (or goal discs) overlap can never both be served."""
    ids = [r.id for r in robots]
    if len(set(ids)) != len(ids):
        raise PlanningError({rid: "duplicate robot id" for rid in ids if ids.count(rid) > 1})
    radii = np.array([r.radius for r in robots])
    for what in ("start", "goal"):
        pts = np.array([getattr(r, what) for r in robots], dtype=float).reshape(-1, 2)
        if len(pts) < 2:
            continue
        from scipy.spatial import cKDTree

        tree = cKDTree(pts)
        failures = {}
        for a, b in tree.query_pairs(2 * radii.max() + margin):
            if np.hypot(*(pts[a] - pts[b])) < radii[a] + radii[b]:
                failures[ids[b]] = f"its {what} disc overlaps the {what} disc of {ids[a]}"
        if failures:
            raise PlanningError(failures)
