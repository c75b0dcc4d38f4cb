"""Every fleet topic name and its QoS profile, in one place (docs/ARCHITECTURE.md, "Topics and QoS").

Nodes create publishers and subscriptions with the pair from here, e.g.
``node.create_subscription(String, TASKS, cb, TASKS_QOS)``, so both ends always match.

QoS choices:

* Commands and events (``TASKS``, ``TASK_EVENTS``): reliable, volatile, deep queue (1000) so a
  burst of tasks is not dropped. Volatile on purpose: a restarted planner must not receive old
  tasks again as if they were new.
* ``ROBOT_STATUS``: best effort, depth 1000 (a fleet-sim process publishes its whole fleet at once,
  and a queue shorter than that burst drops the same robots' statuses every time: bench_load
  showed 90 false offline events at 200 robots with depth 100). Each robot repeats its status at
  10 Hz and each message
  supersedes the last, so a lost one costs nothing, and a slow planner never holds the agents
  back. A best-effort subscription also matches reliable publishers (``ros2 topic pub`` defaults).
  Tests must wait for a status that satisfies a condition, not count messages. Every subscriber
  takes all waiting statuses at each wake-up (``fleet_planner/ros/drain.py``).
* ``/robots/<id>/neighbours``: best effort, depth 10, as the statuses it relays: each record
  supersedes the last, a few times a second.
* ``WAIT_MESSAGES`` (behaviour coordination): reliable, volatile, depth 100. A waiting robot
  repeats its message every couple of seconds, but a wait cycle is only found when a message
  gets all the way round it, so none should be lost on the way.
* Latched state (``/robots/<id>/timed_path``, ``SCHEDULE``, ``MARKERS``, ``MAP``): reliable,
  transient local, depth 1: a late subscriber gets the current value at once.
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .records import robot_id_problem

TASKS = "/fleet/tasks"
TASK_EVENTS = "/fleet/task_events"
ROBOT_STATUS = "/fleet/robot_status"
SCHEDULE = "/fleet/schedule"
MARKERS = "/fleet/markers"
MAP = "/map"
WAIT_MESSAGES = "/fleet/wait_messages"


def timed_path_topic(robot_id: str) -> str:
    """``/robots/<robot_id>/timed_path``; ValueError if the id cannot be part of a topic name."""
    problem = robot_id_problem(robot_id)
    if problem:
        raise ValueError(f"robot id {problem}")
    return f"/robots/{robot_id}/timed_path"


def neighbours_topic(robot_id: str) -> str:
    """``/robots/<robot_id>/neighbours`` (the planner's relay of the statuses a robot must hear);
    ValueError if the id cannot be part of a topic name."""
    problem = robot_id_problem(robot_id)
    if problem:
        raise ValueError(f"robot id {problem}")
    return f"/robots/{robot_id}/neighbours"


def _qos(depth: int, reliable: bool = True, latched: bool = False) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


TASKS_QOS = _qos(1000)
TASK_EVENTS_QOS = _qos(1000)
ROBOT_STATUS_QOS = _qos(1000, reliable=False)
LATCHED_QOS = _qos(1, latched=True)
TIMED_PATH_QOS = LATCHED_QOS
SCHEDULE_QOS = LATCHED_QOS
MARKERS_QOS = LATCHED_QOS
MAP_QOS = LATCHED_QOS
WAIT_MESSAGES_QOS = _qos(100)
NEIGHBOURS_QOS = _qos(10, reliable=False)
