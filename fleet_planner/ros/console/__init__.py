"""``fleet-console``: the web operator console, a node that serves a page on localhost.

    fleet-console --ros-args -p port:=8080 [-p warehouse_file:=...] [-p use_sim_time:=true]

The page shows a live map of the warehouse (robots, the rest of their legs and where they hold,
obstacles, stations, parking spots), the jobs with their states, and has a button or form for
every operator command (pause and resume a robot or the fleet, e-stop and release, cancel a job,
change its priority, send a robot to a station, manual drive with a drive pad) and for submitting
a job. The state is pushed over a websocket a few times a second. The node (:mod:`.node`) hears
the fleet's topics and acts through the operator's interfaces (:mod:`fleet_planner.ros.operate`);
the web server (:mod:`.server`, aiohttp) runs in a thread beside the executor.
"""
from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from rclpy.executors import Executor
from rclpy.parameter import Parameter

from fleet_planner.ros.console.node import ConsoleNode
from fleet_planner.ros.console.server import ConsoleServer
from fleet_planner.ros.entry import CONFIG_ERRORS, run_node, spin_node
from fleet_planner.warehouse import Warehouse

__all__ = ["ConsoleNode", "ConsoleServer", "attach_console", "main"]


def attach_console(executor: Executor, warehouse: Warehouse, parking: Sequence[tuple[float, float]], port: int,
                   **node_kwargs: Any) -> tuple[ConsoleNode, ConsoleServer]:
    """A console node on ``executor`` (simulated time) and its page served on localhost:``port``
    (0: any free port; the URL is ``server.url``): how the demo starts one."""
    node = ConsoleNode(warehouse=warehouse, parking=parking,
                       parameter_overrides=[Parameter("use_sim_time", value=True)], **node_kwargs)
    executor.add_node(node)
    server = ConsoleServer(node, "127.0.0.1", port, node.rate_hz)
    server.start()
    return node, server


def serve(node: ConsoleNode) -> int | None:
    """Serve ``node``'s page while it spins; prints the URL."""
    server = ConsoleServer(node, node.host, node.port, node.rate_hz)
    url = server.start()
    print(f"fleet-console: {url}", flush=True)
    node.get_logger().info(f"serving the operator console on {url}")
    try:
        spin_node(node)
    finally:
        server.stop()
    return None


def main(args: list[str] | None = None) -> None:
    # a bad parameter or a port in use: one line naming it, exit status 2
    run_node(ConsoleNode, sys.argv if args is None else args, prog="fleet-console", spin=serve,
             errors=(*CONFIG_ERRORS, OSError))
