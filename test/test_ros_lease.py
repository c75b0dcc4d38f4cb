"""Leases on ROS (issue 9; fleet_planner/fleet/lease.py): the planner and four agents on one simulated
clock over real DDS. Once a robot drives its leg, its statuses are cut off (its status publisher
suppressed: a radio dead spot; it still hears the planner). It must brake to a stop within its lease
(offline_timeout_s / 2) and braking time, stay stopped while unheard, the planner keeps its way until
it must have stopped and then reserves the stretch it could have reached, and the others keep clear
of it; heard again, it is back online and every job gets done."""
from __future__ import annotations

import math

from rclpy.parameter import Parameter
from test_ros_gate import planner_notes
from test_ros_system import KINDS, MEMBERS, PARKING, WAIT, WH

from fleet_planner.fleet.lease import LEASE_SLACK_S, braking_s
from fleet_planner.ros.demo.bringup import bring_up
from fleet_planner.ros.demo.monitor import spin_until
from msg_schemas.records import Task

RATE = 10.0  # simulated seconds per wall second at most
JOBS = [Task(id="L1", pick="chute_1", place="B04-01"), Task(id="L2", pick="chute_2", place="B01-02"),
        Task(id="L3", pick="chute_1", place="B03-02", needs=("forklift",)),
        Task(id="L4", pick="chute_2", place="B02-01", needs=("manipulator",))]
TIMEOUT_S = 4.0   # the planner's offline_timeout_s: lease 2 s


class _Mute:
    """A status publisher that sends nothing (the robot's radio in a dead spot)."""

    def __init__(self, real):
        self.real = real

    def publish(self, msg):
        pass


def test_a_robot_whose_statuses_are_cut_off_stops_within_its_lease_and_the_others_keep_clear(ros_context):
    fleet = bring_up(ros_context, WH, KINDS, MEMBERS, RATE,
                     planner_params=[Parameter("parking", value=PARKING),
                                     Parameter("offline_timeout_s", value=TIMEOUT_S)])
    notes = planner_notes(fleet)
    try:
        mon = fleet.monitor
        ids = {m.id for m in MEMBERS}
        assert spin_until(fleet.executor, lambda: mon.planner_ready() and ids <= set(mon.status), WAIT)
        for job in JOBS:
            mon.submit(job)

        def driving():
            return sorted(r for r, st in mon.status.items() if st.mode == "driving" and st.progress < 0.5
                          and st.path_id is not None and (st.travelled_m or 0.0) > 0.5)
        assert spin_until(fleet.executor, lambda: bool(driving()), WAIT)
        rid = driving()[0]
        node = fleet.agents[rid]
        agent, model = node.agent, node.agent.model
        assert agent.lease.lease_s == TIMEOUT_S / 2   # the planner's word armed its lease
        node._status = _Mute(node._status)
        cut = mon.now()
        lease = agent.lease
        gaps: list[float] = []

        def watch():
            """The closest approach of any other robot's last status to the cut-off robot (minus radii)."""
            for oid, st in mon.status.items():
                if oid != rid and mon.now() - st.stamp < 1.0:
                    gaps.append(math.hypot(st.x - model.x, st.y - model.y) - st.radius - model.kind.radius)
            return lease.stopped and model.speed == 0.0

        assert spin_until(fleet.executor, watch, WAIT), "it never stopped"
        stopped_at, heard = mon.now(), lease.heard
        assert heard is not None and heard <= cut + 0.5
        # its lease ran out with the first heard record after heard + lease (three a lease), then it braked
        assert stopped_at <= heard + lease.lease_s * (1 + 1 / 3) + braking_s(model.kind) + LEASE_SLACK_S + 0.5, \
            (stopped_at, heard)
        here = (model.x, model.y)
        # the planner marks it offline, keeps its way until it must have stopped, then reserves its stretch
        assert spin_until(fleet.executor, lambda: watch() and any(
            f"robot {rid} offline" in n and "obstacle anywhere it could have driven" in n for n in notes), WAIT), \
            [n for n in notes if rid in n]
        assert any(f"robot {rid} offline" in n and "its leg is kept clear" in n for n in notes)
        assert math.dist(here, (model.x, model.y)) < 1e-6, "it moved while unheard"
        node._status = node._status.real   # heard again: back online, and the fleet goes on
        assert spin_until(fleet.executor, lambda: any(f"robot {rid} is back online" in n for n in notes), WAIT)

        def all_done():
            watch()
            return all(mon.last_event.get(j.id) is not None and mon.last_event[j.id].event == "done" for j in JOBS)
        assert spin_until(fleet.executor, all_done, 4 * WAIT), {j.id: mon.last_event.get(j.id) for j in JOBS}
        assert min(gaps) >= 0.0, f"a robot came {-min(gaps):.3f} m into the cut-off robot {rid}"
        gap, a, b, _ = mon.min_separation()
        assert gap >= 0.0, f"{a} and {b} overlapped by {-gap:.3f} m"
    finally:
        fleet.destroy()
