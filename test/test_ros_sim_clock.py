"""The simulated clock held by a lagging robot simulator (``max_lead_s``) and making up lost ticks
(``catch_up_s``): sim_clock.py as the demo's process mode runs it."""
import time

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import String

from fleet_planner.ros.sim_clock import SimClock
from msg_schemas import topics


def _spin(executor, seconds: float, every=None) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.005)
        if every is not None:
            every()


def test_a_lagging_robot_simulator_holds_the_clock_and_a_silent_one_does_not(ros_context):
    clock = SimClock("clock_lead_test", context=ros_context, parameter_overrides=[
        Parameter("rate", value=20.0), Parameter("max_lead_s", value=0.5), Parameter("lead_grace_s", value=0.5)])
    robots = rclpy.create_node("lagging_robots", context=ros_context)
    pub = robots.create_publisher(String, topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(clock)
    executor.add_node(robots)
    try:
        # a simulator stuck at t = 0.2 s: the clock stops 0.5 s ahead of it (20x: 1 s wall would be 20 s)
        stuck = '{"id":"r1","stamp":0.2}'
        _spin(executor, 1.0, lambda: pub.publish(String(data=stuck)))
        assert clock.held > 0
        assert clock.now_ns / 1e9 <= 0.2 + 0.5 + 0.1 + 1e-9
        # silent for longer than lead_grace_s (no robots, or none left): the clock runs on
        _spin(executor, 1.2)
        assert clock.now_ns / 1e9 > 3.0
    finally:
        executor.shutdown()
        clock.destroy_node()
        robots.destroy_node()


def test_without_a_lead_the_clock_is_never_held(ros_context):
    clock = SimClock("clock_free_test", context=ros_context, parameter_overrides=[Parameter("rate", value=20.0)])
    robots = rclpy.create_node("old_robots", context=ros_context)
    pub = robots.create_publisher(String, topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(clock)
    executor.add_node(robots)
    try:
        _spin(executor, 0.5, lambda: pub.publish(String(data='{"id":"r1","stamp":0.0}')))
        assert clock.held == 0 and clock.now_ns / 1e9 > 2.0
    finally:
        executor.shutdown()
        clock.destroy_node()
        robots.destroy_node()
