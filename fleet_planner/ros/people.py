"""Simulated people for the demo and the tests (``fleet-people``): the intelligent space's view of
people walking in the warehouse, published as ``fleet/obstacle@1`` records on ``/fleet/obstacles``.

A thin node around :class:`~fleet_planner.fleet.people.Walker`: every ``1 / rate_hz`` s of ROS time
(simulated time with ``use_sim_time:=true``) each walker steps and its record goes out; a walker
that is gone is reported ``cleared`` once. It hears the robots' statuses, so that its people do not
walk into a robot standing still (and, with ``yields:=true``, give way to moving ones too). Walkers
may be handed in (tests); otherwise ``count`` people walk at random between free points of the
warehouse (``seed``, ``speed``, ``radius``)::

    fleet-people --ros-args -p count:=3 -p use_sim_time:=true
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from std_msgs.msg import String

from fleet_planner.fleet.people import PERSON_RADIUS, WALKING_SPEED, Walker, random_people
from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.entry import run_node
from fleet_planner.warehouse import Warehouse, load_warehouse
from msg_schemas import topics
from msg_schemas.convert import string_to_record
from msg_schemas.records import ObstacleRecord, RecordError, RobotStatus

#: a robot's status older than this (s of ROS time) no longer says where it is
ROBOT_STALE_S = 2.0


def _double(description: str, lo: float, hi: float) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, read_only=True,
                               floating_point_range=[FloatingPointRange(from_value=lo, to_value=hi)])


class PeopleNode(Node):
    """Simulated people publishing themselves as obstacles (see the module docstring)."""

    def __init__(self, name: str = "people", *, walkers: Sequence[Walker] | None = None,
                 warehouse: Warehouse | None = None, **kwargs: Any):
        super().__init__(name, **kwargs)
        count = self.declare_parameter("count", 2, ParameterDescriptor(
            description="people walking at random (when none are handed in)", read_only=True,
            integer_range=[IntegerRange(from_value=0, to_value=100, step=1)])).value
        seed = self.declare_parameter("seed", 1, ParameterDescriptor(
            description="seed of their walks", read_only=True)).value
        rate = self.declare_parameter("rate_hz", 10.0, _double("records per second of ROS time", 0.5, 100.0)).value
        speed = self.declare_parameter("speed", WALKING_SPEED, _double("walking speed (m/s)", 0.1, 3.0)).value
        radius = self.declare_parameter("radius", PERSON_RADIUS, _double("a person's disc (m)", 0.1, 1.0)).value
        wh_file = self.declare_parameter("warehouse_file", "", ParameterDescriptor(
            description="warehouse YAML (empty: the shipped config/warehouse.yaml)", read_only=True)).value
        if walkers is None:
            warehouse = warehouse if warehouse is not None else load_warehouse(wh_file or None)
            walkers = random_people(warehouse.grid, count, seed, speed=speed, radius=radius,
                                    avoid=[s.pose for s in warehouse.stations.values()])
        self.walkers = list(walkers)
        self._robots: dict[str, RobotStatus] = {}
        self._last: float | None = None
        self._reported_gone: set[str] = set()
        self._pub = self.create_publisher(String, topics.OBSTACLES, topics.OBSTACLES_QOS)
        create_draining_subscription(self, String, topics.ROBOT_STATUS, self._on_status, topics.ROBOT_STATUS_QOS)
        self._timer = self.create_timer(1.0 / rate, self._on_timer)
        self.get_logger().info(f"{len(self.walkers)} simulated people, {rate:g} records per second each")

    def _on_status(self, msg: String) -> None:
        try:
            st = string_to_record(msg, RobotStatus)
        except RecordError:
            return  # the planner and agents say what is wrong with it
        last = self._robots.get(st.id)
        if last is None or st.stamp >= last.stamp:
            self._robots[st.id] = st

    def _on_timer(self) -> None:
        now = self.get_clock().now().nanoseconds / 1e9
        try:
            dt = 0.0 if self._last is None else max(0.0, now - self._last)
            self._last = now
            robots = [(s.x, s.y, s.radius, (s.vx ** 2 + s.vy ** 2) ** 0.5) for s in self._robots.values()
                      if now - s.stamp <= ROBOT_STALE_S]
            for w in self.walkers:
                w.step(now - dt, dt, robots)
                if w.present:
                    self._pub.publish(String(data=w.record(now).to_json()))
                elif w.gone and w.id not in self._reported_gone:
                    self._reported_gone.add(w.id)
                    gone = ObstacleRecord(id=w.id, kind="person", x=w.x, y=w.y, radius=w.radius, stamp=now,
                                          cleared=True)
                    self._pub.publish(String(data=gone.to_json()))
        except Exception as exc:  # a bad step must not stop the others' records
            self.get_logger().error(f"people step failed: {exc!r}", throttle_duration_sec=5.0)


def main(args: list[str] | None = None) -> None:
    run_node(PeopleNode, args, prog="fleet-people")


if __name__ == "__main__":
    main()
