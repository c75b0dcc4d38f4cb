#!/usr/bin/env python3
"""How fast the operator's hand acts, on a small in-process fleet (four robots, one of each kind,
the 16 m x 13 m generated warehouse, simulated clock at up to 20x):

* e-stop latency: from the ``/fleet/estop`` SetBool call to every agent's status reporting the
  e-stop, in wall and simulated seconds (``--trials`` times, with robots driving jobs);
* the console's cost: CPU time of one ``ConsoleNode.snapshot`` and its size as JSON;
* the console's push rate over a real websocket (aiohttp client, ``--seconds`` wall seconds).

    .venv/bin/python bench/bench_operator.py [--trials 5] [--seconds 5]
"""
from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import statistics
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))

import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from fleet_planner.fleet import FleetMember  # noqa: E402
from fleet_planner.robots import load_kinds  # noqa: E402
from fleet_planner.ros.console import ConsoleNode, ConsoleServer  # noqa: E402
from fleet_planner.ros.demo.bringup import bring_up  # noqa: E402
from fleet_planner.ros.demo.monitor import spin_until  # noqa: E402
from fleet_planner.ros.operate import OperatorClient  # noqa: E402
from fleet_planner.warehouse import generate_warehouse  # noqa: E402
from msg_schemas import topics  # noqa: E402
from msg_schemas.records import Task  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--trials", type=int, default=5)
    p.add_argument("--seconds", type=float, default=5.0)
    opts = p.parse_args()
    kinds = {n: replace(k, pick_s=2.0, place_s=2.0, lift_s=1.0 if k.lift_s else 0.0) for n, k in load_kinds().items()}
    wh = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)
    members = [FleetMember(f"r{i + 1}", kind, *s.pose, battery=0.9)
               for i, (kind, s) in enumerate(zip(kinds, wh.stations_of("charger")))]
    ctx = Context()
    rclpy.init(context=ctx)
    fleet = bring_up(ctx, wh, kinds, members, 20.0, job_store=":memory:")  # (its job ids repeat from run to run)
    op = OperatorClient("bench_operator", context=ctx)
    console = ConsoleNode(context=ctx, warehouse=wh, parameter_overrides=[Parameter("use_sim_time", value=True)])
    for node in (op, console):
        fleet.executor.add_node(node)
    ex, mon, ids = fleet.executor, fleet.monitor, [m.id for m in members]
    try:
        assert spin_until(ex, lambda: mon.planner_ready() and set(ids) <= set(mon.status), 60)
        for i, (pick, place) in enumerate([("chute_1", "B01-01"), ("chute_2", "B04-02"), ("chute_1", "B02-03"),
                                           ("chute_2", "B03-01")]):
            mon.submit(Task(id=f"M{i}", pick=pick, place=place))
        spin_until(ex, lambda: sum(st.mode == "driving" for st in mon.status.values()) >= 2, 60)
        wall, sim = [], []
        for _ in range(opts.trials):
            t0, s0 = time.monotonic(), mon.now()
            fut = op.call_set_bool(topics.ESTOP_SERVICE, True)
            assert spin_until(ex, lambda: all(mon.status[r].estop for r in ids), 30)
            wall.append(time.monotonic() - t0)
            sim.append(mon.now() - s0)
            spin_until(ex, lambda f=fut: f is not None and f.done(), 10)
            op.call_set_bool(topics.ESTOP_SERVICE, False)
            spin_until(ex, lambda: not any(mon.status[r].estop for r in ids), 30)
            t1 = mon.now()
            spin_until(ex, lambda t1=t1: mon.now() > t1 + 2.0, 30)
        c0 = time.process_time()
        for _ in range(200):
            console.snapshot()
        snap_ms = 1e3 * (time.process_time() - c0) / 200
        size = len(json.dumps(console.snapshot()))
        server = ConsoleServer(console, "127.0.0.1", 0, rate_hz=4.0)
        url = server.start()
        spinner = threading.Thread(target=ex.spin, daemon=True)
        spinner.start()

        async def pushes() -> float:
            import aiohttp
            async with aiohttp.ClientSession() as s, s.ws_connect(url.replace("http", "ws") + "ws") as ws:
                n, t = 0, time.monotonic()
                while time.monotonic() - t < opts.seconds:
                    n += json.loads((await ws.receive()).data)["type"] == "state"
                return n / (time.monotonic() - t)

        rate = asyncio.run(pushes())
        server.stop()
    finally:
        ex.shutdown()
        for node in (op, console, *fleet.nodes):
            node.destroy_node()
        rclpy.try_shutdown(context=ctx)
    print(f"{'measure':36} {'median':>8} {'max':>8}")
    print(f"{'e-stop -> all agents stopped, wall s':36} {statistics.median(wall):8.3f} {max(wall):8.3f}")
    print(f"{'e-stop -> all agents stopped, sim s':36} {statistics.median(sim):8.3f} {max(sim):8.3f}")
    print(f"{'console snapshot, CPU ms':36} {snap_ms:8.3f} {'':>8}  ({size} bytes of JSON, 4 robots)")
    print(f"{'websocket pushes per s (rate_hz 4)':36} {rate:8.2f}")


if __name__ == "__main__":
    main()
