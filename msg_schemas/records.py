"""The JSON records carried in ``std_msgs/String`` on the fleet topics, versioned and validated.

Pure Python (no rclpy), so the planner core and offline tools can read and write them too.

Every record has a ``schema`` tag (``fleet/<name>@<version>``), ``to_json()`` / ``to_dict()`` and
the classmethods ``from_json(text)`` / ``from_dict(data)``. Construction validates every field, so a
record that exists is a valid one. Anything wrong raises :class:`RecordError` whose message starts
with the path of the offending field, e.g. ``task.deadline: unknown field`` or
``schedule.links[2].M: must be a finite number (got NaN)``. Unknown fields, missing required
fields, NaN and infinities, and wrong types (``true`` is not a number) are all rejected. Optional
fields may be absent or ``null`` and are left out of the JSON when unset.

Only the schema is checked here; whether a station or robot exists is the planner's business.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, Callable, ClassVar, Mapping

from fleet_planner.model import CAPABILITIES, ROBOT_KINDS, STATUS_MODES, Behavior

BEHAVIORS = tuple(b.value for b in Behavior)
TASK_EVENTS = ("accepted", "rejected", "assigned", "picked", "placed", "done", "failed", "cancelled")
EVENTS_NEEDING_REASON = ("rejected", "failed")

_ROS_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class RecordError(ValueError):
    """A record that does not fit its schema; the message starts with the field's path."""


def robot_id_problem(robot_id: object) -> str | None:
    """Why ``robot_id`` cannot name a robot (it must fit in a ROS topic name), or None if it can."""
    if not isinstance(robot_id, str):
        return f"must be a string (got {_show(robot_id)})"
    if not _ROS_TOKEN.fullmatch(robot_id):
        return ("must be letters, digits and '_' only, not starting with a digit, so that it can be "
                f"part of a ROS topic name (got {robot_id!r})")
    return None


# -- a tiny declarative field-spec vocabulary ----------------------------------------------------
# A check takes (value, path) and returns the normalised value or raises RecordError(path: why).
Check = Callable[[Any, str], Any]


def _show(value: object) -> str:
    """A value as the sender wrote it in JSON, short enough for an error message."""
    if isinstance(value, float) and not math.isfinite(value):
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    if value is None or isinstance(value, bool):
        return json.dumps(value)
    text = repr(value) if isinstance(value, (str, int, float)) else type(value).__name__
    return text if len(text) <= 60 else text[:57] + "..."


def number(lo: float = -math.inf, hi: float = math.inf) -> Check:
    """A finite float in [lo, hi] (ints are accepted and converted; bools are not numbers)."""
    def check(value: Any, path: str) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise RecordError(f"{path}: must be a finite number (got {_show(value)})")
        if not lo <= value <= hi:
            bounds = f">= {lo:g}" if hi == math.inf else f"in [{lo:g}, {hi:g}]"
            raise RecordError(f"{path}: must be {bounds} (got {_show(value)})")
        return float(value)
    return check


def integer(lo: int | None = None) -> Check:
    def check(value: Any, path: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise RecordError(f"{path}: must be an integer (got {_show(value)})")
        if lo is not None and value < lo:
            raise RecordError(f"{path}: must be >= {lo} (got {value})")
        return value
    return check


def nonempty(value: Any, path: str) -> str:
    """A non-empty string."""
    if not isinstance(value, str) or not value.strip():
        raise RecordError(f"{path}: must be a non-empty string (got {_show(value)})")
    return value


def ros_id(value: Any, path: str) -> str:
    problem = robot_id_problem(value)
    if problem:
        raise RecordError(f"{path}: {problem}")
    return value


def choice(options: tuple[str, ...]) -> Check:
    def check(value: Any, path: str) -> str:
        if not isinstance(value, str) or value not in options:
            raise RecordError(f"{path}: must be one of {', '.join(options)} (got {_show(value)})")
        return value
    return check


def boolean(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise RecordError(f"{path}: must be true or false (got {_show(value)})")
    return value


def point(value: Any, path: str) -> tuple[float, float]:
    """A list ``[x, y]`` of two finite numbers."""
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise RecordError(f"{path}: must be a list [x, y] (got {_show(value)})")
    return tuple(number()(v, f"{path}[{i}]") for i, v in enumerate(value))


def optional(inner: Check) -> Check:
    """``None`` (absent or JSON null) or whatever ``inner`` accepts."""
    return lambda value, path: None if value is None else inner(value, path)


def list_of(item: Check, unique: bool = False) -> Check:
    def check(value: Any, path: str) -> tuple:
        if not isinstance(value, (list, tuple)):
            raise RecordError(f"{path}: must be a list (got {_show(value)})")
        out = tuple(item(v, f"{path}[{i}]") for i, v in enumerate(value))
        if unique and len(set(out)) != len(out):
            dup = next(v for i, v in enumerate(out) if v in out[:i])
            raise RecordError(f"{path}: {dup!r} appears more than once")
        return out
    return check


def _mapping(value: Any, path: str) -> Mapping:
    if not isinstance(value, Mapping):
        raise RecordError(f"{path}: must be a JSON object (got {_show(value)})")
    return value


def obj(spec: dict[str, Check]) -> Check:
    """A JSON object with exactly the keys of ``spec``; returns a plain dict of checked values."""
    def check(value: Any, path: str) -> dict:
        _exact_keys(_mapping(value, path), spec, set(spec), path)
        return {k: c(value[k], f"{path}.{k}") for k, c in spec.items()}
    return check


def dict_of(item: Check) -> Check:
    """A JSON object with non-empty string keys and values checked by ``item``."""
    def check(value: Any, path: str) -> dict:
        out = {}
        for k, v in _mapping(value, path).items():
            nonempty(k, f"{path} key")
            out[k] = item(v, f"{path}[{k!r}]")
        return out
    return check


def _exact_keys(data: Mapping, known: Mapping, required: set[str], path: str) -> None:
    unknown = [k for k in data if k not in known]
    if unknown:
        raise RecordError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(known)})")
    for name in known:
        if name in required and name not in data:
            raise RecordError(f"{path}.{name}: required field missing")


def spec(check: Check, default: Any = MISSING) -> Any:
    """Declare a record field: its check, and its default if it is optional."""
    return field(default=default, metadata={"check": check})


def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict:
    out = {}
    for k, v in pairs:
        if k in out:
            raise RecordError(f"duplicate key {k!r} in a JSON object")
        out[k] = v
    return out


# -- the record base -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Record:
    """Base of the wire records: fields declared with :func:`spec`, validated on construction."""

    SCHEMA: ClassVar[str]
    NAME: ClassVar[str]  # the prefix of every error path

    def __post_init__(self) -> None:
        for f in fields(self):
            value = f.metadata["check"](getattr(self, f.name), f"{self.NAME}.{f.name}")
            object.__setattr__(self, f.name, value)
        self._check_together()

    def _check_together(self) -> None:
        """Rules that involve several fields (none by default)."""

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"schema": self.SCHEMA}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                out[f.name] = _plain(value)
        return out

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), allow_nan=False, separators=(",", ":"))

    @classmethod
    def from_dict(cls, data: Any) -> "Record":
        data = _mapping(data, cls.NAME)
        schema = data.get("schema", MISSING)
        if schema is MISSING:
            raise RecordError(f"{cls.NAME}.schema: required field missing (expected {cls.SCHEMA!r})")
        if schema != cls.SCHEMA:
            raise RecordError(f"{cls.NAME}.schema: expected {cls.SCHEMA!r} (got {_show(schema)})")
        own = {f.name: f for f in fields(cls)}
        required = {n for n, f in own.items() if f.default is MISSING}
        _exact_keys(data, {"schema": None, **own}, required, cls.NAME)
        return cls(**{k: v for k, v in data.items() if k != "schema"})

    @classmethod
    def from_json(cls, text: str | bytes) -> "Record":
        try:
            data = json.loads(text, object_pairs_hook=_reject_duplicates)
        except RecordError as exc:
            raise RecordError(f"{cls.NAME}: {exc}") from None
        except (ValueError, TypeError) as exc:
            raise RecordError(f"{cls.NAME}: not valid JSON ({exc})") from None
        return cls.from_dict(data)


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


# -- the records -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Task(Record):
    """A transport job from the intelligent space: pick at a chute, place at a storing site."""

    SCHEMA: ClassVar[str] = "fleet/task@1"
    NAME: ClassVar[str] = "task"

    id: str = spec(nonempty)
    pick: str = spec(nonempty)                 # station name
    place: str = spec(nonempty)                # address tag or station name
    needs: tuple[str, ...] = spec(list_of(choice(CAPABILITIES), unique=True), default=())
    payload_kg: float = spec(number(lo=0.0), default=0.0)
    priority: int = spec(integer(), default=0)
    created: float | None = spec(optional(number()), default=None)


@dataclass(frozen=True)
class TaskEvent(Record):
    """What happened to a task; ``reason`` is required for ``rejected`` and ``failed``."""

    SCHEMA: ClassVar[str] = "fleet/task_event@1"
    NAME: ClassVar[str] = "task_event"

    task_id: str = spec(nonempty)
    event: str = spec(choice(TASK_EVENTS))
    stamp: float = spec(number())
    robot_id: str | None = spec(optional(ros_id), default=None)
    reason: str | None = spec(optional(nonempty), default=None)

    def _check_together(self) -> None:
        if self.event in EVENTS_NEEDING_REASON and self.reason is None:
            raise RecordError(f"task_event.reason: required when event is {self.event!r}")


#: ``robot_status.behavior``: a behaviour-coordinated robot's BBMRCA state, what the others' traffic
#: rules need (``fleet_planner.behavior.RobotView``): its behaviour, where its path goes next
#: (null: it stands), the length of the rest of its path and of the straight run ahead (m), the
#: station it is bound for, the robot its behaviour is about, whether its Avoid / Exchange finds no
#: room, the station it docks at and since when it asked to (s, ROS time). Every key is required
#: (null where there is nothing).
BEHAVIOR_STATE: dict[str, Check] = {
    "name": choice(BEHAVIORS), "next": optional(point), "remaining": number(lo=0.0),
    "straight": number(lo=0.0), "station": optional(nonempty), "partner": optional(ros_id),
    "no_space": boolean, "docked_at": optional(nonempty), "dock_since": optional(number())}


@dataclass(frozen=True)
class RobotStatus(Record):
    """A robot's state as its agent reports it (pose, velocity, battery, mode, schedule progress;
    in behaviour coordination also its BBMRCA state)."""

    SCHEMA: ClassVar[str] = "fleet/robot_status@1"
    NAME: ClassVar[str] = "robot_status"

    id: str = spec(ros_id)
    kind: str = spec(choice(ROBOT_KINDS))
    x: float = spec(number())
    y: float = spec(number())
    yaw: float = spec(number())
    vx: float = spec(number())
    vy: float = spec(number())
    battery: float = spec(number(0.0, 1.0))   # fraction of full charge
    mode: str = spec(choice(STATUS_MODES))
    progress: float = spec(number(0.0, 1.0))  # fraction of the current timed path's length driven
    stamp: float = spec(number())
    radius: float = spec(number(lo=0.0))
    task_id: str | None = spec(optional(nonempty), default=None)
    path_id: int | None = spec(optional(integer(lo=0)), default=None)  # which timed path it follows
    lateness_s: float = spec(number(lo=0.0), default=0.0)  # how far behind its due position
    # robots coordinating by behaviours (paper 002) broadcast their BBMRCA state: see BEHAVIOR_STATE
    behavior: dict[str, Any] | None = spec(optional(obj(BEHAVIOR_STATE)), default=None)


@dataclass(frozen=True)
class Schedule(Record):
    """The (M,D) collision model of a plan (paper 001 Table 2) for tools and monitors.

    ``nodes`` maps robot ids to their delayed departure and pure travel time, ``priority`` lists
    every node id from highest to lowest priority, and each link is a collision region
    ``(i, j, k)`` with its characteristics ``M``, ``D`` and collision box: times ``ks..ke`` and
    travelled lengths ``ls..le``.
    """

    SCHEMA: ClassVar[str] = "fleet/schedule@1"
    NAME: ClassVar[str] = "schedule"

    plan_id: int = spec(integer(lo=0))
    stamp: float = spec(number())
    priority: tuple[str, ...] = spec(list_of(nonempty, unique=True))
    nodes: dict[str, dict[str, float]] = spec(dict_of(obj({"delay": number(lo=0.0),
                                                          "travel": number(lo=0.0)})))
    links: tuple[dict[str, Any], ...] = spec(list_of(obj({
        "i": nonempty, "j": nonempty, "k": integer(lo=1), "M": number(), "D": number(),
        "ks": number(), "ke": number(), "ls": number(), "le": number()})), default=())

    def _check_together(self) -> None:
        if set(self.priority) != set(self.nodes):
            missing = sorted(set(self.nodes) - set(self.priority))
            extra = sorted(set(self.priority) - set(self.nodes))
            raise RecordError("schedule.priority: must list every node exactly once "
                              f"(missing {missing}, not a node {extra})")
        for n, link in enumerate(self.links):
            where = f"schedule.links[{n}]"
            for end in ("i", "j"):
                if link[end] not in self.nodes:
                    raise RecordError(f"{where}.{end}: {link[end]!r} is not a node")
            if link["i"] == link["j"]:
                raise RecordError(f"{where}.j: a link joins two different robots (both {link['i']!r})")
            for lo, hi in (("ks", "ke"), ("ls", "le")):
                if link[lo] > link[hi]:
                    raise RecordError(f"{where}.{hi}: must be >= {lo} ({link[hi]:g} < {link[lo]:g})")


@dataclass(frozen=True)
class WaitMessageRecord(Record):
    """A BBMRCA wait message (paper 002, IV.C) on its way from a waiting robot to the robot it waits
    for: ``waiting`` lists the waiting robots it went through, the first sender first and this
    sender last. A robot that finds its own id in it has found a wait cycle."""

    SCHEMA: ClassVar[str] = "fleet/wait_message@1"
    NAME: ClassVar[str] = "wait_message"

    sender: str = spec(ros_id)
    receiver: str = spec(ros_id)
    waiting: tuple[str, ...] = spec(list_of(ros_id, unique=True))
    stamp: float = spec(number())

    def _check_together(self) -> None:
        if not self.waiting or self.waiting[-1] != self.sender:
            raise RecordError(f"wait_message.waiting: must end with the sender {self.sender!r} "
                              f"(got {list(self.waiting)})")
        if self.receiver == self.sender:
            raise RecordError(f"wait_message.receiver: a robot does not wait for itself ({self.sender!r})")


RECORDS: tuple[type[Record], ...] = (Task, TaskEvent, RobotStatus, Schedule, WaitMessageRecord)
