"""The JSON records carried in ``std_msgs/String`` on the fleet topics, versioned and validated.

Pure Python (no rclpy), so the planner core and offline tools can read and write them too.

Every record has a ``schema`` tag (``fleet/<name>@<version>``), ``to_json()`` / ``to_dict()`` and
the classmethods ``from_json(text)`` / ``from_dict(data)``. Construction validates every field, so a
record that exists is a valid one. Anything wrong raises :class:`RecordError` whose message starts
with the path of the offending field, e.g. ``task.deadline: unknown field`` or
``schedule.links[2].M: must be a finite number (got NaN)``. Unknown fields, missing required
fields, NaN and infinities, and wrong types (``true`` is not a number) are all rejected. Optional
fields may be absent or ``null`` and are left out of the JSON when unset.

Parsing is total: whatever the input (any bytes, any text, any object handed to ``from_dict``),
``from_json`` / ``from_dict`` return a record or raise :class:`RecordError`, nothing else, and the
error's message is bounded (:data:`MAX_REASON_CHARS`) and printable (control characters and lone
surrogates escaped), so that it can always be logged and sent back. The limits that keep absurd
input out (docs/ARCHITECTURE.md, "Wire records": strings bounded): :data:`MAX_RECORD_BYTES` of raw
message, :data:`MAX_DEPTH` levels of nesting, :data:`MAX_NAME_CHARS` per id or name,
:data:`MAX_TEXT_CHARS` per free text, :data:`MAX_ITEMS` per list or object, integers of at most 64
bits (:data:`MAX_INT_DIGITS` digits in the JSON). Ids and names must be printable.

Only the schema is checked here; whether a station or robot exists is the planner's business. The
fields are declared with the vocabulary of :mod:`fleet_planner.validation` (values shown as JSON
spells them); the contract is in docs/ARCHITECTURE.md, "Wire records".

BBMRCA is the behaviour-based coordination of Sun, Kleiner and Nebel, "Behavior-based Multi-Robot
Collision Avoidance" (ICRA 2014); the (M,D) model is that of You and Ji, "Design of a Multi-robot
Bin Packing System in an Automatic Warehouse".
"""
from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, fields, replace
from typing import Any, ClassVar

from fleet_planner.model import CAPABILITIES, ROBOT_KINDS, STATUS_MODES, Behavior
from fleet_planner.validation import (
    Check,
    ValidationError,
    Vocabulary,
    all_of,
    check_fields,
    optional,
    printable,
    robot_id_problem,
    show_json,
    spec,
)

BEHAVIORS = tuple(b.value for b in Behavior)
TASK_EVENTS = ("accepted", "rejected", "assigned", "picked", "placed", "done", "failed", "cancelled", "late")
EVENTS_NEEDING_REASON = ("rejected", "failed", "late")


#: the largest raw message taken (bytes of UTF-8; a status is about 400, a 1000-robot schedule 60k)
MAX_RECORD_BYTES = 256 * 1024
#: the deepest nesting of JSON arrays and objects taken (the records need 3: schedule.links[i].M)
MAX_DEPTH = 16
#: the longest id or name (task ids, stations, address tags, robot ids)
MAX_NAME_CHARS = 128
#: the longest free text (a task event's reason)
MAX_TEXT_CHARS = 1000
#: the most items in one list or object
MAX_ITEMS = 10_000
#: the most digits of an integer in the JSON (an int64 has 19)
MAX_INT_DIGITS = 20
#: integers are int64 (stamps in nanoseconds fit)
INT_MIN, INT_MAX = -(2 ** 63), 2 ** 63 - 1
#: the longest error message (a reason never echoes more than a short prefix of the input)
MAX_REASON_CHARS = 300


class RecordError(ValidationError):
    """A record that does not fit its schema; the message starts with the field's path. The
    message (and path and reason) are printable and at most :data:`MAX_REASON_CHARS` long."""

    def __init__(self, message: str, path: str | None = None, reason: str | None = None) -> None:
        super().__init__(printable(str(message), MAX_REASON_CHARS),
                         None if path is None else printable(str(path), MAX_REASON_CHARS),
                         None if reason is None else printable(str(reason), MAX_REASON_CHARS))


# -- the records' words for the field vocabulary (fleet_planner.validation) ---------------------
# A check takes (value, path) and returns the normalised value or raises RecordError(path: why);
# values are shown as JSON spells them (NaN, true, null).
_V = Vocabulary(RecordError, show=show_json, mappings=(Mapping,), lists=(list, tuple),
                not_mapping="must be a JSON object (got {got})", unknown="unknown field (known: {known})",
                missing="required field missing")

number = _V.number            # number(lo, hi): a finite float in [lo, hi]
nonempty = _V.string(min_len=1, max_len=MAX_NAME_CHARS, strip=True, printable_only=True)  # an id or name
text = _V.string(min_len=1, max_len=MAX_TEXT_CHARS, strip=True, printable_only=True)      # free text
ros_id = all_of(_V.ros_id, _V.string(max_len=MAX_NAME_CHARS))  # fits in a ROS topic name
choice = _V.choice            # choice(options)
boolean = _V.boolean
point = _V.point              # [x, y]


def integer(lo: int | None = None) -> Check[int]:
    """An int64 ``>= lo`` (if given)."""
    return _V.integer(INT_MIN if lo is None else lo, INT_MAX)


def list_of(item: Check[Any], unique: bool = False) -> Check[tuple[Any, ...]]:
    """A list of at most :data:`MAX_ITEMS` items, each checked by ``item``; ``unique``: none twice."""
    return _V.list_of(item, unique=unique, max_len=MAX_ITEMS)


def dict_of(item: Check[Any]) -> Check[dict[str, Any]]:
    """An object of at most :data:`MAX_ITEMS` entries with id-like keys, each value checked by ``item``."""
    return _V.dict_of(item, key=nonempty, max_len=MAX_ITEMS)


def obj(members: dict[str, Check[Any]]) -> Check[dict[str, Any]]:
    """A JSON object with exactly the keys of ``members``; returns a plain dict of checked values."""
    return _V.mapping(members)


def _reject_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = {}
    for k, v in pairs:
        if k in out:
            raise RecordError(f"duplicate key {show_json(k)} in a JSON object")
        out[k] = v
    return out


def _parse_int(digits: str) -> int:
    if len(digits.lstrip("-")) > MAX_INT_DIGITS:
        raise RecordError(f"an integer of {len(digits.lstrip('-'))} digits (at most {MAX_INT_DIGITS})")
    return int(digits)


_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_BRACKETS = re.compile(r"[\[\]{}]")


def _too_deep(text: str) -> bool:
    """Whether ``text`` nests arrays and objects more than :data:`MAX_DEPTH` deep (outside its
    strings), found before parsing, so the parser never recurses that far."""
    if text.count("[") + text.count("{") <= MAX_DEPTH:
        return False
    depth = 0
    for m in _BRACKETS.finditer(_STRINGS.sub('""', text)):
        depth += 1 if m.group() in "[{" else -1
        if depth > MAX_DEPTH:
            return True
    return False


def load_json(raw: Any, name: str = "record") -> Any:
    """The JSON value in ``raw`` (text or UTF-8 bytes) within the limits above, or
    ``RecordError("<name>: ...")``; never any other exception."""
    if isinstance(raw, (bytes, bytearray, memoryview)):
        if len(raw) > MAX_RECORD_BYTES:
            raise RecordError(f"{name}: message too long ({len(raw)} bytes, at most {MAX_RECORD_BYTES})")
        try:
            raw = bytes(raw).decode("utf-8")
        except UnicodeDecodeError as exc:
            raise RecordError(f"{name}: not valid JSON (not UTF-8: {exc.reason} at byte {exc.start})") from None
    if not isinstance(raw, str):
        raise RecordError(f"{name}: must be JSON text (got {type(raw).__name__})")
    if len(raw) > MAX_RECORD_BYTES:  # characters: at least as many bytes
        raise RecordError(f"{name}: message too long ({len(raw)} characters, at most {MAX_RECORD_BYTES})")
    if _too_deep(raw):
        raise RecordError(f"{name}: not valid JSON (nested more than {MAX_DEPTH} levels deep)")
    try:
        return json.loads(raw, object_pairs_hook=_reject_duplicates, parse_int=_parse_int)
    except RecordError as exc:
        raise RecordError(f"{name}: {exc}") from None
    except RecursionError:
        raise RecordError(f"{name}: not valid JSON (nested too deeply)") from None
    except (ValueError, TypeError, OverflowError) as exc:
        raise RecordError(f"{name}: not valid JSON ({exc})") from None


# -- the record base -----------------------------------------------------------------------------
@dataclass(frozen=True)
class Record:
    """Base of the wire records: fields declared with :func:`spec`, validated on construction."""

    SCHEMA: ClassVar[str]
    NAME: ClassVar[str]  # the prefix of every error path

    def __post_init__(self) -> None:
        check_fields(self, self.NAME)
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
    def from_dict(cls, data: Any) -> Record:
        """The record in ``data`` (a mapping as JSON decodes it); RecordError and nothing else."""
        try:
            return cls._from_dict(data)
        except RecordError:
            raise
        except (RecursionError, MemoryError):
            raise RecordError(f"{cls.NAME}: too large or nested too deeply") from None
        except Exception as exc:  # noqa: BLE001 - totality: any input is a record or a RecordError
            raise RecordError(f"{cls.NAME}: cannot be read ({type(exc).__name__}: {exc})") from None

    @classmethod
    def _from_dict(cls, data: Any) -> Record:
        data = _V.as_mapping(data, cls.NAME)
        schema = data.get("schema", MISSING)
        if schema is MISSING:
            raise RecordError(f"{cls.NAME}.schema: required field missing (expected {cls.SCHEMA!r})")
        if schema != cls.SCHEMA:
            raise RecordError(f"{cls.NAME}.schema: expected {cls.SCHEMA!r} (got {show_json(schema)})")
        own = fields(cls)
        required = [f.name for f in own if f.default is MISSING]
        _V.keys(data, cls.NAME, ["schema", *(f.name for f in own)], required)
        return cls(**{k: v for k, v in data.items() if k != "schema"})

    @classmethod
    def from_json(cls, text: str | bytes) -> Record:
        """The record in JSON ``text`` (str or UTF-8 bytes); RecordError and nothing else."""
        return cls.from_dict(load_json(text, cls.NAME))


def _plain(value: Any) -> Any:
    if isinstance(value, Record):
        return value.to_dict()
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


#: ``auth``: a shared-key signature of the record (fleet_planner/auth.py says how it is made and
#: checked): the key's id, the signer's counter and the HMAC-SHA256 in hex
AUTH: dict[str, Check] = {"key": nonempty, "ctr": integer(lo=0),
                          "mac": _V.string(min_len=64, max_len=64, pattern=re.compile(r"[0-9a-f]+"))}


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
    auth: dict[str, Any] | None = spec(optional(obj(AUTH)), default=None)  # signature (with keys)
    # when it should be done (s, the planner's ROS time); earliest first among equal priorities,
    # and a ``late`` event when it passes (fleet_planner.fleet.operator)
    deadline: float | None = spec(optional(number()), default=None)


@dataclass(frozen=True)
class TaskEvent(Record):
    """What happened to a task; ``reason`` is required for ``rejected`` and ``failed``."""

    SCHEMA: ClassVar[str] = "fleet/task_event@1"
    NAME: ClassVar[str] = "task_event"

    task_id: str = spec(nonempty)
    event: str = spec(choice(TASK_EVENTS))
    stamp: float = spec(number())
    robot_id: str | None = spec(optional(ros_id), default=None)
    reason: str | None = spec(optional(text), default=None)
    auth: dict[str, Any] | None = spec(optional(obj(AUTH)), default=None)  # signature (with keys)

    def _check_together(self) -> None:
        if self.event in EVENTS_NEEDING_REASON and self.reason is None:
            raise RecordError(f"task_event.reason: required when event is {self.event!r}")


#: ``robot_status.behavior``: a behaviour-coordinated robot's BBMRCA state, what the others' traffic
#: rules need (``fleet_planner.behavior.RobotView``): its behaviour, where its path goes next
#: (null: it stands), the length of the rest of its path and of the straight run ahead (m), the
#: station it is bound for, the robot its behaviour is about, whether its Avoid / Exchange finds no
#: room, the station it docks at and since when it asked to (s, ROS time), and the retreat wave it
#: backs out in (``{"since": s, "by": founder id}``). Every key but ``retreat`` (null if absent:
#: statuses from before it) is required (null where there is nothing).
BEHAVIOR_STATE: dict[str, Check] = {
    "name": choice(BEHAVIORS), "next": optional(point), "remaining": number(lo=0.0),
    "straight": number(lo=0.0), "station": optional(nonempty), "partner": optional(ros_id),
    "no_space": boolean, "docked_at": optional(nonempty), "dock_since": optional(number()),
    "retreat": optional(obj({"since": number(), "by": ros_id}))}


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
    # robots coordinating by behaviours (BBMRCA) broadcast their behaviour state: see BEHAVIOR_STATE
    behavior: dict[str, Any] | None = spec(optional(_V.mapping(BEHAVIOR_STATE, defaults={"retreat": None})),
                                           default=None)
    # the operator's hand (fleet_planner.fleet.manual): driven by cmd_vel / stopped by the e-stop
    # (left out when false)
    manual: bool | None = spec(optional(boolean), default=None)
    estop: bool | None = spec(optional(boolean), default=None)
    # added later (optional, so statuses without them still parse): the length (m) driven along
    # path_id, which gated robots watch (fleet_planner/fleet/gate.py), and the last timed path the
    # robot could not take (the planner re-plans it rather than assume the robot drives it)
    travelled_m: float | None = spec(optional(number(lo=0.0)), default=None)
    rejected_path_id: int | None = spec(optional(integer(lo=0)), default=None)
    # whether it carries the goods of task_id (the robot's word that a pick or place is done)
    loaded: bool | None = spec(optional(boolean), default=None)
    # the last job whose goods it placed (the robot's word that the place is done, kept until it
    # places again): a planner restarted after the place counts the job done from it, exactly once
    placed_task_id: str | None = spec(optional(nonempty), default=None)

    #: the compact form of the same record (:meth:`to_compact_json`), read by the same parser
    COMPACT_SCHEMA: ClassVar[str] = "fleet/robot_status@2"

    def __post_init__(self) -> None:
        # check_fields' checks in its order, but values the check would return unchanged skip it:
        # floats in range, ids and booleans of the right type, null in an optional field, and
        # strings already checked (a status is built 10 times a second per robot)
        for name, check, path, lo, hi, none_ok, fast in _status_checks():
            value = getattr(self, name)
            kind = type(value)
            if kind is float:
                if lo <= value <= hi and _isfinite(value):
                    continue
            elif value is None:
                if none_ok:
                    continue
            elif kind is str:
                known = _STATUS_STRINGS.get((name, value))
                if known is None:
                    known = check(value, path)
                    if len(_STATUS_STRINGS) < _MAX_STATUS_STRINGS:
                        _STATUS_STRINGS[(name, value)] = known
                object.__setattr__(self, name, known)
                continue
            elif kind is bool:
                if fast == "bool":
                    continue
            elif kind is int and fast == "path_id" and 0 <= value <= INT_MAX:
                continue
            object.__setattr__(self, name, check(value, path))
        self._check_together()

    def to_compact_json(self) -> str:
        """This status as ``fleet/robot_status@2``: ``{"schema", "id", "v": [...]}``, the other fields
        by position in the order of :data:`COMPACT_FIELDS` (trailing nulls left out), numbers
        rounded (:data:`COMPACT_ROUNDING`). About half the bytes of :meth:`to_json` and several
        times faster to write and read; :meth:`from_json` reads both forms."""
        v = [f'"{self.kind}",{self.x:.4f},{self.y:.4f},{self.yaw:.4f},{self.vx:.4f},{self.vy:.4f},'
             f'{self.battery:.6f},"{self.mode}",{_floor(self.progress, 6)},{self.stamp!r},{self.radius!r}',
             "null" if self.task_id is None else json.dumps(self.task_id),
             "null" if self.path_id is None else str(self.path_id), f"{self.lateness_s:.3f}",
             "null" if self.behavior is None else json.dumps(_plain(self.behavior), allow_nan=False,
                                                             separators=(",", ":")),
             _json_flag(self.manual), _json_flag(self.estop),
             "null" if self.travelled_m is None else _floor(self.travelled_m, 4),
             "null" if self.rejected_path_id is None else str(self.rejected_path_id), _json_flag(self.loaded),
             "null" if self.placed_task_id is None else json.dumps(self.placed_task_id)]
        while v[-1] == "null":
            v.pop()
        return f'{{"schema":"{self.COMPACT_SCHEMA}","id":"{self.id}","v":[{",".join(v)}]}}'

    @classmethod
    def _from_dict(cls, data: Any) -> Record:
        data = _V.as_mapping(data, cls.NAME)
        if data.get("schema") != cls.COMPACT_SCHEMA:
            return super()._from_dict(data)
        _V.keys(data, cls.NAME, ("schema", "id", "v"), ("schema", "id", "v"))
        values = data["v"]
        if not isinstance(values, (list, tuple)) or not _COMPACT_REQUIRED <= len(values) <= len(COMPACT_FIELDS):
            raise RecordError.at(f"{cls.NAME}.v", f"must be a list of {_COMPACT_REQUIRED} to {len(COMPACT_FIELDS)} "
                                                  f"values (got {show_json(values)})")
        # each value checked as the field it stands for (errors name the field: robot_status.x)
        return cls(id=data["id"], **dict(zip(COMPACT_FIELDS, values)))


#: the fields of ``fleet/robot_status@2`` after ``id``, by position; the first
#: :data:`_COMPACT_REQUIRED` are required, the others may be null or left out at the end
COMPACT_FIELDS = ("kind", "x", "y", "yaw", "vx", "vy", "battery", "mode", "progress", "stamp", "radius",
                  "task_id", "path_id", "lateness_s", "behavior", "manual", "estop", "travelled_m",
                  "rejected_path_id", "loaded", "placed_task_id")
_COMPACT_REQUIRED = 11
#: how ``fleet/robot_status@2`` rounds (decimals): positions, heading and velocity to 0.1 mm (rad,
#: mm/s), battery to 1e-6, lateness to 1 ms; progress and travelled_m are rounded down (a robot
#: never reports itself further along, or arrived, before it is); stamp and radius are exact
COMPACT_ROUNDING = {"x": 4, "y": 4, "yaw": 4, "vx": 4, "vy": 4, "battery": 6, "progress": 6, "lateness_s": 3,
                    "travelled_m": 4}
# the float fields of a status with the bounds of their checks (the fast path of __post_init__;
# test_msg_schemas checks that these are the checks' bounds)
_STATUS_FLOATS = {"x": (-math.inf, math.inf), "y": (-math.inf, math.inf), "yaw": (-math.inf, math.inf),
                  "vx": (-math.inf, math.inf), "vy": (-math.inf, math.inf), "battery": (0.0, 1.0),
                  "progress": (0.0, 1.0), "stamp": (-math.inf, math.inf), "radius": (0.0, math.inf),
                  "lateness_s": (0.0, math.inf), "travelled_m": (0.0, math.inf)}
#: fields whose values of a type skip their check: ids (ints in [0, INT_MAX]) and booleans
_STATUS_TYPED = {"path_id": "path_id", "rejected_path_id": "path_id", "manual": "bool", "estop": "bool",
                 "loaded": "bool"}
_STATUS_CHECKS: list[tuple[str, Check, str, float, float, bool, str]] = []
_STATUS_STRINGS: dict[tuple[str, str], str] = {}   # (field, string) -> what its check returned
_MAX_STATUS_STRINGS = 10_000
_isfinite = math.isfinite


def _none_ok(check: Check, path: str) -> bool:
    try:
        return check(None, path) is None
    except RecordError:
        return False


def _status_checks() -> list[tuple[str, Check, str, float, float, bool, str]]:
    """(field, check, path, float bounds, whether null passes, typed fast path) of every field of
    RobotStatus, in declaration order; fields that are no floats get empty bounds (inf, -inf)."""
    if not _STATUS_CHECKS:
        for f in fields(RobotStatus):
            if "check" in f.metadata:
                check, path = f.metadata["check"], f"{RobotStatus.NAME}.{f.name}"
                _STATUS_CHECKS.append((f.name, check, path, *_STATUS_FLOATS.get(f.name, (math.inf, -math.inf)),
                                       _none_ok(check, path), _STATUS_TYPED.get(f.name, "")))
    return _STATUS_CHECKS


def _floor(value: float, decimals: int) -> str:
    """``value`` rounded down to ``decimals``, as JSON."""
    scale = 10 ** decimals
    k = math.floor(value * scale)
    if k / scale > value:  # value * scale rounded up
        k -= 1
    return f"{k / scale:.{decimals}f}"


def _json_flag(value: bool | None) -> str:
    return "null" if value is None else ("true" if value else "false")


@dataclass(frozen=True)
class Schedule(Record):
    """The (M,D) collision model of a plan (You and Ji, Table 2) for tools and monitors.

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
    """A BBMRCA wait message (Sun, Kleiner and Nebel, section IV.C) on its way from a waiting robot
    to the robot it waits for: ``waiting`` lists the waiting robots it went through, the first
    sender first and this sender last. A robot that finds its own id in it has found a wait cycle."""

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


@dataclass(frozen=True)
class PathAuth(Record):
    """The signature of a timed path (``/robots/<id>/timed_path_auth``, beside the path, which as a
    ``nav_msgs/Path`` has no room for one): which path (its header stamp in ns), its SHA-256
    digest (fleet_planner/ros/signing.py) and the signature of this record."""

    SCHEMA: ClassVar[str] = "fleet/path_auth@1"
    NAME: ClassVar[str] = "path_auth"

    robot_id: str = spec(ros_id)
    path_id: int = spec(integer())
    digest: str = spec(_V.string(min_len=64, max_len=64, pattern=re.compile(r"[0-9a-f]+")))
    auth: dict[str, Any] | None = spec(optional(obj(AUTH)), default=None)


def unsigned_json(rec: Record) -> str:
    """What a record's signature covers: its JSON without ``auth``."""
    if getattr(rec, "auth", None) is None:
        return rec.to_json()
    return replace(rec, auth=None).to_json()  # type: ignore[call-arg]  # (the signed records have auth)


#: the most statuses one neighbours record carries
MAX_NEIGHBOURS = 512


def _status(value: Any, path: str) -> RobotStatus:
    """A robot status inside another record (its errors prefixed with ``path``)."""
    if isinstance(value, RobotStatus):
        return value
    try:
        return RobotStatus._from_dict(value)  # type: ignore[return-value]
    except RecordError as exc:
        raise RecordError(f"{path}: {exc}") from None


@dataclass(frozen=True)
class Neighbours(Record):
    """What the planner relays to one robot (``id``): the last statuses of the robots within its
    safety range and of those its execution gate watches (``fleet_planner.fleet.neighbours``)."""

    SCHEMA: ClassVar[str] = "fleet/neighbours@1"
    NAME: ClassVar[str] = "neighbours"

    id: str = spec(ros_id)
    stamp: float = spec(number())
    robots: tuple[RobotStatus, ...] = spec(_V.list_of(_status, max_len=MAX_NEIGHBOURS))


#: ``command.command``: what the operator asks the planner (fleet_planner.fleet.operator)
COMMANDS = ("pause", "resume", "estop", "release", "cancel", "priority", "send")
#: the fields each command needs besides ``id`` and ``command`` (``robot_id`` is optional for
#: pause / resume: without it they act on the whole fleet)
COMMAND_NEEDS: dict[str, tuple[str, ...]] = {
    "pause": (), "resume": (), "estop": (), "release": (), "cancel": ("task_id",),
    "priority": ("task_id", "priority"), "send": ("robot_id", "station")}
_COMMAND_TAKES: dict[str, tuple[str, ...]] = {
    "pause": ("robot_id",), "resume": ("robot_id",), "estop": (), "release": (), "cancel": ("task_id", "reason"),
    "priority": ("task_id", "priority"), "send": ("robot_id", "station")}


@dataclass(frozen=True)
class Command(Record):
    """An operator command with arguments, answered by a :class:`CommandReply` with the same ``id``
    (the argument-less ones also have std_srvs services: docs/ARCHITECTURE.md, "Topics and QoS")."""

    SCHEMA: ClassVar[str] = "fleet/command@1"
    NAME: ClassVar[str] = "command"

    id: str = spec(nonempty)                   # the request id the reply carries back
    command: str = spec(choice(COMMANDS))
    robot_id: str | None = spec(optional(ros_id), default=None)
    task_id: str | None = spec(optional(nonempty), default=None)
    priority: int | None = spec(optional(integer()), default=None)
    station: str | None = spec(optional(nonempty), default=None)
    reason: str | None = spec(optional(text), default=None)
    auth: dict[str, Any] | None = spec(optional(obj(AUTH)), default=None)  # signature (with operator keys)

    def _check_together(self) -> None:
        for name in COMMAND_NEEDS[self.command]:
            if getattr(self, name) is None:
                raise RecordError(f"command.{name}: required for {self.command!r}")
        for name in ("robot_id", "task_id", "priority", "station", "reason"):
            if getattr(self, name) is not None and name not in _COMMAND_TAKES[self.command]:
                raise RecordError(f"command.{name}: {self.command!r} takes no {name}")


@dataclass(frozen=True)
class CommandReply(Record):
    """The planner's answer to a :class:`Command`: ``ok`` and what happened, or why not (the
    reason names the field at fault, e.g. ``robot_id: unknown robot 'r9'``)."""

    SCHEMA: ClassVar[str] = "fleet/command_reply@1"
    NAME: ClassVar[str] = "command_reply"

    id: str = spec(nonempty)
    ok: bool = spec(boolean)
    message: str = spec(text)
    stamp: float = spec(number())
    command: str | None = spec(optional(choice(COMMANDS)), default=None)


#: what the intelligent space may report as an obstacle (``fleet/obstacle@1``, field ``kind``)
OBSTACLE_KINDS = ("person", "vehicle", "pallet", "robot", "other")
#: the fastest obstacle taken (m/s): anything faster is a tracking error, not a forklift
MAX_OBSTACLE_SPEED = 20.0
#: the largest obstacle disc taken (m)
MAX_OBSTACLE_RADIUS = 10.0


@dataclass(frozen=True)
class ObstacleRecord(Record):
    """Something in the warehouse that is not a robot of the fleet, as the intelligent space sees it
    (You and Ji, section 2.1: "all the static and moving obstacles' positions"): a disc of ``radius``
    at ``(x, y)`` moving at ``(vx, vy)`` (m, m/s, map frame) at ``stamp`` (s, ROS time).

    A record supersedes the last one with the same ``id``. ``persistent``: it stays until a record
    with ``cleared: true`` for its id (a dropped pallet reported once); otherwise it expires when no
    newer record came for a while (a person the tracker lost). ``cleared``: it is gone."""

    SCHEMA: ClassVar[str] = "fleet/obstacle@1"
    NAME: ClassVar[str] = "obstacle"

    id: str = spec(nonempty)
    kind: str = spec(choice(OBSTACLE_KINDS))
    x: float = spec(number())
    y: float = spec(number())
    radius: float = spec(number(0.0, MAX_OBSTACLE_RADIUS, above=0.0))
    stamp: float = spec(number())
    vx: float = spec(number(-MAX_OBSTACLE_SPEED, MAX_OBSTACLE_SPEED), default=0.0)
    vy: float = spec(number(-MAX_OBSTACLE_SPEED, MAX_OBSTACLE_SPEED), default=0.0)
    persistent: bool = spec(boolean, default=False)
    cleared: bool = spec(boolean, default=False)

    def _check_together(self) -> None:
        if self.vx * self.vx + self.vy * self.vy > MAX_OBSTACLE_SPEED ** 2:
            raise RecordError(f"obstacle.vx: speed {(self.vx ** 2 + self.vy ** 2) ** 0.5:g} m/s "
                              f"(at most {MAX_OBSTACLE_SPEED:g})")


#: one link of a gate record: ``robot`` passes the region first on its path ``path_id``; the robot
#: the record is for does not drive beyond ``entry`` (m along its own path) before ``robot`` reports
#: more than ``exit`` (m along ``path_id``; null: it never leaves on that path) or a later path
GATE_LINK: dict[str, Check] = {"robot": ros_id, "path_id": integer(lo=0), "exit": optional(number(lo=0.0)),
                               "entry": number(lo=0.0)}


@dataclass(frozen=True)
class GateRecord(Record):
    """The precedence links a robot must respect on its timed path ``path_id`` (the (M,D)
    network's collision regions, as in an Action Dependency Graph; fleet_planner/fleet/gate.py).
    Latched per robot and re-sent whole, with a higher ``seq``, when it grows. ``watch`` maps each
    robot the links name to the latest path of that robot they were checked against: a robot
    reporting a later path than its ``watch`` entry is unknown progress (wait). Signed by the
    planner where keys are configured (``auth``), like task events."""

    SCHEMA: ClassVar[str] = "fleet/gate@1"
    NAME: ClassVar[str] = "gate"

    robot_id: str = spec(ros_id)
    path_id: int = spec(integer(lo=0))
    seq: int = spec(integer(lo=0))
    stamp: float = spec(number())
    links: tuple[dict[str, Any], ...] = spec(list_of(obj(GATE_LINK)), default=())
    watch: dict[str, int] | None = spec(optional(dict_of(integer(lo=0))), default=None)
    auth: dict[str, Any] | None = spec(optional(obj(AUTH)), default=None)  # signature (with keys)

    def _check_together(self) -> None:
        for n, link in enumerate(self.links):
            if link["robot"] == self.robot_id:
                raise RecordError(f"gate.links[{n}].robot: a robot does not wait for itself ({self.robot_id!r})")


@dataclass(frozen=True)
class Heard(Record):
    """Whom the planner hears (``/fleet/heard``, three times a lease; fleet_planner/fleet/lease.py): per
    robot it counts online, the stamp of the latest status of it that it took in (``robots``) and the
    leg it keeps the others clear of for it (``legs``: its path id; a robot without an entry has none).
    A robot whose stamp here is older than ``lease_s`` behind the newest stamp here (the planner hears
    others but not it), or that is left out, or that heard no record stamped within ``silence_s`` of
    its clock, stops, and drives on only once heard again on a leg the planner keeps (or a new leg).
    Signed by the planner where keys are configured (``auth``), like gate records."""

    SCHEMA: ClassVar[str] = "fleet/heard@1"
    NAME: ClassVar[str] = "heard"

    stamp: float = spec(number())
    lease_s: float = spec(number(0.01, 3600.0))
    silence_s: float = spec(number(0.01, 3600.0))
    robots: dict[str, float] = spec(dict_of(number()))
    legs: dict[str, int] | None = spec(optional(dict_of(integer(lo=0))), default=None)
    auth: dict[str, Any] | None = spec(optional(obj(AUTH)), default=None)  # signature (with keys)

    def _check_together(self) -> None:
        for rid in self.legs or {}:
            if rid not in self.robots:
                raise RecordError(f"heard.legs.{rid}: a leg kept for a robot not heard")


@dataclass(frozen=True)
class OperatorState(Record):
    """What the operator has set on the planner (latched, for consoles): the e-stop, a paused
    fleet, the robots paused and those in manual drive."""

    SCHEMA: ClassVar[str] = "fleet/operator_state@1"
    NAME: ClassVar[str] = "operator_state"

    stamp: float = spec(number())
    estop: bool = spec(boolean)
    fleet_paused: bool = spec(boolean)
    paused: tuple[str, ...] = spec(list_of(ros_id, unique=True), default=())
    manual: tuple[str, ...] = spec(list_of(ros_id, unique=True), default=())


@dataclass(frozen=True)
class RobotCommand(Record):
    """The operator's hand on one robot, for its agent (``/robots/<id>/command``): switch manual
    drive (``manual``) and/or a velocity command in manual drive (``linear`` m/s forward, ``angular``
    rad/s, as a Twist's ``linear.x`` / ``angular.z``). Where operator keys are configured this signed
    record is the only way (the SetBool ``manual`` service and Twist ``cmd_vel`` carry no signature
    and are refused); a switch is answered on ``/fleet/command_replies`` with the same ``id``."""

    SCHEMA: ClassVar[str] = "fleet/robot_command@1"
    NAME: ClassVar[str] = "robot_command"

    id: str = spec(nonempty)
    robot_id: str = spec(ros_id)
    manual: bool | None = spec(optional(boolean), default=None)
    linear: float | None = spec(optional(number()), default=None)
    angular: float | None = spec(optional(number()), default=None)
    auth: dict[str, Any] | None = spec(optional(obj(AUTH)), default=None)  # signature (with operator keys)

    def _check_together(self) -> None:
        if self.manual is None and self.linear is None and self.angular is None:
            raise RecordError("robot_command.manual: a command needs manual, linear or angular")


RECORDS: tuple[type[Record], ...] = (Task, TaskEvent, RobotStatus, Schedule, WaitMessageRecord, PathAuth, Neighbours,
                                     Command, CommandReply, ObstacleRecord, GateRecord, OperatorState, RobotCommand,
                                     Heard)

__all__ = ["AUTH", "BEHAVIORS", "BEHAVIOR_STATE", "COMMANDS", "COMMAND_NEEDS", "Check", "Command", "CommandReply",
           "EVENTS_NEEDING_REASON", "GATE_LINK", "GateRecord", "Heard", "INT_MAX", "INT_MIN", "MAX_DEPTH",
           "MAX_INT_DIGITS", "MAX_ITEMS", "MAX_NAME_CHARS", "MAX_NEIGHBOURS", "MAX_OBSTACLE_RADIUS",
           "MAX_OBSTACLE_SPEED", "MAX_REASON_CHARS", "MAX_RECORD_BYTES", "MAX_TEXT_CHARS", "Neighbours",
           "OBSTACLE_KINDS", "ObstacleRecord", "OperatorState", "PathAuth", "RECORDS", "Record", "RecordError",
           "RobotCommand", "RobotStatus", "Schedule", "TASK_EVENTS", "Task", "TaskEvent", "WaitMessageRecord",
           "boolean", "choice", "dict_of", "integer", "list_of", "load_json", "nonempty", "number", "obj", "optional",
           "point", "robot_id_problem", "ros_id", "spec", "text", "unsigned_json"]
