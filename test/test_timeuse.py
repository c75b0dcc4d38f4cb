"""Where the robots' time went (fleet_planner/ros/demo/timeuse.py): an idle robot's time is told
apart by why it had no job - one free for it, one waiting for its storing site (the dispatcher's
rule of one job per site), one waiting for its chute, or nothing to do."""
from __future__ import annotations

import warnings

import pytest

from fleet_planner.robots import load_kinds
from fleet_planner.ros.demo.timeuse import sites_of, time_use
from fleet_planner.warehouse import load_warehouse
from msg_schemas.records import Task, TaskEvent

KINDS = load_kinds()
WH = load_warehouse()
CHUTES = {s.name: s.pose for s in WH.stations_of("chute")}


def _run(second_place: str, sites: dict[str, str] | None):
    """rA does J1 (chute_1 -> B01) over [0, 100); rB stands idle all along while J2 (chute_2 ->
    ``second_place``) is queued until rB takes it at 100."""
    jobs = [Task(id="J1", pick="chute_1", place="B01-01"), Task(id="J2", pick="chute_2", place=second_place)]
    events = [TaskEvent(task_id="J1", event="accepted", stamp=0.0),
              TaskEvent(task_id="J2", event="accepted", stamp=0.0),
              TaskEvent(task_id="J1", event="assigned", stamp=0.0, robot_id="rA"),
              TaskEvent(task_id="J1", event="picked", stamp=40.0, robot_id="rA"),
              TaskEvent(task_id="J1", event="done", stamp=100.0, robot_id="rA"),
              TaskEvent(task_id="J2", event="assigned", stamp=100.0, robot_id="rB")]
    modes = {"rA": [(0.0, "driving", False, "J1", False, "cargo")],
             "rB": [(0.0, "idle", False, None, False, "cargo")]}
    tracks = {"rA": [(5.0, 5.0, 0.0)], "rB": [(8.0, 5.0, 0.0)]}
    return time_use(modes, events, jobs, KINDS, tracks, CHUTES, 0.0, 100.0, sites=sites).seconds


def test_an_idle_robot_whose_only_job_waits_for_its_storing_site_counts_apart_from_a_free_job():
    sites = sites_of(WH)
    assert sites["B01-02"] == sites["B01-01"] == "B01" and sites["B02-01"] == "B02"
    taken = _run("B01-02", sites)   # J2 goes to the site J1 is under way to
    assert taken["no job: idle, its site was taken"] == pytest.approx(100.0)
    assert taken["no job: idle, a job was free"] == 0.0
    # controls: another site, or no sites given (the old count), and it is a free job
    for seconds in (_run("B02-01", sites), _run("B01-02", None)):
        assert seconds["no job: idle, a job was free"] == pytest.approx(100.0)
        assert seconds["no job: idle, its site was taken"] == 0.0


def test_the_per_job_means_count_only_jobs_whose_steps_happened_and_warn_of_nothing():
    """J1 is accepted at 0 and assigned at 10; J2 was sent but never heard of (no event): its
    queue time is unknown, not infinite, and the mean is J1's alone (was: inf - inf, a NumPy warning)."""
    jobs = [Task(id="J1", pick="chute_1", place="B01-01"), Task(id="J2", pick="chute_2", place="B02-01")]
    events = [TaskEvent(task_id="J1", event="accepted", stamp=0.0),
              TaskEvent(task_id="J1", event="assigned", stamp=10.0, robot_id="rA"),
              TaskEvent(task_id="J1", event="picked", stamp=40.0, robot_id="rA"),
              TaskEvent(task_id="J1", event="done", stamp=100.0, robot_id="rA")]
    modes = {"rA": [(0.0, "driving", False, "J1", False, "cargo")]}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        use = time_use(modes, events, jobs, KINDS, {"rA": [(5.0, 5.0, 0.0)]}, CHUTES, 0.0, 100.0)
    assert (use.queued_s, use.to_pick_s, use.to_place_s) == (10.0, 30.0, 60.0)
