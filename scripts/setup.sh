#!/usr/bin/env bash
# Create or refresh the development virtualenv .venv at the repo root:
#   python3.11 (or python3 >= 3.10), pip, requirements.txt (ROS 2 Jazzy wheels, numpy, shapely, ...),
#   then this package in editable mode, so that .venv/bin/fleet-plan and friends exist.
# Idempotent: reuses a working .venv, and skips the installs while its stamp file is newer than
# setup.py, setup.cfg, package.xml and requirements.txt (a second run takes well under a second).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

VENV=.venv
STAMP="$VENV/.fleet_planner-installed"
INPUTS=(setup.py setup.cfg package.xml requirements.txt)

# a python >= 3.10; 3.11 preferred (what the project is developed and tested with)
pick_python() {
    local candidate
    for candidate in python3.11 python3; do
        if command -v "$candidate" >/dev/null 2>&1 \
            && "$candidate" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null; then
            echo "$candidate"
            return 0
        fi
    done
    return 1
}

venv_works() {
    [[ -x "$VENV/bin/python" ]] \
        && "$VENV/bin/python" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null
}

if ! venv_works; then
    if ! PYTHON=$(pick_python); then
        echo "setup.sh: needs python3.11 (or python3 >= 3.10) on PATH; found none" >&2
        exit 1
    fi
    echo "setup.sh: creating $VENV with $PYTHON ($("$PYTHON" --version 2>&1))"
    [[ "$PYTHON" == python3.11 ]] || echo "setup.sh: python3.11 not found, using $PYTHON instead"
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
fi

# the web console's browser test (test/test_console.py): Debian's chromium and its chromedriver,
# installed with apt when missing (CI runs as root); browser downloads by tool installers do not work here
need_browser() { ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; }
if need_browser; then
    if [[ $(id -u) -eq 0 ]] && command -v apt-get >/dev/null 2>&1; then
        echo "setup.sh: installing chromium and chromium-driver with apt (output in $VENV/apt.log)"
        if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
                chromium chromium-driver; } >"$VENV/apt.log" 2>&1; then
            echo "setup.sh: apt-get could not install chromium; the end of $VENV/apt.log:" >&2
            tail -n 20 "$VENV/apt.log" >&2
            exit 1
        fi
    else
        echo "setup.sh: chromium and chromedriver are missing (apt-get install chromium chromium-driver as root);" \
             "test/test_console.py needs them" >&2
    fi
fi

up_to_date() {
    [[ -f "$STAMP" && -x "$VENV/bin/fleet-plan" ]] || return 1
    local f
    for f in "${INPUTS[@]}"; do
        [[ "$STAMP" -nt "$f" ]] || return 1
    done
}

if up_to_date; then
    echo "setup.sh: $VENV is up to date ($("$VENV/bin/python" --version 2>&1))"
    exit 0
fi

LOG="$VENV/setup.log"
echo "setup.sh: installing into $VENV ($("$VENV/bin/python" --version 2>&1)); pip's output goes to $LOG"
: >"$LOG"
pip_install() {
    if ! "$VENV/bin/python" -m pip --disable-pip-version-check install "$@" >>"$LOG" 2>&1; then
        echo "setup.sh: 'pip install $*' failed; the end of $LOG:" >&2
        tail -n 40 "$LOG" >&2
        exit 1
    fi
}
pip_install --upgrade pip
# setuptools >= 64 and wheel build the editable install without build isolation (no downloads)
pip_install "setuptools>=64" wheel
pip_install -r requirements.txt
pip_install --no-build-isolation --no-deps -e .
if [[ ! -x "$VENV/bin/fleet-plan" ]]; then
    echo "setup.sh: installed, but $VENV/bin/fleet-plan is missing" >&2
    exit 1
fi
touch "$STAMP"
echo "setup.sh: done; console scripts in $VENV/bin (fleet-plan, planner, robot_agent, fleet-demo, fleet-submit)"
