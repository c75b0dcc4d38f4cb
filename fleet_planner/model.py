"""The small vocabulary every part of the planner speaks (no rclpy, no I/O).

* :class:`RobotSpec`  - one robot of a planning problem: a disc with a top speed, a start and a goal.
* :class:`TimedPath`  - what a planner hands a robot: waypoints ``(x, y, t)``; the robot sits on the
  first one until its time, moves at constant speed between consecutive ones and stays on the last
  one for ever after.
* :class:`Plan`       - one timed path per robot, the planner's name and how long it took, and the
  :class:`Network` it was scheduled on when the planner builds one (md).
* :class:`Network`, :class:`Link` - the (M,D) network of You & Ji, "Design of a Multi-robot Bin
  Packing System in an Automatic Warehouse": priority order, per robot its delay and travel time,
  per collision region a link with its (M, D) and collision box.
* :class:`PlanningError` - raised when no valid plan could be made; names the robots and the reason.

Times are seconds from the start of the plan, coordinates metres in the map frame.
"""
from __future__ import annotations

import enum
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

Point = tuple[float, float]

ROBOT_KINDS = ("cargo", "manipulator", "cargo_forklift", "manipulator_forklift")
#: what a robot kind can do beyond driving (a task's ``needs``)
CAPABILITIES = ("manipulator", "forklift")
#: what a robot reports it is doing (``mode`` of a robot status)
STATUS_MODES = ("idle", "waiting", "driving", "picking", "placing", "charging", "offline", "error")
#: how the (M,D) scheduler keeps a lower robot clear of a higher one: out of the higher robot's
#: collision boxes (as in You & Ji) or out of the exact collision regions (a :class:`Network`'s
#: ``mode``, the md planner's ``mode`` option)
COLLISION_TESTS = ("box", "exact")
#: tolerance (s, m) of the (M,D) network: a link is dangerous when both M and D exceed it
EPS = 1e-9


class Behavior(enum.Enum):
    """The 8 behaviours of Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance",
    IV.A. The first five are *active* (the robot moves on its own account), the last three are
    *Wait* behaviours (the robot holds, or only gives way)."""

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


def _time_to_json(x: float) -> float | None:
    """JSON has no infinity: an unbounded time is written as null."""
    return None if math.isinf(x) else float(x)


def _field(data: Any, key: str, where: str) -> Any:
    if not isinstance(data, Mapping):
        raise ValueError(f"{where}: must be a mapping (got {type(data).__name__})")
    if key not in data:
        raise ValueError(f"{where}.{key}: missing")
    return data[key]


def _number(value: Any, where: str, unbounded: bool = False) -> float:
    """A number of the network file; with ``unbounded``, null is an unbounded time (inf)."""
    if value is None and unbounded:
        return math.inf
    if isinstance(value, bool) or not isinstance(value, (int, float)) or math.isnan(value):
        raise ValueError(f"{where}: must be a number{' or null' if unbounded else ''} (got {value!r})")
    return float(value)


@dataclass
class Link:
    """A link (i -> j, k) of the network with its collision box and (M, D) under the final delays:
    robot i (higher priority) enters the k-th collision region along j's path at T1 = ``ks`` and
    leaves it at T4 = ``ke`` (inf if i parks in it); j's travelled length in the region is
    ``ls`` .. ``le``. ``paper_tuple`` is the paper's (lower, higher, k) notation, e.g. (3, 1, 2)."""

    i: str          # higher priority
    j: str          # lower priority
    k: int          # 1-based index of the region along j's path
    M: float
    D: float
    ks: float       # T1: i enters the region (absolute time)
    ke: float       # T4: i leaves it (inf if i parks in it)
    ls: float       # smallest travelled length of j inside the region
    le: float       # largest

    @property
    def paper_tuple(self) -> tuple[str, str, int]:
        return (self.j, self.i, self.k)

    @property
    def dangerous(self) -> bool:
        return self.M > EPS and self.D > EPS

    def to_dict(self) -> dict[str, Any]:
        return {"i": self.i, "j": self.j, "k": self.k, "M": _time_to_json(self.M), "D": _time_to_json(self.D),
                "ks": _time_to_json(self.ks), "ke": _time_to_json(self.ke), "ls": self.ls, "le": self.le}

    @classmethod
    def from_dict(cls, data: Any, where: str = "link") -> Link:
        """A link as :meth:`to_dict` writes it (null: an unbounded time); ValueError names the field."""
        ends = []
        for end in ("i", "j"):
            rid = _field(data, end, where)
            if not isinstance(rid, str) or not rid:
                raise ValueError(f"{where}.{end}: must be a robot id (got {rid!r})")
            ends.append(rid)
        k = _field(data, "k", where)
        if isinstance(k, bool) or not isinstance(k, int) or k < 1:
            raise ValueError(f"{where}.k: must be an integer >= 1 (got {k!r})")
        times = [_number(_field(data, key, where), f"{where}.{key}", unbounded=True) for key in ("M", "D", "ks", "ke")]
        lengths = [_number(_field(data, key, where), f"{where}.{key}") for key in ("ls", "le")]
        unknown = sorted(set(data) - {"i", "j", "k", "M", "D", "ks", "ke", "ls", "le"})
        if unknown:
            raise ValueError(f"{where}.{unknown[0]}: unknown key")
        return cls(ends[0], ends[1], k, *times, *lengths)


@dataclass
class Network:
    """The (V, E, C, T, P) of You & Ji as plain data: nodes with (T_delayed, T_traveled) - each
    robot's departure ``delay`` and its ``travel`` time -, links with (M, D) and collision boxes,
    the ``priority`` order (highest first) and the collision test (:data:`COLLISION_TESTS`) the
    delays were computed with (``mode``; None when not known)."""

    priority: list[str]
    delay: dict[str, float]
    travel: dict[str, float]
    links: list[Link] = field(default_factory=list)
    mode: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``network`` object of the plan file (the ``mode`` is written beside it, as ``mode``)."""
        return {"priority": list(self.priority),
                "nodes": {r: {"delay": self.delay[r], "travel": self.travel[r]} for r in self.priority},
                "links": [link.to_dict() for link in self.links]}

    @classmethod
    def from_dict(cls, data: Any, mode: str | None = None, where: str = "network") -> Network:
        """The network of :meth:`to_dict` (and its ``mode``); ValueError names the field
        (``network.links[3].ke: ...``)."""
        if mode is not None and mode not in COLLISION_TESTS:
            raise ValueError(f"mode: must be one of {', '.join(COLLISION_TESTS)} (got {mode!r})")
        priority = _field(data, "priority", where)
        if not isinstance(priority, list) or not all(isinstance(r, str) and r for r in priority):
            raise ValueError(f"{where}.priority: must be a list of robot ids (got {priority!r})")
        if len(set(priority)) != len(priority):
            raise ValueError(f"{where}.priority: lists a robot twice ({priority!r})")
        nodes = _field(data, "nodes", where)
        if not isinstance(nodes, Mapping) or set(nodes) != set(priority):
            raise ValueError(f"{where}.nodes: must map every robot of the priority list, and only those, to "
                             f"its delay and travel (got {nodes!r})")
        delay = {r: _number(_field(nodes[r], "delay", f"{where}.nodes[{r!r}]"), f"{where}.nodes[{r!r}].delay")
                 for r in priority}
        travel = {r: _number(_field(nodes[r], "travel", f"{where}.nodes[{r!r}]"), f"{where}.nodes[{r!r}].travel")
                  for r in priority}
        raw = _field(data, "links", where)
        if not isinstance(raw, list):
            raise ValueError(f"{where}.links: must be a list (got {type(raw).__name__})")
        links = [Link.from_dict(item, f"{where}.links[{n}]") for n, item in enumerate(raw)]
        for n, link in enumerate(links):
            for end in ("i", "j"):
                if getattr(link, end) not in delay:
                    raise ValueError(f"{where}.links[{n}].{end}: {getattr(link, end)!r} is not a node")
        unknown = sorted(set(data) - {"priority", "nodes", "links"})
        if unknown:
            raise ValueError(f"{where}.{unknown[0]}: unknown key")
        return cls(list(priority), delay, travel, links, mode)


@dataclass
class Plan:
    """One timed path per robot, in the plan-file contract of docs/ARCHITECTURE.md ("Scenario and
    plan files").

    ``network`` is the (M,D) network the plan was scheduled on, for planners that build one (md),
    else None. ``info`` holds the planner's own scalars, which differ from planner to planner (md:
    ``reorders``, ``reroutes``, ``regions``; prior: ``order``, ``reorders``); the plan file writes
    them in its ``info`` object after the network and its ``mode``."""

    planner: str
    paths: list[TimedPath]
    planning_time_s: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    network: Network | None = None

    def __post_init__(self) -> None:
        if "network" in self.info:
            raise ValueError("plan info: the network is Plan.network (a Network), not an info entry")

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
        listed = "\n  ".join(lines)
        super().__init__(f"no valid plan for {len(lines)} robot(s):\n  {listed}")


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
