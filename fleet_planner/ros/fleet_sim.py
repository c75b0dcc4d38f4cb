"""``fleet-sim``: many simulated robots in one process, each with exactly the ROS interface of a
robot's agent node (:mod:`robot_agent.agent_node`), so the planner cannot tell them apart: its own
``/robots/<id>/timed_path``, its status on ``/fleet/robot_status``, the task events and tasks it
learns its jobs from (and, under behaviour coordination, wait messages). The robots are stepped
together by :class:`fleet_planner.fleet.sim.SimFleet` at ``status_rate_hz`` of ROS time; they hear
each other from their last statuses in this process (what the planner's relay would send them,
one step fresher), and with ``hear_relay:=true`` also the robots of other processes from the relay.
One agent process per robot stays the deployment on real robots.

    fleet-sim --ros-args -p fleet_file:=config/fleet.yaml -p use_sim_time:=true
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any

from nav_msgs.msg import Path
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from std_msgs.msg import String

from fleet_planner.fleet import COORDINATION, FleetMember, load_fleet
from fleet_planner.fleet.sim import SimFleet
from fleet_planner.robots import RobotKind, load_kinds
from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.entry import run_node
from fleet_planner.warehouse import Warehouse, load_warehouse
from msg_schemas import topics
from msg_schemas.convert import msg_to_timed_path, stamp_to_ns, string_to_record
from msg_schemas.records import GateRecord, Heard, Neighbours, RecordError, Task, TaskEvent, WaitMessageRecord


def _fixed(description: str) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=True)


class FleetSimNode(Node):
    """The simulated robots of a fleet file (parameter ``fleet_file``; empty: the shipped
    config/fleet.yaml), or of ``members`` handed in (tests, the demo)."""

    def __init__(self, name: str = "fleet_sim", *, warehouse: Warehouse | None = None,
                 kinds: Mapping[str, RobotKind] | None = None, members: Sequence[FleetMember] | None = None,
                 **kwargs: Any):
        super().__init__(name, **kwargs)
        fleet_file = self.declare_parameter("fleet_file", "", _fixed("fleet YAML (empty: config/fleet.yaml)")).value
        wh_file = self.declare_parameter("warehouse_file", "", _fixed(
            "warehouse YAML (empty: the shipped config/warehouse.yaml)")).value
        kinds_file = self.declare_parameter("kinds_file", "", _fixed(
            "robot kinds YAML (empty: the shipped config/robot_kinds.yaml)")).value
        mode = self.declare_parameter("coordination", "central", _fixed("central or behavior")).value
        rate = self.declare_parameter("status_rate_hz", 10.0, ParameterDescriptor(
            description="steps (and statuses of every robot) per second of ROS time", read_only=True,
            floating_point_range=[FloatingPointRange(from_value=0.1, to_value=100.0)])).value
        hear_relay = self.declare_parameter("hear_relay", False, _fixed(
            "also hear robots of other processes from the planner's relay (/robots/<id>/neighbours)")).value
        gated = self.declare_parameter("gated", True, _fixed(
            "central: the robots never enter a collision region before the robot ranked above has left it "
            "(the planner's gate records on /robots/<id>/gate), as agents with gated:=true")).value
        if mode not in COORDINATION:
            raise ValueError(f"parameter coordination: {mode!r} is not one of {', '.join(COORDINATION)}")
        kinds = kinds if kinds is not None else load_kinds(kinds_file or None)
        warehouse = warehouse if warehouse is not None else load_warehouse(wh_file or None)
        members = list(members) if members is not None else load_fleet(fleet_file or None, kinds, warehouse)
        self.sim = SimFleet(members, kinds, warehouse, mode, 1.0 / rate, gated=bool(gated))

        self._status = self.create_publisher(String, topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS)
        subscribe = partial(create_draining_subscription, self)
        # the robots' own topics without rclpy's default QoS-event handlers (a log line on an
        # incompatible publisher): each is a waitable the executor walks at every wake-up, one or
        # two per robot and topic, whichever events the RMW has (the shared topics keep theirs)
        quiet = SubscriptionEventCallbacks(use_default_callbacks=False)
        for rid in self.sim.agents:
            subscribe(Path, topics.timed_path_topic(rid), partial(self._on_path, rid), topics.TIMED_PATH_QOS,
                      event_callbacks=quiet)
            if gated:
                subscribe(String, topics.gate_topic(rid), self._on_gate, topics.GATE_QOS, event_callbacks=quiet)
            if hear_relay:
                subscribe(String, topics.neighbours_topic(rid), self._on_neighbours, topics.NEIGHBOURS_QOS,
                          event_callbacks=quiet)
        subscribe(String, topics.TASKS, self._on_task, topics.TASKS_QOS)
        subscribe(String, topics.TASK_EVENTS, self._on_event, topics.TASK_EVENTS_QOS)
        subscribe(String, topics.HEARD, self._on_heard, topics.HEARD_QOS)   # the robots' leases (fleet/lease.py)
        #: robots whose statuses are not published (a test's radio dead spot: the planner cannot hear them)
        self.unheard: set[str] = set()
        self.lease_stops = 0   # leases run out so far
        self._waits = None
        if self.sim.agents and next(iter(self.sim.agents.values())).strategy.exchanges_wait_messages:
            self._waits = self.create_publisher(String, topics.WAIT_MESSAGES, topics.WAIT_MESSAGES_QOS)
            subscribe(String, topics.WAIT_MESSAGES, self._on_wait_message, topics.WAIT_MESSAGES_QOS)
        self.steps = 0
        self._timer = self.create_timer(1.0 / rate, self._on_timer)
        self.get_logger().info(f"simulating {len(self.sim)} robots, {mode} coordination, {rate:g} steps/s")

    # -- callbacks: none of them lets an exception out ----------------------------------------------
    def _on_path(self, robot_id: str, msg: Path) -> None:
        try:
            radius = self.sim.agents[robot_id].model.kind.radius
            path, t0 = msg_to_timed_path(msg, robot_id, radius)
            t0_ns = stamp_to_ns(t0)
            self.sim.on_path(robot_id, path, t0_ns / 1e9, t0_ns)
        except (RecordError, ValueError) as exc:
            self.get_logger().error(f"robot {robot_id}: timed path ignored: {exc}")

    def _on_gate(self, msg: String) -> None:
        try:
            self.sim.on_gate(string_to_record(msg, GateRecord))
        except RecordError as exc:
            self.get_logger().warning(f"gate record ignored: {exc}", throttle_duration_sec=5.0)

    def _on_task(self, msg: String) -> None:
        try:
            self.sim.on_task(string_to_record(msg, Task))
        except RecordError:
            pass  # the planner answers bad tasks; the robots only need the good ones

    def _on_event(self, msg: String) -> None:
        try:
            self.sim.on_event(string_to_record(msg, TaskEvent))
        except RecordError as exc:
            self.get_logger().warning(f"task event ignored: {exc}", throttle_duration_sec=5.0)

    def _on_heard(self, msg: String) -> None:
        try:
            self.sim.on_heard(string_to_record(msg, Heard))
        except (RecordError, ValueError) as exc:
            self.get_logger().warning(f"heard record ignored: {exc}", throttle_duration_sec=5.0)

    def _on_neighbours(self, msg: String) -> None:
        try:
            self.sim.hear(string_to_record(msg, Neighbours).robots)
        except RecordError as exc:
            self.get_logger().warning(f"neighbours ignored: {exc}", throttle_duration_sec=5.0)

    def _on_wait_message(self, msg: String) -> None:
        try:
            self.sim.on_wait_message(string_to_record(msg, WaitMessageRecord))
        except RecordError as exc:
            self.get_logger().warning(f"wait message ignored: {exc}", throttle_duration_sec=5.0)

    def _on_timer(self) -> None:
        try:
            was = {rid for rid, a in self.sim.agents.items() if a.lease.stopped}
            for status in self.sim.step(self.get_clock().now().nanoseconds / 1e9):
                if status.id not in self.unheard:
                    self._status.publish(String(data=status.to_compact_json()))
            now_stopped = {rid for rid, a in self.sim.agents.items() if a.lease.stopped}
            if now_stopped != was:   # leases that ran out / robots heard again (fleet/lease.py): one line a step
                self.lease_stops += len(now_stopped - was)
                self.get_logger().warning(
                    f"not heard by the planner (lease run out), stopping: {sorted(now_stopped - was)}; heard "
                    f"again, driving on: {sorted(was - now_stopped)} ({len(now_stopped)} stopped, "
                    f"{self.lease_stops} stops so far)")
            if self._waits is not None:
                for wait in self.sim.take_wait_messages():
                    self._waits.publish(String(data=wait.to_json()))
            self.steps += 1
        except Exception as exc:  # keep reporting: the planner must not take live robots for dead
            self.get_logger().error(f"simulation step failed: {exc!r}", throttle_duration_sec=5.0)


def main(args: list[str] | None = None) -> None:
    run_node(FleetSimNode, args, prog="fleet-sim")


if __name__ == "__main__":
    main()
