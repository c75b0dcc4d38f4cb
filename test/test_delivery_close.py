"""Queue places in the room next to the busy stations (``queue="close"``, ours, issue 8): the central methods'
robots wait for a loading station on places placed *before* the problem's other parking spots (which stay only
where they still fit), so the room beside the station - the recesses by the chutes - holds the queue; a place
never cuts a passage nor narrows a passage two robots wide to one; a run with them is valid."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fleet_planner.delivery import simulate, stations, warehouse_problem
from fleet_planner.delivery.layout import (
    ROBOT_RADIUS,
    SPOT_MARGIN,
    _shut_in,
    _StandingPlaces,
    _TwoLanes,
    driving_distances,
)
from fleet_planner.delivery.problem import Delivery, DeliveryProblem
from fleet_planner.delivery.stations import CLOSE_NEW, QUEUE_REACH, _DeliveryRules
from fleet_planner.grid import GridMap
from fleet_planner.paths import PathFinder
from fleet_planner.warehouse import load_warehouse

#: a chute row as in the default warehouse: the north wall with pillars and recesses 1 m deep between them, a
#: band 3 m wide in front of them, a rack wall with one opening 3 m wide, and a hall south of it
ROWS = ["@" * 27,
        "@.......@@@.......@@@.....@",
        "@.......@@@.......@@@.....@",
        *["@.........................@"] * 6,
        *["@@@@@@@@@@@@......@@@@@@@@@"] * 2,
        *["@.........................@"] * 6,
        "@" * 27]


@pytest.fixture(scope="module")
def chute():
    """Four robots; every delivery loads at chute A (under a pillar, recesses on both sides) and unloads at B or
    C in the hall; the problem's two queue spots for A stand where session 25's spots do, one in the recess corner
    and one in the band 2 m from A."""
    grid = GridMap.from_rows(ROWS, 0.5, "chute")
    stations = {"A": grid.centre(9, 4), "B": grid.centre(4, 14), "C": grid.centre(22, 14)}
    homes = [grid.centre(c, 15) for c in (8, 12, 16, 20)]
    spots = homes + [grid.centre(11, 2), grid.centre(13, 4)]
    deliveries = [Delivery("A", "B"), Delivery("A", "C")] * 4
    return DeliveryProblem("chute", grid, stations, deliveries, spots, 4)


def _drive_from(problem, station):
    free = PathFinder(problem.grid, problem.radius).free
    return driving_distances(problem.grid, free, [problem.stations[station]])[0]


def _at(problem, drive, p):
    col, row = problem.grid.cell_of(*p)
    return float(drive[row * problem.grid.width + col])


def test_close_reserves_the_room_next_to_the_busy_station(chute):
    close = _DeliveryRules(chute, claims=True, queue="close")
    near = _DeliveryRules(chute, claims=True, queue="near")
    drive = _drive_from(chute, "A")
    mine = [_at(chute, drive, close.spots[i]) for i in close.slots["A"]]
    theirs = [_at(chute, drive, near.spots[i]) for i in near.slots["A"]]
    assert mine == sorted(mine) and max(mine) <= QUEUE_REACH
    # six places within 2.25 m of driving (both sides of the pillar, the recesses); near finds room for one
    assert len(mine) == CLOSE_NEW and max(mine) < 2.25
    assert len(theirs) <= 1                                       # the control: near, same problem
    assert close.spots[:chute.n_robots] == chute.spots[:chute.n_robots]   # the homes stay
    assert chute.spots[4] not in close.spots                      # the recess corner's spot gave way
    assert all(i >= chute.n_robots for i in close.slots["A"])
    # in the recesses: north of the band, beside the pillars
    assert sum(1 for i in close.slots["A"] if close.spots[i][1] < 1.5) >= 2


def _standing(problem, rules):
    return list(problem.stations.values()) + rules.spots


def test_no_close_place_cuts_or_narrows_a_passage(chute):
    rules = _DeliveryRules(chute, claims=True, queue="close")
    standing = _standing(chute, rules)
    xy = np.asarray(standing)
    gaps = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) + np.eye(len(xy)) * 99
    assert gaps.min() >= 2 * ROBOT_RADIUS + SPOT_MARGIN - 1e-9    # no two discs touch
    hub = chute.grid.centre(14, 6)                                # the middle of the band
    assert _shut_in(chute.grid, chute.radius, list(chute.stations.values()), rules.spots, hub) == []
    # two robots side by side (a disc of twice the radius) still get from the band through the opening to the
    # hall with a robot on every station, spot and place
    assert _wide_way(chute, standing)
    # the rule that keeps it: a robot in the middle of the opening leaves one robot a way past (usable, the
    # control) but not two side by side, so no place goes there
    places = _StandingPlaces(chute.grid, chute.radius)
    lanes = _TwoLanes(places, chute.radius)
    for p in list(chute.stations.values()) + chute.spots[:chute.n_robots]:
        places.take(*places.cell(p))
        lanes.take(*places.cell(p))
    assert places.usable(14, 9) and not lanes.kept(14, 9)
    assert not _wide_way(chute, standing + [chute.grid.centre(14, 9)])
    assert lanes.kept(14, 6)                                      # the band is wide enough for one more


def _wide_way(problem, standing) -> bool:
    wide = 2 * problem.radius
    finder = PathFinder(problem.grid, wide)
    discs = [(p, problem.radius + wide + SPOT_MARGIN) for p in standing]
    return finder.find(problem.grid.centre(14, 6), problem.grid.centre(14, 13), avoid=discs) is not None


def test_no_close_place_in_a_corridor():
    # two rooms joined by a corridor one robot wide; station A in the left room at the corridor's mouth: the
    # corridor is nearer to A by driving than its farthest place, yet no place is in it
    room = "@" + "." * 8 + "@" * 12 + "." * 8 + "@"
    rows = ["@" * 30] + [room] * 4 + ["@" + "." * 28 + "@"] * 3 + [room] * 4 + ["@" * 30]
    grid = GridMap.from_rows(rows, 0.5, "corridor")
    stations = {"A": grid.centre(6, 4), "B": grid.centre(25, 10)}
    problem = DeliveryProblem("corridor", grid, stations, [Delivery("A", "B")] * 4,
                              [grid.centre(3, 9), grid.centre(25, 2)], 2)
    rules = _DeliveryRules(problem, claims=True, queue="close")
    assert len(rules.slots["A"]) >= 3
    for i in rules.slot_of:
        col, _ = grid.cell_of(*rules.spots[i])
        assert not (9 <= col <= 20), f"queue place {rules.spots[i]} is in the corridor"


@pytest.mark.parametrize("method", ["prior", "md"])
def test_a_run_with_close_places_is_valid(chute, method):
    result = simulate(chute, method, queue="close")
    assert result.finished and result.completed == len(chute.deliveries) and result.deadlocks == 0
    assert result.collisions == 0 and result.violations == []    # the independent checker
    assert result.ctime >= result.lower_bound
    rules = _DeliveryRules(chute, claims=True, queue="close")
    places = [rules.spots[i] for i in rules.slots["A"]]
    stood = sum(any(math.dist(w[:2], q) < 1e-6 for q in places for w in tp.waypoints) for tp in result.trajectories)
    assert stood >= 2                                             # the robots did queue on A's places


def test_close_without_a_loading_station_is_the_spots_rule(chute):
    # every station loaded and unloaded at (stations spread over a MovingAI map): no chute to queue at
    both_ways = DeliveryProblem("both", chute.grid, chute.stations, [Delivery("A", "B"), Delivery("B", "A")] * 2,
                                chute.spots, chute.n_robots)
    rules = _DeliveryRules(both_ways, claims=True, queue="close")
    assert rules.queue_rule == "spots" and rules.slots == {} and rules.spots == list(chute.spots)
    assert _DeliveryRules(chute, claims=True, queue="close").queue_rule == "close"   # control: A only loads


def test_auto_is_close_where_the_busy_stations_get_places_and_spots_where_not(chute, monkeypatch):
    # session 28 (queue="auto"): the default warehouse at 100 robots, its homes filling the room by the chutes, got
    # 0-3 close places per chute and ran worse with them than with parking spots (md 1634 -> 1954 s); at 50 robots
    # 4-6 places each and close was far better (795 -> 524 s)
    wh = load_warehouse()
    rules = {n: _DeliveryRules(warehouse_problem(wh, n, 3 * n, 0), claims=True, queue="auto") for n in (50, 100)}
    assert rules[50].queue_rule == "close" and min(len(rules[50].slots[s]) for s in rules[50].close_stations) >= 4
    assert rules[100].queue_rule == "spots" and rules[100].slots == {} and rules[100].close_stations == set()
    close = _DeliveryRules(warehouse_problem(wh, 100, 300, 0), claims=True, queue="close")
    assert min(len(close.slots.get(s, [])) for s in close.close_stations) < stations.AUTO_PLACES   # (why)
    assert _DeliveryRules(chute, claims=True, queue="auto").queue_rule == "close"
    monkeypatch.setattr(stations, "AUTO_PLACES", CLOSE_NEW + 1)    # control: more places than close ever makes
    rules = _DeliveryRules(chute, claims=True, queue="auto")
    assert rules.queue_rule == "spots" and rules.spots == list(chute.spots)
