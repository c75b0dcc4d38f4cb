"""The durable job store (issue 9, nothing accepted is lost): a real SQLite file in tmp_path, a
manager dropped without closing anything (and one killed with SIGKILL in a child process), a new
manager on the same file: every accepted job is open again, events go on, ids stay taken, goods
picked before the restart are never picked again."""
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import pytest
from test_dispatch import FAST, PARKING, WH, Sim, manager, status, task

from fleet_planner.fleet import Decisions, DispatchParams, FleetManager, JobStore
from fleet_planner.fleet import manager as manager_module
from fleet_planner.fleet.jobstore import MEMORY, RESENT, StoreInUse, default_path, emptied, open_store

FLEET = [("r1", "cargo", 2.25, 10.75, 1.0), ("r2", "cargo", 4.25, 10.75, 1.0), ("r3", "cargo", 6.25, 10.75, 1.0)]
TASKS = [task(f"J{i}", pick=f"chute_{1 + i % 2}", place=f"B0{1 + i % 4}-01") for i in range(10)]


def restarted(path, **params):
    """A Sim whose manager is a new one on the job store at ``path`` (the agents are new too)."""
    sim = Sim(FLEET, **params)
    sim.fm = FleetManager(WH, FAST, DispatchParams(**params), PARKING, store=JobStore(path))
    return sim


def test_the_store_is_a_wal_database_and_keeps_every_change(tmp_path):
    store = JobStore(tmp_path / "sub" / "jobs.db")
    assert store.path.exists()
    assert store._db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    fm = FleetManager(WH, FAST, store=store)
    assert [e.event for e in fm.submit(TASKS[0], 1.0)] == ["accepted"]
    assert store.get("J0").state == "queued" and store.get("J0").task == TASKS[0]
    assert [t.event for t in store.history("J0")] == ["accepted"]


def test_accepted_jobs_survive_a_dropped_manager_and_go_on(tmp_path):
    path = tmp_path / "jobs.db"
    fm = FleetManager(WH, FAST, store=JobStore(path))
    assert all(fm.submit(t, 1.0)[0].event == "accepted" for t in TASKS)
    del fm  # no close, no flush: as after kill -9

    sim = restarted(path)
    assert sorted(sim.fm.jobs) == sorted(t.id for t in TASKS)
    assert all(j.state == "queued" for j in sim.fm.jobs.values())
    for t in TASKS:  # the agents learn the tasks again (as from the tasks topic)
        for a in sim.agents.values():
            a.on_task(t)
    assert sim.run_until(lambda: all(sim.last(t.id) == "done" for t in TASKS), limit=1500.0)
    store = JobStore(path)
    assert store.counts() == {"done": 10}
    for t in TASKS:
        events = [e.event for e in sim.events if e.task_id == t.id]
        assert events.count("picked") == 1 and events.count("done") == 1


def test_a_known_id_gets_the_jobs_state_after_a_restart(tmp_path):
    path = tmp_path / "jobs.db"
    fm = FleetManager(WH, FAST, store=JobStore(path))
    fm.submit(TASKS[0], 1.0)
    fm2 = FleetManager(WH, FAST, store=JobStore(path))
    (ev,) = fm2.submit(TASKS[0], 2.0)
    assert (ev.event, ev.robot_id) == ("accepted", None) and ev.reason.startswith(RESENT)
    assert len(fm2.jobs) == 1 and [t.event for t in JobStore(path).history("J0")] == ["accepted", "reloaded"]


def test_a_re_sent_id_gets_its_current_event_also_once_only_the_store_has_the_job(tmp_path, monkeypatch):
    """Ids are idempotent for good: a copy of an id is answered with the event of the job's state now
    (assigned, picked, done, failed with its reason), whether the job is still in memory or, finished
    long ago, only in the store, and before or after a restart; never a second job."""
    monkeypatch.setattr(manager_module, "MAX_CLOSED_JOBS", 3)
    path = tmp_path / "jobs.db"
    sim = Sim(FLEET)
    sim.fm = FleetManager(WH, FAST, DispatchParams(), PARKING, store=JobStore(path))
    seen: dict[str, set] = {}

    def answer(t):
        (ev,) = sim.fm.submit(t, sim.t)
        assert ev.reason.startswith(RESENT) and ev.task_id == t.id, ev
        job = sim.fm.jobs.get(t.id)
        if job is not None and job.state == "active":  # the robot on it, as the planner last said
            assert ev.event == ("picked" if job.picked else "assigned") and ev.robot_id == job.robot
        seen.setdefault(t.id, set()).add(ev.event)
        return ev

    def all_done():
        for t in TASKS[:4]:
            answer(t)
        return all(sim.last(t.id) == "done" for t in TASKS)

    sim.submit(*TASKS)
    assert sim.run_until(all_done, limit=1500.0)
    assert {"accepted", "assigned", "picked", "done"} <= set.union(*seen.values())
    assert len(sim.fm.jobs) == 3  # finished jobs leave memory; the store keeps them
    for fm in (sim.fm, FleetManager(WH, FAST, store=JobStore(path))):  # before and after a restart
        for t in TASKS:
            (ev,) = fm.submit(t, 9999.0)
            assert (ev.event, ev.task_id) == ("done", t.id) and ev.robot_id in {"r1", "r2", "r3"}
    assert JobStore(path).counts() == {"done": 10}
    store = JobStore(path)
    store.add(task("F1"), 99, 1.0)
    store.update("F1", "failed", "failed", "r2", True, 2.0, "robot r2 is offline with the goods")
    (ev,) = FleetManager(WH, FAST, store=JobStore(path)).submit(task("F1"), 3.0)
    assert ev.event == "failed" and ev.robot_id == "r2" and ev.reason == f"{RESENT}; robot r2 is offline with the goods"


def test_a_manager_killed_with_sigkill_loses_nothing(tmp_path):
    path = tmp_path / "jobs.db"
    code = textwrap.dedent(f"""
        import os, signal
        from fleet_planner.fleet import FleetManager, JobStore
        from fleet_planner.robots import load_kinds
        from fleet_planner.warehouse import generate_warehouse
        from msg_schemas.records import Task
        wh = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)
        fm = FleetManager(wh, load_kinds(), store=JobStore({str(path)!r}))
        for i in range(10):
            ev, = fm.submit(Task(id=f"K{{i}}", pick="chute_1", place="B01-01"), 1.0)
            assert ev.event == "accepted"
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    done = subprocess.run([sys.executable, "-c", code], env={**os.environ}, timeout=120)
    assert done.returncode == -signal.SIGKILL
    fm = FleetManager(WH, FAST, store=JobStore(path))
    assert sorted(fm.jobs) == sorted(f"K{i}" for i in range(10))
    (again,) = fm.submit(task("K3"), 2.0)
    assert again.event == "accepted" and again.reason.startswith(RESENT) and len(fm.jobs) == 10


def test_goods_picked_before_a_restart_are_placed_not_picked_again(tmp_path):
    path = tmp_path / "jobs.db"
    sim = Sim(FLEET[:1])
    sim.fm = FleetManager(WH, FAST, DispatchParams(), PARKING, store=JobStore(path))
    sim.submit(TASKS[1])
    assert sim.run_until(lambda: sim.last("J1") == "picked")
    agents, before = sim.agents, list(sim.events)
    sim = restarted(path)
    sim.agents = agents  # the robot lives on, goods on board; only the planner restarted
    job = sim.fm.jobs["J1"]
    assert job.state == "active" and job.picked and job.robot == "r1"
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=300.0)
    events = [e.event for e in before + sim.events if e.task_id == "J1"]
    assert events.count("picked") == 1 and events[-2:] == ["placed", "done"]
    assert [t.event for t in JobStore(path).history("J1")] == ["accepted", "assigned", "picked", "done"]


def test_picked_goods_whose_robot_never_reports_fail_with_the_reason(tmp_path):
    path = tmp_path / "jobs.db"
    store = JobStore(path)
    fm = FleetManager(WH, FAST, store=store)
    fm.submit(TASKS[0], 0.0)
    store.update("J0", "picked", "active", "r9", True, 5.0)
    fm = FleetManager(WH, FAST, DispatchParams(offline_timeout_s=3.0), store=JobStore(path))
    # never announced before the restart (nobody called announced()): the first step announces them
    assert [(e.task_id, e.event, e.robot_id, e.stamp) for e in fm.step(10.0).events] == [
        ("J0", "accepted", None, 0.0), ("J0", "picked", "r9", 5.0)]
    fm.announced()
    fm.on_status(status("r1", "cargo", 2.25, 10.75, stamp=12.0), 12.0)
    events = fm.step(13.5).events
    assert [(e.task_id, e.event) for e in events] == [("J0", "failed")]
    assert "r9 held the goods" in events[0].reason
    assert JobStore(path).get("J0").state == "failed"


def test_changes_committed_but_not_announced_when_the_planner_died_are_announced_once_after(tmp_path):
    """The outbox: a planner killed in the middle of a step (its pick committed, the step's events
    not yet published) - the next planner on the file announces that pick in its first step, with
    the original stamp and robot; what went out before (announced()) is not announced again, and
    neither is the replay after the second planner announced it."""
    path = tmp_path / "jobs.db"
    sim = Sim(FLEET[:1])
    sim.fm = FleetManager(WH, FAST, DispatchParams(), PARKING, store=JobStore(path))
    sim.submit(TASKS[1])
    assert sim.run_until(lambda: sim.last("J1") == "assigned")
    before = list(sim.events)
    fm = sim.fm
    step = fm.step

    def dies_before_publishing(now):  # the step commits the pick; the process dies before its events go out
        d = step(now)
        if any(e.event == "picked" for e in d.events):
            raise SystemExit("killed")
        return d

    fm.step = dies_before_publishing
    with pytest.raises(SystemExit):
        sim.run_until(lambda: False, limit=300.0)
    assert JobStore(path).get("J1").picked and sim.last("J1") == "assigned"   # committed, never announced
    agents = sim.agents
    sim = restarted(path)
    sim.agents = agents
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=300.0)
    events = [(e.event, e.robot_id) for e in before + sim.events if e.task_id == "J1"]
    assert events == [("accepted", None), ("assigned", "r1"), ("picked", "r1"), ("placed", "r1"), ("done", "r1")]
    picked = next(e for e in sim.events if e.event == "picked")
    assert picked.stamp == JobStore(path).history("J1")[2].stamp   # the original stamp: a replay can be told
    third = restarted(path)  # everything went out: nothing to announce again
    assert third.fm.step(9999.0).events == [] and JobStore(path).unannounced() == []


def test_a_replay_waiting_for_the_first_step_is_not_noted_announced_by_what_went_out_before_it(tmp_path):
    """A restarted planner answers tasks before its first step (it waits for its subscribers): noting
    that answer announced must not mark the replay still waiting as announced too (the outbox is one
    mark: a planner killed again before its first step would lose the replay for good)."""
    path = tmp_path / "jobs.db"
    FleetManager(WH, FAST, store=JobStore(path)).submit(TASKS[0], 1.0)   # committed, never announced
    fm = FleetManager(WH, FAST, store=JobStore(path))
    assert fm.replaying
    assert [e.event for e in fm.submit(TASKS[1], 2.0)] == ["accepted"]
    fm.announced()   # J1's answer went out (the planner node, before its first step)
    assert ("J0", "accepted") in [(job, t.event) for job, t in JobStore(path).unannounced()]
    again = FleetManager(WH, FAST, store=JobStore(path))   # killed before that first step
    assert [(e.task_id, e.event, e.stamp) for e in again.step(3.0).events] == [("J0", "accepted", 1.0),
                                                                               ("J1", "accepted", 2.0)]
    again.announced()
    assert JobStore(path).unannounced() == [] and not again.replaying


def test_the_events_of_a_step_that_raised_go_out_with_the_next_step_never_noted_announced_before(tmp_path):
    """A step that raised after committing a change (its events never returned to the publisher): they
    go out with the next step, and what is noted announced in between stops before that change."""
    path = tmp_path / "jobs.db"
    fm = FleetManager(WH, FAST, DispatchParams(), PARKING, store=JobStore(path))
    fm.on_status(status("r1", "cargo", 2.25, 10.75), 0.0)
    fm.step(0.0)
    fm.submit(TASKS[0], 0.5)
    fm.announced()
    housekeeping = fm._housekeeping

    def fails(now, d):
        raise RuntimeError("a bug after the allocation")

    fm._housekeeping = fails
    with pytest.raises(RuntimeError):
        fm.step(1.0)
    assert [t.event for t in JobStore(path).history("J0")] == ["accepted", "assigned"]   # committed
    assert fm.replaying
    fm.submit(TASKS[1], 1.2)
    fm.announced()   # J1's answer went out: J0's assignment did not
    assert [(job, t.event) for job, t in JobStore(path).unannounced()] == [("J0", "assigned"), ("J1", "accepted")]
    fm._housekeeping = housekeeping
    events = fm.step(1.5).events
    assert [(e.task_id, e.event, e.robot_id, e.stamp) for e in events][:1] == [("J0", "assigned", "r1", 1.0)]
    fm.announced()
    assert JobStore(path).unannounced() == []


def test_a_store_from_before_the_outbox_counts_its_history_as_announced(tmp_path):
    path = tmp_path / "jobs.db"
    store = JobStore(path)
    store.add(task("J0"), 0, 1.0)
    store._db.execute("DROP TABLE outbox")   # as a file written before the outbox existed
    store.close()
    store = JobStore(path)
    assert store.unannounced() == []
    n = store.update("J0", "assigned", "active", "r1", False, 2.0)
    assert [(job, t.event) for job, t in store.unannounced()] == [("J0", "assigned")]
    store.mark_announced(n)
    store.mark_announced(n - 1)   # never moves back
    assert store.unannounced() == []


def test_a_store_that_cannot_write_rejects_instead_of_accepting(tmp_path):
    store = JobStore(tmp_path / "jobs.db")
    fm = FleetManager(WH, FAST, store=store)
    store.close()
    (ev,) = fm.submit(TASKS[0], 1.0)
    assert ev.event == "rejected" and ev.reason.startswith("job store: cannot")
    assert fm.jobs == {}


def test_a_store_write_failing_mid_step_changes_nothing_and_is_tried_again(tmp_path, monkeypatch):
    # a full disk while a pick is recorded: the step used to raise after the job had changed in
    # memory (picked, never committed, never announced; the rest of the step lost)
    path = tmp_path / "jobs.db"
    sim = Sim(FLEET[:1])
    store = JobStore(path)
    sim.fm = FleetManager(WH, FAST, DispatchParams(), PARKING, store=store)
    sim.submit(TASKS[1])
    assert sim.run_until(lambda: sim.last("J1") == "assigned")
    write = store.update

    def full(*args, **kwargs):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(store, "update", full)
    assert sim.run_until(lambda: sim.agents["r1"].loaded, limit=300.0)   # the robot picked ...
    assert not sim.run_until(lambda: sim.last("J1") != "assigned", limit=20.0)  # ... nothing announced,
    job = sim.fm.jobs["J1"]
    assert job.state == "active" and not job.picked and sim.fm.robots["r1"].job == "J1"  # nothing changed
    assert any("cannot record 'picked'" in n for n in sim.notes)
    monkeypatch.setattr(store, "update", write)             # the disk has room again: it goes on
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=300.0)
    assert [e.event for e in sim.events if e.task_id == "J1"] == ["accepted", "assigned", "picked", "placed", "done"]
    assert [tr.event for tr in JobStore(path).history("J1")] == ["accepted", "assigned", "picked", "done"]


def test_a_robot_unheard_while_it_picked_gets_its_job_back_and_nobody_picks_it_again(tmp_path):
    # r1 drives on and picks while nobody hears it (cut off): the planner takes it for offline and
    # queues its job again (not picked, as far as it knows) for r2; r1 is heard again carrying the
    # goods (or having placed them): the job is r1's again, r2 drops it before picking it a second time
    sim = Sim(FLEET[:2])
    sim.fm = FleetManager(WH, FAST, DispatchParams(offline_timeout_s=2.0), PARKING, store=JobStore(tmp_path / "j.db"))
    sim.submit(TASKS[1])
    assert sim.run_until(lambda: sim.last("J1") == "assigned")
    first = sim.events[-1].robot_id
    other = next(r for r in sim.agents if r != first)
    sim.mute.add(first)
    assert sim.run_until(lambda: sim.agents[first].loaded, limit=300.0)
    assert [(e.event, e.robot_id) for e in sim.events if e.task_id == "J1"][-1] == ("assigned", other)
    sim.mute.discard(first)
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=300.0)
    events = [(e.event, e.robot_id) for e in sim.events if e.task_id == "J1"]
    assert events[-4:] == [("assigned", first), ("picked", first), ("placed", first), ("done", first)]
    assert events.count(("picked", first)) == 1 and ("picked", other) not in events
    assert sim.fm.robots[other].job is None and not sim.agents[other].loaded


def test_without_a_store_nothing_changes():
    fm = manager()
    assert fm.store is None and fm.submit(TASKS[0], 1.0)[0].event == "accepted"


def test_the_sqlite_file_is_readable_by_plain_sqlite(tmp_path):
    path = tmp_path / "jobs.db"
    FleetManager(WH, FAST, store=JobStore(path)).submit(TASKS[0], 1.0)
    with sqlite3.connect(path) as db:
        assert db.execute("SELECT id, state FROM jobs").fetchall() == [("J0", "queued")]


class PlannerDown:
    """No planner: statuses go nowhere, no legs or events come (the agents drive on)."""

    def on_status(self, status, now):
        pass

    def step(self, now):
        return Decisions()

    def announced(self):
        pass


def planner_killed_when(path, condition, robot_did, **params):
    """A one-robot Sim on a store at ``path``: J1 runs until ``condition(sim)``; the planner dies (the
    robot drives on alone) until ``robot_did(agent)``; then a new planner on the same store. The
    restarted Sim and the events said before the kill."""
    sim = Sim(FLEET[:1], **params)
    sim.fm = FleetManager(WH, FAST, DispatchParams(**params), PARKING, store=JobStore(path))
    sim.submit(TASKS[1])
    assert sim.run_until(lambda: condition(sim))
    before, agents = list(sim.events), sim.agents
    sim.fm = PlannerDown()
    assert sim.run_until(lambda: robot_did(agents["r1"]), limit=300.0)
    sim.fm = FleetManager(WH, FAST, DispatchParams(**params), PARKING, store=JobStore(path))
    sim.events = []
    return sim, before


def test_goods_placed_while_the_planner_was_down_make_the_job_done_once(tmp_path):
    """The robot placed the goods while no planner ran: its status names the job it placed
    (``placed_task_id``), and the restarted planner counts the job done from it, exactly once."""
    path = tmp_path / "jobs.db"
    sim, before = planner_killed_when(path, lambda s: s.last("J1") == "picked", lambda a: a.placed == "J1")
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=30.0)
    sim.run_until(lambda: False, limit=20.0)   # and nothing more about it
    assert [e.event for e in sim.events if e.task_id == "J1"] == ["placed", "done"]
    assert [e.event for e in before + sim.events].count("picked") == 1
    assert [t.event for t in JobStore(path).history("J1")] == ["accepted", "assigned", "picked", "done"]
    assert sim.fm.robots["r1"].free


def test_goods_picked_while_the_planner_was_down_are_announced_once_and_placed(tmp_path):
    path = tmp_path / "jobs.db"
    sim, before = planner_killed_when(path, lambda s: s.last("J1") == "assigned", lambda a: a.loaded)
    assert JobStore(path).get("J1").picked is False
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=300.0)
    events = [e.event for e in before + sim.events if e.task_id == "J1"]
    assert events == ["accepted", "assigned", "picked", "placed", "done"]
    assert [t.event for t in JobStore(path).history("J1")] == ["accepted", "assigned", "picked", "done"]


def test_a_status_naming_a_placed_job_the_store_had_not_seen_picked_finishes_it_once(tmp_path):
    """Picked and placed while no planner ran (the store has it assigned to r1): picked, placed and
    done are announced once; a later status saying the same changes nothing."""
    path = tmp_path / "jobs.db"
    store = JobStore(path)
    FleetManager(WH, FAST, store=store).submit(TASKS[1], 0.0)
    store.mark_announced(store.update("J1", "assigned", "active", "r1", False, 5.0))   # (said before the restart)
    fm = FleetManager(WH, FAST, store=JobStore(path))
    fm.on_status(status("r1", "cargo", 2.25, 10.75, stamp=9.0, loaded=False, placed_task_id="J1"), 9.0)
    assert [(e.event, e.robot_id) for e in fm.step(10.0).events] == [("picked", "r1"), ("placed", "r1"),
                                                                      ("done", "r1")]
    fm.on_status(status("r1", "cargo", 2.25, 10.75, stamp=10.5, loaded=False, placed_task_id="J1"), 10.5)
    assert fm.step(11.0).events == [] and fm.robots["r1"].free
    assert [t.event for t in JobStore(path).history("J1")] == ["accepted", "assigned", "picked", "done"]


def test_a_robot_on_its_way_to_the_chute_at_the_restart_keeps_its_job(tmp_path):
    path = tmp_path / "jobs.db"
    sim, before = planner_killed_when(path, lambda s: s.last("J1") == "assigned", lambda a: True)
    assert sim.fm.jobs["J1"].state == "active" and sim.fm.jobs["J1"].robot == "r1"
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=300.0)
    events = [e.event for e in before + sim.events if e.task_id == "J1"]
    assert events == ["accepted", "assigned", "picked", "placed", "done"]


def test_a_job_whose_robot_never_reports_after_the_restart_is_queued_again_if_not_picked(tmp_path):
    path = tmp_path / "jobs.db"
    store = JobStore(path)
    FleetManager(WH, FAST, store=store).submit(TASKS[0], 0.0)
    store.update("J0", "assigned", "active", "r9", False, 5.0)
    fm = FleetManager(WH, FAST, DispatchParams(offline_timeout_s=3.0), store=JobStore(path))
    assert fm.jobs["J0"].state == "active"
    fm.step(10.0)
    fm.step(13.5)
    assert fm.jobs["J0"].state == "queued" and fm.jobs["J0"].robot is None
    assert [t.event for t in JobStore(path).history("J0")][-1] == "requeued"


def test_the_default_store_is_under_the_ros_home_per_fleet_and_memory_is_asked_for_by_name(tmp_path, monkeypatch):
    fleet_dir = tmp_path / "fleet_planner"
    assert default_path({"ROS_HOME": str(tmp_path)}) == fleet_dir / "domain_0" / "jobs.sqlite"
    assert default_path({"ROS_HOME": str(tmp_path), "ROS_DOMAIN_ID": "31"}, "/site_a/hall_2") == \
        fleet_dir / "domain_31" / "site_a" / "hall_2" / "jobs.sqlite"
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_path({}) == tmp_path / "home" / ".ros" / "fleet_planner" / "domain_0" / "jobs.sqlite"
    assert default_path({"ROS_HOME": ""}) == default_path({})
    store = open_store("", {"ROS_HOME": str(tmp_path / "ros")})  # created, with its folders
    assert store is not None and store.path.exists()
    assert store.path == tmp_path / "ros" / "fleet_planner" / "domain_0" / "jobs.sqlite"
    assert open_store(MEMORY) is None
    assert open_store(str(tmp_path / "x.db")).path == tmp_path / "x.db"
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="job_store: cannot open"):
        open_store(str(tmp_path / "file" / "jobs.db"))  # its folder is a file


def test_a_locked_store_is_one_planners_until_closed_or_its_process_dies(tmp_path):
    path = tmp_path / "jobs.db"
    first = JobStore(path, lock=True)
    with pytest.raises(StoreInUse, match=f"in use by another planner \\(process {os.getpid()}\\)"):
        JobStore(path, lock=True)
    assert JobStore(path).counts() == {}   # reading it without the lock is fine (tools, tests)
    first.close()
    JobStore(path, lock=True).close()
    code = f"import os, signal; from fleet_planner.fleet import JobStore; JobStore({str(path)!r}, lock=True); " \
           "os.kill(os.getpid(), signal.SIGKILL)"
    assert subprocess.run([sys.executable, "-c", code], timeout=120).returncode == -signal.SIGKILL
    JobStore(path, lock=True).close()   # kill -9 let go of it


def test_an_emptied_store_starts_with_no_jobs(tmp_path):
    path = tmp_path / "jobs.sqlite"
    FleetManager(WH, FAST, store=JobStore(path)).submit(TASKS[0], 1.0)
    assert emptied(path) == path and not path.exists()
    assert FleetManager(WH, FAST, store=JobStore(emptied(path))).jobs == {}
