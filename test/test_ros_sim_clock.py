"""The simulated clock held by a lagging robot simulator (``max_lead_s``) and making up lost ticks
(``catch_up_s``): sim_clock.py as the demo's process mode runs it."""
import time
from contextlib import contextmanager

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import String

from fleet_planner.fleet import DispatchParams
from fleet_planner.ros.demo.bringup import CLOCK_LEAD_GRACE_S, clock_lead_grace, planner_param
from fleet_planner.ros.sim_clock import SimClock
from fleet_planner.warehouse import config_path
from msg_schemas import topics


def _spin(executor, seconds: float, every=None) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.005)
        if every is not None:
            every()


@contextmanager
def _clock_and_robots(ros_context, name: str, robots_name: str, **params):
    """A SimClock ``name`` with ``params`` and a node publishing robot statuses, on one executor:
    (clock, status publisher, executor); both nodes destroyed afterwards."""
    clock = SimClock(name, context=ros_context,
                     parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    robots = rclpy.create_node(robots_name, context=ros_context)
    pub = robots.create_publisher(String, topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(clock)
    executor.add_node(robots)
    try:
        yield clock, pub, executor
    finally:
        executor.shutdown()
        clock.destroy_node()
        robots.destroy_node()


def test_a_lagging_robot_simulator_holds_the_clock_and_a_silent_one_does_not(ros_context):
    with _clock_and_robots(ros_context, "clock_lead_test", "lagging_robots",
                           rate=20.0, max_lead_s=0.5, lead_grace_s=0.5) as (clock, pub, executor):
        # a simulator stuck at t = 0.2 s: the clock stops 0.5 s ahead of it (20x: 1 s wall would be 20 s)
        stuck = '{"id":"r1","stamp":0.2}'
        _spin(executor, 1.0, lambda: pub.publish(String(data=stuck)))
        assert clock.held > 0
        assert clock.now_ns / 1e9 <= 0.2 + 0.5 + 0.1 + 1e-9
        # silent for longer than lead_grace_s (no robots, or none left): the clock runs on
        _spin(executor, 1.2)
        assert clock.now_ns / 1e9 > 3.0


def test_without_a_lead_the_clock_is_never_held(ros_context):
    with _clock_and_robots(ros_context, "clock_free_test", "old_robots", rate=20.0) as (clock, pub, executor):
        _spin(executor, 0.5, lambda: pub.publish(String(data='{"id":"r1","stamp":0.0}')))
        assert clock.held == 0 and clock.now_ns / 1e9 > 2.0


def _silence_after_status(ros_context, name: str, grace: float, silent_s: float) -> float:
    """Simulated seconds by which a clock at 20x, held 0.5 s ahead of the robots with ``grace``,
    runs past the last status of a simulator that then stays silent ``silent_s`` wall seconds."""
    with _clock_and_robots(ros_context, name, f"{name}_robots",
                           rate=20.0, max_lead_s=0.5, lead_grace_s=grace) as (clock, pub, executor):
        _spin(executor, 0.3, lambda: pub.publish(String(data='{"id":"r1","stamp":0.2}')))
        _spin(executor, silent_s)   # the simulator starved: no status at all
        return clock.now_ns / 1e9 - 0.2


def test_the_process_fleets_clock_waits_out_a_starved_simulator_so_no_robot_looks_offline(ros_context):
    # the demo's clock (bringup.start_processes): a fleet-sim starved 1.5 wall s (30 simulated s at
    # 20x) stays within the planner's offline timeout of its last status: the clock waited for it
    timeout = planner_param(config_path("planner_params.yaml"), "offline_timeout_s", -1.0)
    assert timeout == DispatchParams().offline_timeout_s == 3.0
    grace = clock_lead_grace(timeout)
    assert grace >= timeout and grace >= CLOCK_LEAD_GRACE_S and clock_lead_grace(60.0) == 60.0
    assert _silence_after_status(ros_context, "clock_grace_test", grace, 1.5) < timeout
    # control: the clock's own default wait (1 wall s) runs on and the planner would count the robots offline
    assert _silence_after_status(ros_context, "clock_short_grace_test", 1.0, 1.5) > timeout
