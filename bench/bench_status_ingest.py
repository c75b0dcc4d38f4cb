#!/usr/bin/env python3
"""Status throughput of the planner node: how many ``/fleet/robot_status`` messages per second it takes in.

A child process publishes ``--count`` status records of ``--robots`` robots (round robin, each
stamped with the wall time it is sent) on ``/fleet/robot_status`` with the topic's QoS (best
effort, depth 100), as fast as it can (``--rate 0``, the default: the planner's capacity) or at
``--rate`` messages per wall second (9 robots at 10 Hz in a 10x simulated demo offer 900/s).
This process runs a :class:`~fleet_planner.ros.planner_node.PlannerNode` on the shipped warehouse
and kinds, beside ``--listeners`` fleet monitors (the demo's :class:`FleetMonitor`, which hear and
parse every status as the agents of the in-process demo do; 0: the planner alone, as in
``fleet-demo --mode procs``), all on the executor the fleet's nodes run on (before issue 7 the
planner's ``DrainingExecutor``, since then rclpy's ``SingleThreadedExecutor``).

Counted is what reaches the fleet manager (``FleetManager.on_status``); printed per repetition:
messages published and ingested (the rest was dropped by the best-effort queue), the publisher's
rate, **ingested messages per second** (ingested / wall time from the first message sent to the
last one ingested), this process's CPU time per ingested status (planner and listeners together:
less sensitive to a busy machine than the rate), and how stale the newest status of a robot was at
each planning step while the publisher ran (median and maximum over steps and robots, wall ms:
what "fresh statuses before each step" means).

    .venv/bin/python bench/bench_status_ingest.py [--count 20000] [--robots 9] [--listeners 9]
        [--rate 0] [--repeat 3]
"""
from __future__ import annotations

import argparse
import json
import os
import random
import select
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
# DDS stays on this machine, on a domain of its own unless the caller chose one (before rclpy loads)
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.logging import LoggingSeverity  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from fleet_planner.ros import planner_node  # noqa: E402
from fleet_planner.ros.demo import FleetMonitor  # noqa: E402
from fleet_planner.warehouse import load_warehouse  # noqa: E402
from msg_schemas import topics  # noqa: E402
from msg_schemas.records import RobotStatus  # noqa: E402

WAIT = 30.0  # wall seconds any one wait (discovery, the end of a run) may take


def fleet_executor(context: Context):
    """The executor the fleet's nodes are spun by (the planner's main and the in-process bring-up)."""
    cls = getattr(planner_node, "DrainingExecutor", SingleThreadedExecutor)
    return cls(context=context)


# -- the publisher (child process) ------------------------------------------------------------------
def publish(count: int, robots: int, rate: float, subscribers: int) -> None:
    """Wait until ``subscribers`` status subscriptions are matched and the parent says go (a line on
    stdin), publish ``count`` statuses, print how long that took."""
    chargers = [s.pose for s in load_warehouse().stations_of("charger")]
    templates = []
    for i in range(robots):
        x, y = chargers[i % len(chargers)]
        rec = RobotStatus(id=f"b{i + 1}", kind="cargo", x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, battery=1.0,
                          mode="idle", progress=0.0, stamp=0.0, radius=0.3)
        templates.append(json.loads(rec.to_json()))
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("bench_status_publisher", context=context)
    try:
        pub = node.create_publisher(String, topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS)
        deadline = time.monotonic() + WAIT
        while pub.get_subscription_count() < subscribers and time.monotonic() < deadline:
            time.sleep(0.01)  # polling the graph: nothing to spin for in this process
        print(f"ready {pub.get_subscription_count()}", flush=True)
        if sys.stdin.readline().strip() != "go":
            return
        clock = node.get_clock()
        t0 = time.perf_counter()
        for k in range(count):
            if rate > 0:
                due = t0 + k / rate
                while time.perf_counter() < due:
                    pass  # pacing the offered load, not waiting for anything
            d = templates[k % robots]
            d["stamp"] = clock.now().nanoseconds / 1e9
            pub.publish(String(data=json.dumps(d)))
        print(f"published {count} {time.perf_counter() - t0:.6f}", flush=True)
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


# -- the planner side ---------------------------------------------------------------------------------
def run_once(context: Context, opts: argparse.Namespace, index: int) -> dict:
    node = planner_node.PlannerNode(f"bench_planner_{index}", context=context,  # (no tasks: no job store)
                                    parameter_overrides=[Parameter("job_store", value=":memory:")])
    node.get_logger().set_level(LoggingSeverity.WARN)  # not a note per robot joining
    listeners = [FleetMonitor(f"bench_listener_{index}_{i}", context=context) for i in range(opts.listeners)]
    executor = fleet_executor(context)
    for each in [node, *listeners]:
        executor.add_node(each)
    fleet = node.fleet
    ingested: list[float] = []
    cpu = [0.0, 0.0]  # this process's CPU time at "go" and at the last status ingested
    stale: list[float] = []
    publishing = [False]
    on_status, step = fleet.on_status, fleet.step

    def counting_on_status(status, now):
        ingested.append(time.monotonic())
        cpu[1] = time.process_time()
        return on_status(status, now)

    def measuring_step(now):
        if publishing[0] and ingested:
            wall = node.get_clock().now().nanoseconds / 1e9  # the publisher stamps with the same clock
            stale.extend(wall - r.status.stamp for r in fleet.robots.values())
        return step(now)

    fleet.on_status = counting_on_status  # type: ignore[method-assign]
    fleet.step = measuring_step  # type: ignore[method-assign]
    child = subprocess.Popen([sys.executable, __file__, "--publisher", "--count", str(opts.count),
                              "--robots", str(opts.robots), "--rate", str(opts.rate),
                              "--subscribers", str(1 + opts.listeners)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdin is not None and child.stdout is not None
        ready = child.stdout.readline().split()
        if ready[:1] != ["ready"] or int(ready[1]) < 1 + opts.listeners:
            raise SystemExit(f"bench: the publisher did not match all subscriptions within {WAIT:g} s ({ready})")
        deadline = time.monotonic() + WAIT
        while node.count_publishers(topics.ROBOT_STATUS) < 1 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.01)
        t_go, cpu[0], publishing[0] = time.monotonic(), time.process_time(), True
        child.stdin.write("go\n")
        child.stdin.flush()
        out = ""
        deadline = time.monotonic() + WAIT + opts.count / 1000.0
        # until the publisher is done and nothing new came for 2 s (or the time is up)
        while time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.01)
            if "published" not in out and select.select([child.stdout], [], [], 0)[0]:
                out += child.stdout.readline()  # the publisher's last line, written whole
                publishing[0] = "published" not in out
            last = ingested[-1] if ingested else t_go
            if "published" in out and time.monotonic() - max(last, t_go) > 2.0:
                break
        child.wait(timeout=WAIT)
        published = [ln for ln in out.splitlines() if ln.startswith("published")]
        if not published:
            raise SystemExit(f"bench: the publisher did not finish within the time ({out!r})")
        _, sent, secs = published[0].split()
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        executor.shutdown()
        for each in [node, *listeners]:
            each.destroy_node()
    span = (ingested[-1] - t_go) if ingested else float("nan")
    return {"published": int(sent), "pub_rate": int(sent) / float(secs), "ingested": len(ingested),
            "rate": len(ingested) / span if ingested else 0.0,
            "cpu_us": 1e6 * (cpu[1] - cpu[0]) / len(ingested) if ingested else float("nan"),
            "stale_med_ms": 1e3 * statistics.median(stale) if stale else float("nan"),
            "stale_max_ms": 1e3 * max(stale) if stale else float("nan")}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--count", type=int, default=20000, help="status messages to publish (default 20000)")
    p.add_argument("--robots", type=int, default=9, help="robots they come from (default 9, the demo's)")
    p.add_argument("--listeners", type=int, default=9,
                   help="other status subscribers on the planner's executor (default 9; 0: the planner alone)")
    p.add_argument("--rate", type=float, default=0.0, help="offered messages per wall second (default 0: flood)")
    p.add_argument("--repeat", type=int, default=3, help="repetitions (default 3)")
    p.add_argument("--publisher", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--subscribers", type=int, default=1, help=argparse.SUPPRESS)
    opts = p.parse_args()
    if opts.publisher:
        publish(opts.count, opts.robots, opts.rate, opts.subscribers)
        return
    context = Context()
    rclpy.init(context=context)
    try:
        executor_name = type(fleet_executor(context)).__name__
        print(f"planner status ingest: {opts.count} statuses of {opts.robots} robots, "
              f"{'flood' if opts.rate <= 0 else f'{opts.rate:g}/s offered'}, {opts.listeners} other subscribers, "
              f"executor {executor_name}, ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}")
        print(f"{'run':>3} {'published':>9} {'pub/s':>8} {'ingested':>8} {'lost':>6} {'ingested/s':>10} "
              f"{'cpu us/msg':>10} {'stale med ms':>12} {'stale max ms':>12}")
        rates, cpus = [], []
        for i in range(opts.repeat):
            r = run_once(context, opts, i)
            rates.append(r["rate"])
            cpus.append(r["cpu_us"])
            print(f"{i + 1:>3} {r['published']:>9} {r['pub_rate']:>8.0f} {r['ingested']:>8} "
                  f"{r['published'] - r['ingested']:>6} {r['rate']:>10.0f} {r['cpu_us']:>10.0f} "
                  f"{r['stale_med_ms']:>12.1f} {r['stale_max_ms']:>12.1f}", flush=True)
        print(f"median ingested/s: {statistics.median(rates):.0f}; median CPU per ingested status: "
              f"{statistics.median(cpus):.0f} us")
    finally:
        rclpy.try_shutdown(context=context)


if __name__ == "__main__":
    main()
