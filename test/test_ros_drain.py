"""Draining subscriptions (fleet_planner/ros/drain.py): when the executor wakes a subscription, every
message waiting on it is handled, in order and up to a bound, on any rclpy executor. This is what
keeps the planner's statuses fresh before each step; if an rclpy upgrade breaks the way messages
are taken, these tests fail."""
import time

import pytest
import rclpy
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from fleet_planner.ros.drain import DRAIN_LIMIT, create_draining_subscription, drain_limit
from msg_schemas import topics

WAIT = 30.0  # wall seconds any one wait may take
QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2 * DRAIN_LIMIT, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def nodes(ros_context):
    sender = rclpy.create_node("drain_sender", context=ros_context)
    receiver = rclpy.create_node("drain_receiver", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(receiver)
    try:
        yield sender, receiver, executor
    finally:
        executor.shutdown()
        receiver.destroy_node()
        sender.destroy_node()


def queue_up(nodes, topic: str, count: int, received: list[str]) -> None:
    """A draining subscription on the receiver with ``count`` messages waiting on it, none taken yet."""
    sender, receiver, executor = nodes
    create_draining_subscription(receiver, String, topic, lambda m: received.append(m.data), QOS)
    pub = sender.create_publisher(String, topic, QOS)
    deadline = time.monotonic() + WAIT
    while not (pub.get_subscription_count() == 1 and receiver.count_publishers(topic) == 1) \
            and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.01)  # nothing published yet: nothing to take
    assert pub.get_subscription_count() == 1
    for i in range(count):
        pub.publish(String(data=str(i)))
    assert pub.wait_for_all_acked(Duration(seconds=WAIT))  # all of them in the receiver's queue


def spin_until_some(executor, received: list[str]) -> None:
    """Spin until the subscription's callback ran once more (one executor wake-up)."""
    deadline = time.monotonic() + WAIT
    before = len(received)
    while len(received) == before and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.1)


def test_one_wake_up_handles_every_waiting_message_in_order(nodes):
    executor = nodes[2]
    received: list[str] = []
    queue_up(nodes, "/test_drain/all", 50, received)
    spin_until_some(executor, received)
    assert received == [str(i) for i in range(50)]  # one executor callback, all 50


def test_a_flood_is_handled_in_bounded_batches(nodes):
    executor = nodes[2]
    received: list[str] = []
    queue_up(nodes, "/test_drain/flood", DRAIN_LIMIT + 500, received)
    spin_until_some(executor, received)
    assert len(received) == DRAIN_LIMIT  # the node's other callbacks get their turn
    spin_until_some(executor, received)
    assert received == [str(i) for i in range(DRAIN_LIMIT + 500)]


def test_a_wake_up_takes_at_most_what_the_queue_can_hold():
    # the old DrainingExecutor took what was waiting when it woke: never more than the depth
    assert drain_limit(topics.ROBOT_STATUS_QOS) == 1000  # a whole fleet-sim burst
    assert drain_limit(topics.TASKS_QOS) == DRAIN_LIMIT == 1000
    assert drain_limit(topics.TIMED_PATH_QOS) == 1
    assert drain_limit(QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=0)) == DRAIN_LIMIT
    assert drain_limit(QOS) == DRAIN_LIMIT


def test_the_limit_must_be_positive(nodes):
    _, receiver, _ = nodes
    with pytest.raises(ValueError, match="limit"):
        create_draining_subscription(receiver, String, "/test_drain/none", print, QOS, limit=0)
