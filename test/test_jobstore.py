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

from test_dispatch import FAST, PARKING, WH, Sim, manager, status, task

from fleet_planner.fleet import DispatchParams, FleetManager, JobStore

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


def test_a_known_id_is_a_duplicate_after_a_restart(tmp_path):
    path = tmp_path / "jobs.db"
    fm = FleetManager(WH, FAST, store=JobStore(path))
    fm.submit(TASKS[0], 1.0)
    fm2 = FleetManager(WH, FAST, store=JobStore(path))
    (ev,) = fm2.submit(TASKS[0], 2.0)
    assert ev.event == "rejected" and "duplicate task id 'J0'" in ev.reason
    assert len(fm2.jobs) == 1


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
    assert fm.submit(task("K3"), 2.0)[0].event == "rejected"


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
    assert fm.step(10.0).events == []
    fm.on_status(status("r1", "cargo", 2.25, 10.75, stamp=12.0), 12.0)
    events = fm.step(13.5).events
    assert [(e.task_id, e.event) for e in events] == [("J0", "failed")]
    assert "r9 held the goods" in events[0].reason
    assert JobStore(path).get("J0").state == "failed"


def test_a_store_that_cannot_write_rejects_instead_of_accepting(tmp_path):
    store = JobStore(tmp_path / "jobs.db")
    fm = FleetManager(WH, FAST, store=store)
    store.close()
    (ev,) = fm.submit(TASKS[0], 1.0)
    assert ev.event == "rejected" and ev.reason.startswith("job store: cannot")
    assert fm.jobs == {}


def test_without_a_store_nothing_changes():
    fm = manager()
    assert fm.store is None and fm.submit(TASKS[0], 1.0)[0].event == "accepted"


def test_the_sqlite_file_is_readable_by_plain_sqlite(tmp_path):
    path = tmp_path / "jobs.db"
    FleetManager(WH, FAST, store=JobStore(path)).submit(TASKS[0], 1.0)
    with sqlite3.connect(path) as db:
        assert db.execute("SELECT id, state FROM jobs").fetchall() == [("J0", "queued")]
