"""md's legs (plan_incremental) with route choice in time: when waiting on the shortest route costs
more than a detour, the leg takes the detour (the independent checker judges the leg)."""
from __future__ import annotations

import numpy as np
import pytest

import fleet_planner.planners.md as md
from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap, MapError
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

    # (session 31: on the finer lattice md plans legs on here, ``leg_lattice``: no longer than on the map's cells)
    problem = warehouse_problem(generate_warehouse(5, 10, 24, 2, 3, 0.5, "large"), 4, 4, seed=0)
    points = sorted(problem.stations.values())
    planner, longer = get_planner("md"), []
    spec = RobotSpec("r", problem.radius, problem.max_speed, points[0], points[1])
    finder = PathFinder(planner._leg_grid(problem.grid, [spec]), problem.radius)
    on_cells = PathFinder(problem.grid, problem.radius)
    for a, b in zip(points[::3], points[1::3]):
        leg = planner.plan_incremental(problem.grid, [RobotSpec("r", problem.radius, problem.max_speed, a, b)],
                                       [], 0.0)[0]
        shortest = polyline_length(finder.find(a, b))
        assert leg.length >= shortest - 1e-6 and leg.arrival_time == pytest.approx(leg.length / problem.max_speed)
        assert leg.length <= polyline_length(on_cells.find(a, b)) + 1e-6
        longer.append(leg.length - shortest)
    assert len(longer) >= 8 and max(longer) < 1e-6


# a 2 m aisle on 0.5 m cells (a rack aisle of the default warehouse): s docks 0.75 m from its lower wall, as at a
# storing site; 0.354 m discs pass it only with their centres between y = 1.978 and 2.146, off the map's lattice
AISLE = GridMap.from_rows(["@" * 16, *["." * 16] * 4, "@" * 16], resolution=0.5, name="aisle")
S = TimedPath("s", 0.354, np.array([[4.25, 1.25, 0.0]]))      # standing there for good
S_SPEC = RobotSpec("s", 0.354, 0.8, (4.25, 1.25), (4.25, 1.25))
PASSER = RobotSpec("r", 0.354, 0.8, (0.75, 1.75), (7.25, 1.75))


def test_a_leg_passes_a_robot_docked_in_a_narrow_aisle_on_the_finer_lattice():
    leg = get_planner("md").plan_incremental(AISLE, [PASSER], [S], 0.0)[0]
    assert check_plan(AISLE, [S_SPEC, PASSER], Plan("md", [S, leg])) == []
    assert leg.waypoints[:, 1].max() > 1.97                          # it passes on the far side of s
    assert leg.arrival_time < 6.5 / 0.8 + 1.0                       # 6.5 m straight, a small swerve, no wait
    # control: on the map's own cells the aisle is shut for as long as s stands there
    with pytest.raises(md.PlanningError):
        get_planner("md", leg_lattice=1).plan_incremental(AISLE, [PASSER], [S], 0.0)


def test_auto_refines_only_cells_narrower_than_the_robots_and_keeps_the_maps_cell_centres():
    planner = get_planner("md")
    assert planner._leg_grid(GRID, [R]) is GRID                      # 1 m cells, 0.8 m robots: two lanes already
    fine = planner._leg_grid(AISLE, [PASSER])
    assert fine.resolution == pytest.approx(0.5 / md.LEG_LATTICE) and planner._leg_grid(AISLE, [PASSER]) is fine
    assert fine.is_free_cell(*fine.cell_of(0.75, 1.75)) and fine.centre(*fine.cell_of(0.75, 1.75)) == \
        pytest.approx((0.75, 1.75))
    assert np.array_equal(fine.blocked[::md.LEG_LATTICE, ::md.LEG_LATTICE], AISLE.blocked)
    with pytest.raises(MapError, match="odd integer"):
        AISLE.refined(2)                                             # the map's cell centres would fall on corners
    from fleet_planner.roadmap import RoadMap, with_lanes
    laned = with_lanes(AISLE, RoadMap.open(AISLE))
    assert get_planner("md", leg_lattice=3)._leg_grid(laned, [PASSER]) is laned   # lanes are laid on its cells


@pytest.mark.parametrize("bad", [2, 0, -3, 1.5, True, "fine"])
def test_a_bad_leg_lattice_is_refused_by_name(bad):
    with pytest.raises(ValueError, match="leg_lattice"):
        get_planner("md", leg_lattice=bad)
