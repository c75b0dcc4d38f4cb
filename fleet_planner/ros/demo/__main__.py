"""``python -m fleet_planner.ros.demo``: the same as ``fleet-demo``."""
from fleet_planner.ros.demo.cli import main

main()
