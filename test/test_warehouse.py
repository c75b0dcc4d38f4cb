"""The warehouse model: the shipped default warehouse and scenario, the loader's errors, the generator
used by benchmarks, and finding config files from a checkout or an install."""
from __future__ import annotations

import sys
import types
from pathlib import Path

import numpy as np
import pytest
import shapely
from scipy import ndimage

from fleet_planner import warehouse as wh
from fleet_planner.grid import GridMap
from fleet_planner.model import ROBOT_KINDS
from fleet_planner.scenario import load_scenario
from fleet_planner.warehouse import (
    STOP_RADIUS,
    Station,
    Warehouse,
    WarehouseError,
    config_path,
    generate_warehouse,
    load_warehouse,
    save_warehouse,
)


def _reachable_region(grid: GridMap, radius: float) -> np.ndarray:
    """Labels of 4-connected regions of cells whose centre leaves a disc of ``radius`` free."""
    rows, cols = np.nonzero(~grid.blocked)
    pts = shapely.points((cols + 0.5) * grid.resolution, (rows + 0.5) * grid.resolution)
    fits = np.zeros(grid.blocked.shape, dtype=bool)
    fits[rows, cols] = shapely.distance(grid.obstacle_geometry, pts) >= radius - 1e-9
    labels, _ = ndimage.label(fits)
    return labels


def _assert_stations_usable(w: Warehouse, radius: float = STOP_RADIUS) -> None:
    """Every stop leaves room for the robot and every stop can be reached from every other one."""
    labels = _reachable_region(w.grid, radius)
    regions = set()
    for s in w.stations.values():
        assert w.grid.clearance(s.x, s.y) >= radius - 1e-9, f"{s.name}: robot disc does not fit at {s.pose}"
        col, row = w.grid.cell_of(s.x, s.y)
        regions.add(int(labels[row, col]))
    assert len(regions) == 1 and 0 not in regions, f"stations lie in {len(regions)} separate regions"


# ---------------------------------------------------------------------------------------------
# the shipped default warehouse and scenario
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def default() -> Warehouse:
    return load_warehouse()


def test_default_warehouse_has_the_stations_of_paper_001(default):
    assert (default.grid.width, default.grid.height, default.grid.resolution) == (80, 50, 0.5)
    chutes, sites, chargers = (default.stations_of(t) for t in ("chute", "storage", "charger"))
    assert len(chutes) == 6 and len(sites) == 24 and len(chargers) >= 4
    assert [s.name for s in sites] == [f"B{i:02d}" for i in range(1, 25)]
    for s in sites:
        assert 2 <= len(s.tags) <= 4
        assert all(tag.startswith(s.name + "-") for tag in s.tags)
        assert all(default.station_for_tag(tag) is s for tag in s.tags)


def test_default_warehouse_stops_fit_the_largest_robot_and_are_connected(default):
    _assert_stations_usable(default)


def test_default_warehouse_has_no_passage_narrower_than_1_5_m(default):
    # every free cell lies in a free 3 x 3 cell (1.5 m) square: opening with that square changes nothing
    free = ~default.grid.blocked
    assert np.array_equal(ndimage.binary_opening(free, structure=np.ones((3, 3))), free)


def test_default_scenario_sends_all_kinds_from_chutes_and_chargers_to_storing_sites(default):
    scenario = load_scenario(config_path("default_scenario.yaml"))
    assert np.array_equal(scenario.grid.blocked, default.grid.blocked)
    assert scenario.grid.resolution == default.grid.resolution
    robots = scenario.robots
    assert len(robots) == 12
    assert {r.kind for r in robots} == set(ROBOT_KINDS)
    starts = {s.pose for s in default.stations_of("chute") + default.stations_of("charger")}
    goals = {s.pose for s in default.stations_of("storage")}
    for r in robots:
        assert 0.3 <= r.radius <= 0.45 and 0.8 <= r.max_speed <= 1.2, r.id
        assert r.start in starts, f"{r.id} does not start at a chute or a charger"
        assert r.goal in goals, f"{r.id} does not go to a storing site"
        for p in (r.start, r.goal):
            assert scenario.grid.clearance(*p) >= r.radius, f"{r.id}: disc does not fit at {p}"
    assert len({r.start for r in robots}) == len({r.goal for r in robots}) == 12


# ---------------------------------------------------------------------------------------------
# loading: errors name the field
# ---------------------------------------------------------------------------------------------
ROWS = ["@@@@@@", "@....@", "@....@", "@@@@@@"]


def _write(tmp_path: Path, stations: list[dict], map_block: dict | None = None) -> Path:
    import yaml

    path = tmp_path / "wh.yaml"
    path.write_text(yaml.safe_dump({"map": map_block or {"rows": ROWS, "resolution": 1.0}, "stations": stations}))
    return path


GOOD = [{"name": "c1", "type": "chute", "x": 1.5, "y": 1.5},
        {"name": "s1", "type": "storage", "x": 3.5, "y": 2.5, "tags": ["s1-01", "s1-02"], "capacity": 2}]


def test_load_small_warehouse(tmp_path):
    w = load_warehouse(_write(tmp_path, GOOD))
    assert list(w.stations) == ["c1", "s1"]
    assert w.stations["s1"] == Station("s1", "storage", 3.5, 2.5, ("s1-01", "s1-02"), 2)
    assert w.station_for_tag("s1-02").name == "s1"
    assert [s.name for s in w.stations_of("chute")] == ["c1"] and w.stations_of("charger") == []


@pytest.mark.parametrize("stations, expected", [
    ([{"name": "x", "type": "shelf", "x": 1.5, "y": 1.5}], "stations[0] ('x').type: 'shelf' is not one of"),
    ([{"name": "x", "type": "chute", "x": 0.5, "y": 1.5}], "stations[0] ('x'): pose (0.5, 1.5) is in a wall"),
    ([{"name": "x", "type": "chute", "x": 9.0, "y": 1.5}], "stations[0] ('x'): pose (9, 1.5) is outside"),
    ([GOOD[0], dict(GOOD[0], x=2.5)], "stations[1].name: duplicate name 'c1'"),
    ([GOOD[1], dict(GOOD[1], name="s2", tags=["s2-01", "s1-02"])],
     "stations[1] ('s2').tags: address tag 's1-02' is already used by station 's1'"),
    ([dict(GOOD[0], tags=["c1-01"])], "stations[0] ('c1').tags: only storing sites carry address tags"),
    ([{"name": "x", "type": "chute", "y": 1.5}], "stations[0].x: missing"),
    ([dict(GOOD[0], tag=["a"])], "stations[0].tag: unknown key"),
    ([dict(GOOD[0], x="1.5")], "stations[0].x: must be a finite number"),
    ([dict(GOOD[0], capacity=0)], "stations[0].capacity: must be an integer >= 1"),
    ([dict(GOOD[1], tags="s1-01")], "stations[0].tags: must be a list"),
])
def test_load_errors_name_the_field(tmp_path, stations, expected):
    path = _write(tmp_path, stations)
    with pytest.raises(WarehouseError) as err:
        load_warehouse(path)
    assert str(err.value).startswith(f"{path}: ")
    assert expected in str(err.value)


@pytest.mark.parametrize("map_block, expected", [
    ({"file": "missing.map", "resolution": 0.5}, "map: "),
    ({"rows": ROWS, "resolution": 0}, "map.resolution: must be > 0"),
    ({"rows": ROWS, "file": "x.map"}, "map: needs exactly one of"),
    ({"rows": ROWS, "origin": [0, 0]}, "map.origin: unknown key"),
])
def test_map_errors_name_the_field(tmp_path, map_block, expected):
    with pytest.raises(WarehouseError, match=expected):
        load_warehouse(_write(tmp_path, GOOD, map_block))


def test_lookups_reject_unknown_names(default):
    with pytest.raises(KeyError, match="no storing site has address tag 'Z99-01'"):
        default.station_for_tag("Z99-01")
    with pytest.raises(ValueError, match="station type 'shelf'"):
        default.stations_of("shelf")


# ---------------------------------------------------------------------------------------------
# generated warehouses
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("args", [(2, 3, 10, 2, 3, 0.5), (3, 2, 12, 1, 1, 1.0), (1, 1, 6, 3, 5, 0.5)])
def test_generated_warehouse_layout_and_stops(args):
    blocks_x, blocks_y, block_w, block_h, aisle, res = args
    w = generate_warehouse(*args)
    main = aisle + 2
    assert w.grid.width == 2 + 2 * aisle + blocks_x * block_w + (blocks_x - 1) * main
    assert w.grid.height == 6 + 2 * main + blocks_y * block_h + (blocks_y - 1) * aisle
    per_block = max(1, round(block_w * res / 8.0))
    assert len(w.stations_of("storage")) == blocks_x * blocks_y * per_block
    assert w.stations_of("chute") and w.stations_of("charger")
    _assert_stations_usable(w)


@pytest.mark.parametrize("kwargs, field", [
    (dict(aisle=2), "aisle"),           # 1 m at 0.5 m cells: no stop pose with 0.45 m clearance
    (dict(blocks_x=0), "blocks_x"),
    (dict(block_w=2.5), "block_w"),
    (dict(resolution=-1.0), "resolution"),
    (dict(chutes=50), "chutes"),
    (dict(chargers=0), "chargers"),
])
def test_generator_rejects_bad_parameters(kwargs, field):
    args = dict(blocks_x=2, blocks_y=2, block_w=10, block_h=2, aisle=3, resolution=0.5) | kwargs
    with pytest.raises(WarehouseError, match=f"^{field}: "):
        generate_warehouse(**args)


def test_save_then_load_gives_the_same_warehouse(tmp_path):
    w = generate_warehouse(2, 2, 12, 2, 3, 0.5, "round trip", chutes=3, chargers=2)
    path = save_warehouse(w, tmp_path / "w.yaml", comment="a comment\nover two lines")
    assert path.read_text().startswith("# a comment\n# over two lines\n")
    back = load_warehouse(path)
    assert np.array_equal(back.grid.blocked, w.grid.blocked) and back.grid.resolution == 0.5
    assert back.stations == w.stations and back.name == "round trip"


# ---------------------------------------------------------------------------------------------
# config files: checkout, ament share directory, sys.prefix
# ---------------------------------------------------------------------------------------------
def test_config_path_in_a_checkout_is_the_repo_config_dir():
    repo = Path(__file__).resolve().parent.parent
    assert config_path("warehouse.yaml") == repo / "config" / "warehouse.yaml"


@pytest.fixture
def installed(monkeypatch, tmp_path):
    """Pretend the package is installed: no checkout beside it, an ament share dir and a venv prefix."""
    monkeypatch.setattr(wh, "_SOURCE_ROOT", tmp_path / "site-packages")
    share = tmp_path / "ament" / "share" / "fleet_planner"
    prefix = tmp_path / "venv"
    (share / "config").mkdir(parents=True)
    (prefix / "share" / "fleet_planner" / "config").mkdir(parents=True)
    monkeypatch.setattr(sys, "prefix", str(prefix))
    packages = types.ModuleType("ament_index_python.packages")

    def get_package_share_directory(name):
        if name != "fleet_planner" or not (share / "config").exists():
            raise LookupError(name)  # the real one raises PackageNotFoundError, a KeyError
        return str(share)

    packages.get_package_share_directory = get_package_share_directory
    parent = types.ModuleType("ament_index_python")
    parent.packages = packages
    monkeypatch.setitem(sys.modules, "ament_index_python", parent)
    monkeypatch.setitem(sys.modules, "ament_index_python.packages", packages)
    return share / "config", prefix / "share" / "fleet_planner" / "config"


def test_config_path_prefers_the_ament_share_dir_then_sys_prefix(installed):
    ament_dir, prefix_dir = installed
    (prefix_dir / "a.yaml").write_text("x: 1\n")
    assert config_path("a.yaml") == prefix_dir / "a.yaml"
    (ament_dir / "a.yaml").write_text("x: 1\n")
    assert config_path("a.yaml") == ament_dir / "a.yaml"
    ament_dir.rename(ament_dir.with_name("gone"))  # package unknown to ament: fall back to sys.prefix
    assert config_path("a.yaml") == prefix_dir / "a.yaml"


def test_config_path_says_where_it_looked(installed):
    with pytest.raises(FileNotFoundError, match="'nope.yaml' not found in any of: .*ament.*venv"):
        config_path("nope.yaml")
