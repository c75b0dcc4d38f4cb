"""The scenario file (YAML) and the plan file (JSON) of docs/ARCHITECTURE.md ("Scenario and plan
files"), read strictly.

Everything a user can get wrong in a scenario is reported as a :class:`ScenarioError` whose message
starts with the path of the offending field (``robots[3].radius: ...``), says why and shows the
value it got. Unknown keys are errors, not silently ignored, so a typo cannot go unnoticed. The
checks are those of the field vocabulary, :mod:`fleet_planner.validation`.
Benchmarks build scenarios from MovingAI ``.map``/``.scen`` pairs with
:func:`scenario_from_movingai` and save them with :func:`dump_scenario`.
"""
from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .grid import GridMap, MapError, load_scen
from .model import ROBOT_KINDS, Network, Plan, RobotSpec, TimedPath
from .validation import ValidationError, Vocabulary, anything, read_yaml

MAP_KEYS = ("file", "rows", "resolution")
ROBOT_KEYS = ("id", "kind", "radius", "max_speed", "start", "goal")
ROBOT_REQUIRED = ("id", "radius", "max_speed", "start", "goal")
PLAN_KEYS = ("planner", "planning_time_s", "robots", "info")
PLAN_ROBOT_KEYS = ("id", "radius", "waypoints")


class ScenarioError(ValidationError):
    """A scenario or plan file that cannot be used; the message starts with the field path."""


# the scenario file's words: values shown as Python writes them, the top level called "scenario"
_V = Vocabulary(ScenarioError, root="scenario", missing="missing (required: {required})")
_POSITIVE = _V.worded(_V.number(above=0), "must be a finite number > 0 (got {got})")
_POINT = _V.worded(_V.point, "must be a list of 2 finite numbers [x, y] (got {got})")
_ROBOT_ID = _V.worded(_V.string(min_len=1, strip=True), "must be a non-empty string (got {got}; quote numbers)")
_KIND = _V.choice(ROBOT_KINDS)
_MAP_FILE = _V.worded(_V.string(min_len=1), "must be a non-empty path string (got {got})")
_ROW_LIST = _V.worded(_V.list_of(anything, min_len=1), "must be a non-empty list of strings (got {got})")
_ROW = _V.string(min_len=1)
_ROBOT_LIST = _V.worded(_V.list_of(anything, min_len=1), "must be a non-empty list of robots (got {got})")


@dataclass
class Scenario:
    """A map and the robots to plan for. ``map_file`` is set when the map came from a ``.map`` file."""

    grid: GridMap
    robots: list[RobotSpec]
    source: Path | None = None
    map_file: Path | None = None


# ---------------------------------------------------------------------------------------------
# scenario: reading and validating
# ---------------------------------------------------------------------------------------------
def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file (a relative ``map.file`` is relative to it)."""
    path = Path(path)
    data = read_yaml(path, ScenarioError, what="scenario file", unique_keys=True)
    scenario = parse_scenario(data, path.parent)
    scenario.source = path
    return scenario


def _keys(data: Any, where: str, allowed: Sequence[str], required: Sequence[str]) -> dict:
    return dict(_V.keys(data, where, allowed, required))


def _positive(value: Any, where: str) -> float:
    return _POSITIVE(value, where)


def _rows(value: Any, where: str) -> tuple[str, ...]:
    """Inline map rows: a non-empty list of non-empty strings, all as long as the first."""
    rows = _ROW_LIST(value, where)
    for i, row in enumerate(rows):
        _ROW(row, f"{where}[{i}]")
        if len(row) != len(rows[0]):
            _V.fail(f"{where}[{i}]", f"has {len(row)} cells, {where}[0] has {len(rows[0])}")
    return rows


def _parse_map(data: Any, base_dir: Path) -> tuple[GridMap, Path | None]:
    m = _V.keys(data, "map", MAP_KEYS)
    resolution = _POSITIVE(m.get("resolution", 1.0), "map.resolution")
    if ("file" in m) == ("rows" in m):
        raise ScenarioError("map: needs exactly one of 'file' (a MovingAI .map) or 'rows' (inline rows)")
    if "file" in m:
        map_file = (base_dir / _MAP_FILE(m["file"], "map.file")).resolve()
        try:
            return GridMap.from_movingai(map_file, resolution), map_file
        except MapError as exc:
            raise ScenarioError(f"map.file: {exc}") from None
    return GridMap.from_rows(_rows(m["rows"], "map.rows"), resolution, "inline"), None


def _parse_robot(data: Any, where: str, grid: GridMap) -> RobotSpec:
    r = _V.keys(data, where, ROBOT_KEYS, ROBOT_REQUIRED)
    rid = _ROBOT_ID(r["id"], f"{where}.id")
    kind = _KIND(r.get("kind", "cargo"), f"{where}.kind")
    radius = _POSITIVE(r["radius"], f"{where}.radius")
    max_speed = _POSITIVE(r["max_speed"], f"{where}.max_speed")
    ends = {}
    w, h = grid.size_m
    for name in ("start", "goal"):  # start whole (shape, map, free space), then goal
        x, y = _POINT(r[name], f"{where}.{name}")
        if not (0 <= x <= w and 0 <= y <= h):
            raise ScenarioError(f"{where}.{name}: ({x:g}, {y:g}) is outside the {w:g} m x {h:g} m map")
        clearance = grid.clearance(x, y)
        if clearance < radius - 1e-9:
            raise ScenarioError(f"{where}.{name}: a disc of radius {radius:g} m at ({x:g}, {y:g}) is not in "
                                f"free space (clearance {clearance:.3f} m)")
        ends[name] = (x, y)
    return RobotSpec(rid, radius, max_speed, ends["start"], ends["goal"], kind)


def _check_disjoint(robots: list[RobotSpec], name: str) -> None:
    """Two start discs (or two goal discs) that overlap make every plan invalid: say so up front."""
    if len(robots) < 2:
        return
    pts = np.array([getattr(r, name) for r in robots])
    rad = np.array([r.radius for r in robots])
    order = np.argsort(pts[:, 0])
    reach = 2 * rad.max()
    for n, i in enumerate(order):
        for j in order[n + 1:]:
            if pts[j, 0] - pts[i, 0] >= reach:
                break
            d = float(np.hypot(*(pts[i] - pts[j])))
            if d < rad[i] + rad[j] - 1e-9:
                a, b = sorted((int(i), int(j)))
                raise ScenarioError(f"robots[{b}].{name}: disc overlaps the {name} disc of robots[{a}] "
                                    f"({robots[a].id!r}): centres {d:.3f} m apart < {rad[a] + rad[b]:g} m")


def parse_scenario(data: Any, base_dir: Path) -> Scenario:
    """Validate a scenario already parsed from YAML (``base_dir`` resolves a relative map file)."""
    top = _V.keys(data, "", ("map", "robots"), ("map", "robots"))
    grid, map_file = _parse_map(top["map"], Path(base_dir))
    robots: list[RobotSpec] = []
    first_index: dict[str, int] = {}
    for i, item in enumerate(_ROBOT_LIST(top["robots"], "robots")):
        spec = _parse_robot(item, f"robots[{i}]", grid)
        if spec.id in first_index:
            raise ScenarioError(f"robots[{i}].id: duplicate id {spec.id!r} (also robots[{first_index[spec.id]}])")
        first_index[spec.id] = i
        robots.append(spec)
    _check_disjoint(robots, "start")
    _check_disjoint(robots, "goal")
    return Scenario(grid, robots, None, map_file)


# ---------------------------------------------------------------------------------------------
# scenario: writing and generating
# ---------------------------------------------------------------------------------------------
def _yaml_scalar(value: Any) -> str:
    # JSON strings and Python float reprs are valid YAML flow scalars and read back exactly
    return json.dumps(value) if isinstance(value, str) else repr(float(value))


def dump_scenario(scenario: Scenario, path: str | Path) -> None:
    """Write a scenario YAML that :func:`load_scenario` reads back to the same map and robots.

    The map is referenced by file (relative to ``path``) when it came from one, else written inline.
    """
    path = Path(path)
    lines = ["map:"]
    if scenario.map_file is not None:
        map_file, here = Path(scenario.map_file).resolve(), path.resolve().parent
        # relative when both share a directory below the root, so the pair can be moved together
        shared = os.path.commonpath([map_file, here]) != map_file.anchor
        lines.append(f"  file: {json.dumps(os.path.relpath(map_file, here) if shared else str(map_file))}")
    else:
        lines.append("  rows:")
        lines.extend(f"    - \"{''.join('@' if b else '.' for b in row)}\"" for row in scenario.grid.blocked)
    lines.append(f"  resolution: {_yaml_scalar(scenario.grid.resolution)}")
    lines.append("robots:")
    for r in scenario.robots:
        fields = [f"id: {_yaml_scalar(r.id)}", f"kind: {r.kind}", f"radius: {_yaml_scalar(r.radius)}",
                  f"max_speed: {_yaml_scalar(r.max_speed)}",
                  f"start: [{_yaml_scalar(r.start[0])}, {_yaml_scalar(r.start[1])}]",
                  f"goal: [{_yaml_scalar(r.goal[0])}, {_yaml_scalar(r.goal[1])}]"]
        lines.append("  - {" + ", ".join(fields) + "}")
    path.write_text("\n".join(lines) + "\n")


def scenario_from_movingai(map_path: str | Path, scen_path: str | Path, n: int, seed: int,
                           radius: tuple[float, float] = (0.35, 0.45), speed: tuple[float, float] = (0.7, 1.0),
                           resolution: float = 1.0, kinds: Sequence[str] = ("cargo",)) -> Scenario:
    """The first ``n`` usable entries of a MovingAI ``.scen`` file as robots, for benchmarks.

    Each entry gets a radius and a top speed drawn uniformly from the given ranges and a kind drawn
    from ``kinds`` (seeded, so the same arguments give the same scenario). An entry is skipped when
    its start or goal disc does not fit in free space at the cell centre, or overlaps the start
    (goal) disc of a robot already taken. Raises :class:`ScenarioError` when fewer than n remain.
    """
    if n < 1:
        raise ScenarioError(f"n: must be >= 1 (got {n})")
    for k in kinds:
        if k not in ROBOT_KINDS:
            raise ScenarioError(f"kinds: {k!r} is not one of {', '.join(ROBOT_KINDS)}")
    try:
        grid = GridMap.from_movingai(map_path, resolution)
        entries = load_scen(scen_path)
    except MapError as exc:
        raise ScenarioError(str(exc)) from None
    rng = np.random.default_rng(seed)
    robots: list[RobotSpec] = []
    taken: dict[str, list[tuple[float, float, float]]] = {"start": [], "goal": []}  # (x, y, r) of accepted discs
    for (s_cell, g_cell) in entries:
        r = float(rng.uniform(*radius))
        v = float(rng.uniform(*speed))
        kind = str(kinds[int(rng.integers(len(kinds)))])
        ends = {}
        for name, cell in (("start", s_cell), ("goal", g_cell)):
            if not grid.is_free_cell(*cell):
                break
            x, y = grid.centre(*cell)
            if not grid.disc_is_free(x, y, r) or any(math.hypot(x - ox, y - oy) < r + orad - 1e-9
                                                      for ox, oy, orad in taken[name]):
                break
            ends[name] = (x, y)
        else:
            for name, (x, y) in ends.items():
                taken[name].append((x, y, r))
            robots.append(RobotSpec(f"r{len(robots)}", r, v, ends["start"], ends["goal"], kind))
            if len(robots) == n:
                return Scenario(grid, robots, None, Path(map_path).resolve())
    raise ScenarioError(f"{scen_path}: only {len(robots)} usable entries, {n} asked for")


# ---------------------------------------------------------------------------------------------
# plan file
# ---------------------------------------------------------------------------------------------
def _jsonable(value: Any) -> Any:
    """numpy scalars and arrays (as planners put them in ``Plan.info``) as plain JSON values."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"plan info: {type(value).__name__} is not JSON serialisable")


def _plan_info(plan: Plan) -> dict[str, Any]:
    """The plan file's ``info``: the network and the collision test it was scheduled with
    (``mode``) first, when the plan has a network, then the planner's own scalars."""
    info: dict[str, Any] = {}
    if plan.network is not None:
        info["network"] = plan.network.to_dict()
        if plan.network.mode is not None:
            info["mode"] = plan.network.mode
    clash = sorted(set(info) & set(plan.info))
    if clash:
        raise ValueError(f"plan info: {', '.join(clash)} belong to the plan's network, not to Plan.info")
    info.update(plan.info)
    return info


def plan_to_dict(plan: Plan) -> dict[str, Any]:
    """The plan-file JSON object (``info`` only when the plan has any; docs/ARCHITECTURE.md,
    "Scenario and plan files")."""
    out: dict[str, Any] = {"planner": plan.planner, "planning_time_s": float(plan.planning_time_s),
                           "robots": [p.to_dict() for p in plan.paths]}
    info = _plan_info(plan)
    if info:
        out["info"] = json.loads(json.dumps(info, default=_jsonable))
    return out


def write_plan(plan: Plan, path: str | Path) -> None:
    """Write the plan file: one line per top-level key and one line per robot (diff- and grep-friendly)."""
    data = plan_to_dict(plan)
    robots = ",\n".join("  " + json.dumps(r) for r in data.pop("robots"))
    head = "".join(f" {json.dumps(k)}: {json.dumps(data[k])},\n" for k in ("planner", "planning_time_s"))
    tail = f",\n \"info\": {json.dumps(data['info'])}" if "info" in data else ""
    Path(path).write_text("{\n" + head + f' "robots": [\n{robots}\n ]' + tail + "\n}\n")


def plan_from_dict(data: Any) -> Plan:
    """Validate a plan-file JSON object; errors name the field (``robots[2].waypoints[5]: ...``)."""
    top = _keys(data, "", PLAN_KEYS, ("planner", "planning_time_s", "robots"))
    if not isinstance(top["planner"], str):
        raise ScenarioError(f"planner: must be a string (got {top['planner']!r})")
    t_plan = top["planning_time_s"]
    if isinstance(t_plan, bool) or not isinstance(t_plan, (int, float)) or not math.isfinite(t_plan) or t_plan < 0:
        raise ScenarioError(f"planning_time_s: must be a finite number >= 0 (got {t_plan!r})")
    info = top.get("info", {})
    if not isinstance(info, dict):
        raise ScenarioError(f"info: must be a mapping (got {type(info).__name__})")
    info, network = dict(info), None
    if "network" in info:   # a typed network; the collision test it was scheduled with beside it
        try:
            network = Network.from_dict(info.pop("network"), info.pop("mode", None))
        except ValueError as exc:
            raise ScenarioError(f"info.{exc}") from None
    if not isinstance(top["robots"], list):
        raise ScenarioError(f"robots: must be a list (got {type(top['robots']).__name__})")
    paths = []
    for i, item in enumerate(top["robots"]):
        where = f"robots[{i}]"
        r = _keys(item, where, PLAN_ROBOT_KEYS, PLAN_ROBOT_KEYS)
        if not isinstance(r["id"], str) or not r["id"]:
            raise ScenarioError(f"{where}.id: must be a non-empty string (got {r['id']!r})")
        radius = _positive(r["radius"], f"{where}.radius")
        wps = r["waypoints"]
        if not isinstance(wps, list) or not wps:
            raise ScenarioError(f"{where}.waypoints: must be a non-empty list of [x, y, t] (got {wps!r})")
        for k, wp in enumerate(wps):
            if (not isinstance(wp, list) or len(wp) != 3
                    or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) for v in wp)):
                raise ScenarioError(f"{where}.waypoints[{k}]: must be [x, y, t] of finite numbers (got {wp!r})")
        paths.append(TimedPath(r["id"], radius, np.array(wps, dtype=float)))
    return Plan(top["planner"], paths, float(t_plan), info, network)


def read_plan(path: str | Path) -> Plan:
    """Read a plan JSON file (structure only: whether the plan is valid is :func:`check_plan`'s job)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: cannot read plan file ({exc})") from exc
    except json.JSONDecodeError as exc:
        raise ScenarioError(f"{path}: not valid JSON ({exc})") from exc
    return plan_from_dict(data)


__all__ = ["Scenario", "ScenarioError", "dump_scenario", "load_scenario", "parse_scenario", "plan_from_dict",
           "plan_to_dict", "read_plan", "scenario_from_movingai", "write_plan"]
