"""Gated execution on ROS (issue 9, deliverable 4): the planner and four agents on one simulated
clock over real DDS, lateness re-planning off; one robot is slowed to 30 % of its speed for 20 s
and another halted for 10 s (their ``speed_scale`` parameter) while they drive. The gates alone
keep them apart: no contact in the robots' own status reports, every job done. bench/bench_gate.py
runs the same scenario against today's lateness re-planning."""
from __future__ import annotations

from dataclasses import dataclass

from rclpy.parameter import Parameter
from test_ros_system import KINDS, MEMBERS, PARKING, WAIT, WH

from fleet_planner.ros.demo.bringup import bring_up
from fleet_planner.ros.demo.monitor import spin_until
from msg_schemas.records import Task

RATE = 20.0  # simulated seconds per wall second at most
JOBS = [Task(id="G1", pick="chute_1", place="B04-01"), Task(id="G2", pick="chute_2", place="B01-02"),
        Task(id="G3", pick="chute_1", place="B03-02", needs=("forklift",)),
        Task(id="G4", pick="chute_2", place="B02-01", needs=("manipulator",)),
        Task(id="G5", pick="chute_1", place="B03-04"), Task(id="G6", pick="chute_2", place="B02-02")]


@dataclass
class Outcome:
    done: bool
    seconds: float      # simulated, from the first task to the last job done
    gap: float          # closest approach minus the sum of radii, from the statuses
    pair: tuple
    slowed: str
    halted: str
    replans: int        # "late: re-planning" notes of the planner


def planner_notes(fleet) -> list[str]:
    """The planner's notes of every step from now on (its step wrapped), as they are made."""
    notes: list[str] = []
    step = fleet.planner.fleet.step

    def counted(now):
        d = step(now)
        notes.extend(d.notes)
        return d
    fleet.planner.fleet.step = counted
    return notes

def slowed_run(ros_context, gated: bool, lateness_s: float, rate: float = RATE, wait: float = WAIT) -> Outcome:
    """The scenario: six jobs; once two robots drive, one at 30 % for 20 s, the other halted 10 s."""
    fleet = bring_up(ros_context, WH, KINDS, MEMBERS, rate,
                     planner_params=[Parameter("parking", value=PARKING), Parameter("offline_timeout_s", value=5.0),
                                     Parameter("lateness_tolerance_s", value=float(lateness_s)),
                                     Parameter("gated", value=gated)],
                     agent_overrides=[Parameter("gated", value=gated)])
    notes = planner_notes(fleet)
    try:
        mon = fleet.monitor
        ids = {m.id for m in MEMBERS}
        assert spin_until(fleet.executor, lambda: mon.planner_ready() and ids <= set(mon.status), wait)
        start = mon.now()
        for job in JOBS:
            mon.submit(job)

        def driving():
            return sorted(r for r, st in mon.status.items() if st.mode == "driving")
        assert spin_until(fleet.executor, lambda: len(driving()) >= 2, wait)
        slowed, halted = driving()[:2]
        t0 = mon.now()
        fleet.agents[slowed].set_parameters([Parameter("speed_scale", value=0.3)])
        fleet.agents[halted].set_parameters([Parameter("speed_scale", value=0.0)])
        assert spin_until(fleet.executor, lambda: mon.now() >= t0 + 10.0, wait)
        fleet.agents[halted].set_parameters([Parameter("speed_scale", value=1.0)])
        assert spin_until(fleet.executor, lambda: mon.now() >= t0 + 20.0, wait)
        fleet.agents[slowed].set_parameters([Parameter("speed_scale", value=1.0)])

        def all_done():
            return all(mon.last_event.get(j.id) is not None and mon.last_event[j.id].event == "done" for j in JOBS)
        done = spin_until(fleet.executor, all_done, 4 * wait)
        end = max((e.stamp for e in mon.events if e.event == "done"), default=mon.now())
        gap, a, b, _ = mon.min_separation()
        return Outcome(done, end - start, gap, (a, b), slowed, halted, sum("late: re-planning" in n for n in notes))
    finally:
        fleet.destroy()



def test_a_slowed_and_a_halted_robot_never_touch_the_others_without_re_planning_and_every_job_is_done(ros_context):
    out = slowed_run(ros_context, gated=True, lateness_s=3600.0)
    assert out.done, out
    assert out.gap >= 0.0, f"{out.pair} overlapped by {-out.gap:.3f} m"
    assert out.replans == 0
