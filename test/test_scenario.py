"""Scenario and plan files: every bad input names its field; good files round-trip."""
from __future__ import annotations

import json

import numpy as np
import pytest

from fleet_planner.checker import check_plan
from fleet_planner.model import Link, Network, Plan, RobotSpec, timed_path_from_polyline
from fleet_planner.scenario import (
    ScenarioError,
    dump_scenario,
    load_scenario,
    parse_scenario,
    plan_to_dict,
    read_plan,
    scenario_from_movingai,
    write_plan,
)

ROWS = ["........",
        "..@@....",
        "........",
        "........"]

MOVINGAI_MAP = "type octile\nheight 4\nwidth 8\nmap\n" + "\n".join(ROWS) + "\n"


def good() -> dict:
    return {"map": {"rows": list(ROWS), "resolution": 1.0},
            "robots": [{"id": "r1", "kind": "cargo", "radius": 0.35, "max_speed": 1.0,
                        "start": [0.5, 0.5], "goal": [7.5, 3.5]},
                       {"id": "r2", "radius": 0.45, "max_speed": 0.8, "start": [7.5, 0.5], "goal": [0.5, 3.5]}]}


def test_a_good_scenario_parses(tmp_path):
    sc = parse_scenario(good(), tmp_path)
    assert sc.grid.blocked.shape == (4, 8) and sc.grid.blocked[1, 2]
    assert sc.robots[0] == RobotSpec("r1", 0.35, 1.0, (0.5, 0.5), (7.5, 3.5), "cargo")
    assert sc.robots[1].kind == "cargo"  # the default


def edit(path, value):
    """``good()`` with the field at ``path`` (keys / indices) set to value, or deleted for DELETE."""
    data = good()
    node = data
    for key in path[:-1]:
        node = node[key]
    if value is DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


DELETE = object()

BAD = [
    # (where, value, expected start of the message, a fragment of the reason)
    (("extra",), 1, "extra: unknown key", "allowed: map, robots"),
    (("robots",), DELETE, "robots: missing", ""),
    (("robots",), [], "robots: must be a non-empty list", ""),
    (("map",), DELETE, "map: missing", ""),
    (("map", "size"), 3, "map.size: unknown key", "allowed: file, rows, resolution"),
    (("map", "rows"), DELETE, "map: needs exactly one of 'file'", ""),
    (("map", "file"), "x.map", "map: needs exactly one of 'file'", ""),
    (("map", "rows", 2), "...", "map.rows[2]: has 3 cells", "map.rows[0] has 8"),
    (("map", "rows", 1), 7, "map.rows[1]: must be a non-empty string", "got 7"),
    (("map", "resolution"), 0, "map.resolution: must be a finite number > 0", "got 0"),
    (("map", "resolution"), float("inf"), "map.resolution: must be a finite number > 0", "inf"),
    (("robots", 1, "priority"), 2, "robots[1].priority: unknown key", "allowed: id, kind"),
    (("robots", 0, "radius"), DELETE, "robots[0].radius: missing", ""),
    (("robots", 1, "id"), "", "robots[1].id: must be a non-empty string", ""),
    (("robots", 1, "id"), 7, "robots[1].id: must be a non-empty string", "quote numbers"),
    (("robots", 1, "id"), "r1", "robots[1].id: duplicate id 'r1'", "also robots[0]"),
    (("robots", 1, "radius"), -1.0, "robots[1].radius: must be a finite number > 0", "got -1.0"),
    (("robots", 1, "radius"), float("nan"), "robots[1].radius: must be a finite number > 0", "nan"),
    (("robots", 1, "radius"), "0.4", "robots[1].radius: must be a finite number > 0", "'0.4'"),
    (("robots", 1, "radius"), True, "robots[1].radius: must be a finite number > 0", "True"),
    (("robots", 0, "max_speed"), float("inf"), "robots[0].max_speed: must be a finite number > 0", "inf"),
    (("robots", 0, "max_speed"), 0, "robots[0].max_speed: must be a finite number > 0", "got 0"),
    (("robots", 0, "kind"), "drone", "robots[0].kind: must be one of cargo", "'drone'"),
    (("robots", 0, "start"), [1.5], "robots[0].start: must be a list of 2 finite numbers", "[1.5]"),
    (("robots", 0, "start"), [1.5, float("nan")], "robots[0].start: must be a list of 2 finite", "nan"),
    (("robots", 0, "goal"), ["a", 1], "robots[0].goal: must be a list of 2 finite numbers", ""),
    (("robots", 0, "goal"), [9.5, 1.5], "robots[0].goal: (9.5, 1.5) is outside the 8 m x 4 m map", ""),
    (("robots", 0, "goal"), [2.5, 1.5], "robots[0].goal: a disc of radius 0.35 m at (2.5, 1.5) is not in free",
     "clearance 0.000"),
    (("robots", 1, "start"), [7.8, 0.5], "robots[1].start: a disc of radius 0.45 m", "clearance 0.200"),
    (("robots", 1, "start"), [1.2, 0.5], "robots[1].start: disc overlaps the start disc of robots[0]",
     "0.700 m apart < 0.8 m"),
    (("robots", 1, "goal"), [7.5, 2.8], "robots[1].goal: disc overlaps the goal disc of robots[0]", ""),
]


@pytest.mark.parametrize("where, value, message, reason", BAD, ids=[m.split(":")[0] + "-" + str(i)
                                                                     for i, (_, _, m, _) in enumerate(BAD)])
def test_bad_scenarios_name_the_field(tmp_path, where, value, message, reason):
    with pytest.raises(ScenarioError) as err:
        parse_scenario(edit(where, value), tmp_path)
    assert str(err.value).startswith(message)
    assert reason in str(err.value)


def test_not_a_mapping(tmp_path):
    with pytest.raises(ScenarioError, match=r"^scenario: must be a mapping"):
        parse_scenario(["map"], tmp_path)
    with pytest.raises(ScenarioError, match=r"^robots\[0\]: must be a mapping"):
        parse_scenario(edit(("robots", 0), "r1"), tmp_path)


def test_map_file_relative_to_the_scenario(tmp_path):
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "small.map").write_text(MOVINGAI_MAP)
    data = edit(("map", "rows"), DELETE)
    data["map"]["file"] = "maps/small.map"
    sc = parse_scenario(data, tmp_path)
    assert (sc.grid.blocked == parse_scenario(good(), tmp_path).grid.blocked).all()
    assert sc.map_file == (tmp_path / "maps" / "small.map").resolve()


@pytest.mark.parametrize("content, reason", [(None, "cannot read map file"),
                                             ("height 4\nwidth 8\n" + "\n".join(ROWS), "not a MovingAI .map")])
def test_bad_map_file(tmp_path, content, reason):
    if content is not None:
        (tmp_path / "bad.map").write_text(content)
    data = edit(("map", "rows"), DELETE)
    data["map"]["file"] = "bad.map"
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data, tmp_path)
    assert str(err.value).startswith("map.file: ") and reason in str(err.value)


def test_yaml_file_errors(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read scenario file"):
        load_scenario(tmp_path / "nope.yaml")
    (tmp_path / "broken.yaml").write_text("map: [unclosed\n")
    with pytest.raises(ScenarioError, match="not valid YAML"):
        load_scenario(tmp_path / "broken.yaml")
    (tmp_path / "twice.yaml").write_text("map:\n  rows: ['....']\n  rows: ['...']\nrobots: []\n")
    with pytest.raises(ScenarioError, match=r"line 3: duplicate key 'rows'"):
        load_scenario(tmp_path / "twice.yaml")


@pytest.mark.parametrize("with_file", [False, True])
def test_scenario_round_trip(tmp_path, with_file):
    data = good()
    if with_file:
        (tmp_path / "m.map").write_text(MOVINGAI_MAP)
        data["map"] = {"file": "m.map", "resolution": 0.5}
        data["robots"] = [{"id": "odd: id", "kind": "manipulator_forklift", "radius": 0.2, "max_speed": 0.1 + 0.2,
                           "start": [0.25, 0.25], "goal": [3.75, 1.75]}]
    sc = parse_scenario(data, tmp_path)
    out = tmp_path / "sub" / "again.yaml"
    out.parent.mkdir()
    dump_scenario(sc, out)
    back = load_scenario(out)
    assert back.robots == sc.robots
    assert (back.grid.blocked == sc.grid.blocked).all() and back.grid.resolution == sc.grid.resolution
    assert back.source == out and back.map_file == sc.map_file


def make_plan() -> Plan:
    a = timed_path_from_polyline("r1", 0.35, [(0.5, 0.5), (4.5, 0.5), (7.5, 3.5)], 1.0, departure=0.3)
    b = timed_path_from_polyline("r2", 0.45, [(7.5, 0.5), (5.0, 2.5), (0.5, 3.5)], 0.8, departure=1 / 3)
    network = Network(["r1", "r2"], {"r1": np.float64(0.3), "r2": 1 / 3}, {"r1": 9.24, "r2": 7.75},
                      [Link("r1", "r2", 1, 2.5, 0.75, 1.25, np.inf, 4.0, 5.5)], "exact")
    return Plan("md", [a, b], 0.125, {"regions": np.int64(4)}, network)


def test_plan_round_trip_and_still_valid(tmp_path):
    plan, sc = make_plan(), parse_scenario(good(), tmp_path)
    assert check_plan(sc.grid, sc.robots, plan) == []
    write_plan(plan, tmp_path / "plan.json")
    back = read_plan(tmp_path / "plan.json")
    assert back.planner == "md" and back.planning_time_s == 0.125
    assert back.info == {"regions": 4}
    assert back.network == plan.network and back.network.links[0].ke == np.inf
    for p, q in zip(plan.paths, back.paths):
        assert p.robot_id == q.robot_id and p.radius == q.radius
        np.testing.assert_allclose(p.waypoints, q.waypoints, atol=1e-6)
    # rounding to 6 decimals must not turn a plan at top speed into a speeding one
    assert check_plan(sc.grid, sc.robots, back) == []


def test_plan_dict_has_exactly_the_contract_keys():
    d = plan_to_dict(make_plan())
    assert list(d) == ["planner", "planning_time_s", "robots", "info"]
    assert set(d["robots"][0]) == {"id", "radius", "waypoints"}
    assert "info" not in plan_to_dict(Plan("x", make_plan().paths))


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(extra=1), "extra: unknown key"),
    (lambda d: d.pop("planning_time_s"), "planning_time_s: missing"),
    (lambda d: d.update(planning_time_s=-1), "planning_time_s: must be a finite number >= 0"),
    (lambda d: d["robots"][1].update(speed=2), "robots[1].speed: unknown key"),
    (lambda d: d["robots"][0].update(waypoints=[]), "robots[0].waypoints: must be a non-empty list"),
    (lambda d: d["robots"][0]["waypoints"][1].pop(), "robots[0].waypoints[1]: must be [x, y, t]"),
    (lambda d: d["robots"][0]["waypoints"][1].__setitem__(2, "soon"), "robots[0].waypoints[1]: must be [x, y, t]"),
    (lambda d: d["robots"][1].update(radius=0), "robots[1].radius: must be a finite number > 0"),
    (lambda d: d["info"]["network"]["links"][0].update(ke="later"),
     "info.network.links[0].ke: must be a number or null"),
    (lambda d: d["info"]["network"]["nodes"]["r2"].pop("travel"), "info.network.nodes['r2'].travel: missing"),
    (lambda d: d["info"].update(mode="boxes"), "info.mode: must be one of box, exact"),
])
def test_bad_plan_files_name_the_field(tmp_path, mutate, message):
    data = plan_to_dict(make_plan())
    mutate(data)
    (tmp_path / "plan.json").write_text(json.dumps(data))
    with pytest.raises(ScenarioError) as err:
        read_plan(tmp_path / "plan.json")
    assert str(err.value).startswith(message)


def test_plan_file_not_json(tmp_path):
    (tmp_path / "plan.json").write_text("{")
    with pytest.raises(ScenarioError, match="not valid JSON"):
        read_plan(tmp_path / "plan.json")


def write_movingai(tmp_path):
    rows = ["......",
            ".@@@..",
            "......"]
    (tmp_path / "w.map").write_text("type octile\nheight 3\nwidth 6\nmap\n" + "\n".join(rows) + "\n")
    entries = [((0, 0), (5, 2)),   # ok
               ((2, 1), (0, 2)),   # start in a wall: skipped
               ((0, 0), (4, 2)),   # same start cell as the first: skipped
               ((5, 0), (5, 2)),   # same goal cell as the first: skipped
               ((5, 0), (0, 2)),   # ok
               ((4, 0), (1, 2))]   # ok
    lines = ["version 1"] + [f"0\tw.map\t6\t3\t{s[0]}\t{s[1]}\t{g[0]}\t{g[1]}\t5.0" for s, g in entries]
    (tmp_path / "w.scen").write_text("\n".join(lines) + "\n")
    return tmp_path / "w.map", tmp_path / "w.scen"


def test_scenario_from_movingai_skips_unusable_entries(tmp_path):
    m, s = write_movingai(tmp_path)
    sc = scenario_from_movingai(m, s, n=3, seed=7, kinds=("cargo", "manipulator"))
    assert [(r.start, r.goal) for r in sc.robots] == [((0.5, 0.5), (5.5, 2.5)), ((5.5, 0.5), (0.5, 2.5)),
                                                       ((4.5, 0.5), (1.5, 2.5))]
    assert all(0.35 <= r.radius <= 0.45 and 0.7 <= r.max_speed <= 1.0 for r in sc.robots)
    assert scenario_from_movingai(m, s, n=3, seed=7, kinds=("cargo", "manipulator")).robots == sc.robots
    assert scenario_from_movingai(m, s, n=3, seed=8).robots != sc.robots
    dump_scenario(sc, tmp_path / "bench.yaml")
    assert load_scenario(tmp_path / "bench.yaml").robots == sc.robots
    with pytest.raises(ScenarioError, match="only 3 usable entries, 4 asked for"):
        scenario_from_movingai(m, s, n=4, seed=7)


def test_scenario_from_movingai_respects_resolution(tmp_path):
    """At 0.5 m cells a disc of r >= 0.35 does not fit between the wall and the edge: nothing fits."""
    m, s = write_movingai(tmp_path)
    sc = scenario_from_movingai(m, s, n=1, seed=0, radius=(0.2, 0.2), resolution=0.5)
    assert sc.robots[0].start == (0.25, 0.25) and sc.grid.resolution == 0.5
    with pytest.raises(ScenarioError):
        scenario_from_movingai(m, s, n=1, seed=0, resolution=0.5)
