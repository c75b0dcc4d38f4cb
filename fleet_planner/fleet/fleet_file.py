"""Fleet files (``config/fleet.yaml``): the robots of a bring-up, each with its id, kind, start pose
and battery (:func:`load_fleet`, :class:`FleetMember`, :class:`FleetError`), checked with the
validation vocabulary of :mod:`fleet_planner.validation`.

A fleet file is a mapping with one key, ``robots``: a non-empty list of ``{id, kind, x, y[, yaw]
[, battery]}``. Checked: ids fit in topic names and are unique, kinds are among ``kinds`` (when
given), numbers are finite, the battery is in [0, 1], and (given ``kinds`` and ``warehouse``) every
robot stands in free space clear of the others. Errors are :class:`FleetError` naming the file, the
robot and the field: ``fleet.yaml: robots[0].y: missing``, ``fleet.yaml: robot 'r1'.battery: must
be in [0, 1] (got 2)``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

from ..robots import RobotKind
from ..validation import ValidationError, Vocabulary, in_file, read_yaml
from ..warehouse import Warehouse, config_path

FLEET_FILE = "fleet.yaml"


@dataclass(frozen=True)
class FleetMember:
    """One robot of a fleet file: its id, kind, start pose and battery (fraction of full)."""

    id: str
    kind: str
    x: float
    y: float
    yaw: float = 0.0
    battery: float = 1.0


#: the fields of a robot in a fleet file, in order (those of ``FleetMember``); the first four are required
MEMBER_FIELDS = ("id", "kind", "x", "y", "yaw", "battery")
MEMBER_REQUIRED = MEMBER_FIELDS[:4]


class FleetError(ValidationError):
    """A fleet file that cannot be used; the message names the file, the robot and the field."""


# the fleet file's words: values shown as Python writes them, the first unknown field in sorted order
_V = Vocabulary(FleetError, not_mapping=f"expected a mapping with {', '.join(MEMBER_FIELDS)} (got {{got}})",
                unknown="unknown field (known: {known})", unknown_sorted=True)
_NUMBERS = {"x": _V.number(), "y": _V.number(), "yaw": _V.number(), "battery": _V.number(0.0, 1.0)}


def fleet_member_fields(item: Any, where: str, kinds: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The ``FleetMember`` keyword arguments of one entry of ``robots`` (numbers as floats; ``yaw``
    and ``battery`` only when given). ``where`` is its path (``robots[3]``) until its id is known,
    then the robot is named by id (``robot 'r3'.kind``)."""
    item = _V.keys(item, where, MEMBER_FIELDS, MEMBER_REQUIRED)
    robot_id = _V.ros_id(item["id"], f"{where}.id")
    where = f"robot {robot_id!r}"
    if kinds is not None and item["kind"] not in kinds:  # (a list or mapping here raises TypeError, as today)
        _V.fail(f"{where}.kind", f"{item['kind']!r} is not one of {', '.join(kinds)}")
    out = {"id": robot_id, "kind": item["kind"]}
    for name, check in _NUMBERS.items():
        if name in item:
            out[name] = check(item[name], f"{where}.{name}")
    return out


def read_fleet_file(path: Path, kinds: Mapping[str, RobotKind] | None = None,
                    warehouse: Warehouse | None = None) -> list[dict[str, Any]]:
    """The robots of the fleet file ``path`` as ``FleetMember`` keyword arguments, in file order."""
    data = read_yaml(path, FleetError, what="fleet file", invalid=None)
    if not isinstance(data, dict) or not isinstance(data.get("robots"), list) or not data["robots"]:
        raise FleetError(f"{path}: expected a mapping with a non-empty list 'robots'")
    unknown = sorted(set(data) - {"robots"})
    if unknown:
        raise FleetError(f"{path}: unknown key(s) {', '.join(unknown)} (known: robots)")
    members: list[dict[str, Any]] = []
    with in_file(path, FleetError):
        for i, item in enumerate(data["robots"]):
            member = fleet_member_fields(item, f"robots[{i}]", kinds)
            where = f"robot {member['id']!r}"
            if any(m["id"] == member["id"] for m in members):
                raise FleetError(f"{where}.id: used twice")
            if warehouse is not None and kinds is not None:
                _check_place(member, where, members, kinds, warehouse)
            members.append(member)
    return members


def _check_place(member: dict[str, Any], where: str, before: list[dict[str, Any]], kinds: Mapping[str, RobotKind],
                 warehouse: Warehouse) -> None:
    """A robot stands in free space for its radius, clear of the robots listed before it."""
    x, y = member["x"], member["y"]
    radius = kinds[member["kind"]].radius
    if not warehouse.grid.disc_is_free(x, y, radius):
        raise FleetError(f"{where}: ({x:g}, {y:g}) is not free for its radius {radius:g} m")
    for m in before:
        if math.dist((m["x"], m["y"]), (x, y)) < radius + kinds[m["kind"]].radius:
            raise FleetError(f"{where}: overlaps robot {m['id']!r} at the start")


assert MEMBER_FIELDS == tuple(f.name for f in fields(FleetMember)), "fleet file fields != FleetMember"


def load_fleet(path: str | Path | None = None, kinds: Mapping[str, RobotKind] | None = None,
               warehouse: Warehouse | None = None) -> list[FleetMember]:
    """The robots of a fleet file (default: the shipped ``config/fleet.yaml``); see the module
    docstring for what is checked. Errors name the file, the robot and the field."""
    path = Path(path) if path is not None else config_path(FLEET_FILE)
    return [FleetMember(**member) for member in read_fleet_file(path, kinds, warehouse)]


__all__ = ["FLEET_FILE", "MEMBER_FIELDS", "FleetError", "FleetMember", "fleet_member_fields", "load_fleet",
           "read_fleet_file"]
