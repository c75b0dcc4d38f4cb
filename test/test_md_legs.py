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


def _no_timing_of_routes(monkeypatch):
    """md cannot time the search's routes itself (its _legs refuses when given routes)."""
    own_legs = md.MDPlanner._legs

    def legs(self, grid, robots, fixed, t0, deadline, routes=None):
        if routes:
            raise md.PlanningError({r.id: "test: no timing of routes" for r in robots})
        return own_legs(self, grid, robots, fixed, t0, deadline, routes)
    monkeypatch.setattr(md.MDPlanner, "_legs", legs)


def test_a_leg_takes_the_searchs_own_timing_when_md_has_nothing_sooner(monkeypatch):
    _no_timing_of_routes(monkeypatch)
    leg = get_planner("md").plan_incremental(GRID, [R], [F], 0.0)[0]
    assert check_plan(GRID, [F_SPEC, R], Plan("md", [F, leg])) == []
    assert leg.arrival_time == pytest.approx(20.0, abs=1e-6)   # the way round, as the search timed it
    # control: without the search's own timing md's leg waits in the direct corridor
    monkeypatch.setattr(md, "_LEG_CORRIDOR_M", 0.0)   # the way round now leaves the corridor: not taken
    own = get_planner("md").plan_incremental(GRID, [R], [F], 0.0)[0]
    assert own.arrival_time > 46.0


def test_the_searchs_own_timing_is_not_taken_outside_the_corridor_where_it_did_not_look(monkeypatch):
    # g parks for ever in the way round, outside r's corridor when the corridor is only r's own line:
    # the search does not see g and goes round through it; md must not take that leg
    g = TimedPath("g", 0.4, np.array([[3.5, 2.5, 0.0]]))
    g_spec = RobotSpec("g", 0.4, 1.0, (3.5, 2.5), (3.5, 2.5))
    monkeypatch.setattr(md, "_LEG_CORRIDOR_M", 0.0)
    leg = get_planner("md").plan_incremental(GRID, [R], [F, g], 0.0)[0]
    assert check_plan(GRID, [F_SPEC, g_spec, R], Plan("md", [F, g, leg])) == []
    assert leg.arrival_time > 46.0   # it waits for f in the direct corridor
    routes, timed = get_planner("md")._space_time_routes(GRID, [R], [F, g], 0.0)
    assert routes and timed is None and _passes_g(routes[0], g)


def _passes_g(route, g) -> bool:
    """The search's route passes g's disc (what taking its leg unchecked would drive into)."""
    from fleet_planner.geometry import polyline_passes_near

    return polyline_passes_near(route, tuple(g.waypoints[0, :2]), 0.8)


def test_a_leg_alone_on_the_map_is_the_shortest_path_for_the_robots_own_radius():
    # session 30: md's path finders take the robot's own radius; rounded up to the centimetre (0.354 m -> 0.36 m
    # on this 0.5 m grid, every cell diagonal to a rack corner blocked) its legs were 0.98 m longer on average
    from fleet_planner.delivery import warehouse_problem
    from fleet_planner.geometry import polyline_length
    from fleet_planner.paths import PathFinder
    from fleet_planner.warehouse import generate_warehouse

    problem = warehouse_problem(generate_warehouse(5, 10, 24, 2, 3, 0.5, "large"), 4, 4, seed=0)
    finder = PathFinder(problem.grid, problem.radius)
    points = sorted(problem.stations.values())
    planner, longer = get_planner("md"), []
    for a, b in zip(points[::3], points[1::3]):
        leg = planner.plan_incremental(problem.grid, [RobotSpec("r", problem.radius, problem.max_speed, a, b)],
                                       [], 0.0)[0]
        shortest = polyline_length(finder.find(a, b))
        assert leg.length >= shortest - 1e-6 and leg.arrival_time == pytest.approx(leg.length / problem.max_speed)
        longer.append(leg.length - shortest)
    assert len(longer) >= 8 and max(longer) < 1e-6
