"""Queue places near the stations (``queue="near"``, ours, issue 8): the central methods' robots wait
for a station on places a few metres from it that cut no passage, are given the station first come
first served and move up as it frees; a run with them is valid (the independent checker and a
sampled overlap test)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fleet_planner.delivery import delivery_problem, simulate
from fleet_planner.delivery.layout import ROBOT_RADIUS, SPOT_MARGIN, _shut_in, driving_distances, queue_places
from fleet_planner.delivery.stations import QUEUE_REACH, QUEUE_SLOTS, _DeliveryRules
from fleet_planner.grid import GridMap
from fleet_planner.paths import PathFinder
from fleet_planner.warehouse import generate_warehouse


@pytest.fixture(scope="module")
def busy():
    """Six robots, every delivery loading at chute_1 of a small warehouse."""
    wh = generate_warehouse(2, 2, 8, 2, 4, 0.5, "tiny")
    chutes = [s.name for s in wh.stations_of("chute")]
    sites = [s.name for s in wh.stations_of("storage")]
    stations = {n: wh.stations[n].pose for n in chutes + sites}
    return delivery_problem(wh.grid, stations, 6, 12, seed=0, pick=[chutes[0]], drop=sites)


def test_queue_places_are_near_their_station_and_cut_no_passage(busy):
    rules = _DeliveryRules(busy, claims=True, queue="near")
    free = PathFinder(busy.grid, busy.radius).free
    drive = driving_distances(busy.grid, free, list(busy.stations.values()))
    names = list(busy.stations)
    assert len(rules.slots["chute_1"]) == QUEUE_SLOTS
    for station, slots in rules.slots.items():
        k = names.index(station)
        d = [drive[k, busy.grid.cell_of(*rules.spots[i])[1] * busy.grid.width + busy.grid.cell_of(*rules.spots[i])[0]]
             for i in slots]
        assert max(d) <= QUEUE_REACH and d == sorted(d), station   # near, nearest first
        assert all(i >= busy.n_robots for i in slots)              # never a robot's home
    # with a robot on every station, spot and place, each can still drive out, and no two touch
    standing = list(busy.stations.values()) + rules.spots
    xy = np.asarray(standing)
    gaps = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) + np.eye(len(xy)) * 99
    assert gaps.min() >= 2 * ROBOT_RADIUS + SPOT_MARGIN - 1e-9
    rows, cols = np.nonzero(free)
    centres = np.column_stack([(cols + 0.5) * busy.grid.resolution, (rows + 0.5) * busy.grid.resolution])
    clear = np.hypot(*(centres[:, None] - xy[None]).transpose(2, 0, 1)).min(axis=1)
    hub = tuple(centres[int(np.argmax(clear))])   # the free place farthest from every standing robot
    assert _shut_in(busy.grid, busy.radius, list(busy.stations.values()), rules.spots, hub) == []


def test_no_queue_place_in_a_corridor():
    # two rooms joined by a corridor 1.5 m wide (at 0.5 m cells only its middle row fits a disc); station A
    # in the left room near the corridor's mouth: a corridor cell is nearer to it by driving than some of its
    # places, but a robot standing there would cut the corridor
    room = "@" + "." * 8 + "@" * 12 + "." * 8 + "@"
    rows = ["@" * 30] + [room] * 4 + ["@" + "." * 28 + "@"] * 3 + [room] * 4 + ["@" * 30]
    grid = GridMap.from_rows(rows, 0.5, "corridor")
    stations = {"A": grid.centre(6, 4), "B": grid.centre(25, 10)}
    places = queue_places(grid, stations, [], 8, QUEUE_REACH, ROBOT_RADIUS)
    assert len(places["A"]) >= 3
    for x, y in places["A"] + places["B"]:
        col, row = grid.cell_of(x, y)
        assert not (9 <= col <= 20), f"queue place ({x}, {y}) is in the corridor"
    # control: the corridor's first cell is nearer to A by driving than the farthest place chosen
    free = PathFinder(grid, ROBOT_RADIUS).free
    d = driving_distances(grid, free, [stations["A"]])[0].reshape(grid.height, grid.width)
    chosen = max(d[grid.cell_of(x, y)[1], grid.cell_of(x, y)[0]] for x, y in places["A"])
    assert free[6, 9] and d[6, 9] < chosen


def _start(rules, r, t):
    """r's leg (to its target) is planned and it drives off."""
    rules.left(r, t)
    rules.enter(r, "drive", t)


@pytest.mark.parametrize("queue", ["near", "close", "spots"])
def test_queue_is_first_come_first_served_and_moves_up(busy, queue):
    rules = _DeliveryRules(busy, claims=True, queue=queue)
    robots = rules.robots
    for r in robots:
        rules.next_target(r, 0.0)
    first = robots[0]
    assert first.target_kind == "pick" and rules.queues.holder["chute_1"] == 0   # free: claimed from afar
    if queue == "spots":   # control (session 25's rule): from afar it queues on a parking spot first
        return _spots_control(rules)
    slots = rules.slots["chute_1"]
    assert [r.booked_spot for r in robots[1:]] == slots[:5]   # the others: its places, nearest first
    for r in robots:
        _start(rules, r, 0.0)
    for idx in (3, 1, 2, 5, 4):                               # they arrive in this order
        rules.arrived(robots[idx], 10.0 + idx)
        assert robots[idx].phase == "queued"
    assert rules.queues.waiting["chute_1"] == [3, 1, 2, 5, 4]
    rules.arrived(first, 20.0)
    rules.docked(first, 25.0)
    _start(rules, first, 25.0)                                # it leaves: the first to come gets the station
    handed = rules.take_handed_over(25.0)
    assert [r.idx for r in handed] == [3] and robots[3].target == busy.stations["chute_1"]
    _start(rules, robots[3], 25.0)                            # robot 3 leaves slot 2: the first behind it
    assert robots[5].phase == "need" and robots[5].booked_spot == slots[2]   # in the queue (5, on slot 4) moves up
    assert robots[4].phase == "queued"                        # robot 4 (slot 3, came after 5) stays
    _start(rules, robots[5], 26.0)
    assert robots[4].phase == "queued"                        # slot 4 is no nearer than its own
    rules.arrived(robots[5], 27.0)
    assert rules.queues.waiting["chute_1"] == [1, 2, 5, 4]    # its place in the queue kept
    rules.arrived(robots[3], 28.0)
    rules.docked(robots[3], 33.0)
    _start(rules, robots[3], 33.0)
    assert [r.idx for r in rules.take_handed_over(33.0)] == [1]   # next in order of arrival
    _start(rules, robots[1], 33.0)
    assert robots[2].phase == "need" and robots[2].booked_spot == slots[0]


def _spots_control(rules) -> None:
    """Session 25's rule: the robots queued on parking spots stay there while the station turns over."""
    robots = rules.robots
    for r in robots:
        if r.phase == "need":
            _start(rules, r, 0.0)
    for r in robots[1:]:
        if r.phase == "drive":
            rules.arrived(r, 10.0)
    queued = [r for r in robots if r.phase == "queued"]
    assert len(queued) >= 3
    rules.arrived(robots[0], 20.0)
    rules.docked(robots[0], 25.0)
    _start(rules, robots[0], 25.0)
    handed = rules.take_handed_over(25.0)
    _start(rules, handed[0], 25.0)
    assert all(r.phase == "queued" for r in queued if r is not handed[0])   # nobody moves up


def _min_gap(paths, radius: float) -> float:
    end = max(float(p.waypoints[-1, 2]) for p in paths)
    times = np.arange(0.0, end + 0.02, 0.02)
    pos = np.stack([np.column_stack([np.interp(times, p.waypoints[:, 2], p.waypoints[:, a]) for a in (0, 1)])
                    for p in paths], axis=1)
    diff = pos[:, :, None, :] - pos[:, None, :, :]
    dist = np.hypot(diff[..., 0], diff[..., 1])
    dist[:, np.arange(len(paths)), np.arange(len(paths))] = np.inf
    return float(dist.min()) - 2 * radius


@pytest.mark.parametrize("method", ["prior", "md"])
def test_a_run_with_queue_places_is_valid(busy, method):
    result = simulate(busy, method, queue="near")
    assert result.finished and result.completed == 12 and result.deadlocks == 0
    assert result.collisions == 0 and result.violations == []    # the independent checker
    assert _min_gap(result.trajectories, busy.radius) >= -1e-6
    assert result.ctime >= result.lower_bound
    # the robots did queue on the chute's places: some stood there before going on to the chute
    rules = _DeliveryRules(busy, claims=True, queue="near")
    places = [rules.spots[i] for i in rules.slots["chute_1"]]
    stood = sum(any(math.dist(w[:2], q) < 1e-6 for q in places for w in tp.waypoints) for tp in result.trajectories)
    assert stood >= 2


def test_bad_queue_rule_is_named():
    with pytest.raises(ValueError, match="queue"):
        simulate(None, "md", queue="far")   # type: ignore[arg-type]
