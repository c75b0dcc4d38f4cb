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

from fleet_planner.ros.console.node import ConsoleNode
from fleet_planner.ros.console.server import ConsoleServer
from fleet_planner.ros.entry import CONFIG_ERRORS, run_node, spin_node

__all__ = ["ConsoleNode", "ConsoleServer", "main"]


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
