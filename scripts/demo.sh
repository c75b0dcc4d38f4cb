#!/usr/bin/env bash
# The demo: plan the default scenario (12 robots in the default warehouse) offline, write the plan
# to out/plan.json and a picture of it to out/plan.png. Extra arguments go to fleet-plan.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((RANDOM % 100 + 1))}"
mkdir -p out
exec .venv/bin/fleet-plan config/default_scenario.yaml --out out/plan.json --plot out/plan.png "$@"
