"""Shared test set-up.

At import time, before any test module can import rclpy, DDS is kept on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) and on a domain of its own: the runner's
``ROS_DOMAIN_ID`` (scripts/test.sh picks one) or else a random one in 1..100, so that test runs
in parallel do not discover each other's nodes.
"""
from __future__ import annotations

import os
import random

import pytest

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))


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
