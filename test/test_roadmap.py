"""Road maps of directed lanes (fleet_planner/roadmap.py): ARMO's program connects every station
pair both ways, lanes files are validated field by field, and md, PRIOR and the path finder plan
along the lanes, their plans passing the independent checker."""
from __future__ import annotations

import numpy as np
import pytest

from fleet_planner._pathgraph import DIRS as _DIRS
from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap
from fleet_planner.model import RobotSpec
from fleet_planner.paths import PathFinder
from fleet_planner.planners import get_planner
from fleet_planner.roadmap import (
    LanesError,
    RoadMap,
    armo_roadmap,
    free_cells,
    lanes_of,
    load_lanes,
    parse_lanes,
    save_lanes,
    with_lanes,
)

# three one-cell aisles between two cross aisles (1 m cells, discs of radius 0.35 fit one cell)
ROWS = ["............",
        ".@@@@@@@@@@.",
        "............",
        ".@@@@@@@@@@.",
        "............"]
STATIONS = {"A": (0.5, 0.5), "B": (11.5, 4.5), "C": (0.5, 4.5), "D": (11.5, 0.5)}
R = 0.35


def _grid() -> GridMap:
    return GridMap.from_rows(ROWS)


def _cells(grid: GridMap) -> list[tuple[int, int]]:
    return [grid.cell_of(*p) for p in STATIONS.values()]


def test_armo_makes_one_way_lanes_that_connect_every_station_pair_both_ways():
    grid = _grid()
    demand = {("A", "B"): 5.0, ("B", "C"): 3.0, ("C", "D"): 5.0, ("D", "A"): 3.0}
    lanes, info = armo_roadmap(grid, R, STATIONS, demand)
    free = free_cells(grid, R)
    assert info.one_way_runs > 0 and lanes.one_way_moves() > 0   # the demand allowed one-way aisles
    assert lanes.unreachable_pairs(free, _cells(grid)) == []      # every pair, both directions
    assert lanes.dead_ends(free) == []
    # every traversable cell still reaches every other (the whole space strongly connected)
    all_cells = [(int(c), int(r)) for r, c in zip(*np.nonzero(free))]
    assert lanes.unreachable_pairs(free, all_cells[::7]) == []


def test_the_shortest_path_trees_are_the_optimum_of_armos_flow_program():
    # the program has no capacities, so its optimum is one shortest-path tree per commodity; HiGHS
    # on the same program (some moves closed by a one-way lane, costs raised by head-on shares)
    # must find the same total cost
    from fleet_planner.roadmap import _flow_lp, _net, _path_flows, _sources

    net, st_node = _net(_grid(), R, STATIONS, keep_right=0.2)
    sources = _sources(st_node, {("A", "B"): 5.0, ("B", "C"): 3.0, ("C", "D"): 5.0, ("D", "A"): 3.0,
                                 ("B", "A"): 1.0})
    rng = np.random.default_rng(3)
    cost = net.cost * (1.0 + rng.random(len(net.cost)))
    open_arc = np.ones(len(cost), dtype=bool)
    open_arc[(net.run == net.run[0]) & (np.arange(len(cost)) >= net.m)] = False   # one lane one-way
    assert net.strongly_connected(open_arc)
    flow = _path_flows(net, cost, open_arc, sources)
    lp_flow, lp_cost = _flow_lp(net, cost, open_arc, sources)
    assert flow @ cost == pytest.approx(lp_cost, rel=1e-9)
    assert not flow[~open_arc].any() and not lp_flow[~open_arc].any()
    assert flow.sum() > 1.0                                       # it carried the demand somewhere


@pytest.mark.parametrize("head_on", [0.0, 1.0])
def test_armo_sends_opposing_flows_along_different_aisles(head_on):
    # P and Q at the two ends of the middle aisle, as much demand each way: the shortest way both
    # ways is the middle aisle, so without head-on costs (the control) it stays two-way with all
    # the traffic meeting head-on; with them one direction takes a side aisle and the middle one
    # becomes one-way
    grid = _grid()
    stations = {"P": (0.5, 2.5), "Q": (11.5, 2.5)}
    lanes, info = armo_roadmap(grid, R, stations, {("P", "Q"): 1.0, ("Q", "P"): 1.0}, head_on=head_on)
    free = free_cells(grid, R)
    assert info.opposed_open == pytest.approx(1.0)
    assert lanes.unreachable_pairs(free, [grid.cell_of(*p) for p in stations.values()]) == []
    middle_one_way = lanes.allows(5, 2, 1, 0) != lanes.allows(5, 2, -1, 0)
    if head_on:
        assert middle_one_way and info.opposed == pytest.approx(0.0)
        assert info.objective <= 1.25 * info.open_objective          # the detour of one direction
    else:
        assert not middle_one_way and info.opposed == pytest.approx(1.0)


@pytest.mark.parametrize("parked", [False, True])
def test_armos_lanes_go_round_a_parked_robot(parked):
    # the scene above with a robot parked in the bottom aisle: laid out without it (the control),
    # the bottom aisle is the only way east and the parked robot cuts P off Q; laid out round it,
    # P and Q reach each other both ways with the robot standing there
    grid = _grid()
    stations = {"P": (0.5, 2.5), "Q": (11.5, 2.5)}
    home = (5.5, 4.5)
    lanes, _ = armo_roadmap(grid, R, stations, {("P", "Q"): 1.0, ("Q", "P"): 1.0},
                            parked=[home] if parked else [])
    free = free_cells(grid, R).copy()
    c, r = grid.cell_of(*home)
    free[r, c] = False                       # the parked robot's cell
    cut = lanes.unreachable_pairs(free, [grid.cell_of(*p) for p in stations.values()])
    assert (cut == []) == parked


@pytest.mark.parametrize("narrow", [1, 2])
def test_a_corridor_too_narrow_to_pass_in_is_one_lane_and_apart_from_the_open_space(narrow):
    # two rows of cells between two open blocks: on a 0.5 m grid (narrow = 2) discs of radius
    # 0.354 in the two rows cannot pass each other, so both rows are one lane (one direction);
    # on a 1 m grid (narrow = 1, the control) they can, and each row is a lane of its own
    from fleet_planner.roadmap import _lanes, _runs

    free = np.zeros((6, 12), dtype=bool)
    free[:, :3] = free[:, 9:] = True
    free[2:4, :] = True
    runs, tails, heads, run_of = _runs(free)
    lane = _lanes(free, runs, tails, heads, run_of, narrow)
    w = free.shape[1]

    def lane_of(row: int, col: int) -> int:      # the edge (col, row) -> (col + 1, row)
        k = int(np.nonzero((tails == row * w + col) & (heads == row * w + col + 1))[0][0])
        return int(lane[k])

    assert (lane_of(2, 5) == lane_of(3, 5)) == (narrow == 2)
    assert lane_of(2, 5) == lane_of(2, 4)                 # one piece along the corridor
    # a narrow corridor is cut off the open blocks' rows; a wide one is not (rows run through)
    assert (lane_of(2, 0) != lane_of(2, 5) != lane_of(2, 10)) == (narrow == 2)


def test_armo_on_the_default_warehouse_takes_seconds_and_connects_every_station_pair_both_ways():
    import time

    from fleet_planner.delivery import ROBOT_RADIUS, warehouse_problem
    from fleet_planner.roadmap import demand_of
    from fleet_planner.warehouse import load_warehouse

    problem = warehouse_problem(load_warehouse(), 20, 60, 0)
    c0 = time.process_time()
    lanes, info = armo_roadmap(problem.grid, ROBOT_RADIUS, problem.stations,
                               demand_of(problem.deliveries, list(problem.stations)))
    cpu = time.process_time() - c0
    assert cpu < 20.0, cpu           # about 0.6 s; one solve of the old single LP took minutes
    assert info.status == "optimal" and info.one_way_runs >= 50 and info.opposed < info.opposed_open
    free = free_cells(problem.grid, ROBOT_RADIUS)
    cells = [problem.grid.cell_of(*p) for p in problem.stations.values()]
    cells = [c for c in cells if free[c[1], c[0]]]
    assert len(cells) >= 20 and lanes.unreachable_pairs(free, cells) == []
    assert lanes.dead_ends(free) == []


def _one_way_east_middle() -> dict:
    return {"name": "t", "radius": R, "lanes": [{"from": [1, 2], "to": [10, 2]}]}


def test_a_lanes_file_round_trips_and_paths_keep_to_its_lanes(tmp_path):
    grid = _grid()
    lanes = parse_lanes(_one_way_east_middle(), grid)
    assert not lanes.allows(5, 2, -1, 0) and lanes.allows(5, 2, 1, 0)
    path = save_lanes(lanes, grid, tmp_path / "lanes.yaml", "test")
    back = load_lanes(path, grid)
    assert np.array_equal(back.allowed, lanes.allowed)

    plain = PathFinder(grid, R).find((10.5, 2.5), (1.5, 2.5))
    assert len(plain) == 2                                  # straight west along the middle aisle
    on_lanes = PathFinder(with_lanes(grid, lanes), R).find((10.5, 2.5), (1.5, 2.5))
    assert on_lanes is not None
    # it may not drive west along the one-way middle aisle: it leaves it for a cross aisle
    assert np.abs(on_lanes[:, 1] - 2.5).max() >= 1.9


@pytest.mark.parametrize("lane, field, words", [
    ({"from": [1, 2], "to": [40, 2]}, "lanes[0].to", "unknown cell"),
    ({"from": [1, 1], "to": [10, 1]}, "lanes[0].from", "not free"),
    ({"from": [1, 2], "to": [3, 4]}, "lanes[0]", "straight"),
])
def test_a_lane_on_an_unknown_cell_is_rejected_naming_the_field(lane, field, words):
    with pytest.raises(LanesError) as err:
        parse_lanes({"lanes": [lane]}, _grid())
    assert err.value.path == field and words in str(err.value)


def test_a_dead_end_is_rejected_naming_the_lane():
    grid = GridMap.from_rows(["......",
                              "@@@@@.",
                              "......"])
    # the top row one-way west ends in the corner cell (0, 0), whose only other way is blocked
    with pytest.raises(LanesError) as err:
        parse_lanes({"lanes": [{"from": [5, 0], "to": [0, 0]}]}, grid)
    assert err.value.path == "lanes[0]" and "dead end" in str(err.value)
    with pytest.raises(LanesError) as err:
        parse_lanes({"lanes": [{"from": [1, 2], "to": [9, 2]}]}, grid)
    assert err.value.path == "lanes[0].to"
    with pytest.raises(LanesError) as err:
        parse_lanes({"lanes": [{"from": [1, 2], "to": [4, 2]}, {"from": [4, 2], "to": [1, 2]}]}, grid)
    assert err.value.path == "lanes[1]" and "against lanes[0]" in str(err.value)


@pytest.mark.parametrize("planner", ["md", "prior"])
def test_md_and_prior_plan_along_the_lanes_and_pass_the_checker(planner):
    grid = _grid()
    lanes = parse_lanes(_one_way_east_middle(), grid)
    lane_grid = with_lanes(grid, lanes)
    assert lanes_of(lane_grid) is lanes and lanes_of(grid) is None
    robots = [RobotSpec("r1", R, 1.0, (10.5, 2.5), (1.5, 2.5)),
              RobotSpec("r2", R, 1.0, (1.5, 2.5), (10.5, 2.5)),
              RobotSpec("r3", R, 1.0, (0.5, 0.5), (11.5, 4.5))]
    plan = get_planner(planner).plan(lane_grid, robots)
    assert check_plan(grid, robots, plan) == []
    by_id = plan.by_id()
    # r1 goes west: not along the east-bound middle aisle
    assert _no_westward_run(by_id["r1"].waypoints)
    assert np.abs(by_id["r1"].waypoints[:, 1] - 2.5).max() >= 1.9   # it took a cross aisle


def test_a_road_map_that_restricts_no_move_is_the_map_itself():
    """ARMO may make no lane one-way (its program on `large`): then paths are straightened as
    without a road map (unstraightened staircases left robots giving way into walls)."""
    grid = _grid()
    open_map = RoadMap.open(grid)
    assert not open_map.restricts and parse_lanes(_one_way_east_middle(), grid).restricts
    plain = PathFinder(grid, R).find((0.5, 0.5), (11.5, 4.5))
    on_open = PathFinder(with_lanes(grid, open_map), R).find((0.5, 0.5), (11.5, 4.5))
    assert np.allclose(plain, on_open)


def test_one_md_planner_keeps_the_lanes_of_a_map_apart_from_the_same_map_without():
    """md's path-finder cache is keyed by the lanes too: the same map with and without lanes,
    planned by one planner in either order, gets each its own paths."""
    grid = _grid()
    lane_grid = with_lanes(grid, parse_lanes(_one_way_east_middle(), grid))
    robots = [RobotSpec("r1", R, 1.0, (10.5, 2.5), (1.5, 2.5))]
    md = get_planner("md")
    plain = md.plan(grid, robots).by_id()["r1"].waypoints
    on_lanes = md.plan(lane_grid, robots).by_id()["r1"].waypoints
    again = md.plan(grid, robots).by_id()["r1"].waypoints
    assert np.abs(plain[:, 1] - 2.5).max() < 1e-6 and np.abs(again[:, 1] - 2.5).max() < 1e-6
    assert _no_westward_run(on_lanes) and np.abs(on_lanes[:, 1] - 2.5).max() >= 1.9


def _no_westward_run(wp: np.ndarray) -> bool:
    """No piece of the path runs west along row 2 inside the aisle."""
    for (x0, y0, _), (x1, y1, _) in zip(wp, wp[1:]):
        on_row = abs(y0 - 2.5) < 1e-6 and abs(y1 - 2.5) < 1e-6
        if on_row and x1 < x0 - 1e-6 and min(x0, x1) < 10.0 and max(x0, x1) > 2.0:
            return False
    return True


def test_a_path_is_found_into_a_part_of_the_lanes_that_has_no_way_back():
    """A road map need not be strongly connected (a lanes file rejects dead ends, not traps): the
    west-bound bottom lane leads from the east room into the west room, which has no way back. The
    path finder's pruning of unreachable pairs must not read that as two unconnected parts."""
    grid = GridMap.from_rows(["..@..",
                              "..@..",
                              "....."])
    lanes = parse_lanes({"lanes": [{"from": [4, 2], "to": [0, 2]}]}, grid, R)
    assert lanes.dead_ends(free_cells(grid, R)) == []
    finder = PathFinder(with_lanes(grid, lanes), R)
    move_ok = lanes.move_mask(lanes.shape)
    # the west room's corner comes first in the cells' order (the one a labelling starts from)
    for start, goal in [((3.5, 0.5), (0.5, 0.5)), ((4.5, 1.5), (1.5, 2.5)), ((3.5, 2.5), (0.5, 1.5))]:
        path = finder.find(start, goal)
        assert path is not None, (start, goal)
        assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
        for a, b in zip(path, path[1:]):      # corners of a grid path: every step an allowed move
            step = np.sign(b - a).astype(int)
            cell = np.floor(a).astype(int)
            for _ in range(int(np.abs(b - a).max())):
                bit = _DIRS.index((int(step[0]), int(step[1])))
                assert move_ok[cell[1], cell[0]] & (1 << bit), (start, goal, cell, step)
                cell = cell + step
    # and there is truly no way back
    assert finder.find((0.5, 0.5), (3.5, 0.5)) is None
    assert finder.find((1.5, 2.5), (4.5, 2.5)) is None


def test_a_road_map_of_another_map_is_refused():
    with pytest.raises(ValueError):
        with_lanes(_grid(), RoadMap.open(GridMap.from_rows(["...", "..."])))


def test_the_shipped_lanes_file_of_the_default_warehouse_loads_and_connects_its_stations():
    from fleet_planner.warehouse import config_path, load_warehouse

    wh = load_warehouse()
    lanes = load_lanes(config_path("lanes_warehouse.yaml"), wh.grid)
    free = free_cells(wh.grid, lanes.radius)
    assert lanes.one_way_moves() > 100
    cells = [wh.grid.cell_of(s.x, s.y) for s in wh.stations.values() if s.type != "charger"]
    cells = [c for c in cells if free[c[1], c[0]]]
    assert len(cells) >= 20 and lanes.unreachable_pairs(free, cells) == []


def test_the_one_way_rack_aisles_of_large_load_and_connect_its_stations():
    # config/lanes_large.yaml (issue 13): bench_delivery's `large`, every rack aisle one-way, the
    # aisles alternating east / west; main, side and cross aisles two-way
    from fleet_planner.warehouse import config_path, generate_warehouse

    wh = generate_warehouse(5, 10, 24, 2, 3, 0.5, "large")
    lanes = load_lanes(config_path("lanes_large.yaml"), wh.grid)
    free = free_cells(wh.grid, lanes.radius)
    assert lanes.allows(10, 11, 1, 0) and not lanes.allows(10, 11, -1, 0)     # top rack aisle: east
    assert lanes.allows(10, 16, -1, 0) and not lanes.allows(10, 16, 1, 0)     # the next one: west
    assert lanes.allows(30, 11, -1, 0) and lanes.allows(30, 11, 1, 0)         # a cross aisle: both ways
    cells = [wh.grid.cell_of(s.x, s.y) for s in wh.stations.values() if s.type != "charger"]
    cells = [c for c in cells if free[c[1], c[0]]]
    assert len(cells) >= 50 and lanes.unreachable_pairs(free, cells) == []
