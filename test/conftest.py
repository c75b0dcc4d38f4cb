"""Shared test set-up.

At import time, before any test module can import rclpy, DDS is kept on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) and on a domain of its own: the runner's
``ROS_DOMAIN_ID`` (scripts/test.sh picks one) or else a random one in 1..100, so that test runs
in parallel do not discover each other's nodes.

``ROS_HOME`` is a fresh folder for the run, for each module and for each test (autouse fixtures):
a planner started without a ``job_store`` keeps its jobs in ``$ROS_HOME/fleet_planner/jobs.sqlite``,
so no test sees the jobs of another test, of an earlier run, or of a run in parallel (child
processes inherit the variable).
"""
from __future__ import annotations

import atexit
import os
import random
import shutil
import tempfile

import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
os.environ["ROS_HOME"] = tempfile.mkdtemp(prefix="fleet_ros_home_")
atexit.register(shutil.rmtree, os.environ["ROS_HOME"], True)


@pytest.fixture(scope="module", autouse=True)
def _ros_home_of_the_module(tmp_path_factory):
    """A ROS home of its own for each module (planners of module-scoped fixtures)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ROS_HOME", str(tmp_path_factory.mktemp("ros_home")))
        yield


@pytest.fixture(autouse=True)
def _ros_home_of_the_test(tmp_path_factory, monkeypatch):
    """A ROS home of its own for each test (its planners' default job store)."""
    monkeypatch.setenv("ROS_HOME", str(tmp_path_factory.mktemp("ros_home")))


@pytest.fixture(scope="session")
def ros_context():
    """One initialised rclpy Context for the whole run (shut down at the end).

    Tests create their nodes with ``rclpy.create_node(name, context=ros_context)`` (or pass the
    context to their executor) and destroy them when done.
    """
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)
