"""The robot agent node: one robot of the fleet, a thin adapter around :class:`RobotAgent`.

It follows the timed paths the planner sends on ``/robots/<id>/timed_path`` (waiting on the ROS
clock for each departure), learns its jobs from ``/fleet/task_events`` (``assigned`` to its id) and
their stations from ``/fleet/tasks``, picks, places and charges where its legs end, and publishes its
status on ``/fleet/robot_status`` at ``status_rate_hz`` of ROS time (simulated time with
``use_sim_time:=true``). It hears the robots near it from the planner's relay on
``/robots/<id>/neighbours`` (``neighbours:=all``: every status on ``/fleet/robot_status``): for
the safety net of a central robot (it waits rather than drive into one), and for the behaviours of a robot with
``coordination:=behavior``, which takes only the goal of each leg, finds its own way there and
resolves conflicts by the BBMRCA rules (Sun, Kleiner and Nebel, "Behavior-based Multi-Robot Collision
Avoidance"; see docs/ARCHITECTURE.md), with wait messages on ``/fleet/wait_messages``.

    ros2 run fleet_planner robot_agent --ros-args -p id:=r3 -p kind:=cargo_forklift -p x:=6.25 -p y:=22.75
"""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from functools import partial
from typing import Any

from nav_msgs.msg import Path
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from std_msgs.msg import String

from fleet_planner.fleet import COORDINATION, RobotAgent
from fleet_planner.fleet.fleet_file import load_fleet
from fleet_planner.fleet.intake import (
    MAX_HEARD,
    MAX_PATH_OFFSET_S,
    MAX_PATH_POSES,
    MAX_STATUS_AGE_S,
    Roster,
    stamp_problem,
)
from fleet_planner.model import ROBOT_KINDS
from fleet_planner.robots import RobotKind, RobotModel, load_kinds
from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.entry import run_node
from fleet_planner.ros.operator_services import AgentOperator
from fleet_planner.ros.origin import OriginCheck
from fleet_planner.ros.signing import Keys, PathPairing
from fleet_planner.validation import printable
from fleet_planner.warehouse import Warehouse, load_warehouse
from msg_schemas import topics
from msg_schemas.convert import msg_to_timed_path, stamp_to_ns, string_to_record
from msg_schemas.records import (
    GateRecord,
    Heard,
    Neighbours,
    ObstacleRecord,
    PathAuth,
    RecordError,
    RobotStatus,
    Task,
    TaskEvent,
    WaitMessageRecord,
    robot_id_problem,
)


def _range(description: str, lo: float, hi: float) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=True,
                               floating_point_range=[FloatingPointRange(from_value=float(lo), to_value=float(hi))])


def _fixed(description: str) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=True)


#: wall seconds a gate record refused only for a publisher without a known name is asked about again
GATE_SETTLE_S = 5.0


class AgentNode(Node):
    """One robot. ``warehouse`` and ``kinds`` may be handed in (tests); otherwise they are read from the
    files named by the parameters ``warehouse_file`` and ``kinds_file`` (empty: the shipped ones).
    The robot's id is the parameter ``id``, or else the last part of the node's namespace (topic
    names are relative, so an agent in ``/r1`` talks on ``/r1/fleet/...``: in a fleet, give the id).

    Task events, timed paths and gate records count only from the planner node (``planner``; see
    ``fleet_planner/ros/origin.py``) or, with ``auth_trust_file``, only when signed by one of its keys
    (``fleet_planner/ros/signing.py``); with ``fleet_file``, only the roster's statuses are heard."""

    def __init__(self, name: str = "robot_agent", *, warehouse: Warehouse | None = None,
                 kinds: Mapping[str, RobotKind] | None = None, **kwargs: Any):
        super().__init__(name, **kwargs)
        robot_id = self.declare_parameter("id", "", _fixed("robot id (letters, digits, _); empty: the namespace")).value
        kind = self.declare_parameter("kind", "cargo", _fixed(f"one of {', '.join(ROBOT_KINDS)}")).value
        x = self.declare_parameter("x", 0.0, _fixed("start x (m, map frame)")).value
        y = self.declare_parameter("y", 0.0, _fixed("start y (m, map frame)")).value
        yaw = self.declare_parameter("yaw", 0.0, _fixed("start heading (rad)")).value
        battery = self.declare_parameter("battery", 1.0, _range("battery at start, fraction of full", 0.0, 1.0)).value
        mode = self.declare_parameter("coordination", "central", _fixed(
            "how the robot avoids others: 'central' (follow the planner's timed paths, with a safety net) "
            "or 'behavior' (BBMRCA: only each leg's goal binds; own path, behaviours, wait messages)")).value
        rate = self.declare_parameter("status_rate_hz", 10.0, _range("status messages per second of ROS time",
                                                                     0.1, 100.0)).value
        hears = self.declare_parameter("neighbours", "relay", _fixed(
            "whom the robot hears: 'relay' (the planner's record of the robots near it, on "
            "/robots/<id>/neighbours) or 'all' (every robot's status on /fleet/robot_status)")).value
        wh_file = self.declare_parameter("warehouse_file", "", _fixed(
            "warehouse YAML (empty: the shipped config/warehouse.yaml)")).value
        kinds_file = self.declare_parameter("kinds_file", "", _fixed(
            "robot kinds YAML (empty: the shipped config/robot_kinds.yaml)")).value
        planner = self.declare_parameter("planner", "planner", _fixed(
            "the planner's node name (relative to this node's namespace, or absolute): task events and timed "
            "paths are taken only while no other node publishes them")).value
        fleet_file = self.declare_parameter("fleet_file", "", _fixed(
            "fleet YAML whose robot ids are the roster: statuses of other ids are ignored (one warning each); "
            "empty: every robot's are heard")).value
        trust_file = self.declare_parameter("auth_trust_file", "", _fixed(
            "key file of the planner (fleet_planner/auth.py): with it, only task events, timed paths and gate "
            "records signed "
            "by one of its keys are taken, from any node (empty: only from the planner node, unsigned)")).value
        operator_file = self.declare_parameter("auth_operator_file", "", _fixed(
            "key file of the operators: with keys (this or auth_trust_file, whose keys it defaults to), manual "
            "drive only by signed fleet/robot_command@1 on /robots/<id>/command (the manual service and cmd_vel "
            "are refused)")).value
        gated = self.declare_parameter("gated", True, _fixed(
            "central: never enter a collision region before the robot ranked above has left it (by the "
            "planner's gate records on /robots/<id>/gate and the others' statuses); false: the clock alone")).value
        scale = self.declare_parameter("speed_scale", 1.0, ParameterDescriptor(
            description="fraction of the top speed the robot may drive at (a speed limit; 0 halts it)",
            floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1.0)])).value

        robot_id = robot_id or self.get_namespace().rstrip("/").rsplit("/", 1)[-1]
        problem = robot_id_problem(robot_id)
        if problem:
            raise ValueError(f"parameter id: {problem}" if robot_id else "parameter id: required (or a namespace)")
        if hears not in ("relay", "all"):
            raise ValueError(f"parameter neighbours: {hears!r} is not one of relay, all")
        if mode not in COORDINATION:
            raise ValueError(f"parameter coordination: {mode!r} is not one of {', '.join(COORDINATION)}")
        kinds = kinds if kinds is not None else load_kinds(kinds_file or None)
        if kind not in kinds:
            raise ValueError(f"parameter kind: {kind!r} is not one of {', '.join(kinds)}")
        warehouse = warehouse if warehouse is not None else load_warehouse(wh_file or None)
        chargers = [s.pose for s in warehouse.stations_of("charger")]
        model = RobotModel(robot_id, kinds[kind], x, y, yaw, battery, chargers)
        self._roster = Roster([m.id for m in load_fleet(fleet_file, kinds)] if fleet_file else None)
        self.planner = OriginCheck.qualify(self, planner)
        self.agent = RobotAgent(model, warehouse, mode, planner=self.planner, gated=bool(gated))
        self.agent.speed_scale = float(scale)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.robot_id = robot_id

        self._status = self.create_publisher(String, topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS)
        # every waiting message at each wake-up: the whole fleet's statuses keep coming (see drain.py)
        subscribe = partial(create_draining_subscription, self)
        paths = subscribe(Path, topics.timed_path_topic(robot_id), self._on_path, topics.TIMED_PATH_QOS)
        gates = subscribe(String, topics.gate_topic(robot_id), self._on_gate, topics.GATE_QOS)
        subscribe(String, topics.TASKS, self._on_task, topics.TASKS_QOS)
        events = subscribe(String, topics.TASK_EVENTS, self._on_event, topics.TASK_EVENTS_QOS)
        self._path_origin, self._event_origin = OriginCheck(self, paths, planner), OriginCheck(self, events, planner)
        self._gate_origin = OriginCheck(self, gates, planner)
        heard = subscribe(String, topics.HEARD, self._on_heard, topics.HEARD_QOS)   # its lease (fleet/lease.py)
        self._heard_origin, self._heard_topic = OriginCheck(self, heard, planner), heard.topic_name
        # a record refused only because its publisher had no known name yet, and until when it may be taken
        self._gate_pending: tuple[GateRecord, float] | None = None
        self._path_pending: tuple[Path, float] | None = None
        self.keys = Keys(trust_file=trust_file)
        self._events_topic, self._gates_topic = events.topic_name, gates.topic_name
        self._pairing: PathPairing | None = None
        if self.keys.checks:  # signed paths: their signatures come beside them
            auth = subscribe(String, topics.timed_path_auth_topic(robot_id), self._on_path_auth,
                             topics.TIMED_PATH_AUTH_QOS)
            self._pairing = PathPairing(self.keys, robot_id, auth.topic_name)
        if hears == "all":
            subscribe(String, topics.ROBOT_STATUS, self._on_status, topics.ROBOT_STATUS_QOS)
        else:
            subscribe(String, topics.neighbours_topic(robot_id), self._on_neighbours, topics.NEIGHBOURS_QOS)
        subscribe(String, topics.OBSTACLES, self._on_obstacle, topics.OBSTACLES_QOS)  # for the safety net
        self._waits: Publisher | None = None
        if self.agent.strategy.exchanges_wait_messages:
            self._waits = self.create_publisher(String, topics.WAIT_MESSAGES, topics.WAIT_MESSAGES_QOS)
            subscribe(String, topics.WAIT_MESSAGES, self._on_wait_message, topics.WAIT_MESSAGES_QOS)
        self.operator = AgentOperator(self, self.agent, robot_id, self.planner,  # manual drive, cmd_vel, e-stop
                                      Keys(trust_file=operator_file or trust_file))
        self._timer = self.create_timer(1.0 / rate, self._on_timer)
        self.get_logger().info(f"robot {robot_id} ({kind}) at ({x:g}, {y:g}), battery {battery:.0%}, "
                               f"{mode} coordination")

    # -- callbacks: none of them lets an exception out ----------------------------------------------
    def _on_path(self, msg: Path) -> None:
        if self._pairing is not None:  # keys: followed once its signature checks out
            self._follow(self._pairing.offer_path(msg))
            return
        problem = self._path_origin.problem()
        if problem:
            if self._path_origin.unnamed_only:  # likely the planner, just discovered: asked again (origin.py)
                self._path_pending = (msg, time.monotonic() + GATE_SETTLE_S)
            self.get_logger().error(printable(f"timed path ignored: not from the planner: {problem}", 300),
                                    throttle_duration_sec=1.0)
            return
        self._path_pending = None
        self._follow(msg)

    def _on_path_auth(self, msg: String) -> None:
        try:
            assert self._pairing is not None
            self._follow(self._pairing.offer_auth(string_to_record(msg, PathAuth)))
            if self._pairing.problem:
                raise RecordError(self._pairing.problem)
        except RecordError as exc:
            self.get_logger().error(printable(f"timed path refused: {exc} ({self.keys.refused} refused so far)",
                                              300), throttle_duration_sec=1.0)

    def _follow(self, msg: Path | None) -> None:
        if msg is None:
            return
        try:
            if len(msg.poses) > MAX_PATH_POSES:
                raise ValueError(f"timed path: {len(msg.poses)} poses (at most {MAX_PATH_POSES})")
            path, t0 = msg_to_timed_path(msg, self.robot_id, self.agent.model.kind.radius)
            t0_ns = stamp_to_ns(t0)
            problem = stamp_problem("timed path", t0_ns / 1e9, self._now(), MAX_PATH_OFFSET_S, MAX_PATH_OFFSET_S)
            if problem:
                raise ValueError(problem)
            self.agent.on_path(path, t0_ns / 1e9, t0_ns)
        except (RecordError, ValueError) as exc:
            self.get_logger().error(printable(f"timed path ignored: {exc}", 300), throttle_duration_sec=1.0)

    def _not_planners(self, record: Any, topic: str, origin: OriginCheck, field: str) -> str | None:
        """Why ``record`` on ``topic`` is not the planner's word (None: it is). With keys, its signature
        is checked (fresh, not replayed); without, the topic must have the planner node alone as publisher."""
        if self.keys.checks:
            problem = self.keys.problem(record, topic)
            return f"{field}.auth: {problem} ({self.keys.refused} refused so far)" if problem else None
        problem = origin.problem()
        return f"not from the planner: {problem}" if problem else None

    def _on_gate(self, msg: String) -> None:
        # a gate record releases the robot into a region: like task events, only the planner's word counts
        try:
            record = string_to_record(msg, GateRecord)
            if problem := self._not_planners(record, self._gates_topic, self._gate_origin, "gate"):
                if not self.keys.checks and self._gate_origin.unnamed_only:
                    # likely the planner, just discovered: asked again (origin.py)
                    self._gate_pending = (record, time.monotonic() + GATE_SETTLE_S)
                raise RecordError(f"gate {record.path_id}/{record.seq}: {problem}")
            self._gate_pending = None
            self.agent.on_gate(record)
        except RecordError as exc:
            self.get_logger().error(printable(f"gate record ignored: {exc}", 300), throttle_duration_sec=1.0)

    def _on_heard(self, msg: String) -> None:
        # whom the planner hears renews the robot's lease: only the planner's word counts
        try:
            record = string_to_record(msg, Heard)
            if problem := self._not_planners(record, self._heard_topic, self._heard_origin, "heard"):
                raise RecordError(problem)
            self.agent.on_heard(record, self._now())
        except (RecordError, ValueError) as exc:
            self.get_logger().warning(printable(f"heard record ignored: {exc}", 300), throttle_duration_sec=5.0)

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name == "speed_scale":
                try:
                    self.agent.speed_scale = float(p.value)
                except (TypeError, ValueError) as exc:
                    return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _on_task(self, msg: String) -> None:
        try:
            self.agent.on_task(string_to_record(msg, Task))
        except RecordError:
            pass  # the planner answers bad tasks; the robot only needs the good ones

    def _on_event(self, msg: String) -> None:
        try:
            event = string_to_record(msg, TaskEvent)
            if problem := self._not_planners(event, self._events_topic, self._event_origin, "task_event"):
                raise RecordError(f"task event {event.task_id} {event.event}: {problem}")
            self.agent.on_event(event, sender=self.planner)
        except RecordError as exc:
            self.get_logger().warning(f"task event ignored: {exc}", throttle_duration_sec=5.0)

    def _on_status(self, msg: String) -> None:
        try:
            status = string_to_record(msg, RobotStatus)
            problem = stamp_problem(f"robot {status.id!r}", status.stamp, self._now(), float("inf"), MAX_STATUS_AGE_S)
            if problem:  # (ahead: RobotAgent.on_status refuses those)
                raise ValueError(problem)
            known, warning = self._roster.admit(status.id)
            if warning:
                self.get_logger().warning(warning)
            if not known:
                return
            if status.id not in self.agent.heard and len(self.agent.heard) >= MAX_HEARD:
                raise ValueError(f"robot {status.id!r}: already hearing {MAX_HEARD} robots; ignored")
            self.agent.on_status(status)
        except (RecordError, ValueError) as exc:
            self.get_logger().warning(f"robot status ignored: {exc}", throttle_duration_sec=5.0)

    def _on_neighbours(self, msg: String) -> None:
        try:
            record = string_to_record(msg, Neighbours)
            if record.id != self.robot_id:
                raise RecordError(f"neighbours.id: {record.id!r} is not this robot")
            self.agent.on_neighbours(record.robots, self.get_clock().now().nanoseconds / 1e9)
        except RecordError as exc:
            self.get_logger().warning(f"neighbours ignored: {exc}", throttle_duration_sec=5.0)

    def _on_obstacle(self, msg: String) -> None:
        try:
            self.agent.on_obstacle(string_to_record(msg, ObstacleRecord), self.get_clock().now().nanoseconds / 1e9)
        except (RecordError, ValueError) as exc:
            self.get_logger().warning(f"obstacle ignored: {exc}", throttle_duration_sec=5.0)

    def _on_wait_message(self, msg: String) -> None:
        try:
            self.agent.on_wait_message(string_to_record(msg, WaitMessageRecord))
        except RecordError as exc:
            self.get_logger().warning(f"wait message ignored: {exc}", throttle_duration_sec=5.0)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds / 1e9

    def _settle(self, pending: tuple[Any, float], origin: OriginCheck, take: Callable[[Any], None],
                what: str) -> tuple[Any, float] | None:
        """A record refused only because its publisher had no known name yet (a gate record or a
        timed path): taken once the graph names only the planner there, dropped if another node is
        named or after GATE_SETTLE_S. Returns what is still pending."""
        record, until = pending
        settled = origin.settled()
        if settled is None and time.monotonic() < until:
            return pending
        if settled:
            self.get_logger().info(f"{what} taken: the planner is known now")
            take(record)
        return None

    def _on_timer(self) -> None:
        try:
            if self._gate_pending is not None:
                gate = self._gate_pending[0]
                self._gate_pending = self._settle(self._gate_pending, self._gate_origin, self.agent.on_gate,
                                                  f"gate record {gate.path_id}/{gate.seq}")
            if self._path_pending is not None:
                self._path_pending = self._settle(self._path_pending, self._path_origin, self._follow, "timed path")
            was = self.agent.lease.stopped
            status = self.agent.tick(self.get_clock().now().nanoseconds / 1e9)
            self._status.publish(String(data=status.to_compact_json()))  # fleet/robot_status@2
            if self.agent.lease.stopped != was:   # its lease ran out / it drives on (fleet/lease.py)
                lease = self.agent.lease
                self.get_logger().warning(
                    f"not heard by the planner since t = {lease.heard:.1f} s (lease {lease.lease_s:g} s): stopping"
                    if lease.stopped else "heard again on a leg the planner keeps: driving on")
            for wait in self.agent.take_wait_messages():  # only robots coordinating by behaviours send any
                if self._waits is not None:
                    self._waits.publish(String(data=wait.to_json()))
        except Exception as exc:  # keep reporting: the planner must not take a live robot for dead
            self.get_logger().error(f"robot step failed: {exc!r}", throttle_duration_sec=5.0)


def main(args: list[str] | None = None) -> None:
    run_node(AgentNode, args, prog="robot_agent")


if __name__ == "__main__":
    main()
