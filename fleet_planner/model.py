"""The small vocabulary every part of the planner speaks (no rclpy, no I/O).

* :class:`RobotSpec`  - one robot of a planning problem: a disc with a top speed, a start and a goal.
* :class:`TimedPath`  - what a planner hands a robot: waypoints ``(x, y, t)``; the robot sits on the
  first one until its time, moves at constant speed between consecutive ones and stays on the last
  one for ever after.
* :class:`Plan`       - one timed path per robot, the planner's name and how long it took.
* :class:`PlanningError` - raised when no valid plan could be made; names the robots and the reason.

Times are seconds from the start of the plan, coordinates metres in the map frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

Point = tuple[float, float]

ROBOT_KINDS = ("cargo", "manipulator", "cargo_forklift", "manipulator_forklift")


@dataclass(frozen=True)
class RobotSpec:
    """A disc robot in a planning problem."""

    id: str
    radius: float
    max_speed: float
    start: Point
    goal: Point
    kind: str = "cargo"

    def __post_init__(self) -> None:
        for name in ("radius", "max_speed"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"robot {self.id!r}: {name} must be a finite number > 0, got {value!r}")


@dataclass
class TimedPath:
    """Waypoints ``(x, y, t)`` with non-decreasing t (see the module docstring for the meaning)."""

    robot_id: str
    radius: float
    waypoints: np.ndarray  # shape (n, 3), float

    def __post_init__(self) -> None:
        self.waypoints = np.asarray(self.waypoints, dtype=float).reshape(-1, 3)
        if len(self.waypoints) == 0:
            raise ValueError(f"robot {self.robot_id!r}: a timed path needs at least one waypoint")

    @property
    def start_time(self) -> float:
        """When the robot leaves its first waypoint (its departure delay)."""
        wp = self.waypoints
        moving = np.nonzero(np.any(wp[1:, :2] != wp[:-1, :2], axis=1))[0]
        return float(wp[moving[0], 2]) if len(moving) else float(wp[-1, 2])

    @property
    def arrival_time(self) -> float:
        """When the robot reaches its last waypoint for good."""
        wp = self.waypoints
        moving = np.nonzero(np.any(wp[1:, :2] != wp[:-1, :2], axis=1))[0]
        return float(wp[moving[-1] + 1, 2]) if len(moving) else float(wp[0, 2])

    @property
    def length(self) -> float:
        return float(np.sum(np.hypot(*np.diff(self.waypoints[:, :2], axis=0).T)))

    def position(self, t: float) -> Point:
        """Where the robot is at time t (clamped to the first and last waypoint)."""
        wp = self.waypoints
        if t <= wp[0, 2]:
            return float(wp[0, 0]), float(wp[0, 1])
        if t >= wp[-1, 2]:
            return float(wp[-1, 0]), float(wp[-1, 1])
        k = int(np.searchsorted(wp[:, 2], t, side="right")) - 1
        t0, t1 = wp[k, 2], wp[k + 1, 2]
        a = 0.0 if t1 <= t0 else (t - t0) / (t1 - t0)
        p = wp[k, :2] + a * (wp[k + 1, :2] - wp[k, :2])
        return float(p[0]), float(p[1])

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.robot_id, "radius": float(self.radius),
                "waypoints": [[round(float(x), 6), round(float(y), 6), round(float(t), 6)]
                              for x, y, t in self.waypoints]}


@dataclass
class Plan:
    """One timed path per robot, in the plan-file contract of ARCHITECTURE.md."""

    planner: str
    paths: list[TimedPath]
    planning_time_s: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)  # planner-specific extras (e.g. the (M,D) network)

    def by_id(self) -> dict[str, TimedPath]:
        return {p.robot_id: p for p in self.paths}

    @property
    def sum_of_arrivals(self) -> float:
        return float(sum(p.arrival_time for p in self.paths))

    @property
    def makespan(self) -> float:
        return float(max((p.arrival_time for p in self.paths), default=0.0))


class PlanningError(RuntimeError):
    """No valid plan: ``failures`` maps robot ids to the reason, in words."""

    def __init__(self, failures: dict[str, str], blockers: dict[str, str] | None = None):
        self.failures = dict(failures)
        #: robot id -> id of the robot in its way, where one is known (e.g. parked on its only path)
        self.blockers = dict(blockers or {})
        lines = [f"{rid}: {why}" for rid, why in self.failures.items()]
        super().__init__("no valid plan for %d robot(s):\n  %s" % (len(lines), "\n  ".join(lines)))


def polyline_length(points: Sequence[Point] | np.ndarray) -> float:
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    return float(np.sum(np.hypot(*np.diff(pts, axis=0).T))) if len(pts) > 1 else 0.0


def timed_path_from_polyline(robot_id: str, radius: float, points: Sequence[Point] | np.ndarray,
                             speed: float, departure: float = 0.0) -> TimedPath:
    """A robot holding at ``points[0]`` until ``departure`` then driving the polyline at ``speed``."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    seg = np.hypot(*np.diff(pts, axis=0).T) if len(pts) > 1 else np.zeros(0)
    keep = np.concatenate([[True], seg > 1e-12])
    pts = pts[keep]
    times = departure + np.concatenate([[0.0], np.cumsum(seg[seg > 1e-12]) / speed])
    wp = np.column_stack([pts, times])
    if departure > 0:
        wp = np.vstack([[pts[0, 0], pts[0, 1], 0.0], wp])
    return TimedPath(robot_id, radius, wp)
