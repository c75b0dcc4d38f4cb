"""The robots themselves: the four kinds of You and Ji, "Design of a Multi-robot Bin Packing System in
an Automatic Warehouse" (section 2.2), and a simulated robot (no rclpy).

* :class:`RobotKind` - what a kind of robot can do: size, speed, acceleration, capabilities
  (``manipulator``, ``forklift``), payload, pick/place/lift durations and its battery.
  :func:`load_kinds` reads them from ``config/robot_kinds.yaml``; the fields are declared with the
  checks of :mod:`fleet_planner.validation`, so a kind built in code is checked as one read from a file.
* :class:`RobotModel` - one simulated robot driving a timed path on a clock: it waits on its start
  until departure, tracks the path's due position under its speed and acceleration limits (never
  ahead of schedule; ``lateness_s`` says how far behind), picks and places for set durations,
  drains its battery and charges at a charger. The agent node and the fleet simulation step it.
  Under behaviour coordination a local controller steers it instead (:meth:`RobotModel.steer`).

The timed-path contract (constant speed between waypoints, see :class:`~fleet_planner.model.TimedPath`)
assumes instant speed changes, so a robot with finite acceleration lags a little after each
departure; with infinite acceleration it is exactly on schedule at every step.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from .model import CAPABILITIES, ROBOT_KINDS, Point, TimedPath
from .validation import ValidationError, Vocabulary, anything, check_fields, in_file, read_yaml, spec
from .warehouse import config_path

ACTIONS = ("pick", "place")

KINDS_FILE = "robot_kinds.yaml"  # the shipped kinds, found by warehouse.config_path

_EPS = 1e-9


class KindsError(ValidationError):
    """A robot kind that cannot be used; the message names the kind and the field."""


# the kinds file's words: "kind 'cargo': radius must be ...", unknown and missing fields named in the kind
_V = Vocabulary(KindsError, not_mapping="expected a mapping of fields (got {got})",
                unknown="unknown field(s) {keys} (known: {known})", unknown_in="mapping", unknown_sorted=True,
                missing="{key} is missing", missing_in="mapping")
_POSITIVE = _V.worded(_V.number(above=0), "must be a finite number > 0 (got {got})")
_AT_LEAST_0 = _V.worded(_V.number(lo=0), "must be a finite number >= 0 (got {got})")
_ACCELERATION = _V.worded(_V.number(above=0, infinite=True), "must be a finite number > 0 (got {got})")  # inf: instant
_CAPABILITIES = _V.worded(_V.list_of(_V.choice(CAPABILITIES), types=(list, tuple, set, frozenset)),
                          f"must be a list drawn from {', '.join(CAPABILITIES)} (got {{got}})")


@dataclass(frozen=True)
class RobotKind:
    """One kind of robot. Powers in watts, energy in watt-hours, durations in seconds.

    ``lift_s`` is the time a forklift needs to raise or lower its fork; it is added to every pick
    and place of a kind with the ``forklift`` capability and must be 0 for the others.
    ``max_accel`` may be ``inf`` (instant speed changes, the planner's own assumption).
    """

    name: str
    radius: float = spec(_POSITIVE)
    max_speed: float = spec(_POSITIVE)
    max_accel: float = spec(_ACCELERATION)
    capabilities: frozenset[str] = spec(anything)  # checked after the numbers, in __post_init__
    payload_kg: float = spec(_AT_LEAST_0)
    pick_s: float = spec(_AT_LEAST_0)
    place_s: float = spec(_AT_LEAST_0)
    battery_wh: float = spec(_POSITIVE)
    drain_w_moving: float = spec(_AT_LEAST_0)
    drain_w_idle: float = spec(_AT_LEAST_0)
    charge_w: float = spec(_POSITIVE)
    lift_s: float = spec(_AT_LEAST_0, default=0.0)

    def __post_init__(self) -> None:
        where = f"kind {self.name!r}"
        if self.name not in ROBOT_KINDS:
            raise KindsError(f"{where}: unknown kind (known: {', '.join(ROBOT_KINDS)})")
        try:
            check_fields(self)
            caps = _CAPABILITIES(self.capabilities, "capabilities")
        except KindsError as exc:  # kinds word it "kind 'cargo': radius must be ..."
            raise KindsError(f"{where}: {exc.path} {exc.reason}") from None
        object.__setattr__(self, "capabilities", frozenset(caps))
        if self.lift_s and "forklift" not in self.capabilities:
            raise KindsError(f"{where}: lift_s is only for kinds with the forklift capability")

    def action_s(self, action: str) -> float:
        """How long a pick or a place takes, fork movement included."""
        if action not in ACTIONS:
            raise ValueError(f"unknown action {action!r} (known: {', '.join(ACTIONS)})")
        return (self.pick_s if action == "pick" else self.place_s) + self.lift_s


def load_kinds(path: str | Path | None = None) -> dict[str, RobotKind]:
    """The robot kinds of a YAML file (a mapping ``kind name -> fields``), by name.

    Without ``path``, the shipped ``config/robot_kinds.yaml``. Every field of :class:`RobotKind`
    but ``name`` is required, ``lift_s`` exactly for the kinds with the ``forklift`` capability.
    Errors name the file, the kind and the field.
    """
    try:
        path = Path(path) if path is not None else config_path(KINDS_FILE)
    except FileNotFoundError as exc:
        raise KindsError(str(exc)) from exc
    data = read_yaml(path, KindsError, what="robot kinds", invalid=None)
    if not isinstance(data, dict) or not data:
        raise KindsError(f"{path}: expected a mapping of kind names to their fields")
    known = [f.name for f in fields(RobotKind) if f.name != "name"]
    kinds = {}
    with in_file(path, KindsError):
        for name, given in data.items():
            _V.keys(given, f"kind {name!r}", known, [k for k in known if k != "lift_s" or _forklift(given)])
            kinds[name] = RobotKind(name=name, **given)
    return kinds


def _forklift(given: Any) -> bool:
    """Whether a kind's fields in a file give it the forklift capability (then ``lift_s`` is required)."""
    caps = given.get("capabilities") if isinstance(given, dict) else None
    return isinstance(caps, list) and "forklift" in caps


class RobotModel:
    """A simulated robot: it follows one timed path at a time, acts, and keeps its battery.

    Time ``t`` is on the same clock as the ``t0`` handed to :meth:`follow` (the agent uses ROS
    time in seconds, the simulation its own). Between calls nothing happens; :meth:`step` moves
    the state from ``t`` to ``t + dt``.

    Tracking: the robot moves along the path's polyline (it never leaves it) to the due arc
    length ``s_due(t)``; it may go slower than planned (speed and acceleration limits, and it
    brakes to stop where the schedule stops), never faster than the schedule, so it is never
    ahead of its due position. That rule wins over the acceleration limit: on the last step into
    a stop the robot may brake up to about twice ``max_accel``. ``lateness_s`` is how long ago
    the schedule passed the robot's position (0 when on time or waiting).
    """

    def __init__(self, robot_id: str, kind: RobotKind, x: float, y: float, yaw: float = 0.0,
                 battery: float = 1.0, chargers: Sequence[Point] = ()) -> None:
        if not 0.0 <= battery <= 1.0:
            raise ValueError(f"robot {robot_id!r}: battery must be in [0, 1], got {battery!r}")
        self.id = robot_id
        self.kind = kind
        self.x, self.y, self.yaw = float(x), float(y), float(yaw)
        self.vx = self.vy = 0.0
        self.speed = 0.0
        self.battery = float(battery)
        self.chargers = [tuple(map(float, c)) for c in chargers]
        self.mode = "idle"
        self.task_id: str | None = None
        self.path: TimedPath | None = None
        self.path_t0 = 0.0
        self.path_id: int | None = None
        self.lateness_s = 0.0
        self._s = 0.0                       # arc length driven along the current path
        self._S = np.zeros(1)               # arc length at each waypoint
        self._T = np.zeros(1)               # absolute due time of each waypoint
        self._stops: np.ndarray = np.zeros((0, 2))  # (arc length, absolute departure) of each halt
        self._action: tuple[str, float] | None = None  # (pick|place, absolute end time)
        self._charging = False
        self._steered: float | None = None  # steered by a controller: the fraction of its leg done
        self._pre: tuple | None = None      # this step's tracking worked out ahead (TrackBatch.prepare)

    # -- commands ---------------------------------------------------------------------------------
    def follow(self, path: TimedPath, t0: float, path_id: int | None = None, at: float = 0.0) -> None:
        """Drive ``path``, whose times count from ``t0``. Ends charging.

        The robot must be within its radius of the path's first waypoint; it is put exactly there
        (the planner plans from reported positions, so the gap is a rounding of the start). With
        ``at`` (m along the path) it joins the path there instead: it must be within its radius of
        that point, and it has driven ``at`` m of the path.
        """
        wp = path.waypoints
        if not np.all(np.isfinite(wp)):
            raise ValueError(f"robot {self.id!r}: timed path has non-finite waypoints")
        if np.any(np.diff(wp[:, 2]) < 0):
            k = int(np.argmax(np.diff(wp[:, 2]) < 0)) + 1
            raise ValueError(f"robot {self.id!r}: timed path waypoint {k} is earlier than waypoint {k - 1}")
        seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
        arc = np.concatenate([[0.0], np.cumsum(seg)])
        at = min(max(float(at), 0.0), float(arc[-1]))
        keep = np.concatenate([[True], seg > 0])
        jx, jy = (float(np.interp(at, arc[keep], wp[keep, 0])), float(np.interp(at, arc[keep], wp[keep, 1]))) \
            if at > 0 else (float(wp[0, 0]), float(wp[0, 1]))
        gap = math.hypot(jx - self.x, jy - self.y)
        if gap > self.kind.radius:
            raise ValueError(f"robot {self.id!r}: timed path starts {gap:.3f} m from the robot "
                             f"(more than its radius {self.kind.radius:g} m)")
        self._S = arc
        self._T = wp[:, 2] + t0
        # the schedule halts on the first waypoint until its time, on every hold, and at the end
        holds = np.nonzero(seg <= _EPS)[0]
        self._stops = np.vstack([[0.0, self._T[0]],
                                 np.column_stack([self._S[holds], self._T[holds + 1]]),
                                 [self._S[-1], math.inf]])
        self.path, self.path_t0, self.path_id = path, float(t0), path_id
        self._s = at
        self.x, self.y = jx, jy
        self._charging = False
        self._steered = None

    def steer(self, path_id: int | None = None) -> None:
        """Drive leg ``path_id`` under a local controller (behaviour coordination) instead of a timed
        path: each :meth:`step` is then given where the controller moves the robot (``to``) and how
        much of the leg is done (``progress``). Ends charging and any timed path."""
        self.path, self.path_id = None, path_id
        self._S, self._s, self._stops = np.zeros(1), 0.0, np.zeros((0, 2))
        self._charging = False
        self._steered = 0.0
        self.lateness_s = 0.0

    def start_action(self, action: str, t: float, duration: float | None = None) -> None:
        """Begin picking or placing at time ``t`` for ``duration`` s (default: the kind's)."""
        duration = self.kind.action_s(action) if duration is None else float(duration)
        if not (math.isfinite(duration) and duration >= 0):
            raise ValueError(f"robot {self.id!r}: action duration must be >= 0, got {duration!r}")
        if self.speed > 0 or self._action is not None or self.mode == "error":
            raise ValueError(f"robot {self.id!r}: cannot {action} while {self.mode}")
        self._action = (action, t + duration)
        self._charging = False
        self.mode = "picking" if action == "pick" else "placing"

    def start_charging(self) -> None:
        """Charge from now on; the robot must stand still within its radius of a charger."""
        near = min((math.hypot(cx - self.x, cy - self.y) for cx, cy in self.chargers), default=math.inf)
        if near > self.kind.radius:
            raise ValueError(f"robot {self.id!r}: not at a charger (nearest is {near:.3f} m away)")
        if self.speed > 0 or self._action is not None:
            raise ValueError(f"robot {self.id!r}: cannot charge while {self.mode}")
        self._charging = True
        self.mode = "charging"

    def stop_charging(self) -> None:
        self._charging = False

    # -- simulation -------------------------------------------------------------------------------
    @property
    def busy_until(self) -> float | None:
        """When the current pick or place ends (None when not acting)."""
        return self._action[1] if self._action else None

    @property
    def progress(self) -> float:
        """Fraction of the current path's length driven (1 when there is none or it has no length);
        steered, the fraction of its leg the controller reports done."""
        if self._steered is not None:
            return self._steered
        total = float(self._S[-1])
        return 1.0 if total <= 0 else min(1.0, self._s / total)

    @property
    def travelled(self) -> float:
        """Length (m) driven along the current timed path (0 without one)."""
        return float(self._s)

    def ahead(self) -> Point | None:
        """The next waypoint of the timed path beyond the robot (where it drives next), or None at
        its end or without one."""
        if self.path is None:
            return None
        k = int(np.searchsorted(self._S, self._s + 1e-6, side="right"))
        if k >= len(self._S):
            return None
        return float(self.path.waypoints[k, 0]), float(self.path.waypoints[k, 1])

    def step(self, t: float, dt: float, *, hold: bool = False, to: Point | None = None,
             progress: float | None = None, brake: bool = False) -> None:
        """Advance the state from time ``t`` to ``t + dt``.

        On a timed path, ``hold`` keeps the robot where it is for this step (an emergency stop: the
        schedule goes on, so the robot gets late); ``brake`` slows it down along its path at its
        ``max_accel`` until it stands (a controlled stop; never ahead of its schedule). Steered
        (:meth:`steer`), the robot drives straight to ``to`` (ValueError if that is beyond its top
        speed) and ``progress`` (0..1) is the fraction of its leg done; braking, a steered robot stands.
        """
        if not dt > 0:
            raise ValueError(f"robot {self.id!r}: dt must be > 0, got {dt!r}")
        end = t + dt
        moved = 0.0
        if self._steered is not None and progress is not None:
            self._steered = min(1.0, max(0.0, float(progress)))
        if self._charging:
            self.battery = min(1.0, self.battery + self.kind.charge_w * dt / 3600.0 / self.kind.battery_wh)
        elif self._action is not None:
            if end >= self._action[1]:
                self._action = None
        elif self.battery <= 0.0 or hold:  # an empty robot stands still
            pass
        elif brake:
            moved = self._brake(end, dt) if self.path is not None else 0.0
        elif self.path is not None:
            moved = self._track(end, dt)
        elif self._steered is not None and to is not None:
            moved = self._drive_to(to, dt)
        self.speed = moved / dt
        if moved > 0:
            self.yaw = math.atan2(self.vy, self.vx)
        else:
            self.vx = self.vy = 0.0
        if not self._charging:
            working = moved > 0 or self._action is not None
            watts = self.kind.drain_w_moving if working else self.kind.drain_w_idle
            self.battery = max(0.0, self.battery - watts * dt / 3600.0 / self.kind.battery_wh)
            self.mode = self._mode_now(moved)
        if self.path is not None:
            self.lateness_s = self._lateness(end)

    def _track(self, end: float, dt: float) -> float:
        """Move along the path towards its due position at ``end``; returns the distance driven."""
        s = self._s
        pre, self._pre = self._pre, None
        if (pre is not None and pre[0] is self._T and pre[1] is self.kind and pre[2] == end and pre[3] == dt
                and pre[4] == s and pre[5] == self.speed):   # worked out for the whole fleet (TrackBatch)
            s_new, x, y = pre[6], pre[7], pre[8]
            if s_new <= s:
                return 0.0
            self.vx, self.vy = (x - self.x) / dt, (y - self.y) / dt
            self.x, self.y, self._s = x, y, s_new
            return s_new - s
        s_due = float(np.interp(end, self._T, self._S))
        v = min(max(0.0, (s_due - s) / dt), self.kind.max_speed * (1 + _EPS))
        a = self.kind.max_accel
        if math.isfinite(a):
            v = min(v, self.speed + a * dt)
            # brake for the next place where the schedule halts beyond now
            ahead = self._stops[(self._stops[:, 0] >= s - _EPS) & (self._stops[:, 1] > end)]
            if len(ahead):
                gap = max(0.0, float(ahead[:, 0].min()) - s)
                v = min(v, math.sqrt(2 * a * gap), gap / dt)
        return self._advance(min(s + v * dt, s_due, float(self._S[-1])), dt)

    def _brake(self, end: float, dt: float) -> float:
        """Slow down along the path at ``max_accel`` (at once without a limit); the distance driven."""
        self._pre = None
        a = self.kind.max_accel
        v = max(0.0, self.speed - a * dt) if math.isfinite(a) else 0.0
        return self._advance(min(self._s + v * dt, float(np.interp(end, self._T, self._S)), float(self._S[-1])), dt)

    def _advance(self, s_new: float, dt: float) -> float:
        """Move forward along the path to arc length ``s_new`` over ``dt`` (never back); the distance driven."""
        s = self._s
        if s_new <= s:
            return 0.0
        x, y = self._point_at(s_new)
        self.vx, self.vy = (x - self.x) / dt, (y - self.y) / dt
        self.x, self.y, self._s = x, y, s_new
        return s_new - s

    def _drive_to(self, to: Point, dt: float) -> float:
        """Move straight to ``to`` over ``dt``; returns the distance driven."""
        x, y = float(to[0]), float(to[1])
        d = math.hypot(x - self.x, y - self.y)
        if not math.isfinite(d) or d > self.kind.max_speed * dt * (1 + 1e-6) + _EPS:
            raise ValueError(f"robot {self.id!r}: cannot drive {d:.3f} m in {dt:g} s "
                             f"(top speed {self.kind.max_speed:g} m/s)")
        if d <= 0:
            return 0.0
        self.vx, self.vy = (x - self.x) / dt, (y - self.y) / dt
        self.x, self.y = x, y
        return d

    def _point_at(self, s: float) -> Point:
        assert self.path is not None  # only called while following a timed path (from _track)
        S, wp = self._S, self.path.waypoints
        if s >= S[-1]:
            return float(wp[-1, 0]), float(wp[-1, 1])
        k = int(np.searchsorted(S, s, side="right")) - 1  # S[k] <= s < S[k + 1]: a real segment
        p = wp[k, :2] + (s - S[k]) / (S[k + 1] - S[k]) * (wp[k + 1, :2] - wp[k, :2])
        return float(p[0]), float(p[1])

    def _lateness(self, now: float) -> float:
        """``now`` minus the last time the schedule was still at or behind the robot's position."""
        S, T = self._S, self._T
        k = int(np.searchsorted(S, self._s + _EPS, side="right")) - 1
        if k >= len(S) - 1:
            return 0.0
        due = T[k] + (self._s - S[k]) / (S[k + 1] - S[k]) * (T[k + 1] - T[k])
        late = now - float(due)
        return late if late > _EPS else 0.0

    def _mode_now(self, moved: float) -> str:
        if self.battery <= 0.0:
            return "error"
        if self._action is not None:
            return "picking" if self._action[0] == "pick" else "placing"
        if moved > 0:
            return "driving"
        if self.path is not None and self._s < self._S[-1] - _EPS:
            return "waiting"
        if self._steered is not None and self._steered < 1.0:
            return "waiting"
        return "idle"

    def status(self, stamp: float) -> dict[str, Any]:
        """The robot's state as the fields of :class:`msg_schemas.records.RobotStatus`."""
        return {"id": self.id, "kind": self.kind.name, "x": self.x, "y": self.y, "yaw": self.yaw,
                "vx": self.vx, "vy": self.vy, "battery": self.battery, "mode": self.mode,
                "progress": self.progress, "stamp": float(stamp), "radius": self.kind.radius,
                "task_id": self.task_id, "path_id": self.path_id, "lateness_s": self.lateness_s}


class TrackBatch:
    """The path tracking of many robots worked out at once (numpy over robots): :meth:`prepare`
    computes, for every robot on a timed path, where :meth:`RobotModel.step` would take it over
    ``[t, t + dt]`` (the due arc length, the speed and acceleration limits, braking for the next
    halt, the point on the polyline) with the same arithmetic as :meth:`RobotModel._track`, and
    leaves it with the robot; the robot's own step then takes that result instead of working it
    out, if nothing it depends on changed in between (else it works it out itself). So a fleet
    stepped after :meth:`prepare` moves exactly as robots stepped one by one (the agent process of
    a real robot never prepares). The robots' paths are kept padded in arrays, refreshed when a
    robot gets a new one.
    """

    def __init__(self, models: Sequence[RobotModel]):
        self.models = list(models)
        n = len(self.models)
        self._paths: list[np.ndarray | None] = [None] * n   # the _T each row was filled from
        self._T = np.full((n, 1), math.inf)
        self._S = np.full((n, 1), math.inf)
        self._X = np.zeros((n, 1, 2))
        self._len = np.ones(n, dtype=np.intp)
        self._stop_s = np.full((n, 1), math.inf)
        self._stop_t = np.full((n, 1), -math.inf)

    def _refresh(self) -> None:
        changed = [i for i, m in enumerate(self.models) if m.path is not None and self._paths[i] is not m._T]
        if not changed:
            return
        width = max([self._T.shape[1]] + [len(self.models[i]._T) for i in changed])
        stops = max([self._stop_s.shape[1]] + [len(self.models[i]._stops) for i in changed])
        n = len(self.models)
        if width > self._T.shape[1]:
            pad = width - self._T.shape[1]
            self._T = np.hstack([self._T, np.full((n, pad), math.inf)])
            self._S = np.hstack([self._S, np.full((n, pad), math.inf)])
            self._X = np.concatenate([self._X, np.zeros((n, pad, 2))], axis=1)
        if stops > self._stop_s.shape[1]:
            pad = stops - self._stop_s.shape[1]
            self._stop_s = np.hstack([self._stop_s, np.full((n, pad), math.inf)])
            self._stop_t = np.hstack([self._stop_t, np.full((n, pad), -math.inf)])
        for i in changed:
            m = self.models[i]
            assert m.path is not None
            k, h = len(m._T), len(m._stops)
            self._T[i], self._S[i], self._stop_s[i], self._stop_t[i] = math.inf, math.inf, math.inf, -math.inf
            self._T[i, :k], self._S[i, :k], self._X[i, :k] = m._T, m._S, m.path.waypoints[:, :2]
            self._stop_s[i, :h], self._stop_t[i, :h] = m._stops[:, 0], m._stops[:, 1]
            self._len[i] = k
            self._paths[i] = m._T

    def prepare(self, t: Sequence[float | None], dt: Sequence[float]) -> None:
        """Work out each robot's tracking over ``[t[i], t[i] + dt[i]]``, as its
        ``step(t[i], dt[i])`` will be called (robots without a timed path, or with ``t[i]`` None or
        ``dt[i]`` not > 0, are left alone)."""
        rows = [i for i, m in enumerate(self.models) if m.path is not None and t[i] is not None and dt[i] > 0]
        if not rows:
            return
        self._refresh()
        idx = np.array(rows)
        dt_ = np.array([dt[i] for i in rows], dtype=float)
        end = np.array([t[i] for i in rows], dtype=float) + dt_
        ms = [self.models[i] for i in rows]
        s = np.array([m._s for m in ms])
        speed = np.array([m.speed for m in ms])
        vmax = np.array([m.kind.max_speed for m in ms])
        acc = np.array([m.kind.max_accel for m in ms])
        T, S, X, last = self._T[idx], self._S[idx], self._X[idx], self._len[idx] - 1
        r = np.arange(len(rows))
        # s_due = np.interp(end, T, S) row by row (np.interp's own arithmetic)
        c = np.count_nonzero(T <= end[:, None], axis=1)
        j = np.clip(c - 1, 0, np.maximum(last - 1, 0))
        j1 = np.minimum(j + 1, last)
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = (S[r, j1] - S[r, j]) / (T[r, j1] - T[r, j])
            mid = slope * (end - T[r, j]) + S[r, j]
        s_due = np.where(c == 0, S[:, 0], np.where(c > last, S[r, last], mid))
        v = np.minimum(np.maximum(0.0, (s_due - s) / dt_), vmax * (1 + _EPS))
        finite = np.isfinite(acc)
        with np.errstate(invalid="ignore"):
            v = np.where(finite, np.minimum(v, speed + acc * dt_), v)
            sel = (self._stop_s[idx] >= (s - _EPS)[:, None]) & (self._stop_t[idx] > end[:, None])
            nearest = np.where(sel, self._stop_s[idx], math.inf).min(axis=1)
            gap = np.maximum(0.0, nearest - s)
            brake = finite & sel.any(axis=1)
            v = np.where(brake, np.minimum(np.minimum(v, np.sqrt(2 * acc * gap)), gap / dt_), v)
        s_new = np.minimum(np.minimum(s + v * dt_, s_due), S[r, last])
        # the point at s_new on the polyline (RobotModel._point_at)
        k = np.clip(np.count_nonzero(S <= s_new[:, None], axis=1) - 1, 0, np.maximum(last - 1, 0))
        k1 = np.minimum(k + 1, last)
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = (s_new - S[r, k]) / (S[r, k1] - S[r, k])
            p = X[r, k] + frac[:, None] * (X[r, k1] - X[r, k])
        at_end = s_new >= S[r, last]
        p = np.where(at_end[:, None], X[r, last], p)
        for q, m in enumerate(ms):
            m._pre = (m._T, m.kind, float(end[q]), float(dt_[q]), m._s, m.speed, float(s_new[q]), float(p[q, 0]),
                      float(p[q, 1]))
