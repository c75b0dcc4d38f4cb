"""``fleet-submit`` when the planner's first answer is lost (DDS discovery is not symmetric: the
planner's event writer can match our reader a moment after our task writer matched its reader):
with nothing heard for a while it sends the task once more, takes the planner's answer to that copy
(the job's current event, its reason starting with RESENT) as "it has the job" and follows the job to
its end. A fake
planner that never answers the first copy stands in for the lost ``accepted``."""
import threading

import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String

from fleet_planner.fleet.jobstore import RESENT
from fleet_planner.ros import submit
from fleet_planner.ros.submit import Submitter, follow
from msg_schemas import topics
from msg_schemas.records import Task, TaskEvent


class FakePlanner:
    """Takes tasks; the first copy of an id goes unanswered, a later one gets the planner's answer
    to a known id (the event ``state``, reason RESENT), then (with ``then``) that event."""

    def __init__(self, context, state: str, then: str | None):
        self.node = rclpy.create_node("fake_planner", context=context)
        self.state, self.then = state, then
        self.copies: dict[str, int] = {}
        self._events = self.node.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
        self.node.create_subscription(String, topics.TASKS, self._on_task, topics.TASKS_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)

    def _spin(self):
        while not self._stop.is_set():
            self.executor.spin_once(timeout_sec=0.05)

    def _on_task(self, msg):
        task = Task.from_json(msg.data)
        n = self.copies[task.id] = self.copies.get(task.id, 0) + 1
        if n == 1:
            return  # its "accepted" is lost
        reason = RESENT + ("; the robot broke down" if self.state == "failed" else "")
        self._events.publish(String(data=TaskEvent(task_id=task.id, event=self.state, stamp=1.0,
                                                   robot_id=None if self.state == "accepted" else "r1",
                                                   reason=reason).to_json()))
        if self.then is not None:
            self._events.publish(String(data=TaskEvent(task_id=task.id, event=self.then, stamp=2.0,
                                                       robot_id="r1").to_json()))

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.executor.shutdown()
        self.node.destroy_node()


def run(ros_context, task_id, state, then, monkeypatch):
    monkeypatch.setattr(submit, "RESEND_S", 1.0)
    node = Submitter(Task(id=task_id, pick="chute_1", place="B01-01"), "resend_submit", planner="fake_planner",
                     context=ros_context)
    try:
        with FakePlanner(ros_context, state, then) as fake:
            code = follow(node, timeout=20.0)
        return code, node, fake
    finally:
        node.destroy_node()


def test_a_lost_first_answer_makes_fleet_submit_send_once_more_and_follow_the_job(ros_context, monkeypatch):
    code, node, fake = run(ros_context, "RS1", "assigned", "done", monkeypatch)
    assert fake.copies == {"RS1": 2} and node.sent == 2
    assert node.already == "assigned" and [e.event for e in node.events] == ["assigned", "done"]
    assert code == 0  # the answer to its own second copy is the job's state, not a rejection


def test_a_job_the_planner_already_finished_ends_the_run_with_that_outcome(ros_context, monkeypatch):
    code, node, fake = run(ros_context, "RS2", "failed", None, monkeypatch)
    assert node.sent == 2 and node.already == "failed" and code == 1
    assert "the robot broke down" in node.events[-1].reason
    code, node, fake = run(ros_context, "RS3", "done", None, monkeypatch)
    assert node.already == "done" and code == 0
