"""A simulated clock: publishes ``rosgraph_msgs/Clock`` on ``/clock``, ``rate`` times faster than
the wall clock, so that nodes started with ``use_sim_time:=true`` run the fleet faster than real time.

Every tick the simulated time advances by ``step_s``, and ticks come every ``step_s / rate`` s of
wall time. When the process is too busy to tick on time (as when it shares one executor with the
whole fleet), simulated time slows down with it instead of jumping, so no node finds the world
moved on while it was computing. As a process of its own (``main``, the demo's process mode) it
makes up ticks lost to a loaded machine's scheduling (a late wake-up), one extra step per tick
while it is at most ``catch_up_s`` behind (``--catch-up``, default 1 s): then the rate is what was
asked unless the machine is starved for good. Keep ``step_s`` at most the period of the fastest ROS-time timer
of the fleet (the agents' 0.1 s status timer), or those timers fire less often than asked::

    python -m fleet_planner.ros.sim_clock --rate 5          # 5x real time
"""
from __future__ import annotations

import argparse
import sys
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from rclpy.time_source import CLOCK_TOPIC
from rosgraph_msgs.msg import Clock as ClockMsg

from fleet_planner.ros.entry import run_node
from msg_schemas.convert import ns_to_stamp


def _double(description: str, lo: float, hi: float) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=True,
                               floating_point_range=[FloatingPointRange(from_value=lo, to_value=hi)])


class SimClock(Node):
    """Publishes simulated time; parameters ``rate`` (x real time), ``step_s`` (simulated seconds per
    tick) and ``start_s`` (simulated time of the first tick). It runs on the wall clock itself."""

    def __init__(self, name: str = "sim_clock", **kwargs: Any):
        super().__init__(name, **kwargs)
        rate = self.declare_parameter("rate", 1.0, _double("simulated seconds per wall second", 0.01, 1000.0)).value
        step = self.declare_parameter("step_s", 0.1, _double("simulated seconds per tick", 0.001, 10.0)).value
        start = self.declare_parameter("start_s", 0.0, _double("simulated time of the first tick", 0.0, 1e9)).value
        catch_up = self.declare_parameter("catch_up_s", 0.0, _double(
            "simulated seconds the clock may fall behind rate x wall time and still make up (by one extra "
            "step per tick at most); 0: a late tick is simply lost", 0.0, 60.0)).value
        if self.get_parameter("use_sim_time").value:
            raise ValueError("use_sim_time: the sim clock cannot run on simulated time itself")
        self._step_ns = round(step * 1e9)
        self.now_ns = round(start * 1e9)
        self._rate, self._catch_up_ns = rate, round(catch_up * 1e9)
        self._wall = Clock(clock_type=ClockType.STEADY_TIME)
        self._origin = (self._wall.now().nanoseconds, self.now_ns)   # (wall ns, simulated ns) in step
        self._pub = self.create_publisher(ClockMsg, CLOCK_TOPIC, QoSProfile(depth=10))
        self._timer = self.create_timer(step / rate, self._tick, clock=self._wall)
        self._publish()
        self.get_logger().info(f"simulated clock at {rate:g}x real time from t = {start:g} s")

    def _tick(self) -> None:
        self.now_ns += self._step_ns
        if self._catch_up_ns > 0:
            # ticks lost to a busy machine (the process woke late) are made up, one extra step per
            # tick at most, as long as the clock is at most catch_up_s behind; further behind, the
            # debt beyond that is forgiven (simulated time slows down rather than jumps)
            wall = self._wall.now().nanoseconds
            due = self._origin[1] + round((wall - self._origin[0]) * self._rate)
            debt = due - self.now_ns
            if debt > self._catch_up_ns:
                self._origin = (wall, self.now_ns + self._catch_up_ns)
                debt = self._catch_up_ns
            if debt > 0:
                self.now_ns += min(debt, self._step_ns)
        self._publish()

    def _publish(self) -> None:
        self._pub.publish(ClockMsg(clock=ns_to_stamp(self.now_ns)))


def main(args: list[str] | None = None) -> None:
    argv = sys.argv if args is None else args
    parser = argparse.ArgumentParser(prog="sim_clock", description=__doc__.split("\n\n")[0])
    parser.add_argument("--rate", type=float, default=1.0, help="simulated seconds per wall second (default 1)")
    parser.add_argument("--step", type=float, default=0.1, help="simulated seconds per tick (default 0.1)")
    parser.add_argument("--start", type=float, default=0.0, help="simulated time of the first tick (default 0)")
    parser.add_argument("--catch-up", type=float, default=1.0,
                        help="simulated seconds of lost ticks made up, one extra step per tick (default 1; 0: "
                             "lost ticks slow simulated time down)")
    opts = parser.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    overrides = [Parameter("rate", value=opts.rate), Parameter("step_s", value=opts.step),
                 Parameter("start_s", value=opts.start), Parameter("catch_up_s", value=opts.catch_up)]
    run_node(lambda: SimClock(parameter_overrides=overrides), argv, prog="sim_clock")


if __name__ == "__main__":
    main()
