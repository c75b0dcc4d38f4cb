"""Subscriptions that take every waiting message at once: how the fleet's nodes keep up with the status stream.

Each robot publishes its status 10 times a (simulated) second and the planner, every agent and the
monitor hear all of them. rclpy's executors take one message per ready subscription per wait
cycle, and a cycle over a whole in-process fleet (a dozen nodes, one executor) costs far more than
handling a message: taking one per cycle, a node falls behind the stream, its best-effort queue
(depth 100) overflows and what it takes is up to 100 messages old. (The demo run that way planned
legs from where robots had been, which the agents refused, "timed path starts 0.900 m from the
robot", did 2 of its 20 jobs in 600 s and let two robots' discs overlap.)
``bench/bench_status_ingest.py`` measures the rate; docs/ARCHITECTURE.md, "Measured facts", has
the figures.

:func:`create_draining_subscription` makes the subscription itself drain its queue: when the
executor hands it a message, it handles that one and then takes and handles every other message
waiting, in order, up to a bound: the queue's depth (what can wait at the wake-up; 100 for the
statuses), at most :data:`DRAIN_LIMIT`. A flood must not starve the node's other callbacks, the
planner's step among them: the rest comes on the next cycle. It takes the messages the way
rclpy's own :func:`rclpy.wait_for_message` does (``Subscription.handle.take_message``), under any
executor, without overriding executor internals. See docs/ARCHITECTURE.md, "Topics and QoS".

Every callback is total by construction: an exception it lets out (a bug; the nodes' callbacks
catch what they expect) is logged in one bounded, throttled line and the next message is handled;
it never reaches the executor, which would stop the node.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.subscription import Subscription

from fleet_planner.validation import printable

#: at most this many messages per wake-up of one subscription
DRAIN_LIMIT = 1000


def drain_limit(qos: QoSProfile) -> int:
    """Messages one wake-up handles at most: the history depth (keep last), at most DRAIN_LIMIT."""
    if qos.history == HistoryPolicy.KEEP_LAST and qos.depth > 0:
        return min(qos.depth, DRAIN_LIMIT)
    return DRAIN_LIMIT


def take_waiting(sub: Subscription) -> Any | None:
    """The next message waiting on ``sub`` (``None`` if there is none or ``sub`` is destroyed),
    taken without an executor."""
    try:
        with sub.handle:  # kept alive while taking, as the executors do
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
    except InvalidHandle:
        return None
    return None if taken is None else taken[0]


def create_draining_subscription(node: Node, msg_type: Any, topic: str, callback: Callable[[Any], None],
                                 qos: QoSProfile, *, limit: int | None = None, **kwargs: Any) -> Subscription:
    """``node.create_subscription(msg_type, topic, callback, qos, **kwargs)`` whose every wake-up
    handles all waiting messages, in the order they came, at most ``limit`` (default:
    :func:`drain_limit` of ``qos``)."""
    limit = drain_limit(qos) if limit is None else limit
    if limit < 1:
        raise ValueError(f"limit must be >= 1 (got {limit})")
    sub: Subscription | None = None
    log = node.get_logger()

    def handle(msg: Any) -> None:
        try:
            callback(msg)
        except Exception as exc:  # noqa: BLE001 - a message must never stop the node
            log.error(printable(f"{topic}: message dropped, handler failed: {exc!r}", 300),
                      throttle_duration_sec=5.0)

    def on_message(msg: Any) -> None:
        handle(msg)
        for _ in range(limit - 1):
            if sub is None:
                return
            more = take_waiting(sub)
            if more is None:
                return
            handle(more)

    sub = node.create_subscription(msg_type, topic, on_message, qos, **kwargs)
    return sub
