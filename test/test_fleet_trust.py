"""Done means done, and only the planner's word counts (issue 9): goods are never picked twice, an
unknown robot id does not join a fleet with a roster, agents keep the first task of an id and act
only on events about their own job (from the planner, where the sender is known), and a pick or
place is finished only when the robot's statuses show it did it, however long the clock runs."""
import pytest
from test_dispatch import CHARGERS, FAST, WH, Sim, four_robots, manager, status, task

from fleet_planner.fleet import FleetManager, RobotAgent
from fleet_planner.fleet.dispatch import PIPELINED
from fleet_planner.robots import RobotModel
from msg_schemas.records import RobotStatus, TaskEvent


def test_a_robot_that_dies_with_the_goods_fails_its_job_and_nobody_picks_again():
    sim = Sim(four_robots(), offline_timeout_s=2.0)
    sim.submit(task("J1", "chute_2", "B04-01"))
    assert sim.run_until(lambda: sim.last("J1") == "picked")
    carrier = next(e.robot_id for e in sim.events if e.event == "picked")
    sim.dead.add(carrier)  # its agent dies with the goods on board
    assert sim.run_until(lambda: sim.last("J1") == "failed", limit=60)
    failed = [e for e in sim.events if e.task_id == "J1" and e.event == "failed"]
    assert failed[0].robot_id == carrier and "with the goods" in failed[0].reason
    sim.run_until(lambda: False, limit=30)  # and nothing more happens to it
    events = [e.event for e in sim.events if e.task_id == "J1"]
    assert events.count("picked") == 1 and events.count("assigned") == 1 and events[-1] == "failed"


def test_an_unknown_robot_does_not_join_a_fleet_with_a_roster():
    fm = FleetManager(WH, FAST, roster=["r1"])
    fm.on_status(status("r1", "cargo", *CHARGERS[0]), 0.0)
    with pytest.raises(ValueError, match="'intruder': not on the fleet's roster"):
        fm.on_status(status("intruder", "cargo", *CHARGERS[1]), 0.0)
    fm.on_status(status("intruder", "cargo", *CHARGERS[1], stamp=0.1), 0.1)  # warned once: now silent
    fm.submit(task("J1"), 0.2)
    assigned = [e for t in (0.5, 1.0) for e in fm.step(t).events if e.event == "assigned"]
    assert set(fm.robots) == {"r1"} and [e.robot_id for e in assigned] == ["r1"]


def test_without_a_roster_any_robot_joins():
    fm = manager()
    fm.on_status(status("anyone", "cargo", *CHARGERS[0]), 0.0)
    assert "anyone" in fm.robots


def agent(**kw):
    return RobotAgent(RobotModel("r1", FAST["cargo"], *CHARGERS[0], chargers=CHARGERS), WH, **kw)


def test_an_agent_keeps_the_first_task_of_an_id():
    a = agent()
    a.on_task(task("J1", "chute_1", "B01-01"))
    a.on_task(task("J1", "chute_2", "B04-01"))  # a duplicate the planner rejects
    assert a.tasks["J1"].pick == "chute_1"


def ev(event, task_id="J1", robot_id="r1", **kw):
    return TaskEvent(task_id=task_id, event=event, stamp=1.0, robot_id=robot_id, **kw)


def test_an_agent_drops_its_job_only_on_the_planners_word_about_it():
    a = agent()
    assert a.on_event(ev("assigned")) and a.job == "J1"
    assert not a.on_event(ev("cancelled", robot_id=None))        # names no robot: not about this one
    assert not a.on_event(ev("failed", robot_id="r2", reason="x"))  # about another robot
    assert not a.on_event(ev("cancelled", task_id="J2"))          # another job
    assert a.job == "J1"
    assert a.on_event(ev("cancelled")) and a.job is None


def test_an_agent_with_a_planner_name_ignores_events_from_other_nodes():
    a = agent(planner="fleet_planner")
    assert not a.on_event(ev("assigned"), sender="forger") and a.job is None
    assert not a.on_event(ev("assigned")) and a.job is None  # sender unknown: not the planner's word
    assert a.on_event(ev("assigned"), sender="fleet_planner") and a.job == "J1"
    assert not a.on_event(ev("cancelled"), sender="forger") and a.job == "J1"
    assert a.on_event(ev("cancelled"), sender="fleet_planner") and a.job is None


def test_a_pick_is_done_only_when_the_robot_reports_it():
    sim = Sim([("r1", "cargo", *CHARGERS[0], 1.0)])
    sim.submit(task("J1", "chute_1", "B01-01"))
    robot = sim.agents["r1"]
    act = robot._act
    robot._act = lambda now: None  # it gets there but never picks
    assert sim.run_until(lambda: "r1" in sim.fm.robots and sim.fm.robots["r1"].arrived_at is not None)
    sim.run_until(lambda: False, limit=60)  # far beyond the pick's nominal time
    assert sim.last("J1") == "assigned"
    robot._act = act  # now it picks: reported, so done
    assert sim.run_until(lambda: sim.last("J1") == "picked", limit=30)
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=120)


def test_a_pick_the_robot_reports_without_the_goods_on_board_is_not_done():
    sim = Sim([("r1", "cargo", *CHARGERS[0], 1.0)])
    sim.submit(task("J1", "chute_1", "B01-01"))
    robot = sim.agents["r1"]
    tick, act, missed = robot.tick, robot._act, []

    def tick_missing_the_first_pick(now):
        st = tick(now)
        if robot.loaded and not missed:  # the first pick ends without the goods: it says so, tries again later
            missed.append(now)
            robot.loaded = False
            st = RobotStatus.from_dict({**st.to_dict(), "loaded": False})
        return st
    robot.tick = tick_missing_the_first_pick
    robot._act = lambda now: act(now) if not missed or now > missed[0] + 3.0 else None
    assert sim.run_until(lambda: sim.last("J1") == "picked", limit=200)
    assert missed and robot.loaded  # "picked" came only once it said it carries them (its second pick)
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=200)


def test_a_robot_that_dies_in_the_middle_of_a_pick_counts_no_pick_and_its_job_is_queued_again():
    sim = Sim(four_robots(), offline_timeout_s=2.0)
    sim.submit(task("J1", "chute_2", "B04-01"))
    assert sim.run_until(lambda: any(a.model.mode == "picking" for a in sim.agents.values()))
    first = next(rid for rid, a in sim.agents.items() if a.model.mode == "picking")
    sim.dead.add(first)  # it dies while picking, however long the pick was due to take
    sim.run_until(lambda: False, limit=30)
    assert "picked" not in [e.event for e in sim.events if e.task_id == "J1"]
    assert sim.fm.jobs["J1"].state == "queued" and not sim.fm.jobs["J1"].picked  # the goods are still at the chute
    assert any("J1 is queued again" in n for n in sim.notes)


def test_a_robot_waiting_for_a_chute_where_the_picker_died_is_let_go_and_its_job_queued_again():
    sim = Sim(four_robots(), offline_timeout_s=2.0)
    sim.fm.policy = PIPELINED
    sim.submit(task("J1", "chute_2", "B04-01"))
    sim.submit(task("J2", "chute_2", "B03-01"))   # the next job there: a robot waits by the chute (policy queue)
    assert sim.run_until(lambda: any(a.model.mode == "picking" for a in sim.agents.values()))
    first = next(rid for rid, a in sim.agents.items() if a.model.mode == "picking")
    waiter = sim.fm.jobs["J2"].robot
    assert waiter is not None and waiter != first
    sim.dead.add(first)  # it dies on the chute
    sim.run_until(lambda: False, limit=30)
    assert sim.fm.jobs["J2"].state == "queued" and sim.fm.robots[waiter].job is None   # not waiting for ever
    assert any("J2 is queued again" in n for n in sim.notes)
