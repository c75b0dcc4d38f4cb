#!/usr/bin/env bash
# The demo, the main job: the planner node and a mixed fleet of robot agents (all four kinds) on the
# default warehouse, over real DDS on this machine, with a simulated clock ~10x faster than real
# time. A stream of pick-and-place jobs goes in on /fleet/tasks; a progress bar runs; at the end a
# summary (jobs done, completion time, speeds, closest approach of two robots) and a picture of the
# run in out/fleet_demo.png. Before the fleet starts, the default scenario is planned offline once
# (out/plan.json, out/plan.png: the paths, the (M,D) view and the schedule).
# Extra arguments go to fleet-demo (e.g. --mode procs, --jobs 40; see fleet-demo -h).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((RANDOM % 100 + 1))}"
mkdir -p out
echo "== offline plan of the default scenario (fleet-plan)"
.venv/bin/fleet-plan config/default_scenario.yaml --out out/plan.json --plot out/plan.png --quiet
echo "== the fleet on ROS 2 (fleet-demo, ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
exec .venv/bin/fleet-demo --out out "$@"
