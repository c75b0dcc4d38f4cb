"""Conversions between the planner's vocabulary and ROS messages (common_interfaces only).

* timed paths <-> ``nav_msgs/Path``: ``header.stamp`` is the plan's start ``t0`` (ROS time) and
  every pose carries the time the robot is due there, ``t0 + t_i``, exact to the nanosecond;
  orientation is the direction of travel.
* grid maps <-> ``nav_msgs/OccupancyGrid``: origin (0, 0) without rotation, row-major data from
  row 0, which is exactly :class:`~fleet_planner.grid.GridMap`'s convention (no flipping).
* a plan (and robot statuses) -> ``visualization_msgs/MarkerArray`` for RViz.
* records <-> ``std_msgs/String``.

Times given as a ``builtin_interfaces/Time``, an ``rclpy.time.Time`` or float seconds.
"""
from __future__ import annotations

import array
import colorsys
import math
import zlib
from collections.abc import Iterable, Sequence
from typing import TypeVar, cast

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point as PointMsg
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import OccupancyGrid, Path
from std_msgs.msg import ColorRGBA, String
from visualization_msgs.msg import Marker, MarkerArray

from fleet_planner.grid import GridMap, MapError
from fleet_planner.model import TimedPath

from .records import Record, RecordError, RobotStatus

R = TypeVar("R", bound=Record)
NS_PER_S = 1_000_000_000
OCCUPIED = 100
FREE = 0


# -- time -------------------------------------------------------------------------------------------
def stamp_to_ns(stamp: Time | float | int) -> int:
    """Nanoseconds of a ``builtin_interfaces/Time``, an ``rclpy.time.Time`` or seconds."""
    if isinstance(stamp, Time):
        return stamp.sec * NS_PER_S + stamp.nanosec
    if hasattr(stamp, "nanoseconds"):  # rclpy.time.Time, without importing rclpy here
        return int(stamp.nanoseconds)
    if isinstance(stamp, bool) or not isinstance(stamp, (int, float)) or not math.isfinite(stamp):
        raise ValueError(f"a time must be a Time message or finite seconds (got {stamp!r})")
    return round(stamp * NS_PER_S)


def ns_to_stamp(ns: int) -> Time:
    if ns < 0:
        raise ValueError(f"a ROS time cannot be negative (got {ns} ns)")
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


# -- timed paths ----------------------------------------------------------------------------------
def _headings(xy: np.ndarray) -> np.ndarray:
    """Yaw at each point: towards the next point elsewhere, else from the last move, else 0."""
    n = len(xy)
    yaw = np.zeros(n)
    d = np.diff(xy, axis=0)
    moves = np.nonzero(np.hypot(d[:, 0], d[:, 1]) > 0)[0]
    if len(moves) == 0:
        return yaw
    seg_yaw = np.arctan2(d[moves, 1], d[moves, 0])
    nxt = np.searchsorted(moves, np.arange(n))  # first move leaving point i or later
    return np.where(nxt < len(moves), seg_yaw[np.minimum(nxt, len(moves) - 1)], seg_yaw[-1])


def timed_path_to_msg(tp: TimedPath, t0: Time | float, frame_id: str = "map") -> Path:
    """A ``nav_msgs/Path`` whose header stamp is ``t0`` and whose poses are stamped ``t0 + t_i``."""
    wp = tp.waypoints
    if not np.all(np.isfinite(wp)):
        raise ValueError(f"robot {tp.robot_id!r}: timed path has non-finite waypoints")
    back = np.nonzero(np.diff(wp[:, 2]) < 0)[0]
    if len(back):
        raise ValueError(f"robot {tp.robot_id!r}: waypoint {back[0] + 1} is earlier than waypoint {back[0]}")
    t0_ns = stamp_to_ns(t0)
    msg = Path()
    msg.header.frame_id = frame_id
    msg.header.stamp = ns_to_stamp(t0_ns)
    for (x, y, t), yaw in zip(wp, _headings(wp[:, :2])):
        pose = PoseStamped()
        pose.header.frame_id = frame_id
        pose.header.stamp = ns_to_stamp(t0_ns + round(t * NS_PER_S))
        pose.pose.position.x, pose.pose.position.y = float(x), float(y)
        pose.pose.orientation.z, pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        msg.poses.append(pose)
    return msg


def msg_to_timed_path(msg: Path, robot_id: str, radius: float) -> tuple[TimedPath, Time]:
    """The timed path in a ``nav_msgs/Path`` (times relative to its header stamp) and that stamp."""
    if not msg.poses:
        raise RecordError("timed_path.poses: a timed path needs at least one pose")
    t0_ns = stamp_to_ns(msg.header.stamp)
    rows = []
    last = None
    for i, pose in enumerate(msg.poses):
        ns = stamp_to_ns(pose.header.stamp)
        if last is not None and ns < last:
            raise RecordError(f"timed_path.poses[{i}].header.stamp: earlier than poses[{i - 1}]")
        x, y = pose.pose.position.x, pose.pose.position.y
        if not (math.isfinite(x) and math.isfinite(y)):
            raise RecordError(f"timed_path.poses[{i}].pose.position: must be finite (got {x}, {y})")
        rows.append((x, y, (ns - t0_ns) / NS_PER_S))
        last = ns
    return TimedPath(robot_id, radius, np.array(rows)), ns_to_stamp(t0_ns)


# -- maps ------------------------------------------------------------------------------------------
def grid_to_msg(grid: GridMap, frame_id: str = "map", stamp: Time | float = 0.0) -> OccupancyGrid:
    """Blocked cells as 100, free as 0; origin (0, 0), row 0 first."""
    msg = OccupancyGrid()
    msg.header.frame_id = frame_id
    msg.header.stamp = msg.info.map_load_time = ns_to_stamp(stamp_to_ns(stamp))
    msg.info.resolution = float(grid.resolution)
    msg.info.width, msg.info.height = grid.width, grid.height
    msg.info.origin.orientation.w = 1.0
    msg.data = array.array("b", (grid.blocked.astype(np.int8) * OCCUPIED).tobytes())
    return msg


def msg_to_grid(msg: OccupancyGrid, occupied_threshold: int = 50) -> GridMap:
    """A grid map from an occupancy grid: values >= ``occupied_threshold`` and unknown (-1) are blocked.

    Only origin (0, 0) without rotation is supported, since :class:`GridMap` has no origin.
    """
    info = msg.info
    if info.width == 0 or info.height == 0:
        raise MapError(f"map.info: width and height must be > 0 (got {info.width} x {info.height})")
    if len(msg.data) != info.width * info.height:
        raise MapError(f"map.data: expected width*height = {info.width * info.height} cells, got {len(msg.data)}")
    if not (math.isfinite(info.resolution) and info.resolution > 0):
        raise MapError(f"map.info.resolution: must be > 0 (got {info.resolution})")
    o = info.origin
    if (o.position.x, o.position.y, o.orientation.x, o.orientation.y, o.orientation.z) != (0, 0, 0, 0, 0):
        raise MapError(f"map.info.origin: must be (0, 0) without rotation (got position "
                       f"({o.position.x}, {o.position.y}), orientation z {o.orientation.z})")
    data = np.asarray(msg.data, dtype=np.int8).reshape(info.height, info.width)
    return GridMap((data < 0) | (data >= occupied_threshold), float(info.resolution),
                   msg.header.frame_id or "map")


# -- markers ---------------------------------------------------------------------------------------
def robot_colour(robot_id: str, alpha: float = 1.0) -> ColorRGBA:
    """A stable colour per robot id (the same in every plan and every run)."""
    r, g, b = colorsys.hsv_to_rgb((zlib.crc32(robot_id.encode()) % 360) / 360.0, 0.8, 0.9)
    return ColorRGBA(r=r, g=g, b=b, a=alpha)


def plan_markers(paths: Sequence[TimedPath], statuses: Iterable[RobotStatus] = (),
                 frame_id: str = "map", stamp: Time | float = 0.0) -> MarkerArray:
    """RViz markers: clear all, then per robot (namespace = its id) its path, its disc and its id.

    A robot is drawn where its status says, else at the start of its path.
    """
    header_stamp = ns_to_stamp(stamp_to_ns(stamp))
    out = MarkerArray()
    clear = Marker(action=Marker.DELETEALL)
    clear.header.frame_id = frame_id
    out.markers.append(clear)

    def marker(ns: str, mid: int, kind: int) -> Marker:
        m = Marker(ns=ns, id=mid, type=kind, action=Marker.ADD)
        m.header.frame_id, m.header.stamp = frame_id, header_stamp
        m.pose.orientation.w = 1.0
        out.markers.append(m)
        return m

    where: dict[str, tuple[float, float, float]] = {
        p.robot_id: (float(p.waypoints[0, 0]), float(p.waypoints[0, 1]), float(p.radius)) for p in paths}
    where.update({s.id: (s.x, s.y, s.radius) for s in statuses})
    for p in paths:
        if len(p.waypoints) < 2:
            continue
        line = marker(p.robot_id, 0, Marker.LINE_STRIP)
        line.scale.x = 0.05
        line.color = robot_colour(p.robot_id)
        line.points = [PointMsg(x=float(x), y=float(y)) for x, y, _ in p.waypoints]
    for rid, (x, y, radius) in where.items():
        disc = marker(rid, 1, Marker.CYLINDER)
        disc.pose.position.x, disc.pose.position.y, disc.pose.position.z = x, y, 0.1
        disc.scale.x = disc.scale.y = 2 * radius
        disc.scale.z = 0.2
        disc.color = robot_colour(rid, alpha=0.8)
        label = marker(rid, 2, Marker.TEXT_VIEW_FACING)
        label.pose.position.x, label.pose.position.y, label.pose.position.z = x, y, 0.5
        label.scale.z = 0.4
        label.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
        label.text = rid
    return out


# -- records ---------------------------------------------------------------------------------------
def record_to_string(rec: Record) -> String:
    return String(data=rec.to_json())


def string_to_record(msg: String, cls: type[R]) -> R:
    """The record in a ``std_msgs/String``; :class:`RecordError` naming the field if it is not one."""
    return cast(R, cls.from_json(msg.data))  # from_json builds cls
