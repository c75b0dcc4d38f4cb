#!/usr/bin/env python3
"""CPU of the fleet simulator (``fleet-sim``'s :class:`~fleet_planner.fleet.sim.SimFleet`) per
simulated second, without a planner process: where it goes.

For each fleet size N the robots are placed as ``fleet-demo --robots N`` places them (default
warehouse up to 30, the generated large one above), then driven round after round: each round the
robots swap their start spots (a random permutation) along a one-shot plan of ``--planner``
(md-departure, else PRIOR: checker-valid, so the safety net only sees robots passing by at their planned
distance), handed to the robots as their timed paths; planning is not timed. The fleet is stepped at
``--rate`` steps per simulated second, each step: the step itself (neighbours, safety net and
kinematics of every robot), encoding every status (``to_json``, what fleet-sim publishes) and, with
``--ros``, publishing it as a ``std_msgs/String`` on ``/fleet/robot_status`` (nobody listening).

Printed per N: simulated seconds, CPU ms per simulated second in total and per part, CPU ms per robot
per simulated second, the bytes of one status, and the share of robots driving. ``--profile`` adds
the top functions of cProfile (by own time).

    .venv/bin/python bench/bench_sim.py [--robots 10 30 100] [--seconds 60] [--rate 10] [--ros]
        [--profile] [--node RATE] [--codec]
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import random
import signal
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))

from fleet_planner.fleet.placement import place_robots, warehouse_for  # noqa: E402
from fleet_planner.fleet.sim import SimFleet  # noqa: E402
from fleet_planner.model import PlanningError, RobotSpec  # noqa: E402
from fleet_planner.planners import get_planner  # noqa: E402
from fleet_planner.robots import load_kinds  # noqa: E402
from fleet_planner.warehouse import load_warehouse  # noqa: E402


def plan_rounds(members, kinds, grid, planners, rng: np.random.Generator, seconds: float) -> list[list]:
    """Rounds of legs covering ``seconds`` of simulated time (plus 5 s after each round): in each the
    robots swap their spots (a random permutation), times counted from the round's start."""
    here = [(m.x, m.y) for m in members]
    rounds: list[list] = []
    total = 0.0
    while total < seconds:
        for attempt in range(20):
            perm = rng.permutation(len(members))
            specs = [RobotSpec(m.id, kinds[m.kind].radius, kinds[m.kind].max_speed, here[i], here[int(perm[i])],
                               m.kind) for i, m in enumerate(members)]
            try:
                plan = planners[attempt % len(planners)].plan(grid, specs)
                break
            except PlanningError:
                continue
        else:
            raise RuntimeError("no plan for 20 permutations")
        rounds.append(plan.paths)
        here = [here[int(k)] for k in perm]
        total += max(float(p.waypoints[-1, 2]) for p in plan.paths) + 5.0
    return rounds


def start_round(sim: SimFleet, paths: list, now: float) -> float:
    """Hand a round's legs to the robots (a robot not yet on its start keeps still); returns when
    the round ends."""
    for p in paths:
        try:
            sim.on_path(p.robot_id, p, now, int(now * 1e9))
        except ValueError:
            pass
    return now + max(float(p.waypoints[-1, 2]) for p in paths) + 5.0


def run(n: int, opts: argparse.Namespace) -> dict:
    kinds = load_kinds()
    warehouse = load_warehouse() if n <= 30 else warehouse_for(n)
    members = place_robots(warehouse, kinds, n)
    sim = SimFleet(members, kinds, warehouse, "central", 1.0 / opts.rate)
    planners = [get_planner(name) for name in opts.planner.split(",")]
    rounds = plan_rounds(members, kinds, warehouse.grid, planners, np.random.default_rng(opts.seed), opts.seconds)
    publish = None
    node = None
    if opts.ros:
        import rclpy
        from std_msgs.msg import String

        from msg_schemas import topics
        rclpy.init()
        node = rclpy.create_node("bench_sim")
        pub = node.create_publisher(String, topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS)

        def publish(text: str) -> None:
            pub.publish(String(data=text))
    dt = 1.0 / opts.rate
    now = 0.0
    sim.step(now)
    parts = {"step": 0.0, "encode": 0.0, "publish": 0.0}
    steps = driving = 0
    size = 0
    prof = cProfile.Profile() if opts.profile else None
    while now < opts.seconds:
        end = start_round(sim, rounds.pop(0), now)
        while now < end and now < opts.seconds:
            now = round(now + dt, 9)
            if prof:
                prof.enable()
            c0 = time.process_time()
            statuses = sim.step(now)
            c1 = time.process_time()
            texts = [s.to_compact_json() if hasattr(s, "to_compact_json") else s.to_json() for s in statuses]
            c2 = time.process_time()
            if publish is not None:
                for t in texts:
                    publish(t)
            c3 = time.process_time()
            if prof:
                prof.disable()
            parts["step"] += c1 - c0
            parts["encode"] += c2 - c1
            parts["publish"] += c3 - c2
            steps += 1
            driving += sum(s.mode == "driving" for s in statuses)
            size += sum(len(t.encode()) for t in texts)
    if node is not None:
        import rclpy
        node.destroy_node()
        rclpy.shutdown()
    total = sum(parts.values())
    if prof:
        pstats.Stats(prof).sort_stats("tottime").print_stats(opts.profile)
    return {"n": n, "sim_s": now, "total": total / now * 1e3, "parts": {k: v / now * 1e3 for k, v in parts.items()},
            "per_robot": total / now * 1e3 / n, "bytes": size / max(1, steps * n),
            "driving": driving / max(1, steps * n)}


def run_node(n: int, opts: argparse.Namespace) -> dict:
    """The fleet-sim node itself on a sim clock (a child process at ``--node`` x real time), spun in
    this process for ``--seconds`` of simulated time; its CPU (the rounds are planned before it starts)."""
    import subprocess

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from fleet_planner.ros.fleet_sim import FleetSimNode
    kinds = load_kinds()
    warehouse = load_warehouse() if n <= 30 else warehouse_for(n)
    members = place_robots(warehouse, kinds, n)
    planners = [get_planner(name) for name in opts.planner.split(",")]
    rounds = plan_rounds(members, kinds, warehouse.grid, planners, np.random.default_rng(opts.seed), opts.seconds)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # so that the clock child is stopped too
    clock = subprocess.Popen([sys.executable, "-m", "fleet_planner.ros.sim_clock", "--rate", str(opts.node)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rclpy.init()
    prof = cProfile.Profile() if opts.profile else None
    try:
        node = FleetSimNode(warehouse=warehouse, kinds=kinds, members=members,
                            parameter_overrides=[Parameter("use_sim_time", value=True),
                                                 Parameter("status_rate_hz", value=opts.rate)])
        ex = SingleThreadedExecutor()
        ex.add_node(node)

        def now() -> float:
            return node.get_clock().now().nanoseconds / 1e9
        deadline = time.monotonic() + 30
        while now() <= 0.0 and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.1)
        start, steps0 = now(), node.steps
        c0, w0 = time.process_time(), time.monotonic()
        end = start
        if prof:
            prof.enable()
        while now() < start + opts.seconds:
            if now() >= end and rounds:
                end = start_round(node.sim, rounds.pop(0), now())
            ex.spin_once()   # no timeout: rclpy would make a timer for it each time (the clock ticks on)
        if prof:
            prof.disable()
        cpu, wall, sim_s = time.process_time() - c0, time.monotonic() - w0, now() - start
        steps = node.steps - steps0
        node.destroy_node()
    finally:
        rclpy.shutdown()
        clock.terminate()
        clock.wait(10)
    if prof:
        pstats.Stats(prof).sort_stats("tottime").print_stats(opts.profile)
    return {"n": n, "sim_s": sim_s, "total": cpu / sim_s * 1e3, "per_robot": cpu / sim_s * 1e3 / n,
            "rate": sim_s / wall, "steps": steps / sim_s}


def codec() -> None:
    """Bytes, and CPU us to build, write and read one status, in each form."""
    import timeit

    from msg_schemas.records import RobotStatus
    st = RobotStatus(id="r12", kind="cargo", x=12.345678901, y=3.45678912, yaw=1.5707963, vx=0.4999999,
                     vy=0.0001234, battery=0.912345678, mode="driving", progress=0.51234567, stamp=123.456789,
                     radius=0.35, task_id="t12", path_id=1796182134055028518, lateness_s=0.1234567,
                     travelled_m=3.2123456, loaded=True)
    fields = {k: v for k, v in st.to_dict().items() if k != "schema"}
    forms = [("fleet/robot_status@1", st.to_json)]
    if hasattr(st, "to_compact_json"):
        forms.append((RobotStatus.COMPACT_SCHEMA, st.to_compact_json))

    def us(f) -> float:
        return min(timeit.Timer(f, timer=time.process_time).repeat(5, 3000)) / 3000 * 1e6
    print(f"build a status (validated): {us(lambda: RobotStatus(**fields)):.1f} us CPU")
    print(f"{'form':>22} {'bytes':>6} {'write us':>9} {'read us':>8}")
    for name, write in forms:
        text = write()
        print(f"{name:>22} {len(text.encode()):>6} {us(write):>9.1f} {us(partial(RobotStatus.from_json, text)):>8.1f}")


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--robots", type=int, nargs="*", default=[10, 30, 100])
    p.add_argument("--seconds", type=float, default=60.0, help="simulated seconds per fleet size (default 60)")
    p.add_argument("--rate", type=float, default=10.0, help="steps per simulated second (default 10)")
    p.add_argument("--planner", default="md-departure,prior",
                   help="one-shot planners of each round, tried in turn (default md-departure,prior)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--ros", action="store_true", help="also publish every status with rclpy")
    p.add_argument("--profile", type=int, nargs="?", const=25, default=0, help="print the top cProfile functions")
    p.add_argument("--node", type=float, default=0.0,
                   help="run the fleet-sim node on a sim clock at this rate x real time instead (0: off)")
    p.add_argument("--codec", action="store_true", help="only the status codec: bytes and CPU us per status")
    opts = p.parse_args()
    if opts.codec:
        codec()
        return
    if opts.node:
        print(f"fleet-sim node, sim clock at {opts.node:g}x, {opts.seconds:g} simulated s per size")
        print(f"{'N':>4} {'sim s':>6} {'CPU ms/sim s':>12} {'ms/robot':>8} {'rate':>6} {'steps/sim s':>11} "
              f"{'CPU ms/step':>11}")
        for n in opts.robots:
            r = run_node(n, opts)
            print(f"{r['n']:>4} {r['sim_s']:>6.0f} {r['total']:>12.1f} {r['per_robot']:>8.2f} {r['rate']:>5.1f}x "
                  f"{r['steps']:>11.1f} {r['total'] / max(r['steps'], 1e-9):>11.1f}", flush=True)
        return
    print(f"SimFleet at {opts.rate:g} steps/s, {opts.seconds:g} simulated s per size"
          + (", statuses published with rclpy" if opts.ros else ""))
    print(f"{'N':>4} {'sim s':>6} {'CPU ms/sim s':>12} {'step':>7} {'encode':>7} {'publish':>7} "
          f"{'ms/robot':>8} {'B/status':>8} {'driving':>7}")
    for n in opts.robots:
        r = run(n, opts)
        q = r["parts"]
        print(f"{r['n']:>4} {r['sim_s']:>6.0f} {r['total']:>12.1f} {q['step']:>7.1f} {q['encode']:>7.1f} "
              f"{q['publish']:>7.1f} {r['per_robot']:>8.2f} {r['bytes']:>8.0f} {r['driving']:>7.0%}", flush=True)


if __name__ == "__main__":
    main()
