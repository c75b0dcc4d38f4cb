#!/usr/bin/env python3
"""CPU time per message of the way the fleet's nodes drain a subscription, against rclpy's one per cycle.

One process, two nodes: a sender publishes ``--batch`` messages (300 characters each, like a status)
on a reliable topic whose queue holds them all, waits until the receiver's queue has every one of
them (``wait_for_all_acked``), then the receiver's executor is spun until all are handled; the
CPU time of that spinning over all batches, per message, is the cost of taking and handling one
message (the callback only appends it). Ways (``--ways``):

* ``fleet``: the way the fleet's nodes take their messages: before issue 7 the planner's
  ``DrainingExecutor`` (it overrode rclpy's private ``_take_subscription``), since then draining
  subscriptions (``fleet_planner/ros/drain.py``) on rclpy's ``SingleThreadedExecutor``;
* ``plain``: a plain subscription on ``SingleThreadedExecutor``, one message per wait cycle.

Unlike ``bench_status_ingest.py`` no other process and no best-effort losses are involved, so the
figures hardly depend on how busy the machine is.

    .venv/bin/python bench/bench_drain.py [--batch 100] [--batches 100] [--repeat 3] [--ways fleet,plain]
"""
from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.duration import Duration  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from fleet_planner.ros import planner_node  # noqa: E402

WAIT = 30.0  # wall seconds any one wait may take


def fleet_way():
    """(name, executor class, subscribe(node, topic, callback, qos)) of the fleet's nodes' way."""
    if hasattr(planner_node, "DrainingExecutor"):  # before issue 7
        return ("DrainingExecutor", planner_node.DrainingExecutor,
                lambda node, topic, cb, qos: node.create_subscription(String, topic, cb, qos))
    from fleet_planner.ros.drain import create_draining_subscription

    return ("draining subscription", SingleThreadedExecutor,
            lambda node, topic, cb, qos: create_draining_subscription(node, String, topic, cb, qos))


def plain_way():
    return ("plain subscription", SingleThreadedExecutor,
            lambda node, topic, cb, qos: node.create_subscription(String, topic, cb, qos))


def run(context: Context, way, batch: int, batches: int, index: int) -> float:
    """CPU microseconds per message handled."""
    _, executor_cls, subscribe = way
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=batch, reliability=ReliabilityPolicy.RELIABLE)
    topic = f"/bench_drain_{index}"
    sender = rclpy.create_node(f"bench_drain_sender_{index}", context=context)
    receiver = rclpy.create_node(f"bench_drain_receiver_{index}", context=context)
    executor = executor_cls(context=context)
    executor.add_node(receiver)
    got: list[str] = []
    try:
        subscribe(receiver, topic, lambda m: got.append(m.data), qos)
        pub = sender.create_publisher(String, topic, qos)
        deadline = time.monotonic() + WAIT
        while not (pub.get_subscription_count() and receiver.count_publishers(topic)) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.01)
        payload = "x" * 300
        cpu = 0.0
        for _ in range(batches):
            for _ in range(batch):
                pub.publish(String(data=payload))
            if not pub.wait_for_all_acked(Duration(seconds=WAIT)):
                raise SystemExit("bench: the receiver did not get a batch in time")
            want = len(got) + batch
            deadline = time.monotonic() + WAIT
            t0 = time.process_time()
            while len(got) < want and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.1)
            cpu += time.process_time() - t0
        return 1e6 * cpu / max(1, len(got))
    finally:
        executor.shutdown()
        receiver.destroy_node()
        sender.destroy_node()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batch", type=int, default=100, help="messages waiting at once (default 100, the status depth)")
    p.add_argument("--batches", type=int, default=100, help="batches per run (default 100)")
    p.add_argument("--repeat", type=int, default=3, help="runs per way (default 3)")
    p.add_argument("--ways", default="fleet,plain", help="comma-separated: fleet, plain (default both)")
    opts = p.parse_args()
    ways = {"fleet": fleet_way, "plain": plain_way}
    context = Context()
    rclpy.init(context=context)
    try:
        print(f"CPU us per message, {opts.batch} waiting at a time, {opts.batches} batches per run")
        index = 0
        for key in opts.ways.split(","):
            way = ways[key]()
            costs = []
            for _ in range(opts.repeat):
                costs.append(run(context, way, opts.batch, opts.batches, index))
                index += 1
            print(f"{key:<6} {way[0]:<22} " + " ".join(f"{c:7.1f}" for c in costs)
                  + f"   median {statistics.median(costs):.1f}", flush=True)
    finally:
        rclpy.try_shutdown(context=context)


if __name__ == "__main__":
    main()
