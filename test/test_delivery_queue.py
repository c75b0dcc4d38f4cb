"""Queue places near the stations (``queue="near"``, ours, issue 8): the central methods' robots wait
for a station on places a few metres from it that cut no passage, are given the station first come
first served and move up as it frees; a run with them is valid (the independent checker and a
sampled overlap test)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fleet_planner.delivery import central, delivery_problem, simulate, stations, warehouse_problem
from fleet_planner.delivery.layout import ROBOT_RADIUS, SPOT_MARGIN, _shut_in, driving_distances, queue_places
from fleet_planner.delivery.result import RunLimits
from fleet_planner.delivery.stations import QUEUE_REACH, QUEUE_SLOTS, _DeliveryRules
from fleet_planner.grid import GridMap
from fleet_planner.paths import PathFinder
from fleet_planner.warehouse import generate_warehouse, load_warehouse


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
def test_queue_is_first_come_first_served_and_moves_up(busy, queue, monkeypatch):
    # the control of JOIN_ON_BOOKING (session 27's order: a robot joins the queue when it reaches its place)
    monkeypatch.setattr(stations, "JOIN_ON_BOOKING", False)
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
    assert rules.queues.waiting["chute_1"] == []              # not in the queue before they get there
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


@pytest.mark.parametrize("queue", ["near", "close"])
def test_a_robot_joins_the_queue_when_it_books_its_place(busy, queue):
    # session 28 (JOIN_ON_BOOKING): at 50 robots on the default warehouse the robots with no place free queued
    # on their homes 20-37 m off at once, ahead of those still driving to the places 1 m from the chute, and the
    # chute idled while the first of them drove in; now the queue is in the order the robots asked for the station
    rules = _DeliveryRules(busy, claims=True, queue=queue)
    robots = rules.robots
    for r in robots:
        rules.next_target(r, 0.0)
    slots = rules.slots["chute_1"]
    assert [r.booked_spot for r in robots[1:]] == slots[:5]
    assert rules.queues.waiting["chute_1"] == [1, 2, 3, 4, 5]   # in the queue before they get there
    for r in robots:
        _start(rules, r, 0.0)
    for idx in (3, 1, 2, 5, 4):                               # they arrive in another order
        rules.arrived(robots[idx], 10.0 + idx)
        assert robots[idx].phase == "queued"
    assert rules.queues.waiting["chute_1"] == [1, 2, 3, 4, 5]   # (the control above: [3, 1, 2, 5, 4])
    rules.arrived(robots[0], 20.0)
    rules.docked(robots[0], 25.0)
    _start(rules, robots[0], 25.0)
    assert [r.idx for r in rules.take_handed_over(25.0)] == [1]   # the first to ask, on the nearest place
    _start(rules, robots[1], 25.0)                            # it leaves slot 0: robot 2 (slot 1) moves up
    assert robots[2].phase == "need" and robots[2].booked_spot == slots[0]
    assert all(robots[i].phase == "queued" for i in (3, 4, 5))


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


@pytest.mark.parametrize("nearest", [True, False])
def test_spots_hand_a_freed_station_to_the_queued_robot_nearest_to_it(busy, nearest, monkeypatch):
    # session 29 (SERVE_NEAREST): under the spots rule the queue stands on parking spots anywhere; a freed station
    # goes to the robot standing nearest to it by driving (control: first come first served)
    monkeypatch.setattr(stations, "SERVE_NEAREST", nearest)
    rules = _DeliveryRules(busy, claims=True, queue="spots")
    robots = rules.robots
    for r in robots:
        rules.next_target(r, 0.0)
    for r in robots:
        if r.phase == "need":
            _start(rules, r, 0.0)
    drive = rules.spot_dist["chute_1"]
    queue = list(rules.queues.waiting["chute_1"])             # those whose home is close queue on it at once
    waiting = sorted((r for r in robots[1:] if r.phase == "drive"), key=lambda r: -drive[r.spot])
    for k, r in enumerate(waiting):                           # the others arrive farthest first
        rules.arrived(r, 10.0 + k)
        assert r.phase == "queued"
    queue += [r.idx for r in waiting]
    assert rules.queues.waiting["chute_1"] == queue
    near = min(queue, key=lambda i: (drive[robots[i].spot], queue.index(i)))
    assert near != queue[0]                                   # (the case tells the two rules apart)
    rules.arrived(robots[0], 20.0)
    rules.docked(robots[0], 25.0)
    _start(rules, robots[0], 25.0)                            # it leaves the chute
    handed = rules.take_handed_over(25.0)
    assert [r.idx for r in handed] == [near if nearest else queue[0]]
    assert handed[0].target == busy.stations["chute_1"]
    assert rules.queues.waiting["chute_1"] == [i for i in queue if i != handed[0].idx]


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


def _turns(busy, method: str) -> tuple:
    """A run of the busy chute with queue places; every turn to a station handed over en route: (robot, where,
    when, the place it was driving to, the station)."""
    run = central._CentralRun(busy, method, RunLimits(3600.0, 600.0, 120.0, 2.0, 600.0), None, None, queue="near")
    turns, en_route = [], []
    to_station_now, take_en_route = run.rules.to_station_now, run.rules.take_en_route

    def logged(r, at, t):
        turns.append((r.idx, at, t, tuple(run.rules.spots[r.spot]), busy.stations[r.station]))
        to_station_now(r, at, t)

    def handed():
        out, t = take_en_route(), now[0]
        en_route.extend((r.idx, run.driving[r.idx].position(t), t, tuple(run.rules.spots[r.spot])) for r in out)
        return out

    now, wake = [0.0], run._wake

    def timed(r, t):
        now[0] = t
        wake(r, t)

    run.rules.to_station_now, run.rules.take_en_route, run._wake = logged, handed, timed
    return run.run(), turns, en_route   # (a drop's storing site has its places too)


@pytest.mark.parametrize("method", ["prior", "md"])
def test_a_robot_handed_its_station_on_the_way_to_its_place_turns_to_it(busy, method, monkeypatch):
    # session 28 (TURN_EN_ROUTE): a robot the freed station is handed to while it drives to its queue place
    # leaves that leg where it is for a leg to the station, instead of driving to the place first
    result, turns, _ = _turns(busy, method)
    assert result.finished and result.completed == 12
    assert result.collisions == 0 and result.violations == []    # the cut trajectories too (independent checker)
    assert _min_gap(result.trajectories, busy.radius) >= -1e-6
    assert turns and result.extra["turned"] == len(turns)
    for idx, at, t, place, station in turns:
        wp = result.trajectories[idx].waypoints
        assert math.dist(result.trajectories[idx].position(t), at) < 1e-6 and math.dist(at, place) > 1e-6
        after = wp[wp[:, 2] >= t]
        stop = next(k for k in range(len(after)) if math.dist(after[k, :2], station) < 1e-6)
        assert all(math.dist(w[:2], place) > 1e-6 for w in after[:stop])   # on to the station, not the place
    # control: without the rule nobody turns; each robot handed the chute on its way drives to its place first
    monkeypatch.setattr(central, "TURN_EN_ROUTE", False)
    result, turns, en_route = _turns(busy, method)
    assert turns == [] and result.extra["turned"] == 0 and result.collisions == 0
    assert en_route
    for idx, at, t, place in en_route:
        wp = result.trajectories[idx].waypoints
        assert math.dist(at, place) > 1e-6 and any(math.dist(w[:2], place) < 1e-6 for w in wp[wp[:, 2] >= t])


def _handovers(busy, method: str) -> tuple:
    """A run of the busy chute with queue places; every station handed over to a queued robot: (station, when
    the robot's leg to it is planned, when the robot leaving it ended its docking)."""
    run = central._CentralRun(busy, method, RunLimits(3600.0, 600.0, 120.0, 2.0, 600.0), None, None, queue="near")
    rules, log, ends = run.rules, [], {}
    docked, take = rules.docked, rules.take_handed_over

    def logged_docked(r, t):
        ends[r.station] = t
        docked(r, t)

    def logged_take(t):
        out = take(t)
        log.extend((q.station, t, ends.get(q.station, -math.inf)) for q in out)
        return out

    rules.docked, rules.take_handed_over = logged_docked, logged_take
    return run.run(), log


def _stays(tp, where) -> list[float]:
    """How long each stay of a driven trajectory on ``where`` lasted (s)."""
    wp, out, since, prev = tp.waypoints, [], None, 0.0
    for w in wp:
        on = math.dist(w[:2], where) < 1e-6
        if on and since is None:
            since = w[2]
        elif not on and since is not None:
            out.append(prev - since)
            since = None
        prev = w[2]
    return out


@pytest.mark.parametrize("method", ["prior", "md"])
def test_a_station_others_queue_for_is_handed_over_before_docking_ends(busy, method, monkeypatch):
    # session 28 (HAND_OVER_EARLY_S): the robot docking at a station others queue for gets its next leg (leaving
    # when its docking ends) that much sooner, so the first robot in the queue is on its way sooner
    result, log = _handovers(busy, method)
    assert result.finished and result.collisions == 0 and result.violations == []
    assert _min_gap(result.trajectories, busy.radius) >= -1e-6
    ahead = [end - t for _, t, end in log]
    early = [a for a in ahead if a > 1e-9]
    assert len(early) >= 2 and early == pytest.approx([central.HAND_OVER_EARLY_S] * len(early))
    stays = [s for tp in result.trajectories for p in busy.stations.values() for s in _stays(tp, p) if s > 1e-9]
    assert len(stays) >= 24 and min(stays) >= busy.dock_s - 1e-6   # every robot still docks its full time
    # (24 dockings: a pick and a drop per delivery; a stay of 0 s is a robot passing over a station's pose)
    # control: handed over when the docking ends
    monkeypatch.setattr(central, "HAND_OVER_EARLY_S", 0.0)
    result, log = _handovers(busy, method)
    assert result.collisions == 0 and log and all(end - t <= 1e-9 for _, t, end in log)


@pytest.mark.parametrize("queue", ["near", "close", "spots"])
def test_a_robot_with_no_delivery_left_parks_on_the_closest_free_spot(busy, queue, monkeypatch):
    # session 28 (PARK_NEAREST, the place rules): the robots done with their deliveries drove home across the
    # warehouse while the others made the last ones; now each parks on the closest free parking spot
    rules = _DeliveryRules(busy, claims=True, queue=queue)
    r = rules.robots[0]
    rules.left(r, 0.0)                                         # it left its home (free again)
    home = rules.spots[0]
    r.pos = max(busy.stations.values(), key=lambda p: math.dist(p, home))   # at the station farthest from it
    rules.next_delivery = len(busy.deliveries)                 # nothing left to hand out
    rules.next_target(r, 10.0)
    if queue == "spots":   # control: the spots rule parks at home (its robots queue on the spots near stations)
        assert r.target_kind == "park" and r.booked_spot == 0 and r.target == home
        return
    free = [i for i in range(len(rules.spots)) if rules.general[i] and (rules.parking.owner[i] in (None, 0))]
    nearest = min(free, key=lambda i: (math.dist(rules.spots[i], r.pos), i))
    assert r.target_kind == "park" and r.booked_spot == nearest != 0 and nearest not in rules.slot_of
    assert math.dist(rules.spots[nearest], r.pos) < math.dist(home, r.pos)
    monkeypatch.setattr(stations, "PARK_NEAREST", False)       # control: home, when free
    rules.parking.owner[nearest], r.booked_spot = None, None
    rules.next_target(r, 10.0)
    assert r.target_kind == "park" and r.booked_spot == 0 and r.target == home


def test_every_robot_docks_its_full_time_on_the_default_warehouse():
    # a robot planned ahead (HAND_OVER_EARLY_S) and then handed the station of its next leg before that leg began
    # was turned from its station at once, leaving it 0.3-3 s before its docking ended (3 of 120 dockings here with
    # prior before the fix); now the leg is planned again from its start, leaving no sooner
    problem = warehouse_problem(load_warehouse(), 20, 60, 0)
    run = central._CentralRun(problem, "prior", RunLimits(3600.0, 600.0, 120.0, 2.0, 600.0), None, None)
    docks, arrived = [], run.rules.arrived

    def logged(r, t):
        if r.target_kind in ("pick", "drop"):
            docks.append((r.idx, problem.stations[r.station], t))
        arrived(r, t)

    run.rules.arrived = logged
    result = run.run()
    assert result.finished and result.collisions == 0 and len(docks) == 120
    assert result.extra["queue"] == "close" and result.extra["turned"] > 0   # (the rules that act here)
    for idx, station, t in docks:
        tp = result.trajectories[idx]
        stay = [t + problem.dock_s * k / 20 for k in range(21)]
        assert all(math.dist(tp.position(s), station) < 1e-6 for s in stay), (tp.robot_id, station, t)


def test_diag_delivery_runs_through_turns_to_a_station(tmp_path, monkeypatch, capsys):
    # bench/diag_delivery.py logs every planned leg; a turn to a station plans its leg from where the robot is
    # (session 28: _plan_leg(start=)), which the script's logger did not take and the run died at the first turn
    import json
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
    import diag_delivery

    turn, turned = central._CentralRun._turn_to_station, []

    def counted(self, q, now):
        ok = turn(self, q, now)
        turned.append(ok)
        return ok

    monkeypatch.setattr(central._CentralRun, "_turn_to_station", counted)
    dump = tmp_path / "legs.json"
    assert diag_delivery.main(["--map", "warehouse", "--n", "20", "--deliveries-per-robot", "1",
                               "--dump", str(dump)]) in (0, None)
    assert any(turned)                       # the run went through turns
    out = capsys.readouterr().out
    assert " 0 collisions" in out
    legs = json.loads(dump.read_text())
    legs = legs["legs"] if isinstance(legs, dict) else legs
    assert len(legs) >= 20 * 2 and all(rec["ok"] is not None for rec in legs)
