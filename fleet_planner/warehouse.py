"""The warehouse of You and Ji, "Design of a Multi-robot Bin Packing System in an Automatic Warehouse"
(section 2.1): a grid map plus the stations robots drive between.

* ``chute``   - where a robot picks items up;
* ``storage`` - a storing site: boxes with address tags (``"B07-02"``) where a robot places items;
* ``charger`` - a charging station, where robots go when low on battery or idle.

A station's ``(x, y)`` is the pose (metres, map frame) where a robot stops to be served, not the
chute, rack or charger itself (those are blocked cells of the map). Warehouses are read from a YAML
file (:func:`load_warehouse`, default ``config/warehouse.yaml``) or generated for benchmarks
(:func:`generate_warehouse`). :func:`config_path` finds the shipped config files both in a source
checkout and in an installed package. The file is checked with the field vocabulary of
:mod:`fleet_planner.validation`; errors name the file and the field.
"""
from __future__ import annotations

import math
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .grid import GridMap, MapError
from .validation import ValidationError, Vocabulary, all_of, anything, in_file, read_yaml

PACKAGE = "fleet_planner"
STATION_TYPES = ("chute", "storage", "charger")
STATION_KEYS = ("name", "type", "x", "y", "tags", "capacity")
MAP_KEYS = ("file", "rows", "resolution")
#: clearance every generated stop pose leaves around it: the largest robot of the default fleet
STOP_RADIUS = 0.45

#: the repository root when running from a checkout or an editable install
_SOURCE_ROOT = Path(__file__).resolve().parent.parent


class WarehouseError(ValidationError):
    """A warehouse that cannot be used; the message names the file or field and the reason."""


# the warehouse file's words: values shown as Python writes them, unknown keys listed as allowed
_V = Vocabulary(WarehouseError)
_NUMBER = _V.number()
_POSITIVE_INT = _V.worded(_V.integer(lo=1), "must be an integer >= 1 (got {got})")
_STATION_TYPE = _V.worded(_V.choice(STATION_TYPES), "{got} is not one of " + ", ".join(STATION_TYPES))
_MAP_FILE = _V.worded(_V.string(min_len=1), "must be a non-empty path string (got {got})")
_MAP_ROWS = _V.worded(_V.list_of(_V.string()), "must be a list of strings (got {got})")
_RESOLUTION = all_of(_NUMBER, _V.number(above=0))  # "> 0" shows the value as a float
_STATIONS = _V.worded(_V.list_of(anything), "must be a list (got {type})")
_STATION = _V.mapping(
    {"name": _V.worded(_V.string(min_len=1, strip=True), "must be a non-empty string (got {got}; quote numbers)"),
     "type": anything,  # checked by Warehouse, as for a generated one
     "tags": _V.worded(_V.list_of(_V.string(min_len=1)), "must be a list of non-empty strings (got {got})"),
     "capacity": _POSITIVE_INT,
     "x": _NUMBER, "y": _NUMBER},
    defaults={"tags": [], "capacity": 1}, known=STATION_KEYS,
    not_mapping=f"must be a mapping with {', '.join(STATION_KEYS[:4])} (got {{got}})")


# ---------------------------------------------------------------------------------------------
# finding config files
# ---------------------------------------------------------------------------------------------
def config_dirs() -> list[Path]:
    """Where config files are looked for, in order.

    1. ``config/`` of the source checkout (running from the repo or after ``pip install -e .``);
    2. the ament share directory (``colcon build`` / a ROS install);
    3. ``share/fleet_planner/config`` under ``sys.prefix`` (a plain ``pip install`` into a venv).
    """
    dirs = []
    if (_SOURCE_ROOT / "package.xml").is_file():
        dirs.append(_SOURCE_ROOT / "config")
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory(PACKAGE)) / "config")
    except (ImportError, LookupError, OSError, ValueError):
        pass  # not on a ROS install (or AMENT_PREFIX_PATH unset): the other places remain
    dirs.append(Path(sys.prefix) / "share" / PACKAGE / "config")
    return dirs


def config_path(name: str) -> Path:
    """The shipped config file ``name`` (e.g. ``"warehouse.yaml"``), from the first of :func:`config_dirs`
    that has it. Raises FileNotFoundError listing the places searched."""
    dirs = config_dirs()
    for d in dirs:
        if (d / name).is_file():
            return d / name
    raise FileNotFoundError(f"config file {name!r} not found in any of: {', '.join(map(str, dirs))}")


# ---------------------------------------------------------------------------------------------
# the model
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Station:
    """A place robots are served at: ``(x, y)`` is where the robot stops."""

    name: str
    type: str
    x: float
    y: float
    tags: tuple[str, ...] = ()
    capacity: int = 1  # robots it serves at once

    @property
    def pose(self) -> tuple[float, float]:
        return self.x, self.y


@dataclass
class Warehouse:
    """A grid map and its stations by name (in file order). Checked on construction: every station
    type is known, every stop pose lies in a free cell and no address tag is used twice."""

    grid: GridMap
    stations: dict[str, Station]
    name: str = "warehouse"
    _by_tag: dict[str, Station] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._by_tag = {}
        for i, (key, s) in enumerate(self.stations.items()):
            where = f"stations[{i}] ({s.name!r})"
            if key != s.name:
                raise WarehouseError(f"{where}: stored under the name {key!r}")
            _STATION_TYPE(s.type, f"{where}.type")
            col, row = self.grid.cell_of(s.x, s.y)
            if not self.grid.in_bounds(col, row):
                w, h = self.grid.size_m
                raise WarehouseError(f"{where}: pose ({s.x:g}, {s.y:g}) is outside the {w:g} m x {h:g} m map")
            if self.grid.blocked[row, col]:
                raise WarehouseError(f"{where}: pose ({s.x:g}, {s.y:g}) is in a wall (cell col {col}, row {row})")
            if s.tags and s.type != "storage":
                raise WarehouseError(f"{where}.tags: only storing sites carry address tags, this is a {s.type}")
            for tag in s.tags:
                if tag in self._by_tag:
                    raise WarehouseError(f"{where}.tags: address tag {tag!r} is already used by station "
                                         f"{self._by_tag[tag].name!r}")
                self._by_tag[tag] = s

    def station_for_tag(self, tag: str) -> Station:
        """The storing site holding the box with this address tag."""
        try:
            return self._by_tag[tag]
        except KeyError:
            raise KeyError(f"no storing site has address tag {tag!r}") from None

    def stations_of(self, type: str) -> list[Station]:
        """All stations of one type, in file order."""
        if type not in STATION_TYPES:
            raise ValueError(f"station type {type!r} is not one of {', '.join(STATION_TYPES)}")
        return [s for s in self.stations.values() if s.type == type]


def _index(stations: Iterable[Station]) -> dict[str, Station]:
    out: dict[str, Station] = {}
    for i, s in enumerate(stations):
        if s.name in out:
            raise WarehouseError(f"stations[{i}].name: duplicate name {s.name!r}")
        out[s.name] = s
    return out


# ---------------------------------------------------------------------------------------------
# reading and writing
# ---------------------------------------------------------------------------------------------
def _parse_map(m: Any, base_dir: Path) -> GridMap:
    m = _V.keys(m, "map", MAP_KEYS, not_mapping="must be a mapping with 'file' and 'resolution' (got {got})")
    resolution = _RESOLUTION(m.get("resolution", 1.0), "map.resolution")
    if ("file" in m) == ("rows" in m):
        raise WarehouseError("map: needs exactly one of 'file' (a MovingAI .map) or 'rows' (inline rows)")
    try:
        if "file" in m:
            return GridMap.from_movingai(base_dir / _MAP_FILE(m["file"], "map.file"), resolution)
        return GridMap.from_rows(_MAP_ROWS(m["rows"], "map.rows"), resolution)
    except MapError as exc:
        raise WarehouseError(f"map: {exc}") from None


def _parse_station(data: Any, where: str) -> Station:
    f = _STATION(data, where)
    return Station(f["name"], f["type"], f["x"], f["y"], f["tags"], f["capacity"])


def parse_warehouse(data: Any, base_dir: Path, name: str = "warehouse") -> Warehouse:
    """Validate a warehouse already parsed from YAML (``base_dir`` resolves a relative map file)."""
    data = _V.keys(data, "", ("name", "map", "stations"), ("map", "stations"),
                   not_mapping="must be a mapping with 'map' and 'stations' (got {type})")
    grid = _parse_map(data["map"], base_dir)
    stations = [_parse_station(s, f"stations[{i}]") for i, s in enumerate(_STATIONS(data["stations"], "stations"))]
    wh_name = _V.string()(data.get("name", name), "name")
    return Warehouse(grid, _index(stations), wh_name)


def load_warehouse(path: str | Path | None = None) -> Warehouse:
    """Read and validate a warehouse YAML file (default: the shipped ``config/warehouse.yaml``).

    Errors are :class:`WarehouseError` starting with the file and the field, e.g.
    ``warehouse.yaml: stations[3].type: 'shelf' is not one of chute, storage, charger``.
    """
    path = Path(path) if path is not None else config_path("warehouse.yaml")
    data = read_yaml(path, WarehouseError, what="warehouse file")
    with in_file(path, WarehouseError):
        return parse_warehouse(data, path.parent, path.stem)


def save_warehouse(warehouse: Warehouse, path: str | Path, comment: str = "") -> Path:
    """Write ``path`` (YAML) and the map beside it (same stem, ``.map``) so that :func:`load_warehouse`
    reads back the same grid and stations. ``comment`` lines go at the top of the YAML."""
    path = Path(path)
    map_path = path.with_suffix(".map")
    grid = warehouse.grid
    rows = ["".join("@" if b else "." for b in row) for row in grid.blocked]
    map_path.write_text(f"type octile\nheight {grid.height}\nwidth {grid.width}\nmap\n" + "\n".join(rows) + "\n")
    lines = [f"# {line}".rstrip() for line in comment.splitlines()]
    lines += [f"name: {yaml.safe_dump(warehouse.name).splitlines()[0]}",
              "map:", f"  file: {map_path.name}", f"  resolution: {grid.resolution!r}", "stations:"]
    for s in warehouse.stations.values():
        item: dict[str, Any] = {"name": s.name, "type": s.type, "x": s.x, "y": s.y}
        if s.tags:
            item["tags"] = list(s.tags)
        if s.capacity != 1:
            item["capacity"] = s.capacity
        lines.append("  - " + yaml.safe_dump(item, default_flow_style=True, sort_keys=False, width=1 << 16).strip())
    path.write_text("\n".join(lines) + "\n")
    return path


# ---------------------------------------------------------------------------------------------
# generated warehouses (benchmarks)
# ---------------------------------------------------------------------------------------------
def generate_warehouse(blocks_x: int, blocks_y: int, block_w: int, block_h: int, aisle: int,
                       resolution: float = 0.5, name: str = "generated", *,
                       chutes: int | None = None, chargers: int | None = None) -> Warehouse:
    """A rectangular warehouse of ``blocks_x`` x ``blocks_y`` rack blocks, sizes in cells.

    Layout, top to bottom: the outer wall; chutes (3 cells wide, 2 deep) on the top wall; a main
    aisle of ``aisle + 2`` rows; rows of rack blocks (``block_w`` x ``block_h``) with ``aisle`` rows
    between them; a main aisle of ``aisle + 2`` rows; chargers (1 cell wide, 2 deep, 4 cells apart)
    on the bottom wall, from the left. Across: side aisles of ``aisle`` columns and cross aisles of
    ``aisle + 2`` columns between blocks. Storing sites stop in the aisle below each block, about one
    per 8 m of rack face, named ``B01``, ``B02``... (row by row) with 2-4 address tags each.
    Every stop pose is a cell centre with at least :data:`STOP_RADIUS` clearance.
    ``chutes`` defaults to one per 13 cells of top wall, ``chargers`` to 6 (fewer if they do not fit).
    """
    for pname, value in (("blocks_x", blocks_x), ("blocks_y", blocks_y), ("block_w", block_w),
                         ("block_h", block_h), ("aisle", aisle)):
        _POSITIVE_INT(value, pname)
    if not (isinstance(resolution, (int, float)) and math.isfinite(resolution) and resolution > 0):
        raise WarehouseError(f"resolution: must be a number > 0 (got {resolution!r})")
    # stops sit k cells away from the block they face: the first cell centre with STOP_RADIUS clearance
    k = math.ceil(STOP_RADIUS / resolution + 0.5 - 1e-9)
    if (aisle - k + 0.5) * resolution < STOP_RADIUS - 1e-9:
        raise WarehouseError(f"aisle: {aisle} cells of {resolution:g} m leave no stop pose with {STOP_RADIUS} m "
                             f"clearance; use at least {2 * k - 1} cells")
    main = aisle + 2
    width = 2 + 2 * aisle + blocks_x * block_w + (blocks_x - 1) * main
    height = 2 + 2 + main + blocks_y * block_h + (blocks_y - 1) * aisle + main + 2
    blocked = np.zeros((height, width), dtype=bool)
    blocked[[0, -1], :] = True
    blocked[:, [0, -1]] = True

    interior = width - 2
    max_chutes = interior // 8  # keeps >= 3 free cells between chutes and beside the walls
    n_chutes = min(max(1, interior // 13), max_chutes) if chutes is None else chutes
    if not 1 <= n_chutes <= max_chutes:
        raise WarehouseError(f"chutes: {n_chutes} do not fit on a top wall of {interior} cells (1..{max_chutes})")
    charger_cols = list(range(4, width - 4, 4))
    n_chargers = min(6, len(charger_cols)) if chargers is None else chargers
    if not 1 <= n_chargers <= len(charger_cols):
        raise WarehouseError(f"chargers: {n_chargers} do not fit on a bottom wall of {interior} cells "
                             f"(1..{len(charger_cols)})")

    stations: list[Station] = []
    for i in range(n_chutes):
        col = 1 + int((i + 0.5) * interior / n_chutes)
        blocked[1:3, col - 1:col + 2] = True
        stations.append(Station(f"chute_{i + 1}", "chute", *_centre(col, 2 + k, resolution)))

    rack_top = 3 + main
    site_cols_in_block = _spread(block_w, max(1, round(block_w * resolution / 8.0)))
    sites: list[tuple[int, int]] = []
    for by in range(blocks_y):
        top = rack_top + by * (block_h + aisle)
        for bx in range(blocks_x):
            left = 1 + aisle + bx * (block_w + main)
            blocked[top:top + block_h, left:left + block_w] = True
            sites += [(left + c, top + block_h - 1 + k) for c in site_cols_in_block]
    digits = max(2, len(str(len(sites))))
    for i, (col, row) in enumerate(sites):
        site = f"B{i + 1:0{digits}d}"
        tags = tuple(f"{site}-{j + 1:02d}" for j in range(2 + i % 3))
        stations.append(Station(site, "storage", *_centre(col, row, resolution), tags))

    for i, col in enumerate(charger_cols[:n_chargers]):
        blocked[height - 3:height - 1, col] = True
        stations.append(Station(f"charger_{i + 1}", "charger", *_centre(col, height - 3 - k, resolution)))
    return Warehouse(GridMap(blocked, resolution, name), _index(stations), name)


def _centre(col: int, row: int, resolution: float) -> tuple[float, float]:
    """Centre (x, y) in metres of cell (col, row), as :meth:`GridMap.centre`."""
    return (col + 0.5) * resolution, (row + 0.5) * resolution


def _spread(length: int, n: int) -> list[int]:
    """n offsets spread evenly over ``length`` cells (centres of n equal parts)."""
    return [int((j + 0.5) * length / n) for j in range(n)]


__all__ = ["STATION_TYPES", "STOP_RADIUS", "Station", "Warehouse", "WarehouseError", "config_dirs", "config_path",
           "generate_warehouse", "load_warehouse", "parse_warehouse", "save_warehouse"]
