"""The plan file is a fixed contract (docs/ARCHITECTURE.md, "Scenario and plan files"): for the same
plan, ``write_plan`` writes the same bytes, and a plan file read back is written again unchanged.

The files in ``test/data/plan_files`` were written before the planner network became a typed
result (``Plan.network``), with the planning time set to 0.125 s (the one field that varies
between runs). Regenerate them only for a deliberate change of the plans themselves:
``.venv/bin/python test/test_plan_file.py`` (and say why in the commit).
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fleet_planner.model import Network, Plan  # noqa: E402
from fleet_planner.planners import get_planner  # noqa: E402
from fleet_planner.scenario import Scenario, load_scenario, parse_scenario, plan_to_dict, read_plan, write_plan  # noqa: E402

DATA = Path(__file__).resolve().parent / "data" / "plan_files"

# three robots crossing between shelf blocks: two links, no re-ordering (the CLI tests' scenario)
from test_cli import CROSSING  # noqa: E402

# a robot parks in the middle aisle that another one drives through: unbounded times (null in the
# file), re-routings and (box mode, prior) re-orderings
CORRIDOR = """\
map:
  rows: ["..........", ".@@@@@@@@.", "..........", ".@@@@@@@@.", ".........."]
robots:
  - {id: a, radius: 0.4, max_speed: 1.0, start: [0.5, 0.5], goal: [5.5, 2.5]}
  - {id: b, radius: 0.4, max_speed: 1.0, start: [0.5, 2.5], goal: [9.5, 2.5]}
  - {id: c, radius: 0.35, max_speed: 0.8, start: [9.5, 4.5], goal: [0.5, 4.5]}
  - {id: d, radius: 0.3, max_speed: 0.9, start: [9.5, 0.5], goal: [2.5, 0.5]}
"""

SCENARIOS = ("corridor", "crossing", "default")
PLANNERS = ("md", "md-box", "prior", "md-departure")   # md: v2 (holds, route choice); md-departure: the paper's


def scenario(name: str) -> Scenario:
    if name == "default":
        return load_scenario(ROOT / "config" / "default_scenario.yaml")
    return parse_scenario(yaml.safe_load({"corridor": CORRIDOR, "crossing": CROSSING}[name]), ROOT)


def write(scenario_name: str, planner: str, path: Path) -> None:
    sc = scenario(scenario_name)
    plan = get_planner(planner).plan(sc.grid, sc.robots)
    plan.planning_time_s = 0.125
    write_plan(plan, path)


CASES = [(s, p) for s in SCENARIOS for p in PLANNERS]


@pytest.mark.parametrize("scenario_name,planner", CASES, ids=[f"{s}-{p}" for s, p in CASES])
def test_write_plan_writes_the_pinned_bytes(tmp_path, scenario_name, planner):
    out = tmp_path / "plan.json"
    write(scenario_name, planner, out)
    assert out.read_bytes() == (DATA / f"{scenario_name}-{planner}.json").read_bytes()


@pytest.mark.parametrize("scenario_name,planner", CASES, ids=[f"{s}-{p}" for s, p in CASES])
def test_a_plan_file_read_back_is_written_unchanged(tmp_path, scenario_name, planner):
    pinned = DATA / f"{scenario_name}-{planner}.json"
    write_plan(read_plan(pinned), tmp_path / "again.json")
    assert (tmp_path / "again.json").read_bytes() == pinned.read_bytes()



@pytest.mark.parametrize("planner", ["md", "md-box"])
def test_the_network_read_back_is_the_planners(planner):
    sc = scenario("corridor")
    plan = get_planner(planner).plan(sc.grid, sc.robots)
    back = read_plan(DATA / f"corridor-{planner}.json")
    assert isinstance(back.network, Network) and back.network == plan.network
    assert back.network.mode == ("box" if planner == "md-box" else "exact")
    assert any(float("inf") in (link.M, link.D, link.ke) for link in back.network.links)   # written as null
    assert back.info == plan.info
    # md v2 also says how many robots took a detour (route choice) and how many moves of its
    # improvement search stayed; md-box is the paper's method
    v2 = {"detours", "improved"} if planner == "md" else set()
    assert set(plan.info) == {"reorders", "reroutes", "regions"} | v2


def test_the_network_is_not_an_info_entry():
    plan = read_plan(DATA / "crossing-md.json")
    with pytest.raises(ValueError, match="the network is Plan.network"):
        Plan("md", plan.paths, 0.0, {"network": plan_to_dict(plan)["info"]["network"]})
    plan.info["mode"] = "box"
    with pytest.raises(ValueError, match="mode belong to the plan's network"):
        plan_to_dict(plan)


if __name__ == "__main__":
    DATA.mkdir(parents=True, exist_ok=True)
    for s, p in CASES:
        write(s, p, DATA / f"{s}-{p}.json")
        print(DATA / f"{s}-{p}.json")
