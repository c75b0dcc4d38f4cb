"""BBMRCA on robots of their own (no ROS): the per-robot BehaviorController, robot agents that hear
each other only through their status records and wait-message records (one control step late),
docking from what a robot hears, and the safety net of a robot that follows a central plan."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from fleet_planner.behavior import Behavior, BehaviorController, HeardDocking, RobotView, WaitMessage, safety_stop
from fleet_planner.checker import min_separation
from fleet_planner.fleet import DispatchParams, FleetManager, RobotAgent, samples_to_path
from fleet_planner.grid import GridMap
from fleet_planner.model import TimedPath
from fleet_planner.robots import RobotModel, load_kinds
from fleet_planner.warehouse import Warehouse, generate_warehouse
from msg_schemas.records import RecordError, RobotStatus, WaitMessageRecord

B = Behavior
KINDS = load_kinds()
CARGO = replace(KINDS["cargo"], max_accel=math.inf, pick_s=2.0, place_s=2.0)  # 0.35 m, 1 m/s
OPEN = Warehouse(GridMap(np.zeros((12, 12), bool)), {})                          # 12 m x 12 m, nothing in it
SMALL = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)    # 16 m x 13 m
DT = 0.1


def leg_to(goal, t0=0.0):
    """A leg as the planner sends it; in behaviour coordination only its last waypoint counts."""
    return TimedPath("x", 0.35, [[goal[0], goal[1], 0.0], [goal[0], goal[1], 1.0]]), t0


class Crowd:
    """Robot agents on one simulated clock that hear each other only through the wire records: the
    statuses of a step reach the others before the next step (as JSON), and so do wait messages."""

    def __init__(self, wh, starts, coordination="behavior", kind=CARGO):
        chargers = [s.pose for s in wh.stations_of("charger")]
        self.agents = {rid: RobotAgent(RobotModel(rid, kind, x, y, chargers=chargers), wh, coordination)
                       for rid, (x, y) in starts.items()}
        self.t, self.sent = 0.0, []
        self.track = {rid: [] for rid in starts}
        for a in self.agents.values():
            a.tick(0.0)

    def go(self, rid, goal, path_id=1):
        path, t0 = leg_to(goal, self.t)
        self.agents[rid].on_path(path, t0, path_id)

    def step(self):
        self.t = round(self.t + DT, 9)
        statuses = [a.tick(self.t).to_json() for a in self.agents.values()]
        waits = [w.to_json() for a in self.agents.values() for w in a.take_wait_messages()]
        self.sent += [WaitMessageRecord.from_json(w) for w in waits]
        for a in self.agents.values():
            for text in statuses:
                a.on_status(RobotStatus.from_json(text))
            for text in waits:
                a.on_wait_message(WaitMessageRecord.from_json(text))
        for rid, a in self.agents.items():
            self.track[rid].append((a.model.x, a.model.y, self.t))

    def run(self, condition, limit_s):
        while not condition():
            if self.t >= limit_s:
                return False
            self.step()
        return True

    def arrived(self, rid):
        return self.agents[rid].controller.arrived

    def min_gap(self):
        return min_separation([samples_to_path(rid, 0.35, tr) for rid, tr in self.track.items()])


# -- one robot, from what it hears ----------------------------------------------------------------
def test_a_robot_waits_for_a_robot_crossing_its_critical_area_and_goes_on_when_it_has_passed():
    me = BehaviorController(OPEN.grid, "me", 0.35, 1.0, (2.0, 6.0))
    me.assign((10.0, 6.0), now=0.0)
    crossing = RobotView("o", (3.3, 6.2), 0.35, B.FOLLOW_WAYPOINT, next_waypoint=(3.3, 11.0))
    me.step(0.0, DT, [crossing])
    assert (me.behavior, me.partner) == (B.WAIT_KEEP_DISTANCE, "o")
    assert me.position == (2.0, 6.0)                       # it holds
    gone = replace(crossing, position=(3.3, 8.5))
    me.step(DT, DT, [gone])
    assert me.behavior is B.FOLLOW_WAYPOINT and me.position[0] > 2.0


def test_a_robot_out_of_range_is_not_sensed_and_its_messages_are_dropped():
    me = BehaviorController(OPEN.grid, "me", 0.35, 1.0, (1.0, 1.0))
    me.assign((1.0, 11.0), now=0.0)
    far = RobotView("far", (1.0, 8.0), 0.35, B.WAIT_KEEP_DISTANCE, next_waypoint=(1.0, 1.0), partner="me")
    assert me.step(0.0, DT, [far], [WaitMessage(("far",))]) == []   # 7 m away: beyond comm_range (6 m)
    assert me.behavior is B.FOLLOW_WAYPOINT


def test_the_local_safety_layer_keeps_clear_of_where_the_other_may_have_driven_since_its_report():
    me = BehaviorController(OPEN.grid, "me", 0.35, 1.0, (2.0, 6.0))
    other = RobotView("o", (3.0, 6.0), 0.35)        # 0.3 m beyond the sum of radii, ahead
    ok = me.keeps_clear([other], {"o": 0.25})       # it may have come 0.25 m closer since it reported
    assert not ok(np.array([2.1, 6.0]))             # closer than 0.7 + 0.25 + the margin, and closer than now
    assert ok(np.array([1.9, 6.0]))                 # backing away is fine
    assert me.keeps_clear([other], {})(np.array([2.1, 6.0]))   # had it stood still, 0.2 m would be left


def test_heard_docking_first_come_first_served_ties_by_id():
    def waiting(rid, since):
        return RobotView(rid, (0.0, 0.0), 0.35, B.WAIT_FOR_DOCKING, (1.0, 0.0), station="S", dock_since=since)
    arb = HeardDocking("r2")
    arb.hear([waiting("r1", 3.0)])
    assert not arb.request("S", "r2", 5.0) and arb.first_waiting("S") == "r1"   # r1 came first
    arb.hear([waiting("r10", 5.0)])
    assert arb.request("S", "r2", 6.0)              # same arrival time as r10 (it asked at 5): r2 < r10
    arb.hear([replace(waiting("r1", 3.0), behavior=B.DOCK, docked_at="S")])
    assert arb.holder("S") == "r1" and not arb.keeps("S", "r2")   # both took it: the later one gives it up
    arb.hear([replace(waiting("r10", 5.0), behavior=B.DOCK, docked_at="S")])
    assert arb.keeps("S", "r2")
    arb.release("S", "r2")
    arb.hear([])
    assert arb.request("S", "r2", 9.0)


# -- robots that only hear each other's records -------------------------------------------------------
def test_three_robots_in_a_wait_cycle_find_it_with_wait_messages_sent_as_records():
    """Three robots on a triangle, each bound past the next one: each waits for the next. The wait
    messages go round as fleet/wait_message@1 records until one robot finds its own id and re-plans."""
    side, centre = 1.4, np.array([6.0, 6.0])
    corners = [centre + side / math.sqrt(3) * np.array([math.cos(a), math.sin(a)]) for a in np.radians([90, 210, 330])]
    crowd = Crowd(OPEN, {f"r{k}": tuple(c) for k, c in enumerate(corners)})
    for k in range(3):
        ahead = (corners[(k + 1) % 3] - corners[k]) / side
        crowd.go(f"r{k}", tuple(corners[k] + 4 * ahead))
    for _ in range(2):
        crowd.step()
    ctl = {rid: a.controller for rid, a in crowd.agents.items()}
    assert {rid: (c.behavior, c.partner) for rid, c in ctl.items()} == {
        "r0": (B.WAIT_KEEP_DISTANCE, "r1"), "r1": (B.WAIT_KEEP_DISTANCE, "r2"), "r2": (B.WAIT_KEEP_DISTANCE, "r0")}
    assert crowd.run(lambda: all(crowd.arrived(r) for r in ctl), limit_s=60.0)
    assert sum(c.deadlocks for c in ctl.values()) >= 1 and sum(c.replans for c in ctl.values()) >= 1
    assert any(len(m.waiting) == 3 for m in crowd.sent)       # forwarded twice: the whole cycle
    assert all(m.waiting[-1] == m.sender for m in crowd.sent)
    assert crowd.min_gap()[0] >= 0.0


def test_robots_bound_for_one_station_dock_one_at_a_time_from_what_they_hear():
    chute = SMALL.stations["chute_1"].pose
    starts = {"r1": (2.0, 3.5), "r2": (6.75, 3.75), "r3": (9.0, 2.0)}
    crowd = Crowd(SMALL, starts)
    for rid in starts:
        crowd.go(rid, chute)
    served, docked_at_once, waited = [], 0, set()
    away = {"r1": (2.25, 10.75), "r2": (4.25, 10.75), "r3": (6.25, 10.75)}

    def watch():
        nonlocal docked_at_once
        views = [a.controller.view() for a in crowd.agents.values()]
        docked_at_once = max(docked_at_once, sum(v.docked_at == "chute_1" for v in views))
        waited.update(v.id for v in views if v.behavior is B.WAIT_FOR_DOCKING)
        for rid in starts:
            there = math.dist(crowd.agents[rid].controller.position, chute) < 1e-6
            if rid not in served and crowd.arrived(rid) and there:
                served.append(rid)
                crowd.go(rid, away[rid], path_id=2)        # done there: leave
        return len(served) == len(starts) and all(crowd.arrived(r) for r in starts)
    assert crowd.run(watch, limit_s=120.0), served
    assert docked_at_once == 1 and waited
    assert crowd.min_gap()[0] >= 0.0


def test_an_agent_in_behaviour_mode_takes_only_the_goal_of_a_leg_and_reports_its_state():
    agent = RobotAgent(RobotModel("r1", CARGO, 2.0, 2.0), OPEN, "behavior")
    agent.tick(0.0)
    planned = TimedPath("r1", 0.35, [[5.0, 5.0, 0.0], [3.0, 9.0, 50.0], [9.0, 9.0, 99.0]])  # stamps bind nothing
    agent.on_path(planned, 0.0, 7)
    st = agent.tick(DT)
    assert (st.path_id, st.behavior["name"], st.mode) == (7, "FollowWayPoint", "driving")
    assert st.behavior["next"] == (9.0, 9.0) and 0.0 <= st.progress < 1.0   # straight to the goal
    t = DT
    while st.progress < 1.0 and t < 20.0:
        t += DT
        st = agent.tick(t)
    assert (st.x, st.y) == (9.0, 9.0) and t < 11.0     # 9.9 m at its top speed of 1 m/s
    assert RobotStatus.from_json(st.to_json()) == st
    with pytest.raises(RecordError, match=r"robot_status\.behavior\.name: must be one of"):
        RobotStatus.from_dict({**st.to_dict(), "behavior": {**st.to_dict()["behavior"], "name": "Dance"}})


def test_wait_message_records_are_checked():
    assert WaitMessageRecord.from_json(WaitMessageRecord(sender="b", receiver="c", waiting=("a", "b"),
                                                         stamp=1.0).to_json()).waiting == ("a", "b")
    with pytest.raises(RecordError, match="wait_message.waiting: must end with the sender 'b'"):
        WaitMessageRecord(sender="b", receiver="c", waiting=("b", "a"), stamp=1.0)
    with pytest.raises(RecordError, match=r"wait_message.waiting: 'a' appears more than once"):
        WaitMessageRecord(sender="a", receiver="c", waiting=("a", "a"), stamp=1.0)
    with pytest.raises(RecordError, match="wait_message.receiver: a robot does not wait for itself"):
        WaitMessageRecord(sender="a", receiver="a", waiting=("a",), stamp=1.0)


# -- the planner in behaviour coordination ---------------------------------------------------------
def test_the_planner_gives_behaviour_legs_without_delays_and_does_not_re_plan_late_robots():
    fm = FleetManager(SMALL, {"cargo": CARGO}, DispatchParams(lateness_tolerance_s=1.0), coordination="behavior")
    fm.on_status(RobotStatus(id="r1", kind="cargo", x=2.25, y=10.75, yaw=0.0, vx=0.0, vy=0.0, battery=1.0,
                             mode="idle", progress=1.0, stamp=0.0, radius=0.35), 0.0)
    fm.submit({"schema": "fleet/task@1", "id": "J1", "pick": "chute_1", "place": "B01-01"}, 0.0)
    [leg] = fm.step(0.5).legs
    wp = leg.path.waypoints
    assert tuple(wp[0, :2]) == (2.25, 10.75) and tuple(wp[-1, :2]) == SMALL.stations["chute_1"].pose
    assert fm.schedule(0.5).nodes["r1"]["delay"] == 0.0
    late = RobotStatus(id="r1", kind="cargo", x=2.25, y=9.0, yaw=0.0, vx=0.0, vy=0.0, battery=1.0, mode="waiting",
                       progress=0.2, stamp=30.0, radius=0.35, path_id=leg.path_id, lateness_s=20.0)
    fm.on_status(late, 30.0)
    assert fm.step(30.0).legs == []
    with pytest.raises(ValueError, match="coordination: 'swarm' is not one of central, behavior"):
        FleetManager(SMALL, {"cargo": CARGO}, coordination="swarm")


# -- the safety net of a robot on a central plan --------------------------------------------------------
def central_robot_heading_east(other: RobotStatus, speed=1.0):
    """A central agent at (2, 6) driving east at ``speed`` on a timed path, hearing ``other``."""
    agent = RobotAgent(RobotModel("me", CARGO, 2.0, 6.0), OPEN)
    agent.on_path(TimedPath("me", 0.35, [[2.0, 6.0, 0.0], [10.0, 6.0, 8.0 / speed]]), 0.0, 1)
    agent.on_status(other)
    return agent


def status(rid, x, y, vx=0.0, vy=0.0, stamp=0.0):
    return RobotStatus(id=rid, kind="cargo", x=x, y=y, yaw=0.0, vx=vx, vy=vy, battery=1.0,
                       mode="driving" if vx or vy else "idle", progress=1.0, stamp=stamp, radius=0.35)


def drive(agent, other_at=None, seconds=4.0):
    """Tick the agent; ``other_at(t)``: the other robot's status at t (heard a step late)."""
    t, closest, held = 0.0, math.inf, 0
    agent.tick(0.0)
    while t < seconds - 1e-9:
        t = round(t + DT, 9)
        st = agent.tick(t)
        held += st.mode == "waiting"
        if other_at is not None:
            o = other_at(t)
            closest = min(closest, math.hypot(o.x - st.x, o.y - st.y) - 0.7)
            agent.on_status(o)
    return st, closest, held


def test_a_central_robot_waits_rather_than_drive_into_a_robot_standing_in_its_way():
    agent = central_robot_heading_east(status("o", 4.0, 6.1))    # the plan did not know it was there
    st, closest, held = drive(agent, lambda t: status("o", 4.0, 6.1, stamp=t))
    assert st.mode == "waiting" and agent.waits_for == "o" and held > 10
    assert 0.0 < closest < 0.3 and st.lateness_s > 1.0            # the planner re-plans it once it is late


@pytest.mark.parametrize("name, other_at", [
    ("passing beside at the planned margin", lambda t: status("o", 8.0 - t, 6.0 + 0.7 + 0.23, vx=-1.0, stamp=t)),
    ("followed at the planned margin", lambda t: status("o", 2.0 + 0.7 + 0.23 + t, 6.0, vx=1.0, stamp=t)),
    ("crossing ahead of it", lambda t: status("o", 4.2, 5.5 + t, vy=1.0, stamp=t)),
])
def test_the_safety_net_stays_out_of_the_way_of_a_plan_that_keeps_the_robots_apart(name, other_at):
    agent = central_robot_heading_east(other_at(0.0))
    st, closest, held = drive(agent, other_at)
    assert held == 0 and st.lateness_s == 0.0, name
    assert closest > 0.2


def test_safety_stop_sweeps_the_other_disc_along_its_motion():
    me = RobotView("me", (0.0, 0.0), 0.35, next_waypoint=(10.0, 0.0))
    beside = RobotView("o", (0.5, 0.9), 0.35)                     # beside my channel ...
    assert safety_stop(me, [beside], 0.1, 0.05) is None
    assert safety_stop(me, [beside], 0.1, 0.05, {"o": (0.0, -0.2)}).id == "o"   # ... coming into it
    assert safety_stop(me, [beside], 0.1, 0.05, {"o": (0.0, 0.2)}) is None      # ... leaving it
    assert safety_stop(replace(me, next_waypoint=None), [beside], 0.1, 0.05, {"o": (0.0, -0.5)}) is None
