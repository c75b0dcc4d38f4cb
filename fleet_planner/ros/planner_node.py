"""The central planner node: a thin adapter between the fleet topics and :class:`FleetManager`.

Subscribes ``/fleet/tasks``, ``/fleet/robot_status`` and ``/fleet/obstacles`` (the intelligent
space's people, vehicles and pallets, planned around as participants above every robot); on a
timer (ROS time) asks the fleet manager what changes and publishes each robot's new timed path
(``/robots/<id>/timed_path``, one stamp per pose), the task events, the schedule, RViz markers
(obstacles with their predictions too), and once the map. No single message can stop it: a bad
task is answered with a ``rejected`` event naming the problem, a bad status or obstacle with a
logged warning.

    ros2 run fleet_planner planner --ros-args --params-file config/planner_params.yaml
"""
from __future__ import annotations

import sqlite3
import time
import traceback
from collections import deque
from collections.abc import Mapping
from dataclasses import fields, replace
from typing import Any

from nav_msgs.msg import OccupancyGrid, Path
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.time_source import CLOCK_TOPIC
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from fleet_planner.fleet import COORDINATION, Decisions, DispatchParams, FleetManager
from fleet_planner.fleet.coordination import AGENT_BEHAVIOR
from fleet_planner.fleet.fleet_file import load_fleet
from fleet_planner.fleet.gate import watched_robots
from fleet_planner.fleet.inbox import StatusInbox
from fleet_planner.fleet.intake import MAX_STATUS_AGE_S, stamp_problem
from fleet_planner.fleet.jobstore import open_store
from fleet_planner.fleet.legs import MAX_CLOCK_SKEW_S
from fleet_planner.fleet.manager import paced_budgets
from fleet_planner.fleet.neighbours import RELAY_PERIOD_S
from fleet_planner.fleet.obstacles import ObstacleParams
from fleet_planner.robots import RobotKind, load_kinds
from fleet_planner.ros.drain import create_draining_subscription, drain_limit, take_waiting
from fleet_planner.ros.entry import run_node
from fleet_planner.ros.operator_services import PlannerOperator
from fleet_planner.ros.relay import NeighbourPublisher
from fleet_planner.ros.signing import Keys
from fleet_planner.validation import printable
from fleet_planner.warehouse import Warehouse, load_warehouse
from msg_schemas import topics
from msg_schemas.convert import (
    grid_to_msg,
    ns_to_stamp,
    plan_markers,
    record_to_string,
    string_to_record,
    timed_path_to_msg,
)
from msg_schemas.records import ObstacleRecord, RecordError, RobotStatus, Task, TaskEvent

#: at most this many notes of one step are logged (one log line; the rest are counted)
MAX_NOTES_LOGGED = 40
#: wall seconds between two log lines of the same kind from the status path (rclpy's own throttle
#: still finds the caller's frame on every call: a cost per status, not per line)
STATUS_LOG_EVERY_S = 5.0

#: the largest share of wall time the RViz markers may take (they are sent less often when they cost more)
MARKERS_SHARE = 0.05

#: a planner that reloaded open jobs waits before its first step until the subscribers of its task
#: events have stopped appearing for this many wall seconds (events are volatile: one announced
#: before a subscriber matched is lost to it, and a restart announces picks and places made while
#: the planner was down) ...
EVENTS_SETTLE_S = 1.0
#: ... but no longer than this many wall seconds after it started
EVENTS_SETTLE_MAX_S = 10.0
#: task events handed to the middleware are noted in the job store as announced (its outbox, see
#: fleet/jobstore.py) once every matched subscriber acknowledged them - published is not delivered: a
#: sample a subscriber missed (its queue full for a moment) is sent again by the reliability protocol
#: only while the planner lives, and a planner killed before that repair took it with it - or, when
#: events flow faster than acknowledgements come (Fast DDS: about every 3 s), once they were out this
#: many wall seconds with the planner running (time for several rounds of repair): what a restart
#: announces again stays that short
EVENTS_REPAIR_S = 10.0
_NO_WAIT = Duration(seconds=0)

#: parameters that shape planned legs and cannot change while the node runs
_FIXED = ("speed_factor", "safety_margin")
#: heard records (fleet/lease.py) per lease: a robot's lease is renewed this often while it is heard
HEARD_PER_LEASE = 3.0

_HELP = {
    "speed_factor": "legs are planned at this fraction of each robot's top speed",
    "safety_margin": "m added to the margin that covers the robots' tracking lag",
    "lead_s": "s between planning a leg and its start (time to deliver it)",
    "offline_timeout_s": "s without a status after which a robot is offline",
    "lateness_tolerance_s": "s behind schedule after which a robot re-plans its leg",
    "low_battery": "battery fraction below which a free robot goes to a charger",
    "min_task_battery": "battery fraction a robot needs to take a job",
    "idle_s": "s a free robot waits before it goes to a charger",
    "lease_s": "s a robot the planner does not hear (while it hears others) drives on before it stops "
               "(0: offline_timeout_s / 2)",
    "silence_s": "s a robot that hears no heard record drives on before it stops (0: 3 x offline_timeout_s)",
}

_OBSTACLE_HELP = {
    "horizon_s": "s a moving obstacle is predicted ahead (constant velocity)",
    "growth": "m its predicted disc grows per second of prediction",
    "stale_s": "s after its last record an obstacle that is not persistent is forgotten",
}


def quiet_events() -> PublisherEventCallbacks:
    """No QoS event handlers for a publisher: rclpy's default one (incompatible QoS) puts one more
    entity into every wait of the executor, for each of the per-robot publishers (3 per robot)."""
    return PublisherEventCallbacks(use_default_callbacks=False)


QUIET = quiet_events()


def _range(description: str, lo: float, hi: float, read_only: bool = True) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=read_only,
                               floating_point_range=[FloatingPointRange(from_value=float(lo), to_value=float(hi))])


class PlannerNode(Node):
    """The planner. ``warehouse`` and ``kinds`` may be handed in (tests); otherwise they are read from
    the files named by the parameters ``warehouse_file`` and ``kinds_file`` (empty: the shipped ones)."""

    def __init__(self, name: str = "planner", *, warehouse: Warehouse | None = None,
                 kinds: Mapping[str, RobotKind] | None = None, **kwargs: Any):
        super().__init__(name, **kwargs)
        wh_file = self.declare_parameter("warehouse_file", "", ParameterDescriptor(
            description="warehouse YAML (empty: the shipped config/warehouse.yaml)", read_only=True)).value
        kinds_file = self.declare_parameter("kinds_file", "", ParameterDescriptor(
            description="robot kinds YAML (empty: the shipped config/robot_kinds.yaml)", read_only=True)).value
        self.frame_id = self.declare_parameter("frame_id", "map", ParameterDescriptor(
            description="frame of the paths, markers and map", read_only=True)).value
        spots = self.declare_parameter("parking", Parameter.Type.DOUBLE_ARRAY, ParameterDescriptor(
            description="parking spots besides the chargers, flattened: [x1, y1, x2, y2, ...] (m)",
            read_only=True)).value or []
        period = self.declare_parameter("step_period_s", 0.5, _range(
            "s of ROS time between planning steps", 0.05, 10.0)).value
        coordination = self.declare_parameter("coordination", "central", ParameterDescriptor(
            description="how the robots avoid each other: 'central' (timed paths with (M,D) delays) or "
                        "'behavior' (legs bind only their goals; the robots use BBMRCA)", read_only=True)).value
        store_file = self.declare_parameter("job_store", "", ParameterDescriptor(
            description="SQLite file keeping every accepted job across restarts (created if missing; empty: "
                        "$ROS_HOME/fleet_planner/domain_<ROS_DOMAIN_ID>/<namespace>/jobs.sqlite, ROS_HOME defaulting "
                        "to ~/.ros; ':memory:': jobs live in memory only); restart with the same file and open jobs "
                        "carry on; one planner per file (a second one is refused)", read_only=True)).value
        relay_period = self.declare_parameter("neighbour_period_s", RELAY_PERIOD_S, _range(
            "s of ROS time between the neighbours records sent to each robot (/robots/<id>/neighbours)",
            0.02, 2.0)).value
        self._markers_period = self.declare_parameter("markers_period_s", 1.0, _range(
            "s of wall time between two RViz marker arrays at most (they cost time in proportion to the fleet, "
            "and a viewer looks at them in wall time, however fast the simulated clock runs)",
            0.0, 60.0)).value
        gated = self.declare_parameter("gated", True, ParameterDescriptor(
            description="central: send each robot its legs' precedence links on /robots/<id>/gate (for agents "
                        "with gated:=true, which never enter a collision region before the robot above left it)",
            read_only=True)).value
        skew = self.declare_parameter("max_clock_skew_s", MAX_CLOCK_SKEW_S, _range(
            "s a robot status may be stamped ahead of the planner's clock before it is refused", 0.0, 60.0)).value
        self._max_age = self.declare_parameter("max_status_age_s", MAX_STATUS_AGE_S, _range(
            "s a robot status may be stamped behind the planner's clock before it is refused", 1.0, 3600.0)).value
        fleet_file = self.declare_parameter("fleet_file", "", ParameterDescriptor(
            description="fleet YAML whose robot ids are the roster: statuses of other ids are ignored (one "
                        "warning each); empty: any robot may join", read_only=True)).value
        self.keys = Keys(self.declare_parameter("auth_key_file", "", ParameterDescriptor(
            description="key file (fleet_planner/auth.py): sign task events and timed paths with its first key "
                        "(empty: unsigned)", read_only=True)).value,
                         self.declare_parameter("auth_trust_file", "", ParameterDescriptor(
            description="key file of the clients: with it, only tasks signed by one of its keys are taken "
                        "(empty: any task)", read_only=True)).value)
        operator_file = self.declare_parameter("auth_operator_file", "", ParameterDescriptor(
            description="key file of the operators: with keys (this, or else auth_trust_file's), only commands on "
                        "/fleet/commands signed by one of them are obeyed, and the pause and e-stop services are "
                        "refused but for engaging the e-stop (fleet_planner/ros/operator_services.py)",
            read_only=True)).value
        trust = self.get_parameter("auth_trust_file").value
        # obstacles of the intelligent space (fleet/obstacles.py): how they are predicted and forgotten
        ob_defaults = ObstacleParams()
        ob_values = {f.name: self.declare_parameter(f"obstacle_{f.name}", float(getattr(ob_defaults, f.name)), _range(
            _OBSTACLE_HELP[f.name], *ObstacleParams.RANGES[f.name])).value for f in fields(ObstacleParams)}
        defaults = DispatchParams()
        values = {}
        for f in fields(DispatchParams):
            lo, hi = DispatchParams.RANGES[f.name]
            values[f.name] = self.declare_parameter(f.name, float(getattr(defaults, f.name)), _range(
                _HELP[f.name], lo, hi, read_only=f.name in _FIXED)).value
        if len(spots) % 2:
            raise ValueError(f"parking: needs x, y pairs (got {len(spots)} numbers)")

        warehouse = warehouse if warehouse is not None else load_warehouse(wh_file or None)
        kinds = kinds if kinds is not None else load_kinds(kinds_file or None)
        roster = [m.id for m in load_fleet(fleet_file, kinds)] if fleet_file else None
        if coordination not in COORDINATION:
            raise ValueError(f"parameter coordination: {coordination!r} is not one of {', '.join(COORDINATION)}")
        store = open_store(store_file, namespace=self.get_namespace(), lock=True)
        self.fleet = FleetManager(warehouse, kinds, DispatchParams(**values),
                                  [(spots[i], spots[i + 1]) for i in range(0, len(spots), 2)], coordination,
                                  store=store, max_clock_skew_s=skew,
                                  roster=roster, obstacle_params=ObstacleParams(**ob_values), gated=bool(gated))
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._events = self.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
        self._schedule = self.create_publisher(String, topics.SCHEDULE, topics.SCHEDULE_QOS)
        self._markers = self.create_publisher(MarkerArray, topics.MARKERS, topics.MARKERS_QOS)
        self._map = self.create_publisher(OccupancyGrid, topics.MAP, topics.MAP_QOS)
        # whom it hears, for the robots' leases (fleet/lease.py): three times a lease (ROS time; every agent
        # parses the whole record, ~0.4 ms at 100 robots: fleet-wide that is the cost, not the planner's)
        self._heard_pub = self.create_publisher(String, topics.HEARD, topics.HEARD_QOS)
        self._heard_timer = self.create_timer(self.fleet.params.lease / HEARD_PER_LEASE, self._refresh)
        self._paths: dict[str, tuple[Publisher, Publisher | None]] = {}
        self._gates: dict[str, Publisher] = {}
        self._inbox = StatusInbox()  # only the latest status of each robot is parsed (fleet/inbox.py)
        self._markers_at = -float("inf")   # (wall time, time.monotonic)
        self._markers_gap = self._markers_period   # wall s until the next markers (see _publish)
        self._arrival_wall, self._arrival_now = -float("inf"), 0.0   # (see _arrival)
        self._said: dict[str, float] = {}   # when a line of each kind of the status path was last logged
        # every waiting task and status at each wake-up: fresh statuses before each step (see drain.py)
        self._tasks = create_draining_subscription(self, String, topics.TASKS, self._on_task, topics.TASKS_QOS)
        self._status_sub = create_draining_subscription(self, String, topics.ROBOT_STATUS, self._on_status,
                                                        topics.ROBOT_STATUS_QOS)
        self._status_limit = drain_limit(topics.ROBOT_STATUS_QOS)
        self._paced: tuple[float, float] | None = None   # (ROS time, wall time) of the last step
        self._rate = 1.0   # ROS seconds per wall second, measured
        limit = getattr(self.fleet.planner, "leg_time_limit", None)
        self._leg_limit = float(limit) if isinstance(limit, (int, float)) else None
        # pause, e-stop, cancel, priority, send, manual drive (services and topics: operator_services.py)
        self.operator = PlannerOperator(self, self.fleet, self._publish, Keys(trust_file=operator_file or trust))
        create_draining_subscription(self, String, topics.OBSTACLES, self._on_obstacle, topics.OBSTACLES_QOS)
        # (wall time it started, matched subscribers of its events, when that count last changed)
        self._settling = (time.monotonic(), -1, time.monotonic()) if self.fleet.jobs or self.fleet.replaying else None
        #: (wall time, FleetManager.handed_out) after each publication of task events not yet noted as announced
        self._unconfirmed: deque[tuple[float, int]] = deque()
        self._sent_n = 0   # the last handed_out in it
        self._timer = self.create_timer(period, self._on_timer)
        # each robot hears only its neighbours (fleet_planner/fleet/neighbours.py) and the robots its
        # execution gate watches (fleet_planner/fleet/gate.py)
        self.neighbour_relay = NeighbourPublisher(
            self, self.fleet, relay_period, AGENT_BEHAVIOR.comm_range if coordination == "behavior" else 0.0,
            refresh=self._take_statuses)
        gates = self.fleet.gates
        if gates is not None:  # a gated robot hears every robot its links name, however far
            self.neighbour_relay.watch = lambda rid: watched_robots(gates.records.get(rid))
        self._map.publish(grid_to_msg(warehouse.grid, self.frame_id, self._now()))
        self.get_logger().info(
            f"planning for warehouse {warehouse.name!r} ({len(warehouse.stations)} stations), {coordination} "
            f"coordination, margin {self.fleet.margin:.2f} m, {len(self.fleet.parking)} parking spots, "
            f"step every {period:g} s; jobs "
            + (f"in {str(store.path)!r} ({len(self.fleet.jobs)} open reloaded)" if store else "in memory only"))

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds / 1e9

    def _refresh(self) -> None:
        """Every lease / HEARD_PER_LEASE s: the statuses waiting now, and whom the planner hears."""
        self._take_statuses()
        self._publish_heard(self._now())

    def _publish_heard(self, now: float) -> None:
        """Whom the planner hears (``fleet/heard@1``, signed with keys): the robots' leases (fleet/lease.py)."""
        try:
            self._heard_pub.publish(record_to_string(self.keys.sign(self.fleet.heard(now), self._heard_pub.topic_name)))
        except Exception as exc:  # (never out of a callback; the robots then stop: their leases run out)
            self.get_logger().error(f"heard record not sent: {exc!r}", throttle_duration_sec=5.0)

    def destroy_node(self) -> None:
        """Also lets go of the job store (its lock: another planner may open it then), noting in it the task
        events acknowledged by now (no wait: the next planner on the store announces the rest again)."""
        if getattr(self, "_unconfirmed", None):
            try:
                self._confirm_announced()
            except Exception:   # (rclpy shut down first: the next planner announces them again)
                pass
        super().destroy_node()
        fleet = getattr(self, "fleet", None)
        if fleet is not None and fleet.store is not None:
            fleet.store.close()

    # -- callbacks: none of them lets an exception out ----------------------------------------------
    def _on_task(self, msg: String) -> None:
        now = self._now()
        try:
            events = self._signed_task(msg, now) if self.keys.checks else self.fleet.submit(msg.data, now)
        except Exception as exc:  # a bug must not take the fleet down: answer, log, carry on
            self.get_logger().error(f"task {msg.data[:200]!r}: {printable(repr(exc), 300)}")
            events = [TaskEvent(task_id="?", event="rejected", stamp=now,
                                reason=printable(f"internal error: {exc}", 300))]
        for ev in events:
            if ev.event == "rejected":
                self.get_logger().warning(f"task {ev.task_id} rejected: {ev.reason}", throttle_duration_sec=1.0)
        self._publish_events(events)

    def _signed_task(self, msg: String, now: float) -> list[TaskEvent]:
        """A task, taken only with a good signature of a client key (rejected and counted otherwise)."""
        try:
            task = string_to_record(msg, Task)
        except RecordError:
            return self.fleet.submit(msg.data, now)  # the rejection names the field
        problem = self.keys.problem(task, self._tasks.topic_name)
        if problem:
            return [TaskEvent(task_id=task.id, event="rejected", stamp=now,
                              reason=f"task.auth: {problem} ({self.keys.refused} refused so far)")]
        return self.fleet.submit(replace(task, auth=None), now)

    def _arrival(self) -> float:
        """The planner's clock for a status just taken, read from rclpy at most once per wall
        millisecond (statuses come in thousands a second; reading the ROS clock costs more than filing one)."""
        wall = time.monotonic()
        if wall - self._arrival_wall >= 1e-3:
            self._arrival_wall, self._arrival_now = wall, self._now()
        return self._arrival_now

    def _on_status(self, msg: String) -> None:
        at_once = self._inbox.offer(msg.data, self._arrival())
        if at_once is not None:
            self._status(*at_once)

    def _take_statuses(self) -> None:
        """Every status waiting now, the latest of each robot parsed. First the simulated clock's
        latest tick and what waits in the status queue, so a step that follows a long one sees the
        time and the fleet as they are now, not as they were before it (a robot is never found
        silent only because the planner was not listening)."""
        self._catch_up_clock()
        self._arrival_wall = -float("inf")   # the clock may have moved on
        for _ in range(self._status_limit):
            msg = take_waiting(self._status_sub)
            if msg is None:
                break
            self._on_status(msg)
        for raw, arrived in self._inbox.take():
            self._status(raw, arrived)

    def _catch_up_clock(self) -> None:
        """Hand the latest waiting ``/clock`` tick to the node's time source (with use_sim_time):
        rclpy reads it only when the executor comes to it, after the callbacks already due."""
        sub = next((s for s in self.subscriptions if s.topic_name == CLOCK_TOPIC), None)
        if sub is None:
            return
        last = None
        for _ in range(1000):
            msg = take_waiting(sub)
            if msg is None:
                break
            last = msg
        if last is not None:
            sub.callback(last)

    def _say(self, kind: str, text: str, error: bool = False) -> None:
        """One log line of ``kind`` per STATUS_LOG_EVERY_S wall seconds (a cheap throttle, checked
        before rclpy's logger is called at all)."""
        wall = time.monotonic()
        if wall - self._said.get(kind, -float("inf")) < STATUS_LOG_EVERY_S:
            return
        self._said[kind] = wall
        log = self.get_logger()
        (log.error if error else log.warning)(text)

    def _status(self, raw: str, arrived: float) -> None:
        msg = String(data=raw)
        try:
            status = string_to_record(msg, RobotStatus)
            # it cannot have arrived before it was stamped (one clock): a planner whose clock lagged
            # when the status came in (busy, its /clock not yet read) must not find it ahead, or the
            # robot silent; never later than the planner's clock now
            fresh = self._arrival()
            if status.stamp > fresh + 1.0:  # its clock ahead of ours: ours may lag (no /clock read yet)
                self._catch_up_clock()
                self._arrival_wall = -float("inf")
                fresh = self._arrival()
            arrived = max(arrived, min(fresh, status.stamp))
            problem = stamp_problem(f"robot {status.id!r}", status.stamp, arrived, float("inf"), self._max_age)
            if problem:  # (ahead: the fleet manager's max_clock_skew_s)
                raise ValueError(problem)
            self.fleet.on_status(status, arrived)
            self.neighbour_relay.relay.offer_json(status, raw)
        except (RecordError, ValueError) as exc:
            self._say("status ignored", f"robot status ignored: {exc}")
        except Exception as exc:
            self._say("status failed", f"robot status {msg.data[:200]!r}: {exc!r}", error=True)

    def _on_obstacle(self, msg: String) -> None:
        try:
            self.fleet.on_obstacle(string_to_record(msg, ObstacleRecord), self._now())
        except (RecordError, ValueError) as exc:
            self.get_logger().warning(f"obstacle ignored: {exc}", throttle_duration_sec=5.0)
        except Exception as exc:
            self.get_logger().error(f"obstacle {msg.data[:200]!r}: {exc!r}", throttle_duration_sec=5.0)

    def _pace(self, now: float) -> None:
        """Fit the step's planning budget and the planner's limit per leg to the clock
        (:func:`~fleet_planner.fleet.manager.paced_budgets`); the rate is measured between steps."""
        wall = time.monotonic()
        if self._paced is not None:
            d_ros, d_wall = now - self._paced[0], wall - self._paced[1]
            if d_ros > 0 and d_wall > 0:
                self._rate = 0.8 * self._rate + 0.2 * min(1000.0, d_ros / d_wall)
        self._paced = (now, wall)
        self.fleet.step_budget_s, leg_limit = paced_budgets(self.fleet.params.lead_s, self._rate, self._leg_limit)
        if leg_limit is not None:  # the planner's own limit per leg (md: detours, re-orderings)
            self.fleet.planner.leg_time_limit = leg_limit  # type: ignore

    def _heard(self) -> bool:
        """Whether the task events would reach the fleet's subscribers now: always, but for a planner
        that reloaded open jobs, not before its events publisher's matched subscribers stopped
        changing for EVENTS_SETTLE_S (at most EVENTS_SETTLE_MAX_S after it started)."""
        if self._settling is None:
            return True
        started, count, since = self._settling
        wall, now_count = time.monotonic(), self._events.get_subscription_count()
        if now_count != count:
            self._settling = (started, now_count, wall)
            since = wall
        if wall - started < EVENTS_SETTLE_MAX_S and (now_count == 0 or wall - since < EVENTS_SETTLE_S):
            return False
        self._settling = None
        self.get_logger().info(f"{now_count} subscribers of the task events matched: first step")
        return True

    def _on_timer(self) -> None:
        self._take_statuses()
        self._confirm_announced()
        if not self._heard():
            return
        now = self._now()
        self._pace(now)
        wall = time.monotonic()
        try:
            decisions = self.operator.step(now)  # the fleet's step, with the operator's part
        except Exception as exc:
            self.get_logger().error(f"planning step failed: {exc!r}\n{traceback.format_exc(limit=-8)}",
                                    throttle_duration_sec=5.0)
            return
        self._publish(decisions, now)
        # its legs reached the robots this late: the next ones start later (FleetManager.note_pace)
        self.fleet.note_pace(self._rate, time.monotonic() - wall)

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        names = {f.name for f in fields(DispatchParams)}
        changes = {p.name: p.value for p in params if p.name in names}
        if not changes:
            return SetParametersResult(successful=True)
        try:
            self.fleet.set_params(replace(self.fleet.params, **changes))
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    # -- output ---------------------------------------------------------------------------------------
    def _publish(self, d: Decisions, now: float) -> None:
        log = self.get_logger()
        if d.notes:  # one line per step (a log call costs far more than a note)
            more = len(d.notes) - MAX_NOTES_LOGGED
            log.info("\n".join(d.notes[:MAX_NOTES_LOGGED] + ([f"... and {more} more notes"] if more > 0 else [])))
        for gate in d.gates:  # before the legs: a robot waits for the record of its leg
            gate_pub = self._publisher(self._gates, topics.gate_topic, String, gate.robot_id)
            gate_pub.publish(record_to_string(self.keys.sign(gate, gate_pub.topic_name)))  # signed with keys
        for leg in d.legs:
            try:
                msg = timed_path_to_msg(leg.relative(), ns_to_stamp(leg.path_id), self.frame_id)
                path_pub, auth_pub = self._path_publisher(leg.robot_id)
                if auth_pub is not None:  # the signature first: the agent holds the path until it has both
                    auth = self.keys.path_auth(msg, leg.robot_id, auth_pub.topic_name)
                    if auth is not None:   # (there is an auth publisher only with a signing key)
                        auth_pub.publish(record_to_string(auth))
                path_pub.publish(msg)
            except ValueError as exc:
                log.error(f"robot {leg.robot_id}: timed path not sent: {exc}")
        self._publish_events(d.events)
        if d.legs:
            self._schedule.publish(record_to_string(self.fleet.schedule(now)))
        wall = time.monotonic()
        if not 0.0 <= wall - self._markers_at < self._markers_gap:
            self._markers_at = wall
            self._markers.publish(plan_markers(self.fleet.trajectories() + self.fleet.obstacles.trajectories(now),
                                               self.fleet.statuses(), self.frame_id, now))
            # paced by their cost too: 500 robots' markers take ~0.2 s, which every second was a fifth
            # of the planner's time and stretched the steps they fell into
            self._markers_gap = max(self._markers_period, (time.monotonic() - wall) / MARKERS_SHARE)

    def _publish_events(self, events: list[TaskEvent]) -> None:
        for ev in events:
            self._events.publish(record_to_string(self.keys.sign(ev, self._events.topic_name)))
        n = self.fleet.handed_out
        if n > self._sent_n:   # (a change committed: its events just went to the middleware)
            self._sent_n = n
            self._unconfirmed.append((time.monotonic(), n))
        self._confirm_announced()

    def _delivered(self) -> bool:
        """Every task event published so far was acknowledged by every matched subscriber (no wait)."""
        return self._events.wait_for_all_acked(_NO_WAIT)

    def _confirm_announced(self) -> None:
        """Note in the job store the task events that reached their subscribers (EVENTS_REPAIR_S): a
        planner killed from then on does not announce them again (FleetManager.announced)."""
        if not self._unconfirmed:
            return
        upto = 0
        if self._delivered():
            upto = self._unconfirmed[-1][1]
            self._unconfirmed.clear()
        else:
            old = time.monotonic() - EVENTS_REPAIR_S
            while self._unconfirmed and self._unconfirmed[0][0] <= old:
                upto = self._unconfirmed.popleft()[1]
        if not upto:
            return
        try:
            self.fleet.announced(upto)
        except sqlite3.Error as exc:
            self.get_logger().error(f"job store: cannot note the task events as announced ({exc}); "
                                    "a restart announces them again", throttle_duration_sec=5.0)

    def _publisher(self, table: dict[str, Publisher], topic: Any, kind: Any, robot_id: str) -> Publisher:
        if robot_id not in table:
            table[robot_id] = self.create_publisher(kind, topic(robot_id), topics.LATCHED_QOS,
                                                    event_callbacks=QUIET)
        return table[robot_id]

    def _path_publisher(self, robot_id: str) -> tuple[Publisher, Publisher | None]:
        """The publishers of a robot's timed paths and (with a signing key) of their signatures."""
        if robot_id not in self._paths:
            auth = None if self.keys.signer is None else self.create_publisher(
                String, topics.timed_path_auth_topic(robot_id), topics.TIMED_PATH_AUTH_QOS, event_callbacks=QUIET)
            self._paths[robot_id] = (self.create_publisher(Path, topics.timed_path_topic(robot_id),
                                                           topics.TIMED_PATH_QOS, event_callbacks=QUIET), auth)
        return self._paths[robot_id]


def main(args: list[str] | None = None) -> None:
    run_node(PlannerNode, args, prog="planner")


if __name__ == "__main__":
    main()
