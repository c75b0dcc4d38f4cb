"""Holds anywhere along the path (issue 8, deliverable 1): the md scheduler lets a robot wait at
any vertex of its fixed path, against the higher robots' trajectories as timed (holds included).

The constructed case, worked out by hand (radii 0.5 m, margin 0, so R = 1 m; speeds 1 m/s;
priority 1, 2, j):
  robot 1: (11, 1) -> (11, 21), at y = 11 at t = 10
  robot 2: (3, 7)  -> (3, 21),  at y = 11 at t = 4
  robot j: (1, 11) -> (6, 11) -> (16, 11): 5 m then 10 m
Robot j crosses robot 2's line (x = 3) 2 m after its start and robot 1's (x = 11) 10 m after it.
Crossing a robot that moves at right angles at the same speed: with j at the crossing at t = c + s
where the other one is there at c, they are sqrt(s^2 + (s - e)^2) apart at time c + s ... the
smallest distance over t of two such discs is |e| / sqrt(2), e = (j's time at the crossing) -
(the other's), so they collide iff |e| < sqrt(2).
  departure only (delay d): robot 2: |(d + 2) - 4| < sqrt 2 -> d in (0.586, 3.414);
                            robot 1: |(d + 10) - 10| < sqrt 2 -> d in (-1.414, 1.414);
                            so d = 2 + sqrt 2, arrival 15 + 2 + sqrt 2 = 18.414.
  holds: leave at 0 (passes x = 3 at t = 2: |2 - 4| >= sqrt 2), reach (6, 11) at t = 5, wait there
         (it is 5 m from robot 1's line and 3 m from robot 2's) and leave at E with
         |(E + 5) - 10| >= sqrt 2: E = 5 + sqrt 2, arrival E + 10 = 15 + sqrt 2 = 16.414.
"""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from test_plans_valid import scenarios

from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap
from fleet_planner.model import Plan, PlanningError, RobotSpec, TimedPath
from fleet_planner.planners import get_planner
from fleet_planner.planners.md import MDPlanner, schedule_paths

IDS = ["1", "2", "j"]
PATHS = [np.array([[11, 1], [11, 21]], float), np.array([[3, 7], [3, 21]], float),
         np.array([[1, 11], [6, 11], [16, 11]], float)]
RADII = [0.5, 0.5, 0.5]
SPEEDS = [1.0, 1.0, 1.0]
GRID = GridMap(np.zeros((23, 18), dtype=bool), 1.0, "open")
SPECS = [RobotSpec(i, r, v, tuple(p[0]), tuple(p[-1])) for i, r, v, p in zip(IDS, RADII, SPEEDS, PATHS)]
S2 = math.sqrt(2)


@pytest.mark.parametrize("holds", ["none", "anywhere"])
def test_a_hold_en_route_beats_a_departure_delay(holds):
    result = schedule_paths(IDS, PATHS, RADII, SPEEDS, mode="exact", holds=holds)
    assert result.blocked is None
    assert check_plan(GRID, SPECS, Plan("md", result.paths)) == []
    j = result.paths[2]
    if holds == "none":
        assert j.start_time == pytest.approx(2 + S2)
        assert j.arrival_time == pytest.approx(17 + S2)
    else:
        assert j.start_time == pytest.approx(0.0)
        assert j.arrival_time == pytest.approx(15 + S2)
        # the hold: at (6, 11) from t = 5 to t = 5 + sqrt 2
        assert j.waypoints[:, :2].tolist() == [[1, 11], [6, 11], [6, 11], [16, 11]]
        assert j.waypoints[:, 2] == pytest.approx([0.0, 5.0, 5 + S2, 15 + S2])
        assert result.network.delay["j"] == pytest.approx(0.0)
        assert result.network.travel["j"] == pytest.approx(15 + S2)   # the hold counts as travel
    assert result.paths[0].arrival_time == pytest.approx(20.0)
    assert result.paths[1].arrival_time == pytest.approx(14.0)
    # the network under the final timing: j's links to both robots, none of them a collision
    assert {link.paper_tuple[:2] for link in result.network.links} == {("j", "1"), ("j", "2")}


def test_the_md_planner_holds_where_a_delay_costs_more():
    """The same case through the planner (given order, no margin): md-holds holds, md-departure delays."""
    arrivals = {}
    for name in ("md-holds", "md-departure"):
        plan = get_planner(name, order="given", margin=0.0).plan(GRID, SPECS)
        assert check_plan(GRID, SPECS, plan) == []
        arrivals[name] = plan.by_id()["j"].arrival_time
    assert arrivals["md-holds"] == pytest.approx(15 + S2)
    assert arrivals["md-departure"] == pytest.approx(17 + S2)


def test_holds_options():
    assert MDPlanner().holds == "anywhere" and get_planner("md").holds == "anywhere"   # md v2
    assert get_planner("md").detours == 2 and get_planner("md", holds="none").detours == 0
    assert get_planner("md-holds").holds == get_planner("md-routes").holds == "anywhere"
    assert get_planner("md-holds").detours == 0
    assert MDPlanner(mode="box").holds == "none"
    assert get_planner("md-departure").holds == "none"
    assert get_planner("md-box").holds == "none"
    with pytest.raises(ValueError, match="holds: must be one of none, anywhere"):
        MDPlanner(holds="sometimes")
    with pytest.raises(ValueError, match="holds: 'anywhere' needs mode 'exact'"):
        MDPlanner(mode="box", holds="anywhere")


def _from(path: TimedPath, t0: float) -> TimedPath:
    """What is left of a timed path from t0 (the robot where it is at t0, then the rest)."""
    wp = path.waypoints
    return TimedPath(path.robot_id, path.radius, np.vstack([[*path.position(t0), t0], wp[wp[:, 2] > t0]]))


@pytest.mark.parametrize("name", ["md", "md-holds", "md-departure", "md-routes"])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=scenarios(), t0=st.sampled_from([0.0, 0.7, 2.0, 4.5]))
def test_every_incremental_leg_is_valid(name, case, t0):
    """Plan half the robots, then the other half as new legs from t0 around what the first half is
    driving (holds included); everything from t0 on must be valid for the checker."""
    grid, robots = case
    first, new = robots[: len(robots) // 2], robots[len(robots) // 2:]
    planner = get_planner(name)
    try:
        plan = planner.plan(grid, first)
    except PlanningError:
        return
    fixed = [_from(p, t0) for p in plan.paths]
    here = np.array([f.waypoints[0, :2] for f in fixed])
    for r in new:   # a new robot appears where no fixed robot is at t0
        assume(all(np.hypot(*(np.array(r.start) - q)) >= r.radius + f.radius + 0.05 for q, f in zip(here, fixed)))
    try:
        legs = planner.plan_incremental(grid, new, plan.paths, t0)
    except PlanningError as err:
        assert err.failures and set(err.failures) <= {r.id for r in new}
        return
    assert [p.robot_id for p in legs] == [r.id for r in new]
    assert all(p.waypoints[0, 2] == pytest.approx(t0) for p in legs)
    specs = [RobotSpec(r.id, r.radius, r.max_speed, tuple(f.waypoints[0, :2]), r.goal)
             for r, f in zip(first, fixed)] + new
    assert check_plan(grid, specs, Plan(name, fixed + legs)) == []


def test_the_cli_takes_holds_and_names_the_option_when_it_is_bad(tmp_path, capsys):
    from fleet_planner import cli
    from fleet_planner.scenario import read_plan

    scen = tmp_path / "s.yaml"
    scen.write_text("map:\n  rows: ['........', '........']\n  resolution: 1.0\nrobots:\n"
                    "  - {id: a, radius: 0.4, max_speed: 1.0, start: [0.5, 0.5], goal: [7.5, 0.5]}\n"
                    "  - {id: b, radius: 0.4, max_speed: 1.0, start: [7.5, 1.5], goal: [0.5, 1.5]}\n")
    out = tmp_path / "p.json"
    for holds in ("none", "anywhere"):
        assert cli.main([str(scen), "--out", str(out), "--holds", holds, "--quiet"]) == cli.EXIT_OK
        assert read_plan(out).planner == "md"
    with pytest.raises(SystemExit) as stop:
        cli.main([str(scen), "--out", str(out), "--holds", "sometimes"])
    assert stop.value.code == 2
    assert "--holds" in capsys.readouterr().err
    assert cli.main([str(scen), "--out", str(out), "--planner", "md-box", "--holds", "anywhere"]) == cli.EXIT_INPUT
    assert "holds" in capsys.readouterr().err


def test_route_choice_takes_the_detour_when_waiting_costs_more():
    """A higher robot comes head-on down the direct corridor (row 2) and leaves by a side stub
    next to the lower robot's start; without route choice the lower one waits at its start until
    the corridor is clear, with it it drives the northern corridor (16 m instead of 12, but it
    arrives earlier)."""
    grid = GridMap.from_rows([".............",
                              ".@@@@@@@@@@@.",
                              ".............",
                              "@." + "@" * 9 + ".@",
                              "@." + "@" * 9 + ".@"])
    robots = [RobotSpec("h", 0.4, 1.0, (11.5, 4.5), (1.5, 4.5)),
              RobotSpec("j", 0.4, 1.0, (0.5, 2.5), (12.5, 2.5))]
    plans = {name: get_planner(name, order="given").plan(grid, robots) for name in ("md-holds", "md-routes")}
    for plan in plans.values():
        assert check_plan(grid, robots, plan) == []
    held, routed = plans["md-holds"].by_id()["j"], plans["md-routes"].by_id()["j"]
    assert held.arrival_time > 20.0                     # waited for h to clear the corridor
    assert routed.arrival_time == pytest.approx(16.0)   # 16 m at 1 m/s, no wait
    assert plans["md-routes"].info["detours"] >= 1
    assert np.any(routed.waypoints[:, 1] < 1.0)         # it took the northern corridor
