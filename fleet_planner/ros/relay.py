"""The planner's neighbour relay on the wire: every ``period_s`` of ROS time, each robot the fleet
manager knows gets the statuses of the robots within its safety range (and of those its execution
gate watches) on ``/robots/<id>/neighbours`` (``fleet/neighbours@1``); the selection is
:class:`fleet_planner.fleet.neighbours.NeighbourRelay`. A robot with nobody near gets an empty
record only when that changes and then once a second (so a quiet fleet costs little).
"""
from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.publisher import Publisher
from std_msgs.msg import String

from fleet_planner.fleet import FleetManager
from fleet_planner.fleet.neighbours import NeighbourRelay, Watch, no_watch
from msg_schemas import topics

#: a robot with no neighbours gets an (empty) record at least this often (s of ROS time)
EMPTY_EVERY_S = 1.0
_EMPTY_TAIL = '"robots":[]}'
#: wall seconds between two looks at who subscribes to the robots' neighbours topics
LISTENERS_EVERY_S = 1.0


class NeighbourPublisher:
    """Publishes the neighbours records of ``fleet``'s robots from ``node`` every ``period_s``."""

    def __init__(self, node: Node, fleet: FleetManager, period_s: float, sense_m: float = 0.0,
                 watch: Watch = no_watch, refresh: Callable[[], None] | None = None):
        self.node = node
        self.fleet = fleet
        self.relay = NeighbourRelay({k.name: k.max_speed for k in fleet.kinds.values()}, period_s, sense_m, watch)
        self._pubs: dict[str, Publisher] = {}
        self._empty_at: dict[str, float] = {}   # when the last empty record went to a robot
        self.sent = 0
        self._refresh = refresh   # called first at each tick (the planner takes in its waiting statuses)
        self._listeners_at = -float("inf")   # (wall time) when the listeners were last asked for
        self._heard_by: set[str] = set()
        self._timer = node.create_timer(period_s, self._tick)

    @property
    def watch(self) -> Watch:
        return self.relay.watch

    @watch.setter
    def watch(self, fn: Watch) -> None:
        """``fn(robot_id) -> set of robot ids`` its gate watches (relayed to it however far)."""
        self.relay.watch = fn

    def _listeners(self) -> set[str]:
        """The robots whose neighbours topic someone subscribes to (asked of DDS at most once per
        LISTENERS_EVERY_S wall seconds; a robot new to the fleet is asked at once)."""
        wall = time.monotonic()
        robots = self.fleet.robots
        if wall - self._listeners_at >= LISTENERS_EVERY_S or any(rid not in self._pubs for rid in robots):
            self._listeners_at = wall
            self._heard_by = {rid for rid in robots if self._publisher(rid).get_subscription_count() > 0}
        return self._heard_by

    def _tick(self) -> None:
        try:
            listeners = self._listeners()
            if not listeners:  # nobody hears a record (fleet-sim robots, synthetic ones): no work
                return
            if self._refresh is not None:
                self._refresh()
            now = self.node.get_clock().now().nanoseconds / 1e9
            records = self.relay.records([r.status for r in self.fleet.robots.values()], now, only=listeners)
            for rid, text in records.items():
                if text.endswith(_EMPTY_TAIL):
                    last = self._empty_at.get(rid)
                    if last is not None and 0.0 <= now - last < EMPTY_EVERY_S:
                        continue
                    self._empty_at[rid] = now
                else:
                    self._empty_at.pop(rid, None)
                pub = self._publisher(rid)
                if pub.get_subscription_count() == 0:
                    continue  # nobody hears this robot's record (a fleet-sim robot, a synthetic one)
                pub.publish(String(data=text))
                self.sent += 1
        except Exception as exc:  # the relay must never take the planner down
            self.node.get_logger().error(f"neighbour relay failed: {exc!r}", throttle_duration_sec=5.0)

    def _publisher(self, robot_id: str) -> Publisher:
        pub = self._pubs.get(robot_id)
        if pub is None:
            pub = self._pubs[robot_id] = self.node.create_publisher(
                String, topics.neighbours_topic(robot_id), topics.NEIGHBOURS_QOS,
                event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))  # no entity in each wait
        return pub
