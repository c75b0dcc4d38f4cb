"""md's legs (plan_incremental) with route choice in time: when waiting on the shortest route costs
more than a detour, the leg takes the detour (the independent checker judges the leg)."""
from __future__ import annotations

import numpy as np
import pytest

import fleet_planner.planners.md as md
from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap
from fleet_planner.model import Plan, RobotSpec, TimedPath
from fleet_planner.planners import get_planner

# two corridors joined at both ends and in the middle: y = 0.5 (direct, 12 m from r's start to its
# goal) and y = 2.5 (the way round: 1 + 2 + 14 + 2 + 1 = 20 m); a pocket at (7.5, 3.5)
GRID = GridMap.from_rows(["...............", ".@@@@@@.@@@@@@.", "...............", "@@@@@@@.@@@@@@@"])
# f stands in the direct corridor until t = 40, then drives up into the pocket and parks there
F = TimedPath("f", 0.4, np.array([[7.5, 0.5, 0.0], [7.5, 0.5, 40.0], [7.5, 2.5, 42.0], [7.5, 3.5, 43.0]]))
F_SPEC = RobotSpec("f", 0.4, 1.0, (7.5, 0.5), (7.5, 3.5))
R = RobotSpec("r", 0.4, 1.0, (1.5, 0.5), (13.5, 0.5))


def test_a_leg_goes_the_way_round_when_waiting_in_the_direct_corridor_costs_more(monkeypatch):
    leg = get_planner("md").plan_incremental(GRID, [R], [F], 0.0)[0]
    assert check_plan(GRID, [F_SPEC, R], Plan("md", [F, leg])) == []
    # by hand: 20 m round at 1 m/s, no wait (r passes x = 7.5 on y = 2.5 at t = 10, f only at t = 41)
    assert leg.arrival_time == pytest.approx(20.0, abs=1e-6)
    assert leg.waypoints[:, 1].max() == pytest.approx(2.5)
    # md's own routes only: it waits in the direct corridor until f has left (40 s + the 6 m on)
    monkeypatch.setattr(md, "_LEG_ROUTES", False)
    own = get_planner("md").plan_incremental(GRID, [R], [F], 0.0)[0]
    assert check_plan(GRID, [F_SPEC, R], Plan("md", [F, own])) == []
    assert own.arrival_time > 46.0


def test_the_paper_method_keeps_its_departure_delays_only():
    leg = get_planner("md-departure").plan_incremental(GRID, [R], [F], 0.0)[0]
    assert check_plan(GRID, [F_SPEC, R], Plan("md", [F, leg])) == []
    wp = leg.waypoints
    moving = np.hypot(*np.diff(wp[:, :2], axis=0).T) > 1e-9
    first = int(np.argmax(moving))
    assert moving[first:].all()   # once it moves, it never stops before its goal
