"""The dispatcher (fleet/dispatch.py): batch assignment by estimated arrival, one job per chute,
way lengths over the map, staging spots near the chutes, and the manager's use of them (idle
robots wait near the chutes, charge only when the battery asks)."""
import math

import numpy as np
import pytest

from fleet_planner.fleet import DispatchParams, FleetManager
from fleet_planner.fleet.dispatch import (
    STAGED,
    STAGING_CLEARANCE_M,
    Candidate,
    DispatchPolicy,
    TravelTimes,
    assign,
    staging_spots,
)
from fleet_planner.robots import load_kinds
from fleet_planner.warehouse import generate_warehouse, load_warehouse
from msg_schemas.records import RobotStatus, Task

KINDS = load_kinds()
WH = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)


def lengths_table(table):
    """A ``lengths`` function from {chute: {(x, y): metres}}."""
    return lambda chute, pts: np.array([table[chute][tuple(p)] for p in pts])


def test_batch_assignment_minimises_the_sum_of_arrivals_where_nearest_first_does_not():
    a, b = Candidate("a", (0.0, 0.0), 1.0, 1.0), Candidate("b", (1.0, 0.0), 1.0, 1.0)
    # job J1 (first in the queue) at X: a is 1 m away, b 2 m; J2 at Y: a 2 m, b 10 m. Nearest-first
    # gives J1 to a and leaves b 10 m from Y (11 s in all); the best pairing is b->X, a->Y (4 s)
    table = {"X": {(0.0, 0.0): 1.0, (1.0, 0.0): 2.0}, "Y": {(0.0, 0.0): 2.0, (1.0, 0.0): 10.0}}
    pairs = assign([a, b], [("J1", "X"), ("J2", "Y")], lambda r, j: True, lengths_table(table))
    assert sorted((r, j) for r, j, _ in pairs) == [("a", "J2"), ("b", "J1")]
    assert sum(t for *_, t in pairs) == pytest.approx(4.0)
    # a slower robot's arrival counts its speed: b at half speed is 4 s from X, a 1 s
    slow_b = Candidate("b", (1.0, 0.0), 0.5, 1.0)
    pairs = assign([a, slow_b], [("J1", "X")], lambda r, j: True, lengths_table(table))
    assert [(r, j) for r, j, _ in pairs] == [("a", "J1")]


def test_one_job_per_chute_the_first_in_the_queue_busy_chutes_and_inability_respected():
    robots = [Candidate(f"r{i}", (float(i), 0.0), 1.0, 1.0) for i in range(3)]
    table = {c: {(float(i), 0.0): 1.0 + i for i in range(3)} for c in "XYZ"}
    jobs = [("J1", "X"), ("J2", "X"), ("J3", "Y"), ("J4", "Z")]
    pairs = assign(robots, jobs, lambda r, j: True, lengths_table(table), busy=lambda c: c == "Z")
    assert sorted(j for _, j, _ in pairs) == ["J1", "J3"]  # J2 waits behind J1 at X, Z is busy
    # nobody able to do J1: the next job at X is taken instead (the chute is not left idle)
    pairs = assign(robots, jobs, lambda r, j: j != "J1", lengths_table(table))
    assert sorted(j for _, j, _ in pairs) == ["J2", "J3", "J4"]
    # only r2 can do J3: it gets it, whatever the distances
    pairs = assign(robots, jobs[2:3], lambda r, j: r == "r2", lengths_table(table))
    assert [(r, j) for r, j, _ in pairs] == [("r2", "J3")]
    assert assign(robots, jobs, lambda r, j: False, lengths_table(table)) == []
    assert assign([], jobs, lambda r, j: True, lengths_table(table)) == []


def test_a_job_whose_storing_site_is_taken_waits_and_the_next_at_its_chute_goes_first():
    robots = [Candidate(f"r{i}", (float(i), 0.0), 1.0, 1.0) for i in range(2)]
    table = {c: {(float(i), 0.0): 1.0 + i for i in range(2)} for c in "XY"}
    jobs = [("J1", "X"), ("J2", "X"), ("J3", "Y")]
    site = {"J1": "S1", "J2": "S2", "J3": "S3"}.get
    # J1's site is taken by another robot's job: J2 is the first at X; J3 (site free) at Y as before
    pairs = assign(robots, jobs, lambda r, j: True, lengths_table(table), site_of=site, taken_sites={"S1"})
    assert sorted(j for _, j, _ in pairs) == ["J2", "J3"]
    # every job of a chute has its site taken: the chute waits (no robot picks there to stand on it)
    pairs = assign(robots, jobs, lambda r, j: True, lengths_table(table), site_of=site, taken_sites={"S1", "S2"})
    assert [j for _, j, _ in pairs] == ["J3"]
    # two chutes' first jobs for one site: only the first in the queue goes
    same = {"J1": "S1", "J2": "S2", "J3": "S1"}.get
    pairs = assign(robots, jobs, lambda r, j: True, lengths_table(table), site_of=same)
    assert [j for _, j, _ in pairs] == ["J1"]


def test_the_manager_holds_back_a_job_for_a_site_another_job_goes_to():
    fm = FleetManager(WH, KINDS, DispatchParams(idle_s=5.0))
    fm.step_budget_s = 60.0
    assert fm.policy.sites
    fm.on_status(status("r1", "cargo", 6.25, 3.75), 0.0)
    fm.on_status(status("r2", "cargo", 12.75, 11.75), 0.0)
    fm.submit(Task(id="J1", pick="chute_1", place="B01-01"), 0.0)
    fm.submit(Task(id="J2", pick="chute_2", place="B01-02"), 0.0)   # the same storing site
    d = fm.step(0.5)
    assert [e.task_id for e in d.events if e.event == "assigned"] == ["J1"]
    fm.policy = DispatchPolicy(sites=False)   # without the rule both go at once
    assert [e.task_id for e in fm.step(1.0).events if e.event == "assigned"] == ["J2"]


def test_way_lengths_go_round_the_racks():
    wh = load_warehouse()
    tt = TravelTimes(wh)
    chute = wh.stations["chute_1"].pose
    assert tt.length("chute_1", np.array([chute]))[0] == pytest.approx(0.0)
    # from the middle of a rack block's aisle the way runs to the aisle's end first: longer than straight
    inside = np.array([[10.25, 13.25]])
    straight = math.dist(inside[0], chute)
    way = tt.length("chute_1", inside)[0]
    assert straight < way < 2.0 * straight
    # across the open north aisle it is (nearly) straight
    open_pt = np.array([[12.25, 3.75]])
    assert tt.length("chute_1", open_pt)[0] == pytest.approx(math.dist(open_pt[0], chute), rel=0.1)


@pytest.mark.parametrize("wh", [load_warehouse(), WH], ids=["default", "small"])
def test_staging_spots_are_free_clear_of_stations_spaced_and_between_the_chutes_and_their_wall(wh):
    r = 0.45
    spots = staging_spots(wh, r)
    assert spots
    chute_y = min(s.y for s in wh.stations_of("chute"))
    for k, (x, y) in enumerate(spots):
        assert wh.grid.disc_is_free(x, y, r)
        assert y < chute_y
        assert all(math.hypot(x - s.x, y - s.y) >= 2 * r + STAGING_CLEARANCE_M - 1e-9 for s in wh.stations.values())
        assert all(math.dist((x, y), o) >= 2 * r + 0.25 - 1e-9 for o in spots[:k])


def status(rid, kind, x, y, battery=1.0, stamp=0.0):
    return RobotStatus(id=rid, kind=kind, x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, battery=battery, mode="idle",
                       progress=1.0, stamp=stamp, radius=KINDS[kind].radius)


def test_idle_robots_wait_near_the_chutes_and_charge_only_when_the_battery_asks():
    fm = FleetManager(WH, KINDS, DispatchParams(idle_s=5.0))
    fm.step_budget_s = 60.0  # (a first leg loads the compiled kernels: not this test's concern)
    assert fm.policy == DispatchPolicy() and fm.staging
    fm.policy = STAGED
    south = (12.75, 11.75)
    for t in (0.0, 6.0):
        fm.on_status(status("full", "cargo", *south, battery=0.9, stamp=t), t)
        fm.on_status(status("half", "cargo", 1.25, 6.75, battery=0.4, stamp=t), t)
    legs = {leg.robot_id: leg for leg in fm.step(6.0).legs}
    assert legs["full"].purpose == "park" and tuple(legs["full"].path.waypoints[-1, :2]) in fm.staging.values()
    assert legs["half"].purpose == "charge"
    # the old rule (LEGACY) sends both to chargers
    from fleet_planner.fleet.dispatch import LEGACY
    old = FleetManager(WH, KINDS, DispatchParams(idle_s=5.0))
    old.policy = LEGACY
    for t in (0.0, 6.0):
        old.on_status(status("full", "cargo", *south, battery=0.9, stamp=t), t)
    [leg] = old.step(6.0).legs
    assert leg.purpose == "charge"


def test_a_robot_on_its_way_to_a_staging_spot_takes_a_job():
    fm = FleetManager(WH, KINDS, DispatchParams(idle_s=5.0))
    fm.step_budget_s = 60.0  # (a first leg loads the compiled kernels: not this test's concern)
    fm.policy = STAGED
    for t in (0.0, 6.0):
        fm.on_status(status("r1", "cargo", 12.75, 11.75, stamp=t), t)
    [leg] = fm.step(6.0).legs
    assert leg.purpose == "park"
    moving = RobotStatus(id="r1", kind="cargo", x=12.75, y=11.0, yaw=0.0, vx=0.0, vy=-0.5, battery=1.0,
                         mode="driving", progress=0.1, stamp=7.5, radius=KINDS["cargo"].radius, path_id=leg.path_id)
    fm.on_status(moving, 7.5)
    fm.submit(Task(id="J1", pick="chute_1", place="B01-01"), 7.5)
    d = fm.step(7.5)
    assert [(e.event, e.robot_id) for e in d.events] == [("assigned", "r1")]
    assert d.legs[0].purpose == "pick"


def test_the_next_job_at_a_taken_chute_goes_to_a_robot_that_waits_by_it():
    fm = FleetManager(WH, KINDS, DispatchParams(idle_s=5.0))
    fm.step_budget_s = 60.0
    fm.policy = STAGED
    assert set(fm.queue_spot) == {"chute_1", "chute_2"}
    fm.on_status(status("r1", "cargo", 6.25, 3.75), 0.0)
    fm.on_status(status("r2", "cargo", 12.75, 11.75), 0.0)
    fm.submit(Task(id="J1", pick="chute_1", place="B01-01"), 0.0)
    fm.submit(Task(id="J2", pick="chute_1", place="B02-01"), 0.0)
    d = fm.step(0.5)
    assert sorted((e.task_id, e.robot_id) for e in d.events if e.event == "assigned") == [("J1", "r1"), ("J2", "r2")]
    legs = {leg.robot_id: leg for leg in d.legs}
    assert (legs["r1"].purpose, legs["r1"].goal) == ("pick", "chute_1")
    spot = fm.queue_spot["chute_1"]
    assert (legs["r2"].purpose, legs["r2"].goal) == ("park", spot)
    assert tuple(legs["r2"].path.waypoints[-1, :2]) == fm.staging[spot]
    # a third job there waits in the queue: one robot waits per chute
    fm.on_status(status("r3", "cargo", 1.25, 6.75), 0.5)
    fm.submit(Task(id="J3", pick="chute_1", place="B03-01"), 0.5)
    assert not [e for e in fm.step(1.0).events if e.event == "assigned"]


@pytest.mark.parametrize("hold", ["soon", "done"])
def test_a_picked_job_about_to_place_frees_its_site_for_the_next_job_with_site_hold_soon(hold):
    fm = FleetManager(WH, KINDS, DispatchParams(idle_s=5.0))
    fm.step_budget_s = 60.0
    fm.policy = DispatchPolicy(site_hold=hold)

    def carrying(x, y, t):
        return RobotStatus(id="r1", kind="manipulator", x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, battery=1.0,
                           mode="driving", progress=0.5, stamp=t, radius=KINDS["manipulator"].radius,
                           task_id="J1", loaded=True)

    fm.on_status(status("r1", "manipulator", 6.25, 3.75), 0.0)
    fm.submit(Task(id="J1", pick="chute_1", place="B01-01"), 0.0)
    assert [e.robot_id for e in fm.step(0.5).events if e.event == "assigned"] == ["r1"]
    fm.on_status(carrying(12.75, 3.75, 1.0), 1.0)   # picked, and 8.5 m of way from B01
    assert [e.event for e in fm.step(1.0).events] == ["picked"]
    fm.on_status(carrying(12.75, 3.75, 1.5), 1.5)
    fm.on_status(status("r2", "manipulator", 12.75, 11.75, stamp=1.5), 1.5)
    fm.submit(Task(id="J2", pick="chute_2", place="B01-02"), 1.5)   # the same storing site
    # r1 needs 8.5 m at 0.72 m/s and a 12 s place (24 s); a robot given J2 now could be at B01 after
    # a 12 s pick and 4 m from chute_1 (17.6 s): J2 waits, with either hold
    assert not [e for e in fm.step(1.5).events if e.event == "assigned"]
    fm.on_status(carrying(4.75, 6.25, 2.0), 2.0)   # r1 at B01: its place (12 s) ends before anyone else can come
    fm.on_status(status("r2", "manipulator", 12.75, 11.75, stamp=2.0), 2.0)
    assigned = [(e.task_id, e.robot_id) for e in fm.step(2.0).events if e.event == "assigned"]
    assert assigned == ([("J2", "r2")] if hold == "soon" else [])   # (control: "done" holds it until J1 is done)
