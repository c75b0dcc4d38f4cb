"""The habits CI enforces: ruff on the whole tree and mypy on the pure core and the ROS glue (settings in
pyproject.toml)."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
#: the pure core: everything that must run without ROS (docs/ARCHITECTURE.md, "Layers")
PURE_CORE = ["fleet_planner", "msg_schemas/records.py", "msg_schemas/__init__.py"]
#: mypy checks these: the pure core and, inside fleet_planner, the ROS glue (fleet_planner/ros: since
#: session 25; rclpy's own annotations where installed)
MYPY_PATHS = PURE_CORE


def _tool(name: str) -> str:
    exe = Path(sys.executable).with_name(name)
    found = str(exe) if exe.exists() else shutil.which(name)
    if not found:
        pytest.fail(f"{name} is not installed (scripts/setup.sh installs it from requirements.txt)")
    return found


def _run(cmd: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600)


def test_ruff_finds_nothing():
    done = _run([_tool("ruff"), "check", "--no-cache", "."])
    assert done.returncode == 0, done.stdout[-6000:] + done.stderr[-2000:]


def test_mypy_on_the_pure_core_and_the_ros_glue_finds_nothing():
    done = _run([_tool("mypy"), "--no-incremental", "--cache-dir", "/dev/null"] + MYPY_PATHS)
    assert done.returncode == 0, done.stdout[-6000:] + done.stderr[-2000:]
