"""``fleet-submit``: publish one job on ``/fleet/tasks`` and follow it until it ends.

    fleet-submit --pick chute_2 --place B12-04 --needs forklift [--id J1] [--timeout 60]

Prints each task event of the job as it comes (``J1 assigned to r3``) and exits 0 when it is done,
1 when it is rejected, fails or the timeout (wall seconds) runs out first. Events count only from
the planner node (``--planner``, default ``planner``): while another node publishes task events,
they are refused (``fleet_planner/ros/origin.py``), so a forged ``done`` never reads as success.
With keys (``fleet_planner/auth.py``): ``--key FILE`` signs the task with the file's first key,
``--trust FILE`` takes only events signed by one of that file's keys (then from any node).

DDS discovery is not symmetric: the planner's event writer may match our reader a moment after our
task writer matched its reader, and then its first answer (``accepted``) is lost. When nothing at
all is heard for ``RESEND_S`` after sending, the task is sent once more (signed anew): the planner
takes an id once for good and answers a copy of a known id with the job's current event (``accepted``,
``assigned``, ``picked``, ``done``, ``failed`` or ``cancelled``, its reason starting with
:data:`~fleet_planner.fleet.jobstore.RESENT`), which is followed on like any event (a job already
done or failed ends the run with that outcome).
"""
from __future__ import annotations

import argparse
import sys
import time
import uuid
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.subscription import Subscription
from std_msgs.msg import String

from fleet_planner.fleet.jobstore import RESENT
from fleet_planner.model import CAPABILITIES
from fleet_planner.ros.entry import run_node
from fleet_planner.ros.origin import OriginCheck
from fleet_planner.ros.signing import Keys
from msg_schemas import topics
from msg_schemas.convert import string_to_record
from msg_schemas.records import RecordError, Task, TaskEvent

ENDS = {"done": 0, "rejected": 1, "failed": 1, "cancelled": 1}
#: wall seconds without any event after sending before the task is sent once more
RESEND_S = 3.0


def planner_matched(node: Node, tasks_pub: Publisher, events_sub: Subscription) -> bool:
    """A node that takes tasks and publishes task events (the planner) is in the graph, and our task
    publisher and event subscription are matched with every endpoint on those topics: a task sent
    now reaches it, and its answer reaches us."""
    takers = {(i.node_namespace, i.node_name) for i in node.get_subscriptions_info_by_topic(topics.TASKS)}
    tellers = {(i.node_namespace, i.node_name) for i in node.get_publishers_info_by_topic(topics.TASK_EVENTS)}
    return bool(takers & tellers) and tasks_pub.get_subscription_count() >= len(takers) \
        and events_sub.get_publisher_count() >= len(tellers)


class Submitter(Node):
    """Publishes one task once the planner can hear it, and collects the task's events."""

    def __init__(self, task: Task, name: str = "fleet_submit", *, planner: str = "planner", keys: Keys | None = None,
                 **kwargs: Any):
        super().__init__(name, **kwargs)
        self.task = task
        self.keys = keys or Keys()
        self.events: list[TaskEvent] = []
        self.sent = 0
        #: the job's state (an event) as the planner told it answering a copy of a known id (None: not heard)
        self.already: str | None = None
        self._pub = self.create_publisher(String, topics.TASKS, topics.TASKS_QOS)
        self._sub = self.create_subscription(String, topics.TASK_EVENTS, self._on_event, topics.TASK_EVENTS_QOS)
        self.origin = OriginCheck(self, self._sub, planner)

    def planner_ready(self) -> bool:
        return planner_matched(self, self._pub, self._sub)

    def send(self) -> None:
        self._pub.publish(String(data=self.keys.sign(self.task, self._pub.topic_name).to_json()))
        self.sent += 1

    @property
    def ended(self) -> str | None:
        """How the job ended (an event in ENDS), None while it runs."""
        return next((e.event for e in self.events if e.event in ENDS), None)

    def _on_event(self, msg: String) -> None:
        try:
            ev = string_to_record(msg, TaskEvent)
        except RecordError:
            return
        if ev.task_id != self.task.id:
            return
        if self.keys.checks:
            problem = self.keys.problem(ev, self._sub.topic_name)
            if problem:
                self.get_logger().warning(f"task event {ev.event} ignored: task_event.auth: {problem}",
                                          throttle_duration_sec=2.0)
                return
        elif problem := self.origin.problem():
            self.get_logger().warning(f"task event {ev.event} ignored: not from the planner: {problem}",
                                      throttle_duration_sec=2.0)
            return
        if (ev.reason or "").startswith(RESENT):  # the job's state, answering a copy: the planner has it
            self.already = ev.event
            last = self.events[-1] if self.events else None
            if last is not None and (last.event, last.robot_id) == (ev.event, ev.robot_id):
                return  # what we heard already
        elif any((e.event, e.stamp) == (ev.event, ev.stamp) for e in self.events):
            return  # announced again by a restarted planner (at least once: the original stamp)
        self.events.append(ev)


def describe(ev: TaskEvent) -> str:
    text = f"{ev.task_id} {ev.event}"
    if ev.robot_id:
        text += f" {'to' if ev.event == 'assigned' else 'by'} {ev.robot_id}"
    if ev.reason:
        text += f": {ev.reason}"
    return f"[t={ev.stamp:.1f}] {text}"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fleet-submit", description=__doc__.split("\n\n")[0])
    p.add_argument("--pick", required=True, help="chute to pick at (station name)")
    p.add_argument("--place", required=True, help="address tag (or storing site) to place at")
    p.add_argument("--needs", action="append", choices=CAPABILITIES, default=[],
                   help="a capability the robot needs (repeat for several)")
    p.add_argument("--payload", type=float, default=0.0, help="kg (default 0)")
    p.add_argument("--priority", type=int, default=0, help="higher goes first (default 0)")
    p.add_argument("--deadline", type=float, help="when it should be done (s, the planner's ROS time); "
                   "earliest first among equal priorities, a 'late' event when it passes")
    p.add_argument("--id", help="task id (default: a fresh one)")
    p.add_argument("--timeout", type=float, default=60.0, help="wall seconds to wait for the end (default 60)")
    p.add_argument("--key", default="", metavar="FILE", help="key file: sign the task with its first key")
    p.add_argument("--trust", default="", metavar="FILE",
                   help="key file of the planner: take only events signed by one of its keys")
    p.add_argument("--planner", default="planner",
                   help="the planner's node name; events from other nodes are refused (default planner)")
    return p


def follow(node: Submitter, timeout: float) -> int:
    """Send the task once the planner hears us, print its events until it ends or ``timeout`` wall
    seconds pass; the exit status (``ENDS``, 1 when it did not end)."""
    task = node.task
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    deadline = time.monotonic() + timeout
    while not node.planner_ready() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)
    if not node.planner_ready():
        print(f"{task.id}: no planner on {node._pub.topic_name} within {timeout:g} s", file=sys.stderr)
        return 1
    node.send()
    resend_at = time.monotonic() + RESEND_S
    shown = 0
    while time.monotonic() < deadline and node.ended is None:
        executor.spin_once(timeout_sec=0.1)
        if node.sent == 1 and not node.events and time.monotonic() >= resend_at:
            print(f"{task.id}: no answer within {RESEND_S:g} s: sent once more", file=sys.stderr)
            node.send()
        for ev in node.events[shown:]:
            print(describe(ev), flush=True)
        shown = len(node.events)
    for ev in node.events[shown:]:
        print(describe(ev), flush=True)
    end = node.ended
    if node.already is not None:
        print(f"{task.id}: the planner has it ({node.already})", flush=True)
    if end is None:
        print(f"{task.id}: not finished within {timeout:g} s", file=sys.stderr)
        return 1
    return ENDS[end]


def main(args: list[str] | None = None) -> None:
    argv = sys.argv if args is None else args
    opts = _parser().parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    try:
        task = Task(id=opts.id or f"job_{uuid.uuid4().hex[:8]}", pick=opts.pick, place=opts.place,
                    needs=tuple(opts.needs), payload_kg=opts.payload, priority=opts.priority,
                    deadline=opts.deadline)
        keys = Keys(opts.key, opts.trust)
    except (RecordError, ValueError) as exc:
        _parser().error(str(exc))
    # interrupted: 1 (not done); a bad --ros-args shows its traceback, as before
    run_node(lambda: Submitter(task, planner=opts.planner, keys=keys), argv, prog="fleet-submit",
             spin=lambda node: follow(node, opts.timeout), errors=(), interrupted=1)


if __name__ == "__main__":
    main()
