"""Watching the fleet: :class:`FleetMonitor`, the demo's (and the system tests') eyes and hands on the
topics, and :func:`spin_until`, a bounded wait on an executor."""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from rclpy.executors import Executor
from rclpy.node import Node
from std_msgs.msg import String

from fleet_planner.checker import min_separation
from fleet_planner.fleet import samples_to_path
from fleet_planner.fleet.obstacles import closest_approach
from fleet_planner.model import TimedPath
from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.submit import planner_matched
from msg_schemas import topics
from msg_schemas.convert import string_to_record
from msg_schemas.records import ObstacleRecord, RecordError, RobotStatus, Task, TaskEvent

#: a robot this far (s) behind its schedule counts as held back (by its gate or its safety net)
LATE_S = 0.5


class FleetMonitor(Node):
    """Submits tasks and records what the fleet reports: every task event, and every robot's
    positions (x, y, stamp) from its status messages."""

    def __init__(self, name: str = "fleet_monitor", **kwargs: Any):
        super().__init__(name, **kwargs)
        self.events: list[TaskEvent] = []
        self.last_event: dict[str, TaskEvent] = {}
        self._heard_events: set[tuple[str, str, float]] = set()   # (task, event, stamp): one copy of a replay
        #: per robot, its reported positions (x, y, stamp); of a stay at one spot only its first and last
        self.tracks: dict[str, list[tuple[float, float, float]]] = {}
        self.radius: dict[str, float] = {}
        self.status: dict[str, RobotStatus] = {}
        #: per robot, its status whenever the mode, lateness (late or not), job or load changed:
        #: (stamp, mode, late, task_id, loaded, kind) - what :mod:`.timeuse` reads
        self.modes: dict[str, list[tuple[float, str, bool, str | None, bool, str]]] = {}
        self._tasks = self.create_publisher(String, topics.TASKS, topics.TASKS_QOS)
        # every waiting message at each wake-up, as the planner and the agents (see drain.py)
        self._events = create_draining_subscription(self, String, topics.TASK_EVENTS, self._on_event,
                                                    topics.TASK_EVENTS_QOS)
        create_draining_subscription(self, String, topics.ROBOT_STATUS, self._on_status, topics.ROBOT_STATUS_QOS)
        # the obstacles the intelligent space reports (people...): positions (x, y, stamp) by id
        self.obstacle_tracks: dict[str, list[tuple[float, float, float]]] = {}
        self.obstacle_radius: dict[str, float] = {}
        create_draining_subscription(self, String, topics.OBSTACLES, self._on_obstacle, topics.OBSTACLES_QOS)

    def now(self) -> float:
        return self.get_clock().now().nanoseconds / 1e9

    def latest_stamp(self) -> float:
        """The newest status stamp heard (simulated s; 0 before any), readable after ROS shut down."""
        return max((st.stamp for st in self.status.values()), default=0.0)

    def submit(self, task: Task | str) -> None:
        self._tasks.publish(String(data=task if isinstance(task, str) else task.to_json()))

    def planner_ready(self) -> bool:
        return planner_matched(self, self._tasks, self._events)

    def _on_event(self, msg: String) -> None:
        try:
            ev = string_to_record(msg, TaskEvent)
        except RecordError as exc:
            self.get_logger().warning(f"task event ignored: {exc}")
            return
        key = (ev.task_id, ev.event, ev.stamp)
        if key in self._heard_events:  # a restarted planner announcing again what may have gone out (at least once)
            return
        self._heard_events.add(key)
        self.events.append(ev)
        self.last_event[ev.task_id] = ev

    def _on_status(self, msg: String) -> None:
        try:
            st = string_to_record(msg, RobotStatus)
        except RecordError as exc:
            self.get_logger().warning(f"robot status ignored: {exc}", throttle_duration_sec=5.0)
            return
        self.status[st.id] = st
        self.radius[st.id] = st.radius
        track = self.tracks.setdefault(st.id, [])
        if len(track) >= 2 and track[-1][0] == track[-2][0] == st.x and track[-1][1] == track[-2][1] == st.y:
            # standing still: the stay is its first and its latest report (the same timed path, exactly;
            # a fleet mostly waiting would otherwise make the closest-approach sweep of the summary
            # quadratic in the reports at one spot)
            track[-1] = (st.x, st.y, st.stamp)
        else:
            track.append((st.x, st.y, st.stamp))
        entry = (st.stamp, st.mode, st.lateness_s > LATE_S, st.task_id, bool(st.loaded), st.kind)
        log = self.modes.setdefault(st.id, [])
        if not log or log[-1][1:] != entry[1:]:
            log.append(entry)

    def _on_obstacle(self, msg: String) -> None:
        try:
            ob = string_to_record(msg, ObstacleRecord)
        except RecordError as exc:
            self.get_logger().warning(f"obstacle ignored: {exc}", throttle_duration_sec=5.0)
            return
        if not ob.cleared:
            self.obstacle_radius[ob.id] = ob.radius
            self.obstacle_tracks.setdefault(ob.id, []).append((ob.x, ob.y, ob.stamp))

    def obstacle_trajectories(self) -> list[TimedPath]:
        """Each obstacle's reported positions as a timed path (straight between records)."""
        return [samples_to_path(oid, self.obstacle_radius[oid], track) for oid, track in self.obstacle_tracks.items()]

    def obstacle_separation(self) -> tuple[float, str | None, str | None, float | None]:
        """Smallest distance minus the sum of radii between a robot and an obstacle, over every
        reported time (each obstacle counted only while it was reported)."""
        return closest_approach(self.trajectories(), self.obstacle_trajectories())

    def events_of(self, task_id: str) -> list[TaskEvent]:
        return [e for e in self.events if e.task_id == task_id]

    def trajectories(self) -> list[TimedPath]:
        """Each robot's reported positions as a timed path (straight between reports)."""
        return [samples_to_path(rid, self.radius[rid], track) for rid, track in self.tracks.items()]

    def min_separation(self) -> tuple[float, str | None, str | None, float | None]:
        """Smallest distance minus the sum of radii over all pairs and all reported times."""
        return min_separation(self.trajectories())


def spin_until(executor: Executor, condition: Callable[[], bool], timeout: float, step: float = 0.05) -> bool:
    """Spin ``executor`` until ``condition()`` holds or ``timeout`` wall seconds pass; returns it."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=step)
    return True
