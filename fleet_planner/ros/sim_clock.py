"""A simulated clock: publishes ``rosgraph_msgs/Clock`` on ``/clock``, ``rate`` times faster than
the wall clock, so that nodes started with ``use_sim_time:=true`` run the fleet faster than real time.

Every tick the simulated time advances by ``step_s``, and ticks come every ``step_s / rate`` s of
wall time. When the process is too busy to tick on time (as when it shares one executor with the
whole fleet), simulated time slows down with it instead of jumping, so no node finds the world
moved on while it was computing. As a process of its own (``main``, the demo's process mode) it
may make up ticks lost to a loaded machine's scheduling (a late wake-up), one extra step per tick
while it is at most ``catch_up_s`` behind (``--catch-up``); and with ``max_lead_s`` (``--max-lead``)
it is held while the newest robot status it hears is more than that behind it: a simulator of the
robots (fleet-sim) starved of CPU holds simulated time instead of its robots driving blind, their
statuses silent (the planner would take them for offline). The demo's process mode uses both.
Keep ``step_s`` at most the period of the fastest ROS-time timer
of the fleet (the agents' 0.1 s status timer), or those timers fire less often than asked::

    python -m fleet_planner.ros.sim_clock --rate 5          # 5x real time
"""
from __future__ import annotations

import argparse
import re
import sys
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.time_source import CLOCK_TOPIC
from rosgraph_msgs.msg import Clock as ClockMsg
from std_msgs.msg import String

from fleet_planner.ros.entry import run_node
from msg_schemas import topics
from msg_schemas.convert import ns_to_stamp

_STAMP = re.compile(r'"stamp"\s*:\s*(-?[0-9][0-9.eE+-]{0,30})')


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
        lead = self.declare_parameter("max_lead_s", 0.0, _double(
            "simulated seconds the clock may run ahead of the newest robot status it hears (a starved "
            "simulator holds the clock instead of its robots driving blind); 0: never held", 0.0, 60.0)).value
        self._grace = self.declare_parameter("lead_grace_s", 1.0, _double(
            "wall seconds without any robot status after which the clock runs on unheld (no robots yet, or "
            "none left)", 0.01, 60.0)).value
        if self.get_parameter("use_sim_time").value:
            raise ValueError("use_sim_time: the sim clock cannot run on simulated time itself")
        self._step_ns = round(step * 1e9)
        self.now_ns = round(start * 1e9)
        self._rate, self._catch_up_ns = rate, round(catch_up * 1e9)
        self._wall = Clock(clock_type=ClockType.STEADY_TIME)
        self._origin = (self._wall.now().nanoseconds, self.now_ns)   # (wall ns, simulated ns) in step
        self._pub = self.create_publisher(ClockMsg, CLOCK_TOPIC, QoSProfile(depth=10))
        self._lead_ns = round(lead * 1e9)
        self._robots_ns, self._robots_wall = -1, -float("inf")   # newest status stamp heard, and when
        self.held = 0   # ticks held back for the robots
        if self._lead_ns > 0:  # the latest status only (keep last 1): a handful of callbacks per tick at most
            self.create_subscription(String, topics.ROBOT_STATUS, self._on_status,
                                     QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        self._timer = self.create_timer(step / rate, self._tick, clock=self._wall)
        self._publish()
        self.get_logger().info(f"simulated clock at {rate:g}x real time from t = {start:g} s")

    def _on_status(self, msg: String) -> None:
        m = _STAMP.search(msg.data)
        if m is None:
            return
        try:
            stamp = round(float(m.group(1)) * 1e9)
        except (ValueError, OverflowError):
            return
        if stamp <= self.now_ns + self._step_ns:  # (a stamp from another clock ahead of ours: ignored)
            self._robots_ns = max(self._robots_ns, stamp)
            self._robots_wall = self._wall.now().nanoseconds / 1e9

    def _held(self) -> bool:
        """The robots' simulator lags more than max_lead_s behind (it was starved of CPU): wait for it."""
        if self._lead_ns <= 0 or self._robots_ns < 0:
            return False
        if self._wall.now().nanoseconds / 1e9 - self._robots_wall > self._grace:
            return False
        return self.now_ns + self._step_ns > self._robots_ns + self._lead_ns

    def _tick(self) -> None:
        if self._held():
            self.held += 1
            self._origin = (self._wall.now().nanoseconds, self.now_ns)   # no catching up on a held tick
            return
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
    parser.add_argument("--catch-up", type=float, default=0.0,
                        help="simulated seconds of lost ticks made up, one extra step per tick (default 0: lost "
                             "ticks slow simulated time down)")
    parser.add_argument("--max-lead", type=float, default=0.0,
                        help="simulated seconds the clock may run ahead of the newest robot status (default 0: "
                             "never held)")
    parser.add_argument("--lead-grace", type=float, default=1.0,
                        help="wall seconds without any robot status after which a held clock runs on (default 1)")
    opts = parser.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    overrides = [Parameter("rate", value=opts.rate), Parameter("step_s", value=opts.step),
                 Parameter("start_s", value=opts.start), Parameter("catch_up_s", value=opts.catch_up),
                 Parameter("max_lead_s", value=opts.max_lead), Parameter("lead_grace_s", value=opts.lead_grace)]
    run_node(lambda: SimClock(parameter_overrides=overrides), argv, prog="sim_clock")


if __name__ == "__main__":
    main()
