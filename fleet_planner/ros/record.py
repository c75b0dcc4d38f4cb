"""Recorded runs (``fleet-record``, ``fleet-demo --record run.mcap``): the fleet's topics written
as they go over the wire into an MCAP file with ROS 2 message encoding, the format of
``ros2 bag record -s mcap`` (MCAP's ``ros2`` profile: CDR messages, ``ros2msg`` schemas, each
channel's offered QoS), readable by ``ros2 bag`` and Foxglove; :mod:`.replay` draws one.

:class:`McapRecorder` writes (the messages arrive serialized: the node subscribes raw, so nothing is
decoded and encoded again); :class:`RecorderNode` subscribes the fleet topics (and every robot's
timed path as it appears) and hands it each message stamped with its ROS clock (simulated time with
``use_sim_time:=true``, as ``ros2 bag record --use-sim-time``)::

    fleet-record run.mcap --ros-args -p use_sim_time:=true
"""
from __future__ import annotations

import argparse
import os
import re
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import IO, Any

import rclpy
from mcap.writer import CompressionType, Writer
from nav_msgs.msg import OccupancyGrid
from nav_msgs.msg import Path as PathMsg
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.entry import run_node
from msg_schemas import topics

#: what a run is: (topic, message type, QoS the recorder subscribes with); plus every robot's timed path
RECORDED: tuple[tuple[str, Any, QoSProfile], ...] = (
    (topics.TASKS, String, topics.TASKS_QOS),
    (topics.TASK_EVENTS, String, topics.TASK_EVENTS_QOS),
    (topics.ROBOT_STATUS, String, topics.ROBOT_STATUS_QOS),
    (topics.OBSTACLES, String, topics.OBSTACLES_QOS),
    (topics.SCHEDULE, String, topics.SCHEDULE_QOS),
    (topics.WAIT_MESSAGES, String, topics.WAIT_MESSAGES_QOS),
    (topics.MARKERS, MarkerArray, topics.MARKERS_QOS),
    (topics.MAP, OccupancyGrid, topics.MAP_QOS),
)
_TIMED_PATH = re.compile(r"^/robots/[A-Za-z0-9_]+/timed_path$")
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
               "uint32", "int64", "uint64", "string", "wstring"}
_SEPARATOR = "=" * 80


def type_name(msg_type: Any) -> str:
    """``pkg/msg/Name`` of a ROS message class."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


def _msg_file(package: str, name: str) -> Path:
    """The .msg file of ``package/name``: in the ament prefixes, else beside this Python (the wheels)."""
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    for prefix in prefixes:
        f = Path(prefix) / "share" / package / "msg" / f"{name}.msg"
        if f.is_file():
            return f
    raise FileNotFoundError(f"no {package}/msg/{name}.msg under {', '.join(prefixes)}")


def message_definition(msg_type: Any) -> str:
    """The ``ros2msg`` schema of a message type as rosbag2 writes it: its .msg text, then the text of
    every type it uses (depth first, each once) after a line of ``=`` and ``MSG: pkg/Name``."""
    package, _, name = type_name(msg_type).split("/")
    order: list[tuple[str, str]] = []
    seen: set[tuple[str, str]] = set()

    def visit(pkg: str, nm: str) -> None:
        text = _msg_file(pkg, nm).read_text()
        order.append((f"{pkg}/{nm}", text))
        for line in text.splitlines():
            words = line.split("#", 1)[0].split()
            if len(words) < 2 or "=" in words[1]:
                continue  # blank, comment or constant
            base = re.sub(r"\[.*\]$", "", words[0]).split("<=")[0]
            if base in _PRIMITIVES:
                continue
            parts = base.split("/")
            dep = (parts[0], parts[-1]) if len(parts) > 1 else (pkg, parts[0])
            if dep not in seen:
                seen.add(dep)
                visit(*dep)

    seen.add((package, name))
    visit(package, name)
    main_text = order[0][1]
    return main_text + "".join(f"\n{_SEPARATOR}\nMSG: {full}\n{text}" for full, text in order[1:])


def qos_yaml(qos: QoSProfile) -> str:
    """A QoS profile as rosbag2 lists a channel's ``offered_qos_profiles`` (rmw enum values)."""
    forever = "{sec: 2147483647, nsec: 4294967295}"
    return (f"- history: {int(qos.history.value)}\n  depth: {int(qos.depth)}\n"
            f"  reliability: {int(qos.reliability.value)}\n  durability: {int(qos.durability.value)}\n"
            f"  deadline: {forever}\n  lifespan: {forever}\n  liveliness: 1\n"
            f"  liveliness_lease_duration: {forever}\n  avoid_ros_namespace_conventions: false\n")


class McapRecorder:
    """Writes serialized ROS 2 messages (CDR) to an MCAP file, one channel per topic, one schema per type."""

    def __init__(self, out: str | Path | IO[bytes]):
        self._file: IO[bytes] = open(out, "wb") if isinstance(out, (str, Path)) else out  # noqa: SIM115
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library="fleet_planner fleet-record")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self.count = 0
        self.closed = False

    def add_topic(self, topic: str, msg_type: Any, qos: QoSProfile) -> None:
        if topic in self._channels:
            return
        name = type_name(msg_type)
        if name not in self._schemas:
            self._schemas[name] = self._writer.register_schema(name=name, encoding="ros2msg",
                                                               data=message_definition(msg_type).encode())
        self._channels[topic] = self._writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=self._schemas[name],
            metadata={"offered_qos_profiles": qos_yaml(qos)})
        self._seq[topic] = 0

    def has(self, topic: str) -> bool:
        """Whether ``topic`` (its full name) has a channel."""
        return topic in self._channels

    def written(self, topic: str) -> int:
        """How many messages were written on ``topic`` (its full name)."""
        return self._seq.get(topic, 0)

    def write(self, topic: str, data: bytes, stamp_ns: int) -> None:
        """One serialized message on ``topic`` (added before) at ``stamp_ns``."""
        if self.closed:
            return
        self._seq[topic] += 1
        self._writer.add_message(self._channels[topic], log_time=stamp_ns, data=data, publish_time=stamp_ns,
                                 sequence=self._seq[topic])
        self.count += 1

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._writer.finish()
            self._file.close()


class RecorderNode(Node):
    """Records the fleet's topics into ``output`` (parameter; an MCAP file) until it is destroyed."""

    def __init__(self, name: str = "fleet_recorder", *, output: str | Path | None = None,
                 extra: Iterable[tuple[str, Any, QoSProfile]] = (), **kwargs: Any):
        super().__init__(name, **kwargs)
        out = self.declare_parameter("output", str(output or "run.mcap")).value
        self.output = Path(out)
        self.recorder = McapRecorder(self.output)
        # the timed paths of this fleet's robots (this node's namespace)
        self._timed_path = re.compile("^" + re.escape(self.get_namespace().rstrip("/")) + _TIMED_PATH.pattern[1:])
        for topic, msg_type, qos in (*RECORDED, *extra):
            self._subscribe(topic, msg_type, qos)
        self._discover = self.create_timer(0.5, self._find_paths)
        self.get_logger().info(f"recording the fleet's topics to {self.output}")

    def _subscribe(self, topic: str, msg_type: Any, qos: QoSProfile) -> None:
        topic = self.resolve_topic_name(topic)  # channels carry full names (``/site_a/fleet/...`` in a namespace)
        self.recorder.add_topic(topic, msg_type, qos)

        def on_message(data: bytes) -> None:
            try:
                self.recorder.write(topic, data, self.get_clock().now().nanoseconds)
            except Exception as exc:  # a full disk must not take the fleet down
                self.get_logger().error(f"cannot record {topic}: {exc!r}", throttle_duration_sec=5.0)

        create_draining_subscription(self, msg_type, topic, on_message, qos, raw=True)

    def _find_paths(self) -> None:
        """Every robot's timed path, as its topic appears."""
        for topic, types in self.get_topic_names_and_types():
            if self._timed_path.match(topic) and "nav_msgs/msg/Path" in types and not self.recorder.has(topic):
                self._subscribe(topic, PathMsg, topics.TIMED_PATH_QOS)

    def destroy_node(self) -> None:
        self.recorder.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    argv = sys.argv if args is None else args
    parser = argparse.ArgumentParser(prog="fleet-record", description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("output", type=Path, help="the MCAP file to write (e.g. run.mcap)")
    opts = parser.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    run_node(lambda: RecorderNode(parameter_overrides=[Parameter("output", value=str(opts.output))]), argv,
             prog="fleet-record")


if __name__ == "__main__":
    main()
