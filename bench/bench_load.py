#!/usr/bin/env python3
"""Planner load: N synthetic robots at 10 Hz from separate processes against one planner node.

For each N of ``--robots`` this process runs a :class:`~fleet_planner.ros.planner_node.PlannerNode`
(wall clock) on a generated warehouse sized for N (:func:`fleet_planner.fleet.placement.warehouse_for`),
and ``--procs`` child processes publish the statuses of N idle robots standing on free spots
(:func:`~fleet_planner.fleet.placement.place_robots`) at ``--hz`` each, stamped with the wall
clock, for ``--seconds``; a task is submitted every 2 s. Idle robots are what the planner plans
for (chargers, parking): issue 9's load case. Printed per N:

* planner CPU: this process's CPU time / wall time (the planner and a tiny task client), and the
  publishers' CPU (all children together), in % of one core;
* step gaps: wall seconds between planning steps (median, max; the step period is 0.5 s) and the
  longest timer callback (step + publishing);
* step work: CPU milliseconds inside the fleet manager's step (median, max), and the most CPU one
  timer callback took (statuses taken, step, publishing): the work a step costs whatever else runs
  on the machine (on a loaded machine a gap is this CPU stretched by the share of a core it gets);
* status age: wall age of each robot's newest status at each step (median, max);
* offline: robots the planner took for offline (all of them are alive: each one is false);
* accept latency: wall seconds from publishing a task to its ``accepted`` event (median, max), and
  how many of the tasks were accepted (one more task goes before the measured seconds: a process's
  first legs load numba's compiled kernels, a one-time cost of about a second).

Timings on a loaded machine are noisy; CPU time is the better figure.

    nice .venv/bin/python bench/bench_load.py [--robots 50 100 200 500 1000] [--seconds 20] [--procs 4]
        [--profile out/load.prof]   # cProfile of the planner process over the measured seconds (last N)
"""
from __future__ import annotations

import argparse
import cProfile
import json
import math
import os
import random
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.logging import LoggingSeverity  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from fleet_planner.fleet.jobstore import emptied  # noqa: E402
from fleet_planner.fleet.placement import parking_spots, place_robots, warehouse_for  # noqa: E402
from fleet_planner.robots import load_kinds  # noqa: E402
from fleet_planner.ros.demo.bringup import node_command  # noqa: E402
from fleet_planner.ros.planner_node import PlannerNode  # noqa: E402
from fleet_planner.warehouse import save_warehouse  # noqa: E402
from msg_schemas import topics  # noqa: E402
from msg_schemas.records import RobotStatus, Task, TaskEvent  # noqa: E402

WAIT = 60.0


def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (from /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def proc_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


# -- a publisher (child process) -----------------------------------------------------------------------
def publish(spec_file: str, hz: float, seconds: float) -> None:
    """Publish the statuses of the robots in ``spec_file`` at ``hz`` until ``seconds`` after "go"."""
    robots = json.loads(Path(spec_file).read_text())
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node(f"bench_load_pub_{os.getpid()}", context=context)
    try:
        pub = node.create_publisher(String, topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS)
        deadline = time.monotonic() + WAIT
        while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.05)  # polling the graph: nothing to spin for here
        print("ready", flush=True)
        if sys.stdin.readline().strip() != "go":
            return
        period = 1.0 / hz
        start = time.monotonic()
        k = 0
        while time.monotonic() - start < seconds:
            stamp = time.time()
            for d in robots:
                d["stamp"] = stamp
                pub.publish(String(data=json.dumps(d)))
            k += 1
            time.sleep(max(0.0, start + k * period - time.monotonic()))  # pacing the offered load
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)


# -- the planner side --------------------------------------------------------------------------------------
def run(context: Context, n: int, opts: argparse.Namespace, tmp: Path, profiler: Any = None) -> dict:
    kinds = load_kinds()
    warehouse = warehouse_for(min(n, 200))  # synthetic robots stand anywhere there is room
    members = place_robots(warehouse, kinds, n)
    parking = [v for p in parking_spots(warehouse, members) for v in p]
    node = PlannerNode(f"bench_load_planner_{n}", context=context, warehouse=warehouse, kinds=kinds,
                       parameter_overrides=[Parameter("parking", value=parking),
                                            Parameter("offline_timeout_s", value=3.0),
                                            Parameter("job_store", value=str(emptied(tmp / f"jobs_{n}.sqlite")))])
    node.get_logger().set_level(LoggingSeverity.WARN)
    client = rclpy.create_node(f"bench_load_client_{n}", context=context)
    tasks_pub = client.create_publisher(String, topics.TASKS, topics.TASKS_QOS)
    sent: dict[str, float] = {}
    accepted: dict[str, float] = {}

    def on_event(msg: String) -> None:
        ev = TaskEvent.from_json(msg.data)
        if ev.event == "accepted" and ev.task_id in sent and ev.task_id not in accepted:
            accepted[ev.task_id] = time.monotonic()

    client.create_subscription(String, topics.TASK_EVENTS, on_event, topics.TASK_EVENTS_QOS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(client)

    fleet = node.fleet
    steps: list[float] = []
    works: list[float] = []
    cb_cpus: list[float] = []
    cb_cpu0 = [0.0]
    callbacks: list[float] = []
    ages: list[float] = []
    offline = [0]
    measuring = [False]
    step, publish_decisions, take = fleet.step, node._publish, node._take_statuses

    def measured_take():
        cb_cpu0[0] = time.process_time()
        take()

    def measured_step(now):
        t0, c0 = time.monotonic(), time.process_time()
        d = step(now)
        if measuring[0]:
            works.append(time.process_time() - c0)
            steps.append(t0)
            wall = time.time()
            ages.extend(wall - r.status.stamp for r in fleet.robots.values())
            offline[0] += sum("offline" in note for note in d.notes)
        return d

    def measured_publish(d, now):
        t0 = time.monotonic()
        publish_decisions(d, now)
        if measuring[0] and steps:
            callbacks.append(time.monotonic() - steps[-1])
            cb_cpus.append(time.process_time() - cb_cpu0[0])
        return t0

    fleet.step = measured_step  # type: ignore[method-assign]
    node._publish = measured_publish  # type: ignore[method-assign]
    node._take_statuses = measured_take  # type: ignore[method-assign]  # (the timer's call, not the relay's)

    agents = []
    if opts.agents:  # real agent processes among the synthetic robots, measured
        wh_file = save_warehouse(warehouse, tmp / f"warehouse_{n}.yaml")
        for m in members[:opts.agents]:
            agents.append(subprocess.Popen(node_command("robot_agent", "robot_agent.agent_node") + [
                "--ros-args", "-r", f"__node:=agent_{m.id}", "-p", f"id:={m.id}", "-p", f"kind:={m.kind}",
                "-p", f"x:={m.x!r}", "-p", f"y:={m.y!r}", "-p", f"neighbours:={opts.hear}",
                "-p", f"warehouse_file:={wh_file}"], stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT))
        members = members[opts.agents:]
    chunks = [members[i::opts.procs] for i in range(opts.procs)]
    children = []
    for i, chunk in enumerate(c for c in chunks if c):
        recs = [json.loads(RobotStatus(id=m.id, kind=m.kind, x=m.x, y=m.y, yaw=0.0, vx=0.0, vy=0.0, battery=0.9,
                                       mode="idle", progress=1.0, stamp=0.0, radius=kinds[m.kind].radius).to_json())
                for m in chunk]
        spec = tmp / f"robots_{n}_{i}.json"
        spec.write_text(json.dumps(recs))
        children.append(subprocess.Popen([sys.executable, __file__, "--publisher", str(spec), "--hz", str(opts.hz),
                                          "--seconds", str(opts.seconds)],
                                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True))
    try:
        for c in children:
            assert c.stdout is not None
            if c.stdout.readline().strip() != "ready":
                raise SystemExit("bench: a publisher did not come up")
        deadline = time.monotonic() + WAIT
        while node.count_publishers(topics.ROBOT_STATUS) < len(children) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        cpu0, kids0 = time.process_time(), sum(proc_cpu_s(c.pid) for c in children)
        for c in children:
            assert c.stdin is not None
            c.stdin.write("go\n")
            c.stdin.flush()
        start = time.monotonic()
        warm = start + min(5.0, opts.seconds / 4)  # everyone joined; measured from then on
        chutes = [s.name for s in warehouse.stations_of("chute")]
        tags = [t for s in warehouse.stations_of("storage") for t in s.tags]
        # one task before the measured seconds: the first legs of a process load numba's compiled
        # kernels for their types (about 1 s, once), which is not a step gap of a running planner
        tasks_pub.publish(String(data=Task(id=f"load_{n}_warm", pick=chutes[-1], place=tags[-1]).to_json()))
        k = 0
        while time.monotonic() - start < opts.seconds:
            executor.spin_once(timeout_sec=0.01)
            now = time.monotonic()
            if now >= warm and not measuring[0]:
                measuring[0] = True
                if profiler is not None:
                    profiler.enable()
                cpu0, wall0 = time.process_time(), now
                kids0 = sum(proc_cpu_s(c.pid) for c in children)
                agents0 = [proc_cpu_s(a.pid) for a in agents]
            if measuring[0] and now >= wall0 + 2.0 * len(sent):
                task = Task(id=f"load_{n}_{k}", pick=chutes[k % len(chutes)], place=tags[k % len(tags)])
                k += 1
                sent[task.id] = time.monotonic()
                tasks_pub.publish(String(data=task.to_json()))
        measuring[0] = False
        if profiler is not None:
            profiler.disable()
        wall = time.monotonic() - wall0
        cpu = time.process_time() - cpu0
        kids = sum(proc_cpu_s(c.pid) for c in children) - kids0
        rss = proc_rss_mb(os.getpid())
        agent_cpu = [100 * (proc_cpu_s(a.pid) - c0) / wall for a, c0 in zip(agents, agents0)]
        agent_rss = [proc_rss_mb(a.pid) for a in agents]
        end = time.monotonic() + 3.0
        while time.monotonic() < end and len(accepted) < len(sent):
            executor.spin_once(timeout_sec=0.05)
    finally:
        for c in children:
            c.wait(timeout=WAIT)
        for a in agents:
            a.send_signal(signal.SIGINT)
        for a in agents:
            try:
                a.wait(timeout=10)
            except subprocess.TimeoutExpired:
                a.kill()
                a.wait()
        executor.shutdown()
        node.destroy_node()
        client.destroy_node()
    gaps = [b - a for a, b in zip(steps, steps[1:])]
    lat = [accepted[t] - sent[t] for t in accepted]
    return {"n": n, "joined": len(fleet.robots), "cpu": 100 * cpu / wall, "pubs_cpu": 100 * kids / wall, "rss": rss,
            "gap_med": statistics.median(gaps) if gaps else math.nan, "gap_max": max(gaps, default=math.nan),
            "cb_max": max(callbacks, default=math.nan),
            "work_med": 1e3 * statistics.median(works) if works else math.nan,
            "work_max": 1e3 * max(works, default=math.nan),
            "cb_cpu_max": 1e3 * max(cb_cpus, default=math.nan),
            "age_med": statistics.median(ages) if ages else math.nan, "age_max": max(ages, default=math.nan),
            "offline": offline[0], "lat_med": statistics.median(lat) if lat else math.nan,
            "lat_max": max(lat, default=math.nan), "accepted": len(accepted), "sent": len(sent),
            "load": os.getloadavg()[0],  # the machine's 1-minute load average at the end
            "agent_cpu": statistics.mean(agent_cpu) if agent_cpu else math.nan,
            "agent_rss": statistics.mean(agent_rss) if agent_rss else math.nan}


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--robots", type=int, nargs="+", default=[50, 100, 200, 500, 1000])
    p.add_argument("--seconds", type=float, default=20.0, help="wall seconds of publishing per N (default 20)")
    p.add_argument("--procs", type=int, default=4, help="publisher processes (default 4)")
    p.add_argument("--hz", type=float, default=10.0, help="statuses per robot per second (default 10)")
    p.add_argument("--agents", type=int, default=0,
                   help="of the N robots, this many are real agent processes (measured: CPU, memory)")
    p.add_argument("--hear", choices=("relay", "all"), default="relay",
                   help="what the agents hear: the planner's neighbour relay (default) or every status")
    p.add_argument("--profile", metavar="FILE", help="cProfile the planner process over the measured seconds "
                   "of the last N into FILE (pstats)")
    p.add_argument("--publisher", help=argparse.SUPPRESS)
    opts = p.parse_args()
    if opts.publisher:
        publish(opts.publisher, opts.hz, opts.seconds)
        return
    tmp = REPO / "out" / "bench_load"
    tmp.mkdir(parents=True, exist_ok=True)
    context = Context()
    rclpy.init(context=context)
    print(f"planner load: idle robots at {opts.hz:g} Hz from {opts.procs} processes, {opts.seconds:g} s each, "
          f"a task every 2 s, ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']}"
          + (f"; {opts.agents} of them real agents hearing {opts.hear}" if opts.agents else ""))
    print(f"{'N':>5} {'joined':>6} {'planner CPU%':>12} {'pubs CPU%':>9} {'RSS MB':>6} {'gap med s':>9} "
          f"{'gap max s':>9} {'cb max s':>8} {'step ms med':>11} {'step ms max':>11} {'cb CPU ms max':>13} "
          f"{'age med s':>9} {'age max s':>9} {'offline':>7} {'accept med s':>12} "
          f"{'accept max s':>12} {'accepted':>8} {'load':>5}"
          + (f" {'agent CPU%':>10} {'agent MB':>8}" if opts.agents else ""))
    try:
        for i, n in enumerate(opts.robots):
            profiler = cProfile.Profile() if opts.profile and i == len(opts.robots) - 1 else None
            r = run(context, n, opts, tmp, profiler)
            if profiler is not None:
                profiler.dump_stats(opts.profile)
            print(f"{r['n']:>5} {r['joined']:>6} {r['cpu']:>12.0f} {r['pubs_cpu']:>9.0f} {r['rss']:>6.0f} "
                  f"{r['gap_med']:>9.2f} {r['gap_max']:>9.2f} {r['cb_max']:>8.2f} {r['work_med']:>11.1f} "
                  f"{r['work_max']:>11.1f} {r['cb_cpu_max']:>13.1f} {r['age_med']:>9.2f} "
                  f"{r['age_max']:>9.2f} {r['offline']:>7} {r['lat_med']:>12.2f} {r['lat_max']:>12.2f} "
                  f"{r['accepted']:>4}/{r['sent']:<3} {r['load']:>5.1f}"
                  + (f" {r['agent_cpu']:>10.1f} {r['agent_rss']:>8.0f}" if opts.agents else ""), flush=True)
    finally:
        rclpy.try_shutdown(context=context)


if __name__ == "__main__":
    main()
