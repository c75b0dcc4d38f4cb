"""Fleet files (``config/fleet.yaml``): the robots of a bring-up, each with its id, kind, start pose
and battery (:func:`load_fleet`, :class:`FleetMember`, :class:`FleetError`)."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import yaml

from msg_schemas.records import robot_id_problem

from ..robots import RobotKind
from ..warehouse import Warehouse, config_path

FLEET_FILE = "fleet.yaml"


class FleetError(ValueError):
    """A fleet file that cannot be used; the message names the file, the robot and the field."""


@dataclass(frozen=True)
class FleetMember:
    """One robot of a fleet file: its id, kind, start pose and battery (fraction of full)."""

    id: str
    kind: str
    x: float
    y: float
    yaw: float = 0.0
    battery: float = 1.0


def load_fleet(path: str | Path | None = None, kinds: Mapping[str, RobotKind] | None = None,
               warehouse: Warehouse | None = None) -> list[FleetMember]:
    """The robots of a fleet file (default: the shipped ``config/fleet.yaml``), a mapping with a list
    ``robots`` of ``{id, kind, x, y[, yaw][, battery]}``. Checked: ids fit in topic names and are
    unique, kinds are among ``kinds``, numbers are finite, and (given ``warehouse``) every robot
    stands in free space clear of the others. Errors name the file, the robot and the field."""
    path = Path(path) if path is not None else config_path(FLEET_FILE)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise FleetError(f"{path}: cannot read fleet file ({exc})") from exc
    if not isinstance(data, dict) or not isinstance(data.get("robots"), list) or not data["robots"]:
        raise FleetError(f"{path}: expected a mapping with a non-empty list 'robots'")
    unknown = sorted(set(data) - {"robots"})
    if unknown:
        raise FleetError(f"{path}: unknown key(s) {', '.join(unknown)} (known: robots)")
    known = [f.name for f in fields(FleetMember)]
    out: list[FleetMember] = []
    for i, item in enumerate(data["robots"]):
        where = f"{path}: robots[{i}]"
        if not isinstance(item, dict):
            raise FleetError(f"{where}: expected a mapping with {', '.join(known)} (got {item!r})")
        bad = sorted(set(item) - set(known))
        if bad:
            raise FleetError(f"{where}.{bad[0]}: unknown field (known: {', '.join(known)})")
        for name in known[:4]:
            if name not in item:
                raise FleetError(f"{where}.{name}: missing")
        problem = robot_id_problem(item["id"])
        if problem:
            raise FleetError(f"{where}.id: {problem}")
        where = f"{path}: robot {item['id']!r}"
        if kinds is not None and item["kind"] not in kinds:
            raise FleetError(f"{where}.kind: {item['kind']!r} is not one of {', '.join(kinds)}")
        for name in ("x", "y", "yaw", "battery"):
            value = item.get(name, 0.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise FleetError(f"{where}.{name}: must be a finite number (got {value!r})")
        if not 0.0 <= item.get("battery", 1.0) <= 1.0:
            raise FleetError(f"{where}.battery: must be in [0, 1] (got {item['battery']!r})")
        values: dict[str, Any] = {k: (float(v) if k not in ("id", "kind") else v) for k, v in item.items()}
        member = FleetMember(**values)
        if any(m.id == member.id for m in out):
            raise FleetError(f"{where}.id: used twice")
        if warehouse is not None and kinds is not None:
            radius = kinds[member.kind].radius
            if not warehouse.grid.disc_is_free(member.x, member.y, radius):
                raise FleetError(f"{where}: ({member.x:g}, {member.y:g}) is not free for its radius {radius:g} m")
            for m in out:
                if math.dist((m.x, m.y), (member.x, member.y)) < radius + kinds[m.kind].radius:
                    raise FleetError(f"{where}: overlaps robot {m.id!r} at the start")
        out.append(member)
    return out
