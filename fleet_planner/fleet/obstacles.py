"""Obstacles from the intelligent space (You & Ji, "Design of a Multi-robot Bin Packing System in an
Automatic Warehouse", section 2.1: the space gives the central planner "all the static and moving
obstacles' positions"): people, foreign vehicles, dropped pallets, as ``fleet/obstacle@1`` records
(:class:`~msg_schemas.records.ObstacleRecord`). Pure (no rclpy); used on both ends of the fleet.

:class:`ObstacleMap` keeps the obstacles now known, by id (a record supersedes the last of its
id; ``cleared`` removes it; one that is not ``persistent`` expires ``stale_s`` after its last
record), and turns them into what the planner and the robots need:

* **the planner's fixed trajectories** (:meth:`ObstacleMap.trajectories`): each obstacle is a
  participant above every robot in the (M,D) network: it goes into the ``fixed`` trajectories of
  :meth:`~fleet_planner.planners.Planner.plan_incremental`, so legs are delayed, held or re-routed
  around it. A moving obstacle is predicted at constant velocity over ``horizon_s`` and its disc
  grows by ``growth`` m per second of prediction (it may turn, speed up or stop). The planner
  interface takes one radius per trajectory and parks every fixed trajectory on its last waypoint
  for ever, so the prediction goes in as one straight trajectory from where the obstacle is now to
  where it will be at the horizon, with the disc it has at the horizon (the grown disc's upper
  bound over the whole horizon: conservative), parked there. The fleet manager asks for the way
  followed on for :data:`OBSTACLE_LOOKAHEAD` horizons (the disc grown over the first only), so that
  no leg waits where the obstacle walks a little later; a robot standing where a moving obstacle is
  about to walk steps aside to one of :meth:`ObstacleMap.refuges`. A static obstacle (slower than
  :data:`STILL_MPS`) stands where it is for ever: its cells are blocked until it is cleared.
* **which legs an obstacle now threatens** (:meth:`ObstacleMap.threats`): a leg whose disc comes
  closer than the sum of radii plus the margin to the obstacle's predicted disc (grown exactly
  with the prediction time) within the horizon, or, for a static obstacle, anywhere on the rest of
  the leg. The manager re-plans such legs (or holds the robot where no leg can be planned); when an
  obstacle goes (cleared or expired), the legs that were re-planned for it are re-planned again,
  so that robots sent round it may take the direct way.
* **the robots' safety net** (:meth:`ObstacleMap.net_discs`): each obstacle as a disc swept along
  its velocity to the end of the control step, for the critical-area check of a central robot
  (:func:`~fleet_planner.behavior.safety_stop`).

Times are seconds on one clock (ROS time): ``now`` is always passed in.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from msg_schemas.records import ObstacleRecord

from ..checker import min_separation
from ..geometry import polyline_passes_near
from ..model import Point, TimedPath
from ..validation import check_ranges

#: an obstacle slower than this (m/s) is static: it stands where it is
STILL_MPS = 0.05
#: the threat check samples the prediction this often (s); what two discs may close in between
#: (at most their closing speed times half of it, a few centimetres) is within the planner's margin
SAMPLE_S = 0.05
#: at most this many obstacles are kept (the oldest record goes first)
MAX_OBSTACLES = 1000
#: a robot a moving obstacle would walk into steps aside to a refuge at most this far (m) ...
REFUGE_WITHIN_M = 3.0
#: ... clear of the obstacle's way followed on for this many prediction horizons; legs are planned
#: against the same longer prediction (the planner parks a fixed trajectory on its end for ever: with
#: one horizon a leg could wait on the obstacle's way just beyond it, where it walks a moment later)
OBSTACLE_LOOKAHEAD = 3.0
#: the prefix of an obstacle's id in the planner's fixed trajectories and the robots' safety net
PREFIX = "obstacle:"


@dataclass(frozen=True)
class ObstacleParams:
    """How obstacles are predicted and forgotten (seconds, metres)."""

    horizon_s: float = 3.0   # a moving obstacle is predicted this far ahead (constant velocity)
    growth: float = 0.1      # m its disc grows per second of prediction
    stale_s: float = 1.5     # an obstacle that is not persistent is gone this long after its last record

    RANGES = {"horizon_s": (0.0, 60.0), "growth": (0.0, 5.0), "stale_s": (0.05, 3600.0)}

    def __post_init__(self) -> None:
        check_ranges(self, self.RANGES)


def is_static(ob: ObstacleRecord) -> bool:
    return math.hypot(ob.vx, ob.vy) < STILL_MPS


class ObstacleMap:
    """The obstacles known now, by id, and what follows from them (see the module docstring).
    ``max_clock_skew_s``: a record stamped further ahead of ``now`` is refused."""

    def __init__(self, params: ObstacleParams | None = None, max_clock_skew_s: float = 2.0):
        self.params = params or ObstacleParams()
        self.max_clock_skew_s = float(max_clock_skew_s)
        self.obstacles: dict[str, ObstacleRecord] = {}
        #: per obstacle id, the robots whose legs were re-planned for it (re-planned again when it goes)
        self.affected: dict[str, set[str]] = {}
        self._removed: list[ObstacleRecord] = []   # cleared since the last expire()

    def __len__(self) -> int:
        return len(self.obstacles)

    def __iter__(self) -> Iterator[ObstacleRecord]:
        return iter(self.obstacles.values())

    # -- input ------------------------------------------------------------------------------------
    def update(self, ob: ObstacleRecord, now: float) -> str | None:
        """Take a record; returns a note when it changes what is known (an obstacle appears or is
        cleared), None for an update or an old record. ValueError (naming the field) for a record
        stamped more than ``max_clock_skew_s`` ahead of ``now``."""
        if ob.stamp > now + self.max_clock_skew_s:
            raise ValueError(f"obstacle.stamp: {ob.id!r} is stamped {ob.stamp - now:.3g} s ahead of the clock "
                             f"(at most {self.max_clock_skew_s:g} s)")
        last = self.obstacles.get(ob.id)
        if last is not None and ob.stamp < last.stamp:
            return None  # overtaken by a newer record
        if ob.cleared:
            if last is None:
                return None
            del self.obstacles[ob.id]
            self._removed.append(last)
            return f"obstacle {ob.id} ({last.kind}) cleared"
        if not ob.persistent and now - ob.stamp > self.params.stale_s:
            return None  # already stale: it says nothing about now
        if last is None and len(self.obstacles) >= MAX_OBSTACLES:
            oldest = min(self.obstacles.values(), key=lambda o: o.stamp)
            del self.obstacles[oldest.id]
        self.obstacles[ob.id] = ob
        if last is None:
            return (f"obstacle {ob.id} ({ob.kind}, radius {ob.radius:g} m) at ({ob.x:.2f}, {ob.y:.2f})"
                    + (" static" if is_static(ob) else f" moving at {math.hypot(ob.vx, ob.vy):.2f} m/s"))
        return None

    def expire(self, now: float) -> list[ObstacleRecord]:
        """Forget the obstacles that are not persistent and had no record for ``stale_s``; returned
        with those cleared since the last call: every obstacle gone since then."""
        stale = [o for o in self.obstacles.values() if not o.persistent and now - o.stamp > self.params.stale_s]
        for o in stale:
            del self.obstacles[o.id]
        gone, self._removed = self._removed + stale, []
        return gone

    def take_affected(self, obstacle_id: str) -> set[str]:
        """The robots re-planned for an obstacle that is gone (forgotten here)."""
        return self.affected.pop(obstacle_id, set())

    # -- prediction ---------------------------------------------------------------------------------
    def position(self, ob: ObstacleRecord, t: float) -> Point:
        """Where ``ob`` is predicted at ``t`` (constant velocity from its stamp)."""
        ahead = max(0.0, t - ob.stamp)
        return ob.x + ob.vx * ahead, ob.y + ob.vy * ahead

    def trajectories(self, now: float, lookahead: float = 1.0) -> list[TimedPath]:
        """Every obstacle as a fixed trajectory for the planner, from ``now`` (see the module docstring);
        a moving one followed for ``lookahead`` horizons (its disc grows only over the first)."""
        out = []
        for ob in self.obstacles.values():
            name = PREFIX + ob.id
            if is_static(ob):
                out.append(TimedPath(name, ob.radius, np.array([[ob.x, ob.y, now]])))
                continue
            end = now + self.params.horizon_s * lookahead
            radius = ob.radius + self.params.growth * max(0.0, now + self.params.horizon_s - ob.stamp)
            (x0, y0), (x1, y1) = self.position(ob, now), self.position(ob, end)
            if end <= now or math.hypot(x1 - x0, y1 - y0) < 1e-9:
                out.append(TimedPath(name, radius, np.array([[x1, y1, now]])))
            else:
                out.append(TimedPath(name, radius, np.array([[x0, y0, now], [x1, y1, end]])))
        return out

    def threats(self, legs: Iterable[tuple[str, TimedPath, float]], now: float, margin: float,
                lookahead: float = 1.0) -> dict[str, str]:
        """For legs ``(robot id, timed path in absolute time, radius)``, those an obstacle threatens
        from ``now`` on, a moving one followed for ``lookahead`` horizons (its disc grows only over
        the first): robot id -> obstacle id (the first found). The robot is noted as affected by
        that obstacle (:meth:`take_affected`)."""
        if not self.obstacles:
            return {}
        moving = [o for o in self.obstacles.values() if not is_static(o)]
        static = [o for o in self.obstacles.values() if is_static(o)]
        if moving:
            ts, ox, oy, reach = self._predicted(moving, now, lookahead)
        out: dict[str, str] = {}
        for rid, path, radius in legs:
            wp = path.waypoints
            hit = None
            for o in static:
                ahead_pts = wp[wp[:, 2] > now, :2]
                pts = np.vstack([path.position(now), ahead_pts]) if len(ahead_pts) else np.array([path.position(now)])
                if polyline_passes_near(pts, (o.x, o.y), radius + o.radius + margin):
                    hit = o.id
                    break
            if hit is None and moving:
                if len(wp) == 1:
                    rx, ry = np.full_like(ts, wp[0, 0]), np.full_like(ts, wp[0, 1])
                else:
                    rx, ry = np.interp(ts, wp[:, 2], wp[:, 0]), np.interp(ts, wp[:, 2], wp[:, 1])
                close = np.hypot(ox - rx[None, :], oy - ry[None, :]) < reach + radius + margin
                rows = np.nonzero(close.any(axis=1))[0]
                if len(rows):
                    hit = moving[int(rows[0])].id
            if hit is not None:
                out[rid] = hit
                self.affected.setdefault(hit, set()).add(rid)
        return out

    def _predicted(self, moving: Sequence[ObstacleRecord], now: float, lookahead: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The sample times (T,) from ``now`` over ``lookahead`` horizons and, for each of ``moving``,
        its predicted centre x, y and disc radius at them (K, T): constant velocity from its stamp,
        the disc growing by ``growth`` per second of prediction up to the first horizon."""
        h = self.params.horizon_s
        ts = np.append(np.arange(now, now + h * lookahead, SAMPLE_S), now + h * lookahead)
        stamps = np.array([o.stamp for o in moving])
        ahead = np.clip(ts[None, :] - stamps[:, None], 0.0, None)   # (K, T): prediction time
        ox = np.array([o.x for o in moving])[:, None] + np.array([o.vx for o in moving])[:, None] * ahead
        oy = np.array([o.y for o in moving])[:, None] + np.array([o.vy for o in moving])[:, None] * ahead
        reach = np.array([o.radius for o in moving])[:, None] + self.params.growth * np.minimum(
            ahead, np.clip(now + h - stamps[:, None], 0.0, None))
        return ts, ox, oy, reach

    def refuges(self, pos: Point, radius: float, margin: float, now: float, is_free,
                within: float = REFUGE_WITHIN_M, step: float = 0.5, most: int = 8) -> list[Point]:
        """Where a robot of ``radius`` standing at ``pos`` may step aside from the moving obstacles:
        points of a ``step`` lattice round ``pos`` (at most ``within`` m away) where ``is_free(x, y)``
        holds and that every moving obstacle's way, followed on at its velocity for
        :data:`OBSTACLE_LOOKAHEAD` horizons (a person does not stop at the horizon) with its disc grown
        as the prediction grows it up to the horizon, passes no closer than the sum of radii plus
        ``margin``; the ``most`` nearest, those on the robot's side of every obstacle's way first
        (stepping aside does not cross in front of it), nearest first. Empty when no obstacle moves."""
        moving = [o for o in self.obstacles.values() if not is_static(o)]
        if not moving:
            return []
        _, ox, oy, reach = self._predicted(moving, now, OBSTACLE_LOOKAHEAD)
        k = int(within / step)
        offs = np.arange(-k, k + 1) * step
        gx, gy = np.meshgrid(pos[0] + offs, pos[1] + offs)
        cand = np.column_stack([gx.ravel(), gy.ravel()])
        far = np.hypot(cand[:, 0] - pos[0], cand[:, 1] - pos[1])
        cand, far = cand[far <= within + 1e-9], far[far <= within + 1e-9]
        ok = np.ones(len(cand), dtype=bool)
        across = np.zeros(len(cand), dtype=bool)
        for i, o in enumerate(moving):
            side = o.vx * (pos[1] - o.y) - o.vy * (pos[0] - o.x)
            across |= (o.vx * (cand[:, 1] - o.y) - o.vy * (cand[:, 0] - o.x)) * side < 0.0
            gap = np.hypot(cand[:, None, 0] - ox[i][None, :], cand[:, None, 1] - oy[i][None, :]) - reach[i][None, :]
            ok &= gap.min(axis=1) > radius + margin
        out: list[Point] = []
        for x, y in cand[ok][np.lexsort((far[ok], across[ok]))]:
            if len(out) >= most:
                break
            if is_free(float(x), float(y)):
                out.append((float(x), float(y)))
        return out

    # -- the robots' safety net ---------------------------------------------------------------------
    def net_discs(self, t: float, dt: float, stale_s: float) -> list[tuple[str, Point, float, tuple[float, float]]]:
        """Every obstacle as ``(id, position, radius, sweep)`` for a robot's safety net from ``t`` to
        ``t + dt``: where it was reported, and how far it may move by the end of the step at its
        velocity (a record older than ``stale_s``: it may be anywhere it could have walked since,
        so it is swept that far, at most ``stale_s`` of walking)."""
        out = []
        for ob in self.obstacles.values():
            ahead = min(max(0.0, t + dt - ob.stamp), stale_s)
            out.append((PREFIX + ob.id, (ob.x, ob.y), ob.radius, (ob.vx * ahead, ob.vy * ahead)))
        return out


def closest_approach(robots: Sequence[TimedPath], obstacles: Sequence[TimedPath]
                     ) -> tuple[float, str | None, str | None, float | None]:
    """Smallest distance minus the sum of radii between a robot and an obstacle, each obstacle taken
    only over the time it was seen (its first to last waypoint), by the independent checker:
    ``(gap, robot id, obstacle id, t)``, ``(inf, None, None, None)`` when there is no pair."""
    best: tuple[float, str | None, str | None, float | None] = (math.inf, None, None, None)
    for ob in obstacles:
        t0, t1 = float(ob.waypoints[0, 2]), float(ob.waypoints[-1, 2])
        for r in robots:
            wp = r.waypoints
            inside = wp[(wp[:, 2] > t0) & (wp[:, 2] < t1)]
            during = TimedPath(r.robot_id, r.radius, np.vstack([[*r.position(t0), t0], inside, [*r.position(t1), t1]]))
            gap = min_separation([during, ob])
            if gap[0] < best[0]:
                best = gap
    return best
