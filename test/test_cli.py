"""``fleet-plan``: exit codes, and a plan file only when the plan is valid."""
from __future__ import annotations

import importlib.util

import pytest

from fleet_planner import cli, planners
from fleet_planner.checker import check_plan
from fleet_planner.model import Plan, PlanningError, timed_path_from_polyline
from fleet_planner.planners.base import Planner
from fleet_planner.scenario import load_scenario, read_plan

needs_md = pytest.mark.skipif(importlib.util.find_spec("fleet_planner.planners.md") is None,
                              reason="the md planner is not written yet")

CROSSING = """\
map:
  rows: ["..........", "..@@..@@..", "..........", "..@@..@@..", "..........", ".........."]
  resolution: 1.0
robots:
  - {id: a, radius: 0.4, max_speed: 1.0, start: [2.5, 2.5], goal: [9.5, 2.5]}
  - {id: b, radius: 0.4, max_speed: 1.0, start: [4.5, 0.5], goal: [4.5, 5.5]}
  - {id: c, kind: manipulator, radius: 0.35, max_speed: 0.8, start: [7.5, 4.5], goal: [0.5, 4.5]}
"""

# two robots swapping ends of a one-cell corridor: no plan exists
SWAP = """\
map:
  rows: [".....", "@@@@@"]
robots:
  - {id: a, radius: 0.4, max_speed: 1.0, start: [0.5, 0.5], goal: [4.5, 0.5]}
  - {id: b, radius: 0.4, max_speed: 1.0, start: [4.5, 0.5], goal: [0.5, 0.5]}
"""


@pytest.fixture
def scenario(tmp_path):
    def write(text: str, name: str = "scenario.yaml"):
        path = tmp_path / name
        path.write_text(text)
        return path
    return write


class StraightLines(Planner):
    """A planner with a bug: everyone drives straight at once, whatever is in the way."""

    name = "straight"

    def plan(self, grid, robots, progress=None):
        if progress:
            progress(1, 1, "driving straight")
        return Plan(self.name, [timed_path_from_polyline(r.id, r.radius, [r.start, r.goal], r.max_speed)
                                for r in robots], 0.0)

    def plan_incremental(self, grid, robots, fixed, t0):
        raise NotImplementedError


class Refuses(Planner):
    name = "refuses"

    def plan(self, grid, robots, progress=None):
        raise PlanningError({robots[0].id: "no path to the goal", robots[1].id: "blocked by a"})

    def plan_incremental(self, grid, robots, fixed, t0):
        raise PlanningError({robots[0].id: "no path to the goal"})


@pytest.fixture
def fake_planners(monkeypatch):
    monkeypatch.setitem(planners._REGISTRY, "straight", planners.Variant(f"{__name__}:StraightLines"))
    monkeypatch.setitem(planners._REGISTRY, "refuses", planners.Variant(f"{__name__}:Refuses"))


@needs_md
def test_plans_checks_writes_and_plots(scenario, tmp_path, capsys):
    path = scenario(CROSSING)
    out, png = tmp_path / "plan.json", tmp_path / "plan.png"
    assert cli.main([str(path), "--out", str(out), "--plot", str(png), "--check", "--quiet"]) == cli.EXIT_OK
    sc, plan = load_scenario(path), read_plan(out)
    assert check_plan(sc.grid, sc.robots, plan) == []
    assert plan.planner == "md"
    assert sorted(p.robot_id for p in plan.paths) == ["a", "b", "c"]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = capsys.readouterr().out
    assert "manipulator" in text and "makespan" in text and "sum of arrivals" in text
    assert "check: valid" in text


@needs_md
def test_no_plan_possible_exits_2_naming_the_robots(scenario, tmp_path, capsys):
    out = tmp_path / "plan.json"
    assert cli.main([str(scenario(SWAP)), "--out", str(out), "--quiet"]) == cli.EXIT_INPUT
    assert not out.exists()
    err = capsys.readouterr().err
    assert "nothing written" in err and ("a:" in err or "b:" in err)


def test_planning_error_lists_every_failure(fake_planners, scenario, tmp_path, capsys):
    out = tmp_path / "plan.json"
    assert cli.main([str(scenario(CROSSING)), "--out", str(out), "--planner", "refuses"]) == cli.EXIT_INPUT
    assert not out.exists()
    err = capsys.readouterr().err
    assert "a: no path to the goal" in err and "b: blocked by a" in err


def test_an_invalid_plan_is_never_written(fake_planners, scenario, tmp_path, capsys):
    out = tmp_path / "plan.json"
    assert cli.main([str(scenario(CROSSING)), "--out", str(out), "--planner", "straight"]) == cli.EXIT_INVALID_PLAN
    assert not out.exists()
    err = capsys.readouterr().err
    assert "INVALID plan" in err and "[collision] a, b" in err and "[collision] b, c" in err


@pytest.mark.parametrize("text, message", [
    (CROSSING.replace("radius: 0.35", "radius: -1"), "robots[2].radius: must be a finite number > 0"),
    (CROSSING.replace('rows: ["..........", ', 'file: missing.map\n  rows: ["..........", '),
     "map: needs exactly one of"),
    ("map:\n  file: missing.map\nrobots: []\n", "map.file: "),
])
def test_bad_scenario_exits_2(scenario, tmp_path, capsys, text, message):
    out = tmp_path / "plan.json"
    assert cli.main([str(scenario(text)), "--out", str(out), "--planner", "prior"]) == cli.EXIT_INPUT
    assert not out.exists()
    assert message in capsys.readouterr().err


def test_unknown_planner_is_a_usage_error(scenario, tmp_path):
    with pytest.raises(SystemExit) as stop:
        cli.main([str(scenario(CROSSING)), "--out", str(tmp_path / "p.json"), "--planner", "nope"])
    assert stop.value.code == 2


@needs_md
def test_planner_variants_come_from_the_registry(scenario, tmp_path, capsys):
    path, out = scenario(CROSSING), tmp_path / "plan.json"
    assert cli.main([str(path), "--out", str(out), "--planner", "md-box", "--quiet"]) == cli.EXIT_OK
    assert read_plan(out).network.mode == "box"
    assert cli.main([str(path), "--out", str(out), "--planner", "md", "--mode", "box", "--quiet"]) == cli.EXIT_OK
    assert read_plan(out).network.mode == "box"
    out.unlink()
    assert cli.main([str(path), "--out", str(out), "--planner", "md-box", "--mode", "exact"]) == cli.EXIT_INPUT
    assert not out.exists()
    assert "mode is 'box' in this variant" in capsys.readouterr().err
