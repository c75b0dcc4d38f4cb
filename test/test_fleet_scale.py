"""Fleets of any size, pure parts: robots placed on free spots clear of each other and of the
stations; the planner step's occupancy index answers as a scan of every robot does; the status
inbox keeps the latest status of each robot and hands back what it cannot file."""
import math

import numpy as np
import pytest

from fleet_planner.fleet.inbox import StatusInbox
from fleet_planner.fleet.legs import Leg
from fleet_planner.fleet.placement import STATION_CLEARANCE_M, parking_spots, place_robots, warehouse_for
from fleet_planner.fleet.sim import SimFleet
from fleet_planner.fleet.state import FleetRobot, Occupancy
from fleet_planner.model import TimedPath
from fleet_planner.robots import load_kinds
from fleet_planner.warehouse import load_warehouse
from msg_schemas.records import RobotStatus, Task

KINDS = load_kinds()


@pytest.mark.parametrize("n, large", [(30, False), (100, True)])
def test_robots_are_placed_on_free_spots_clear_of_each_other_and_of_the_stations(n, large):
    warehouse = warehouse_for(n) if large else load_warehouse()
    members = place_robots(warehouse, KINDS, n)
    assert len(members) == n and len({m.id for m in members}) == n
    assert {m.kind for m in members} == set(KINDS)
    chargers = [s.pose for s in warehouse.stations_of("charger")]
    for i, m in enumerate(members):
        r = KINDS[m.kind].radius
        assert warehouse.grid.disc_is_free(m.x, m.y, r)
        for o in members[:i]:
            assert math.dist((m.x, m.y), (o.x, o.y)) >= r + KINDS[o.kind].radius
        if (m.x, m.y) not in chargers:
            assert min(math.dist((m.x, m.y), s.pose) for s in warehouse.stations.values()) >= STATION_CLEARANCE_M
    assert len(parking_spots(warehouse, members)) == n - min(n, len(chargers))
    with pytest.raises(ValueError, match="only"):
        place_robots(load_warehouse(), KINDS, 400)


def status(rid, x, y, kind="cargo", stamp=1.0):
    return RobotStatus(id=rid, kind=kind, x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, battery=1.0, mode="idle",
                       progress=1.0, stamp=stamp, radius=KINDS[kind].radius)


def test_the_occupancy_index_answers_as_a_scan_of_every_robot():
    rng = np.random.default_rng(5)
    robots = []
    for k in range(80):
        r = FleetRobot(KINDS["cargo"], status(f"r{k}", *rng.uniform(0, 30, 2)), 0.0, 0.0)
        if k % 3 == 0:
            end = rng.uniform(0, 30, 2)
            r.leg = Leg(r.id, TimedPath(r.id, r.radius, np.array([[r.pos[0], r.pos[1], 0.0], [*end, 10.0]])), 1,
                        "park", "p")
        robots.append(r)
    occ = Occupancy(robots)
    occ.touch(robots[1])  # changed after the index was made: checked directly
    robots[1].leg = Leg("r1", TimedPath("r1", 0.35, np.array([[robots[1].pos[0], robots[1].pos[1], 0.0],
                                                               [15.0, 15.0, 5.0]])), 2, "park", "p")

    def scan(pose, radius, exclude):
        for o in robots:
            if o is exclude:
                continue
            ends = [o.pos] + ([tuple(o.leg.path.waypoints[-1, :2])] if o.leg is not None else [])
            if any(math.dist(p, pose) < o.radius + radius for p in ends):
                return o
        return None

    for pose in [(15.0, 15.0), *rng.uniform(0, 30, (300, 2))]:
        got, want = occ.occupant(tuple(pose), 0.45, robots[0]), scan(tuple(pose), 0.45, robots[0])
        assert (got is None) == (want is None), pose


def test_the_inbox_keeps_the_latest_status_of_each_robot_and_hands_back_what_it_cannot_file():
    inbox = StatusInbox()
    a1, a2, b1 = status("a", 1, 1).to_json(), status("a", 2, 2, stamp=2.0).to_json(), status("b", 5, 5).to_json()
    assert inbox.offer(a1, 1.0) is None and inbox.offer(b1, 1.1) is None and inbox.offer(a2, 1.2) is None
    assert inbox.offer("not json", 1.3) == ("not json", 1.3)
    assert inbox.offer('{"id": "x' + "y" * 5000 + '"}', 1.4) is not None
    assert inbox.take() == [(a2, 1.2), (b1, 1.1)]
    assert inbox.take() == [] and inbox.superseded == 1


def test_simulated_robots_hear_their_neighbours_and_report_every_step():
    warehouse = load_warehouse()
    members = place_robots(warehouse, KINDS, 12)
    sim = SimFleet(members, KINDS, warehouse)
    first = sim.step(0.0)
    assert [s.id for s in first] == [m.id for m in members]
    second = sim.step(0.1)
    assert all(s.stamp == 0.1 for s in second)
    heard = sim.agents[members[0].id].heard   # r1 on the first charger hears r2 on the next one (2 m)
    assert members[1].id in heard and members[-1].id not in heard


class _Refusing:
    """A planner that refuses every leg, counting how often it is asked."""

    name = "refusing"

    def __init__(self):
        self.calls = 0

    def plan_incremental(self, grid, robots, fixed, t0):
        from fleet_planner.model import PlanningError
        self.calls += 1
        raise PlanningError({r.id: "refused for the test" for r in robots})


def test_a_refused_leg_is_tried_again_after_a_growing_back_off_not_at_every_step():
    from fleet_planner.fleet import FleetManager
    from fleet_planner.fleet.manager import LEG_RETRY_MAX_S, LEG_RETRY_S

    wh = load_warehouse()
    planner = _Refusing()
    fleet = FleetManager(wh, KINDS, planner=planner)
    fleet.step_budget_s = math.inf   # (no wall-time limit: the back-off alone is looked at)
    fleet.on_status(status("r1", 2.25, 22.75), 0.0)
    chute = next(s for s in wh.stations.values() if s.type == "chute")
    store = next(s for s in wh.stations.values() if s.type == "storage")
    assert fleet.submit(Task(id="j1", pick=chute.name, place=store.tags[0]), 0.0)[0].event == "accepted"
    asked = []
    for k in range(1, 61):   # 30 s of steps every 0.5 s
        now = k * 0.5
        fleet.on_status(status("r1", 2.25, 22.75, stamp=now), now)
        before = planner.calls
        fleet.step(now)
        if planner.calls > before:
            asked.append(now)
    gaps = np.diff(asked)
    assert len(asked) < 20   # at every step it would be 60
    assert gaps[0] >= LEG_RETRY_S and max(gaps) <= LEG_RETRY_MAX_S + 0.5 and list(gaps) == sorted(gaps)


def test_a_step_plans_legs_only_within_its_budget():
    from fleet_planner.fleet import FleetManager

    wh = load_warehouse()
    planner = _Refusing()
    fleet = FleetManager(wh, KINDS, planner=planner)
    members = place_robots(wh, KINDS, 12)
    for m in members:
        fleet.on_status(status(m.id, m.x, m.y, m.kind), 0.0)
    chutes = [s for s in wh.stations.values() if s.type == "chute"]
    stores = [s for s in wh.stations.values() if s.type == "storage"]   # (one site each: one job per site at a time)
    for k, c in enumerate(chutes):
        assert fleet.submit(Task(id=f"j{k}", pick=c.name, place=stores[k].tags[0]), 0.0)[0].event == "accepted"
    fleet.step_budget_s = 0.0   # spent at once: no leg this step
    fleet.step(0.5)
    assert planner.calls == 0
    fleet.step_budget_s = 10.0
    fleet.step(1.0)
    assert planner.calls > 1


def test_a_fleet_files_robots_park_where_they_start_besides_the_params_files_spots():
    """fleet-demo --fleet F: robots that start off the params file's parking spots get their start spots
    as parking too (with only the nine's spots, 22 robots idled in the aisles and blocked the jobs); the
    default fleet starts on them already, so nothing changes for it (the control)."""
    from dataclasses import replace

    from fleet_planner.fleet import load_fleet
    from fleet_planner.ros.demo.bringup import parking_of
    from fleet_planner.ros.demo.cli import DEMO_PARAMS, fleet_parking
    from fleet_planner.warehouse import config_path

    wh, params = load_warehouse(None), config_path(DEMO_PARAMS)
    nine = load_fleet(None, load_kinds(), wh)
    assert fleet_parking(params, wh, nine) == []
    moved = replace(nine[0], x=nine[0].x + 7.0)
    spots = fleet_parking(params, wh, [*nine, moved])
    pairs = list(zip(spots[0::2], spots[1::2]))
    assert pairs[:len(parking_of(params))] == parking_of(params)
    assert pairs[len(parking_of(params)):] == [(moved.x, moved.y)]
