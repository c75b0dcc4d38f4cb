#!/usr/bin/env bash
# Run the test suite in the project virtualenv (created or refreshed first by scripts/setup.sh).
# Extra arguments go to pytest, e.g. `scripts/test.sh -k warehouse -x`.
# DDS stays on this machine: ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, and a ROS_DOMAIN_ID of the
# caller's choosing or a random one in 1..100 so parallel runs do not see each other's nodes.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

bash scripts/setup.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((RANDOM % 100 + 1))}"
echo "test.sh: ROS_DOMAIN_ID=$ROS_DOMAIN_ID ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE"
# exec: pytest's exit status is ours (5 = no tests collected counts as a failure)
exec .venv/bin/python -m pytest test -q "$@"
