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

import enum
import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

Point = tuple[float, float]

ROBOT_KINDS = ("cargo", "manipulator", "cargo_forklift", "manipulator_forklift")
#: what a robot kind can do beyond driving (a task's ``needs``)
CAPABILITIES = ("manipulator", "forklift")
#: what a robot reports it is doing (``mode`` of a robot status)
STATUS_MODES = ("idle", "waiting", "driving", "picking", "placing", "charging", "offline", "error")


class Behavior(enum.Enum):
    """The 8 behaviours of paper 002, IV.A. The first five are *active* (the robot moves on its own
    account), the last three are *Wait* behaviours (the robot holds, or only gives way)."""

    FOLLOW_WAYPOINT = "FollowWayPoint"
    AVOID = "Avoid"
    EXCHANGE = "Exchange"
    GO_THROUGH = "GoThrough"
    DOCK = "Dock"
    WAIT_KEEP_DISTANCE = "WaitKeepDistance"
    WAIT_FOR_GO_THROUGH = "WaitForGoThrough"
    WAIT_FOR_DOCKING = "WaitForDocking"

    @property
    def is_active(self) -> bool:
        return self in ACTIVE_BEHAVIORS

    @property
    def is_wait(self) -> bool:
        return self in WAIT_BEHAVIORS


ACTIVE_BEHAVIORS = frozenset({Behavior.FOLLOW_WAYPOINT, Behavior.AVOID, Behavior.EXCHANGE, Behavior.GO_THROUGH,
                              Behavior.DOCK})
WAIT_BEHAVIORS = frozenset({Behavior.WAIT_KEEP_DISTANCE, Behavior.WAIT_FOR_GO_THROUGH, Behavior.WAIT_FOR_DOCKING})


@dataclass(frozen=True)
class RobotSpec:
    """A disc robot in a planning problem."""

    id: str
    radius: float
    max_speed: float
    start: Point
    goal: Point
    kind: str = "cargo"
    #: m/s^2; None = speed changes are instantaneous (the plan contract's constant-speed segments)
    max_accel: float | None = None

    def __post_init__(self) -> None:
        for name in ("radius", "max_speed") + (("max_accel",) if self.max_accel is not None else ()):
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


#: constant-speed pieces per acceleration or braking ramp (a robot that accelerates at its limit
#: stays within accel * dt^2 / 8 of such a plan, dt = ramp time / RAMP_PIECES)
RAMP_PIECES = 16


def drive_profile(points: Sequence[Point] | np.ndarray, speed: float, accel: float | None = None,
                  ramp_pieces: int = RAMP_PIECES) -> tuple[np.ndarray, np.ndarray]:
    """How a robot drives a polyline from standstill to standstill: (vertices, times from its
    departure). With ``accel`` the speed follows a trapezoid (a triangle on short paths), written
    as ``ramp_pieces`` constant-speed pieces per ramp in equal time steps (the plan contract has
    constant speed between waypoints); a robot that accelerates at ``accel`` stays within
    accel * dt^2 / 8 of that (dt = ramp time / ramp_pieces) instead of lagging v^2 / (2 accel)
    behind a plan that assumes instant speed changes."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    seg = np.hypot(*np.diff(pts, axis=0).T) if len(pts) > 1 else np.zeros(0)
    pts = pts[np.concatenate([[True], seg > 1e-12])]
    cum = np.concatenate([[0.0], np.cumsum(seg[seg > 1e-12])])
    total = float(cum[-1])
    if accel is None or not math.isfinite(accel) or total == 0.0:
        return pts, cum / speed
    peak = min(speed, math.sqrt(accel * total))
    t_ramp = peak / accel
    s_ramp = 0.5 * peak * t_ramp
    dt = t_ramp / ramp_pieces
    k = np.arange(ramp_pieces + 1)
    up_s, up_t = 0.5 * accel * (k * dt) ** 2, k * dt
    cruise_t = (total - 2 * s_ramp) / peak
    down_s = total - up_s[::-1]
    down_t = t_ramp + cruise_t + (t_ramp - up_t[::-1])
    bs = np.concatenate([up_s, down_s])
    bt = np.concatenate([up_t, down_t])
    bs, keep = np.unique(bs, return_index=True)
    bt = bt[keep]
    s_all = np.union1d(cum, bs)
    s_all = s_all[np.concatenate([[True], np.diff(s_all) > 1e-9])]
    xy = np.column_stack([np.interp(s_all, cum, pts[:, 0]), np.interp(s_all, cum, pts[:, 1])])
    return xy, np.interp(s_all, bs, bt)


def timed_path_from_profile(robot_id: str, radius: float, points: np.ndarray, times: np.ndarray,
                            departure: float = 0.0) -> TimedPath:
    """A robot holding at ``points[0]`` until ``departure``, then at ``points[k]`` at
    ``departure + times[k]`` (see :func:`drive_profile`)."""
    wp = np.column_stack([np.asarray(points, dtype=float).reshape(-1, 2), departure + np.asarray(times, dtype=float)])
    if departure > 0:
        wp = np.vstack([[wp[0, 0], wp[0, 1], 0.0], wp])
    return TimedPath(robot_id, radius, wp)


def timed_path_from_polyline(robot_id: str, radius: float, points: Sequence[Point] | np.ndarray,
                             speed: float, departure: float = 0.0) -> TimedPath:
    """A robot holding at ``points[0]`` until ``departure`` then driving the polyline at ``speed``."""
    pts, times = drive_profile(points, speed)
    return timed_path_from_profile(robot_id, radius, pts, times, departure)
