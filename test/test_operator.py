"""The operator's commands without ROS (fleet/operator.py on the planner's end, fleet/manual.py on
the robot's): pause and resume, e-stop, cancel, priority, send to a station, manual drive,
deadlines; bad input is refused naming the field. Runs on test_dispatch's simulated clock, and
the robots' driven positions are judged by the independent checker (no two discs ever touch)."""
import math

import numpy as np
import pytest
from test_dispatch import CHARGERS, FAST, PARKING, WH, Sim, four_robots, status, task

from fleet_planner.checker import min_separation
from fleet_planner.fleet import DispatchParams, FleetManager, JobStore, Leg
from fleet_planner.fleet.manual import DEADMAN_S, check_twist
from fleet_planner.fleet.operator import Operator
from fleet_planner.model import TimedPath
from msg_schemas.records import Command, RecordError


class OpSim(Sim):
    """test_dispatch's simulation with the operator stepping the manager; commands take effect at
    once, as the ROS glue does (the e-stop also reaches every agent at once)."""

    def __init__(self, fleet, **kwargs):
        super().__init__(fleet, **kwargs)
        self.op = Operator(self.fm)

    def step(self, now):
        return self.op.step(now)

    def do(self, name, *args, **kwargs):
        out = getattr(self.op, name)(*args, self.t, **kwargs)
        self.deliver(out.decisions)
        if name in ("estop", "release"):
            for a in self.agents.values():
                a.hand.set_estop(name == "estop")
        return out

    def pos(self, rid):
        m = self.agents[rid].model
        return m.x, m.y

    def no_contact(self):
        gap, a, b, t = min_separation(self.driven())
        assert gap >= 0.0, f"{a} and {b} overlapped by {-gap:.3f} m at t = {t}"


def events_of(sim, task_id):
    return [e.event for e in sim.events if e.task_id == task_id]


def started(sim, rid):
    """``rid`` has a job and is on its way (some distance from where it stood)."""
    return sim.agents[rid].job is not None and sim.agents[rid].model.speed > 0


def two_jobs_sim():
    sim = OpSim(four_robots())
    sim.submit(task("J1", "chute_1", "B01-01"), task("J2", "chute_2", "B04-02", needs=("manipulator",)))
    assert sim.run_until(lambda: all(sim.fm.jobs[j].robot for j in ("J1", "J2")) and
                         any(started(sim, r) for r in sim.agents), 60)
    return sim


def test_a_paused_robot_holds_where_it_is_the_others_go_on_and_it_finishes_once_resumed():
    sim = two_jobs_sim()
    rid = sim.fm.jobs["J1"].robot
    other = sim.fm.jobs["J2"].robot
    assert sim.run_until(lambda: started(sim, rid), 30)
    out = sim.do("pause", rid)
    assert out.ok and sim.fm.robots[rid].paused and [leg.purpose for leg in out.decisions.legs] == ["hold"]
    sim.run_until(lambda: False, 1.0)  # it brakes
    here = sim.pos(rid)
    assert not sim.run_until(lambda: math.dist(sim.pos(rid), here) > 1e-6, 10.0), "a paused robot moved"
    assert sim.run_until(lambda: sim.last("J2") == "done", 120), "the others go on"
    assert sim.last("J1") in ("assigned", "picked")
    assert sim.do("resume", rid).ok
    assert sim.run_until(lambda: sim.last("J1") == "done", 120)
    assert sim.agents[other].job is None
    sim.no_contact()


def test_a_paused_fleet_takes_no_job_and_does_them_all_when_resumed():
    sim = OpSim(four_robots())
    assert sim.do("pause", None).ok
    sim.submit(task("J1"), task("J2", "chute_2", "B03-01"))
    sim.run_until(lambda: False, 5.0)
    assert events_of(sim, "J1") == ["accepted"] and all(a.model.speed == 0 for a in sim.agents.values())
    assert sim.do("resume", None).message == "fleet resumed (4 robots were paused)"
    assert sim.run_until(lambda: sim.last("J1") == sim.last("J2") == "done", 120)
    sim.no_contact()


def test_the_e_stop_stops_every_robot_at_once_until_released():
    sim = two_jobs_sim()
    assert sim.run_until(lambda: sum(a.model.speed > 0 for a in sim.agents.values()) >= 1, 30)
    sim.do("estop")
    sim.run_until(lambda: False, 0.1)  # one step: the robots brake within it (the model stops at once)
    frozen = {rid: sim.pos(rid) for rid in sim.agents}
    legs = sum(len(v) for v in sim.legs.values())
    sim.submit(task("J3", "chute_1", "B02-03"))
    assert not sim.run_until(lambda: any(math.dist(sim.pos(r), p) > 1e-9 for r, p in frozen.items()), 10.0)
    assert sum(len(v) for v in sim.legs.values()) == legs, "no new legs during an e-stop"
    assert all(sim.agents[r].tick(sim.t).estop for r in sim.agents)
    assert sim.do("release").ok
    assert sim.run_until(lambda: all(sim.last(j) == "done" for j in ("J1", "J2", "J3")), 180)
    sim.no_contact()


def test_cancelling_a_queued_an_assigned_and_a_carried_job():
    sim = OpSim(four_robots())
    sim.do("pause", None)
    sim.submit(task("Q1"))
    out = sim.do("cancel", "Q1")
    assert out.ok and [e.event for e in out.decisions.events] == ["cancelled"]
    sim.do("resume", None)
    # assigned, not yet picked: the robot is released where it is
    sim.submit(task("A1", "chute_1", "B01-01"))
    assert sim.run_until(lambda: started(sim, sim.fm.jobs["A1"].robot or "r1"), 30)
    rid = sim.fm.jobs["A1"].robot
    [ev] = sim.do("cancel", "A1", reason="wrong chute").decisions.events
    assert (ev.event, ev.robot_id) == ("cancelled", rid) and "wrong chute" in ev.reason
    assert sim.agents[rid].job is None and sim.fm.robots[rid].job is None
    # picked: the goods go to a drop-off (a free storing site) and the event says where
    sim.submit(task("P1", "chute_2", "B04-02"))
    assert sim.run_until(lambda: sim.last("P1") == "picked", 120)
    rid = sim.fm.jobs["P1"].robot
    [ev] = sim.do("cancel", "P1").decisions.events
    target = sim.fm.robots[rid].target
    assert target is not None and target.purpose == "park" and f"to the drop-off {target.name}" in ev.reason
    assert sim.run_until(lambda: math.dist(sim.pos(rid), target.pose) < 0.05, 60)
    assert "Q1" not in [e.task_id for e in sim.events if e.event == "assigned"]
    assert [sim.fm.jobs[j].state for j in ("Q1", "A1", "P1")] == ["cancelled"] * 3
    # nothing more to cancel
    for job, words in (("P1", "task_id: job P1 is already cancelled"), ("nope", "task_id: unknown job 'nope'"),
                       (7, "task_id: must be a job id (got 7)")):
        out = sim.do("cancel", job)
        assert not out.ok and out.message.startswith(words) and not out.decisions.events
    sim.no_contact()


def test_a_changed_priority_and_an_earlier_deadline_go_first_and_late_jobs_are_reported():
    sim = OpSim([("r1", "cargo", *CHARGERS[0], 1.0)])
    sim.do("pause", None)
    sim.submit(task("J1", "chute_1", "B01-01"), task("J2", "chute_1", "B02-01"), task("J3", "chute_1", "B03-01"),
               task("J4", "chute_1", "B04-01", deadline=2.0))
    out = sim.do("set_priority", "J3", 5)
    assert out.ok and out.message == "job J3: priority 0 -> 5"
    assert not sim.do("set_priority", "J3", "high").ok
    assert sim.do("set_priority", "J3", True).message == "priority: must be an integer (got True)"
    sim.do("resume", None)
    assert sim.run_until(lambda: all(sim.last(j) == "done" for j in ("J1", "J2", "J3", "J4")), 400)
    order = [e.task_id for e in sim.events if e.event == "assigned"]
    assert order == ["J3", "J4", "J1", "J2"], order
    late = [e for e in sim.events if e.event == "late"]
    assert [e.task_id for e in late] == ["J4"] and "deadline t=2.0 s passed" in late[0].reason


def test_a_robot_sent_to_a_station_goes_there_and_bad_sends_are_refused():
    sim = OpSim(four_robots())
    sim.run_until(lambda: False, 1.0)
    out = sim.do("send", "r1", "chute_2")
    assert out.ok, out.message
    pose = sim.fm.warehouse.stations["chute_2"].pose
    assert sim.run_until(lambda: math.dist(sim.pos("r1"), pose) < 0.05, 60)
    for args, words in ((("r9", "chute_1"), "robot_id: unknown robot 'r9' (known: r1, r2, r3, r4)"),
                        (("r2", "chute_9"), "station: unknown station 'chute_9'"),
                        (("r2", "chute_2"), "station: chute_2 is taken by robot r1"),
                        ((None, "chute_1"), "robot_id: must be a robot id (got None)")):
        out = sim.do("send", *args)
        assert not out.ok and out.message.startswith(words), out.message
    sim.submit(task("J1", "chute_1", "B01-01"))
    assert sim.run_until(lambda: sim.fm.robots[sim.fm.jobs["J1"].robot or "r1"].job == "J1", 30)
    busy = sim.fm.jobs["J1"].robot
    out = sim.do("send", busy, "charger_1")
    assert not out.ok and out.message == f"robot_id: robot {busy} is on job J1; cancel it first"


def test_manual_drive_moves_the_robot_by_velocity_commands_and_leaving_it_re_joins_the_plan():
    sim = OpSim(four_robots())
    sim.submit(task("J1", "chute_1", "B01-01"))
    assert sim.run_until(lambda: sim.fm.jobs["J1"].robot is not None, 30)
    rid = sim.fm.jobs["J1"].robot
    hand = sim.agents[rid].hand
    sim.run_until(lambda: False, 0.5)
    assert "manual drive on" in hand.set_manual(True)
    sim.run_until(lambda: sim.fm.robots[rid].manual, 2.0)
    assert sim.fm.robots[rid].leg is None and sim.fm.robots[rid].manual
    legs = len(sim.legs[rid])
    start = sim.pos(rid)
    yaw, t0 = sim.agents[rid].model.yaw, sim.t
    for _ in range(20):  # 2 s of commands at 10 Hz: 0.3 m/s forward
        hand.command((0.3, 0.0, 0.0), (0.0, 0.0, 0.0), sim.t)
        sim.run_until(lambda: False, 0.1)
    moved = math.dist(sim.pos(rid), start)
    blocked = hand.blocked_by
    assert 0.2 < moved <= 0.3 * (sim.t - t0) + 1e-6 or blocked is not None, (moved, blocked)
    if blocked is None:
        assert abs(math.atan2(sim.pos(rid)[1] - start[1], sim.pos(rid)[0] - start[0]) - yaw) < 1e-6
    here = sim.pos(rid)
    sim.run_until(lambda: False, DEADMAN_S + 0.5)  # no more commands: the dead man's switch stops it
    stopped = sim.pos(rid)
    sim.run_until(lambda: False, 1.0)
    assert sim.pos(rid) == stopped and math.dist(here, stopped) < 0.2
    assert len(sim.legs[rid]) == legs, "no leg for a robot in manual drive"
    with pytest.raises(ValueError, match=r"^twist\.linear\.x: must be a finite number \(got nan\)"):
        hand.command((math.nan, 0.0, 0.0), (0.0, 0.0, 0.0), sim.t)
    with pytest.raises(ValueError, match=r"^twist\.linear\.x: 9 m/s is beyond"):
        hand.command((9.0, 0.0, 0.0), (0.0, 0.0, 0.0), sim.t)
    with pytest.raises(ValueError, match=r"^twist\.linear\.y: must be 0"):
        hand.command((0.1, 0.2, 0.0), (0.0, 0.0, 0.0), sim.t)
    assert "re-joins the plan" in hand.set_manual(False)
    assert sim.run_until(lambda: sim.last("J1") == "done", 120)
    assert not sim.fm.robots[rid].manual
    sim.no_contact()


def test_check_twist_takes_a_good_command_and_a_robot_not_in_manual_refuses_commands():
    assert check_twist((0.5, 0, 0), (0, 0, -1.0), 1.0) == (0.5, -1.0)
    sim = OpSim(four_robots())
    with pytest.raises(ValueError, match=r"^twist: robot r1 is not in manual drive"):
        sim.agents["r1"].hand.command((0.1, 0, 0), (0, 0, 0), 0.0)


def test_commands_for_unknown_robots_are_refused_and_the_status_of_a_manual_robot_says_so():
    sim = OpSim(four_robots())
    sim.run_until(lambda: False, 0.5)
    for name in ("pause", "resume"):
        out = sim.do(name, "ghost")
        assert not out.ok and out.message.startswith("robot_id: unknown robot 'ghost'")
    sim.fm.on_status(status("r1", "cargo", *CHARGERS[0], stamp=sim.t, manual=True), sim.t)
    sim.op.step(sim.t)
    assert sim.fm.robots["r1"].manual and not sim.fm.robots["r1"].free


@pytest.mark.parametrize("data, words", [
    ({"id": "c1", "command": "cancel"}, "command.task_id: required for 'cancel'"),
    ({"id": "c1", "command": "send", "robot_id": "r1"}, "command.station: required for 'send'"),
    ({"id": "c1", "command": "estop", "robot_id": "r1"}, "command.robot_id: 'estop' takes no robot_id"),
    ({"id": "c1", "command": "priority", "task_id": "J1", "priority": 1.5}, "command.priority: must be an integer"),
    ({"id": "c1", "command": "launch"}, "command.command: must be one of"),
])
def test_bad_command_records_are_refused_naming_the_field(data, words):
    with pytest.raises(RecordError, match="^" + words.replace("(", r"\(").replace(")", r"\)")):
        Command.from_dict({"schema": Command.SCHEMA, **data})


def test_every_command_record_is_carried_out():
    sim = OpSim(four_robots())
    sim.run_until(lambda: False, 0.5)
    sim.submit(task("J1"))
    for data in ({"command": "pause", "robot_id": "r2"}, {"command": "resume", "robot_id": "r2"},
                 {"command": "priority", "task_id": "J1", "priority": 3}, {"command": "estop"},
                 {"command": "release"}, {"command": "cancel", "task_id": "J1"},
                 {"command": "send", "robot_id": "r3", "station": "chute_2"}):
        out = sim.op.execute(Command(id="c", **data), sim.t)
        assert out.ok, (data, out.message)


def test_a_changed_priority_is_kept_in_the_job_store_and_a_cancelled_job_is_not_reloaded(tmp_path):
    store = JobStore(tmp_path / "jobs.db")
    fm = FleetManager(WH, FAST, DispatchParams(), PARKING, store=store)
    op = Operator(fm)
    fm.submit(task("J1"), 0.0)
    fm.submit(task("J2"), 0.0)
    assert op.set_priority("J1", 4, 1.0).ok and op.cancel("J2", 1.0).ok
    assert store.get("J1").task.priority == 4 and store.get("J2").state == "cancelled"
    assert [h.event for h in store.history("J1")] == ["accepted", "priority"]
    again = FleetManager(WH, FAST, DispatchParams(), PARKING, store=store)
    assert set(again.jobs) == {"J1"} and again.jobs["J1"].task.priority == 4


def test_manual_drive_is_refused_while_the_robot_picks():
    sim = OpSim([("r1", "cargo", *CHARGERS[0], 1.0)])
    m = sim.agents["r1"].model
    m.start_action("pick", 0.0, 5.0)
    with pytest.raises(ValueError, match=r"^data: robot r1 is picking"):
        sim.agents["r1"].hand.set_manual(True)


def _corridor():
    """A y on the test warehouse with a free straight run from x = 1.5 to 14.5 for the largest robot."""
    return next(y + 0.5 for y in range(1, 12) if all(WH.grid.disc_is_free(x / 4, y + 0.5, 0.45)
                                                      for x in range(6, 59)))


def _leg(rid, radius, points, path_id, purpose, goal):
    return Leg(rid, TimedPath(rid, radius, np.array(points, dtype=float)), path_id, purpose, goal)


@pytest.mark.parametrize("follower", [True, False])
def test_a_paused_robot_in_the_way_drives_on_along_its_leg_to_a_place_nobody_passes(follower):
    """r1 drives east down a corridor; r2 follows it and stops 0.5 m beyond where r1 is now. Paused,
    r1 would stand in r2's way: it drives on along its own leg, as planned, to the first place r2
    never comes near, and holds there; without r2 behind it, it holds where it is."""
    y = _corridor()
    fm = FleetManager(WH, FAST, DispatchParams(), PARKING)
    op = Operator(fm)
    now = 0.5
    fm.on_status(status("r1", "cargo", 5.5, y, mode="driving", stamp=now, path_id=1, progress=0.5 / 8), now)
    r1 = fm.robots["r1"]
    r1.leg, r1.last_path_id = _leg("r1", r1.radius, [[5.0, y, 0.0], [13.0, y, 8.0]], 1, "park", "parking_1"), 1
    if follower:
        fm.on_status(status("r2", "cargo", 2.5, y, mode="driving", stamp=now, path_id=2, progress=0.5 / 4), now)
        r2 = fm.robots["r2"]
        r2.leg, r2.last_path_id = _leg("r2", r2.radius, [[2.0, y, 0.0], [6.0, y, 4.0]], 2, "park", "parking_2"), 2
    out = op.pause("r1", now)
    [leg] = out.decisions.legs
    end = leg.path.waypoints[-1]
    if not follower:
        assert leg.purpose == "hold" and len(leg.path.waypoints) == 1 and abs(end[0] - 5.5) < 1e-6
        return
    clearance = 2 * r1.radius + fm.margin
    assert leg.purpose == "hold" and 6.0 + clearance <= end[0] <= 6.0 + clearance + 0.3, end
    assert leg.path.waypoints[0][:2].tolist() == [5.5, y]
    # the hold leg is the planned leg up to there (same place at every time), then standing
    for t in np.linspace(now, end[2], 20):
        assert np.allclose(leg.path.position(t), r1.leg.path.position(t) if t <= end[2] else end[:2])
    assert not fm.robots["r2"].replan and "drives on" in " ".join(out.decisions.notes)
