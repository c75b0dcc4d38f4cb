"""The console's ROS end: :class:`ConsoleNode` hears the fleet (statuses, timed paths, tasks and
their events, the operator's state, obstacles), keeps a view of it for the page
(:meth:`ConsoleNode.snapshot`) and carries out what the page asks (:meth:`ConsoleNode.request`,
thread-safe: the web server runs in a thread of its own) through the operator's interfaces
(:class:`~fleet_planner.ros.operate.OperatorClient`: SetBool services, the command topic, Twist).

Everything the page sends is checked here field by field (the records' checks); a bad request is
answered with the reason naming the field, never an exception.
"""
from __future__ import annotations

import concurrent.futures
import functools
import math
import queue
import threading
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from nav_msgs.msg import Path
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.parameter import Parameter
from rclpy.task import Future
from std_msgs.msg import String

from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.operate import OperatorClient
from fleet_planner.warehouse import Warehouse, load_warehouse
from msg_schemas import topics
from msg_schemas.convert import msg_to_timed_path, stamp_to_ns, string_to_record
from msg_schemas.records import (
    MAX_NAME_CHARS,
    Command,
    OperatorState,
    RecordError,
    RobotStatus,
    Task,
    TaskEvent,
    load_json,
    robot_id_problem,
)

#: wall seconds the console waits for an answer from the fleet
ANSWER_S = 10.0
#: an obstacle not heard of for this long (s, ROS time) is no longer drawn (unless persistent)
OBSTACLE_EXPIRES_S = 5.0
#: at most this many robots on the map (a flood of made-up ids must not grow the console without bound)
MAX_ROBOTS = 1000
#: at most this many jobs in the table (the oldest finished ones go first)
MAX_JOBS = 500
#: the events after which a job is over
FINISHED = ("done", "failed", "rejected", "cancelled")
#: what the page may ask
REQUESTS = ("command", "manual", "drive", "submit")
_SERVICE_COMMANDS = {"pause", "resume", "estop", "release"}
#: the intelligent space's obstacles (fleet/obstacle@1; named in msg_schemas.topics where that branch has landed)
OBSTACLES_TOPIC = topics.OBSTACLES
OBSTACLES_QOS = getattr(topics, "OBSTACLES_QOS", topics.COMMANDS_QOS)


class BadRequest(ValueError):
    """A page request that cannot be carried out; the message starts with the field."""


@dataclass
class _Pending:
    future: concurrent.futures.Future
    deadline: float
    service: Future | None = None
    command_id: str | None = None
    task_id: str | None = None


def _round(value: float) -> float:
    return round(float(value), 3)


class ConsoleNode(OperatorClient):
    """The fleet as the console sees it, and its hand on the fleet."""

    def __init__(self, name: str = "fleet_console", *, warehouse: Warehouse | None = None,
                 parking: Sequence[tuple[float, float]] | None = None, **kwargs: Any):
        super().__init__(name, **kwargs)
        wh_file = self.declare_parameter("warehouse_file", "", ParameterDescriptor(
            description="warehouse YAML (empty: the shipped config/warehouse.yaml)", read_only=True)).value
        spots = self.declare_parameter("parking", Parameter.Type.DOUBLE_ARRAY, ParameterDescriptor(
            description="the planner's parking spots, flattened: [x1, y1, x2, y2, ...] (m)", read_only=True)).value
        self.host = self.declare_parameter("host", "127.0.0.1", ParameterDescriptor(
            description="address the page is served on (localhost only by default)", read_only=True)).value
        self.port = self.declare_parameter("port", 8080, ParameterDescriptor(
            description="TCP port of the page (0: any free one)", read_only=True)).value
        self.rate_hz = self.declare_parameter("rate_hz", 4.0, ParameterDescriptor(
            description="state pushes per second to each open page", read_only=True)).value
        if parking is None:
            flat = list(spots or [])
            if len(flat) % 2:
                raise ValueError(f"parking: needs x, y pairs (got {len(flat)} numbers)")
            parking = [(flat[i], flat[i + 1]) for i in range(0, len(flat), 2)]
        self.warehouse = warehouse if warehouse is not None else load_warehouse(wh_file or None)
        self.parking = {f"parking_{i + 1}": (float(x), float(y)) for i, (x, y) in enumerate(parking)}
        self._lock = threading.Lock()
        self._requests: queue.Queue[tuple[dict[str, Any], concurrent.futures.Future]] = queue.Queue(maxsize=1000)
        self._pending: list[_Pending] = []
        self.status: dict[str, RobotStatus] = {}
        self.paths: dict[str, tuple[list[tuple[float, float, float]], float]] = {}  # id -> (waypoints, t0)
        self.tasks: dict[str, Task] = {}
        self.jobs: dict[str, dict[str, Any]] = {}
        self.operator = OperatorState(stamp=0.0, estop=False, fleet_paused=False)
        self.obstacles: dict[str, dict[str, Any]] = {}
        self.task_events: dict[str, TaskEvent] = {}
        self._submitted: set[str] = set()            # jobs the page submitted, not yet answered
        self._verdicts: dict[str, TaskEvent] = {}    # their accepted / rejected events
        self._tasks_pub = self.create_publisher(String, topics.TASKS, topics.TASKS_QOS)
        sub = create_draining_subscription
        sub(self, String, topics.ROBOT_STATUS, self._on_status, topics.ROBOT_STATUS_QOS)
        sub(self, String, topics.TASKS, self._on_task, topics.TASKS_QOS)
        sub(self, String, topics.TASK_EVENTS, self._on_event, topics.TASK_EVENTS_QOS)
        sub(self, String, OBSTACLES_TOPIC, self._on_obstacle, OBSTACLES_QOS)
        self.create_subscription(String, topics.OPERATOR_STATE, self._on_operator_state, topics.OPERATOR_STATE_QOS)
        # page requests are served on the wall clock: a paused or slow simulated clock must not stall them
        self._timer = self.create_timer(0.05, self._serve, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def now(self) -> float:
        return self.get_clock().now().nanoseconds / 1e9

    # -- what the fleet says ----------------------------------------------------------------------
    def _on_status(self, msg: String) -> None:
        try:
            st = string_to_record(msg, RobotStatus)
        except RecordError as exc:
            self.get_logger().warning(f"robot status ignored: {exc}", throttle_duration_sec=5.0)
            return
        with self._lock:
            new = st.id not in self.status
            if new and len(self.status) >= MAX_ROBOTS:
                self.get_logger().warning(f"robot {st.id}: more than {MAX_ROBOTS} robots; not shown",
                                          throttle_duration_sec=5.0)
                return
            self.status[st.id] = st
        if new:  # its legs, latched: the current one comes at once
            self.create_subscription(Path, topics.timed_path_topic(st.id), functools.partial(self._on_path, st.id),
                                     topics.TIMED_PATH_QOS)

    def _on_path(self, rid: str, msg: Path) -> None:
        try:
            path, t0 = msg_to_timed_path(msg, rid, self.status[rid].radius)
        except (RecordError, ValueError, KeyError) as exc:
            self.get_logger().warning(f"timed path of {rid} ignored: {exc}", throttle_duration_sec=5.0)
            return
        with self._lock:
            self.paths[rid] = ([(float(x), float(y), float(t)) for x, y, t in path.waypoints], stamp_to_ns(t0) / 1e9)

    def _on_task(self, msg: String) -> None:
        try:
            task = string_to_record(msg, Task)
        except RecordError:
            return  # the planner answers bad tasks
        with self._lock:
            self.tasks.setdefault(task.id, task)

    def _on_event(self, msg: String) -> None:
        try:
            ev = string_to_record(msg, TaskEvent)
        except RecordError as exc:
            self.get_logger().warning(f"task event ignored: {exc}", throttle_duration_sec=5.0)
            return
        with self._lock:
            self.task_events[ev.task_id] = ev
            if ev.event in ("accepted", "rejected") and ev.task_id in self._submitted:
                self._verdicts[ev.task_id] = ev  # the answer to a job the page submitted
            job = self.jobs.setdefault(ev.task_id, {"id": ev.task_id, "robot": None, "late": False})
            if ev.event == "late":
                job["late"] = True
            else:
                job["state"] = ev.event
            if ev.robot_id and ev.event in ("assigned", "picked", "placed", "done"):
                job["robot"] = ev.robot_id
            job["reason"] = ev.reason or job.get("reason")
            job["stamp"] = ev.stamp
            while len(self.jobs) > MAX_JOBS:
                old = next((k for k, j in self.jobs.items() if j.get("state") in FINISHED), next(iter(self.jobs)))
                self.jobs.pop(old)
                self.tasks.pop(old, None)

    def _on_operator_state(self, msg: String) -> None:
        try:
            state = string_to_record(msg, OperatorState)
        except RecordError as exc:
            self.get_logger().warning(f"operator state ignored: {exc}", throttle_duration_sec=5.0)
            return
        with self._lock:
            self.operator = state

    def _on_obstacle(self, msg: String) -> None:
        """An obstacle of the intelligent space (``fleet/obstacle@1``), read for drawing only: id,
        kind, position, radius, and whether it is cleared or persistent."""
        try:
            data = load_json(msg.data, "obstacle")
            if not isinstance(data, dict) or not isinstance(data.get("id"), str) or len(data["id"]) > MAX_NAME_CHARS:
                raise RecordError("obstacle.id: must be a non-empty string")
            x, y, r = (data.get(k, math.nan) for k in ("x", "y", "radius"))   # (missing: not finite)
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in (x, y, r)):
                raise RecordError("obstacle.x: x, y and radius must be finite numbers")
        except RecordError as exc:
            self.get_logger().warning(f"obstacle ignored: {exc}", throttle_duration_sec=5.0)
            return
        with self._lock:
            if data.get("cleared") is True:
                self.obstacles.pop(data["id"], None)
                return
            self.obstacles[data["id"]] = {"id": data["id"], "kind": str(data.get("kind", "?"))[:32],
                                          "x": _round(x), "y": _round(y), "radius": _round(r),
                                          "persistent": data.get("persistent") is True, "seen": self.now()}
            while len(self.obstacles) > 1000:
                self.obstacles.pop(next(iter(self.obstacles)))

    # -- the view for the page --------------------------------------------------------------------
    def layout(self) -> dict[str, Any]:
        """What does not change: the map (blocked cells as runs per row), the stations, the parking spots."""
        grid = self.warehouse.grid
        runs = []
        for row in range(grid.height):
            line = grid.blocked[row]
            col = 0
            while col < grid.width:
                if line[col]:
                    start = col
                    while col < grid.width and line[col]:
                        col += 1
                    runs.append([start, row, col - start])
                else:
                    col += 1
        return {"type": "layout", "name": self.warehouse.name, "resolution": grid.resolution,
                "width": grid.width, "height": grid.height, "blocked": runs,
                "stations": [{"name": s.name, "type": s.type, "x": s.x, "y": s.y, "tags": list(s.tags)}
                             for s in self.warehouse.stations.values()],
                "parking": [{"name": k, "x": v[0], "y": v[1]} for k, v in self.parking.items()]}

    def snapshot(self) -> dict[str, Any]:
        """The fleet now, for the page (thread-safe)."""
        now = self.now()
        with self._lock:
            op = self.operator
            robots = []
            for rid in sorted(self.status):
                st = self.status[rid]
                path, holds = self._path_ahead(rid, now)
                robots.append({"id": rid, "kind": st.kind, "x": _round(st.x), "y": _round(st.y), "yaw": _round(st.yaw),
                               "radius": st.radius, "mode": st.mode, "battery": round(st.battery, 3),
                               "job": st.task_id, "manual": bool(st.manual), "estop": bool(st.estop),
                               "paused": rid in op.paused or op.fleet_paused, "stale": now - st.stamp > 3.0,
                               "path": path, "holds": holds})
            jobs = []
            for jid, job in self.jobs.items():
                task = self.tasks.get(jid)
                jobs.append({**job, "pick": task.pick if task else None, "place": task.place if task else None,
                             "priority": task.priority if task else None,
                             "deadline": task.deadline if task else None})
            for oid in [k for k, o in self.obstacles.items() if not o["persistent"]
                        and now - o["seen"] > OBSTACLE_EXPIRES_S]:
                self.obstacles.pop(oid)
            obstacles = [{k: v for k, v in o.items() if k != "seen"} for o in self.obstacles.values()]
            return {"type": "state", "t": round(now, 2), "estop": op.estop, "fleet_paused": op.fleet_paused,
                    "robots": robots, "jobs": jobs, "obstacles": obstacles}

    def _path_ahead(self, rid: str, now: float) -> tuple[list[list[float]], list[list[float]]]:
        """The rest of ``rid``'s leg from where it is, and the places on it where it holds."""
        if rid not in self.paths:
            return [], []
        wp, t0 = self.paths[rid]
        st = self.status[rid]
        if st.manual or st.path_id is not None and round(t0 * 1e9) != st.path_id and now > t0 + 1.0:
            return [], []  # a leg it no longer drives
        ahead = [[_round(x), _round(y)] for x, y, t in wp if t0 + t > now]
        holds = [[_round(a[0]), _round(a[1])] for a, b in zip(wp, wp[1:]) if a[:2] == b[:2] and t0 + b[2] > now]
        if len(wp) == 1:
            holds = [[_round(wp[0][0]), _round(wp[0][1])]]
        return [[_round(st.x), _round(st.y)], *ahead], holds

    # -- what the page asks -----------------------------------------------------------------------
    def request(self, data: Any) -> concurrent.futures.Future:
        """Queue a page request (any thread); the future gives ``{"ok": bool, "message": str}``."""
        fut: concurrent.futures.Future = concurrent.futures.Future()
        try:
            self._requests.put_nowait((data, fut))
        except queue.Full:
            fut.set_result({"ok": False, "message": "the console is busy; try again"})
        return fut

    def _serve(self) -> None:
        """Take queued page requests and settle the answered ones (in the executor's thread)."""
        try:
            while True:
                data, fut = self._requests.get_nowait()
                try:
                    self._start(data, fut)
                except (BadRequest, RecordError, ValueError) as exc:
                    fut.set_result({"ok": False, "message": str(exc)})
                except Exception as exc:  # a bug must not stop the console
                    self.get_logger().error(f"console request {str(data)[:200]!r}: {exc!r}")
                    fut.set_result({"ok": False, "message": f"internal error: {exc}"})
        except queue.Empty:
            pass
        still = []
        for p in self._pending:
            answer = self._answer(p)
            if answer is None and time.monotonic() > p.deadline:
                answer = {"ok": False, "message": "no answer from the fleet in time"}
                with self._lock:
                    self._submitted.discard(p.task_id or "")
                    self._verdicts.pop(p.task_id or "", None)
            if answer is None:
                still.append(p)
            elif not p.future.done():
                p.future.set_result(answer)
        self._pending = still

    def _answer(self, p: _Pending) -> dict[str, Any] | None:
        if p.service is not None:
            if not p.service.done():
                return None
            res = p.service.result()
            return {"ok": bool(res.success), "message": str(res.message)} if res is not None else \
                {"ok": False, "message": "the service call failed"}
        if p.command_id is not None:
            reply = self.replies.get(p.command_id)
            return None if reply is None else {"ok": reply.ok, "message": reply.message}
        if p.task_id is not None:
            with self._lock:
                ev = self._verdicts.pop(p.task_id, None)
                if ev is not None:
                    self._submitted.discard(p.task_id)
            if ev is None:
                return None
            return {"ok": ev.event == "accepted",
                    "message": f"job {p.task_id} {ev.event}" + (f": {ev.reason}" if ev.reason else "")}
        return {"ok": True, "message": "sent"}

    def _start(self, data: Any, fut: concurrent.futures.Future) -> None:
        if not isinstance(data, dict):
            raise BadRequest("request: must be a JSON object")
        kind = data.get("type")
        if kind not in REQUESTS:
            raise BadRequest(f"type: must be one of {', '.join(REQUESTS)} (got {str(kind)[:40]!r})")
        pending = _Pending(fut, time.monotonic() + ANSWER_S)
        if kind == "command":
            fields = data.get("command")
            if not isinstance(fields, dict):
                raise BadRequest("command: must be a JSON object")
            cmd = Command.from_dict({**fields, "schema": Command.SCHEMA, "id": f"console_{uuid.uuid4().hex[:10]}"})
            assert isinstance(cmd, Command)
            if cmd.command in _SERVICE_COMMANDS and cmd.robot_id is None:  # the standard services
                pending.service = self._set_bool(_service_of(cmd), cmd.command in ("pause", "estop"))
            else:
                if not self.commands_heard():
                    raise BadRequest("command: no planner hears commands now")
                self.send_command(cmd)
                pending.command_id = cmd.id
        elif kind == "manual":
            rid, on = _robot_id(data.get("robot_id")), data.get("on")
            if not isinstance(on, bool):
                raise BadRequest(f"on: must be true or false (got {str(on)[:40]!r})")
            pending.service = self._set_bool(topics.robot_topic(rid, "manual"), on)
        elif kind == "drive":
            rid = _robot_id(data.get("robot_id"))
            speeds = []
            for name in ("linear", "angular"):
                value = data.get(name)
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                    raise BadRequest(f"{name}: must be a finite number (got {str(value)[:40]!r})")
                speeds.append(float(value))
            self.drive(rid, speeds[0], speeds[1])   # the agent checks the limits
        else:
            fields = data.get("task")
            if not isinstance(fields, dict):
                raise BadRequest("task: must be a JSON object")
            fields = {k: v for k, v in fields.items() if v not in (None, "")}
            fields.setdefault("id", f"web_{uuid.uuid4().hex[:8]}")
            task = Task.from_dict({**fields, "schema": Task.SCHEMA})
            assert isinstance(task, Task)
            if self._tasks_pub.get_subscription_count() == 0:
                raise BadRequest("task: no planner takes tasks now")
            with self._lock:
                self.tasks.setdefault(task.id, task)
                if len(self._submitted) >= MAX_JOBS:
                    raise BadRequest("task: too many jobs waiting for the planner's answer")
                self._submitted.add(task.id)
            self._tasks_pub.publish(String(data=task.to_json()))
            pending.task_id = task.id
        self._pending.append(pending)

    def _set_bool(self, service: str, value: bool) -> Future:
        future = self.call_set_bool(service, value)
        if future is None:
            raise BadRequest(f"{service}: no such service now (is the planner or robot up?)")
        return future


def _robot_id(value: Any) -> str:
    problem = robot_id_problem(value) if isinstance(value, str) else "must be a string"
    if problem:
        raise BadRequest(f"robot_id: {problem}")
    return value


def _service_of(cmd: Command) -> str:
    if cmd.command in ("estop", "release"):
        return topics.ESTOP_SERVICE
    return topics.PAUSE_FLEET_SERVICE  # (one robot is paused by a command: operator_services.py)
