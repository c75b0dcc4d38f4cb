"""The dense solver's diagonal steps (crowd_smooth): shorter paths where the grid has room, never a
collision (the independent checker is the judge), never a later sum of arrivals."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from test_crowd_refine import crowds

from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap
from fleet_planner.model import Plan, PlanningError, RobotSpec
from fleet_planner.planners.crowd import CrowdPlanner


def _soc(plan: Plan) -> float:
    return sum(p.arrival_time for p in plan.paths)


def _plan(rows: list[str], robots: list[RobotSpec], diagonal: bool = True) -> Plan:
    grid = GridMap.from_rows(rows)
    plan = CrowdPlanner(refine_s=0, timed_refine_s=0, diagonal=diagonal).plan(grid, robots)
    assert check_plan(grid, robots, plan) == []
    return plan


def test_a_robot_crosses_open_floor_on_the_diagonal():
    """Alone on an open 5x5 floor from one corner to the other: 4 diagonal steps (4 sqrt 2 m) instead
    of 8 unit steps (control: ``diagonal=False``)."""
    robot = [RobotSpec("a", 0.45, 1.0, (0.5, 0.5), (4.5, 4.5))]
    assert _plan(["." * 5] * 5, robot).paths[0].arrival_time == pytest.approx(4 * math.sqrt(2))
    assert _plan(["." * 5] * 5, robot, diagonal=False).paths[0].arrival_time == pytest.approx(8.0)


def test_diagonal_steps_only_up_to_their_crowd_size(monkeypatch):
    """Beyond ``DIAGONAL_MAX`` robots the plan keeps its unit steps (they cost too much there)."""
    from fleet_planner.planners import crowd

    robot = [RobotSpec("a", 0.45, 1.0, (0.5, 0.5), (4.5, 4.5))]
    monkeypatch.setattr(crowd, "DIAGONAL_MAX", 0)
    plan = _plan(["." * 5] * 5, robot)
    assert plan.paths[0].arrival_time == pytest.approx(8.0) and "diagonal_s" not in plan.info


@pytest.mark.parametrize("rows, arrival", [(["..", ".."], math.sqrt(2)), (["..", "@."], 2.0), (["@.", ".."], 2.0)])
def test_a_diagonal_step_never_cuts_a_wall_corner(rows, arrival):
    """From the top-left cell to the bottom-right one: diagonal only when both side cells are free
    (a disc of 0.45 m on the diagonal passes 0 m from the corner of a blocked side cell)."""
    start, goal = (0.5, 0.5), (1.5, 1.5)
    if rows[0][0] == "@":
        start, goal = (1.5, 0.5), (0.5, 1.5)
    plan = _plan(rows, [RobotSpec("a", 0.45, 1.0, start, goal)])
    assert plan.paths[0].arrival_time == pytest.approx(arrival)


def test_a_diagonal_step_keeps_off_a_robot_on_a_side_cell():
    """b stands on one side cell of a's diagonal (its centre 0.71 m from the diagonal, radii 0.45 +
    0.4): a goes round in unit steps; without b it takes the diagonal (control)."""
    a = RobotSpec("a", 0.45, 1.0, (0.5, 0.5), (1.5, 1.5))
    b = RobotSpec("b", 0.4, 1.0, (1.5, 0.5), (1.5, 0.5))
    rows = ["...", "...", "..."]
    assert _plan(rows, [a, b]).paths[0].arrival_time == pytest.approx(2.0)
    assert _plan(rows, [a]).paths[0].arrival_time == pytest.approx(math.sqrt(2))


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=crowds())
def test_diagonal_steps_are_valid_and_never_later(case):
    """Random small floors, 2-12 discs of mixed radii and speeds: the plan with diagonal steps
    passes the checker and its sum of arrivals is no larger than the same plan's without them (no
    LNS: both start from the same first plan)."""
    from fleet_planner.planners import crowd

    grid, robots = case
    if len(robots) < 2:
        return
    try:
        plain = CrowdPlanner(refine_s=0, timed_refine_s=0, diagonal=False).plan(grid, robots)
    except Exception:   # noqa: BLE001 - unreachable goals: not this test's business
        return
    with pytest.MonkeyPatch.context() as mp:   # the post-pass alone (no diagonal steps in the search)
        mp.setattr(crowd, "DIAGONAL_SEARCH", False)
        smooth = CrowdPlanner(refine_s=0, timed_refine_s=0).plan(grid, robots)
    assert check_plan(grid, robots, smooth) == []
    assert _soc(smooth) <= _soc(plain) + 1e-6
    # the network's regions lie on the robots' paths: l_s < l_e <= the path's length
    length = {p.robot_id: float(np.sum(np.hypot(*np.diff(p.waypoints[:, :2], axis=0).T))) for p in smooth.paths}
    for link in smooth.network.links:
        assert 0.0 <= link.ls < link.le <= length[link.j] + 1e-6


def test_the_timed_search_takes_diagonal_steps_itself(monkeypatch):
    """Alone on an open floor the timed first plan's own search crosses on the diagonal (no post-pass
    needed: ``diagonal_s`` absent); with ``DIAGONAL_SEARCH`` off (the control) the search plans unit
    steps and the post-pass finds the diagonal."""
    from fleet_planner.planners import crowd

    robot = [RobotSpec("a", 0.45, 1.0, (0.5, 0.5), (4.5, 4.5))]
    plan = _plan(["." * 5] * 5, robot)
    assert plan.info["diagonal_search"] and "diagonal_s" not in plan.info
    assert plan.paths[0].arrival_time == pytest.approx(4 * math.sqrt(2))
    monkeypatch.setattr(crowd, "DIAGONAL_SEARCH", False)
    plan = _plan(["." * 5] * 5, robot)
    assert not plan.info["diagonal_search"]
    assert plan.info["diagonal_gain_s"] == pytest.approx(8 - 4 * math.sqrt(2), abs=1e-3)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=crowds())
def test_plans_with_diagonal_steps_in_the_search_are_valid(case):
    """Random small floors, 2-12 discs of mixed radii and speeds, with diagonal steps in the timed first
    plan and the timed LNS: every plan passes the checker, and the network's regions lie on the paths.
    (Hypothesis found a step whose side cells were never free again timed at t = inf: the search now
    drops it.)"""
    grid, robots = case
    try:
        plan = CrowdPlanner(refine_s=0.05, timed_refine_s=0.05).plan(grid, robots)
    except PlanningError:   # unreachable goals: not this test's business
        return
    assert check_plan(grid, robots, plan) == []
    length = {p.robot_id: float(np.sum(np.hypot(*np.diff(p.waypoints[:, :2], axis=0).T))) for p in plan.paths}
    for link in plan.network.links:
        assert 0.0 <= link.ls < link.le <= length[link.j] + 1e-6
