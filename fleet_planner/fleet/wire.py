"""Between the wire records and the core: a robot's status as the behaviour layer sees it
(:func:`view_of_status`), a robot's behaviour state as the ``behavior`` field of its status
(:func:`behavior_state`), and position samples from statuses as a timed path (:func:`samples_to_path`)."""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from msg_schemas.records import RobotStatus

from ..behavior import Behavior, RobotView
from ..model import TimedPath


def behavior_state(view: RobotView) -> dict[str, Any]:
    """A robot's behaviour state as the ``behavior`` field of its status
    (``msg_schemas.records.BEHAVIOR_STATE``)."""
    return {"name": view.behavior.value, "next": list(view.next_waypoint) if view.next_waypoint else None,
            "remaining": view.remaining, "straight": view.straight, "station": view.station,
            "partner": view.partner, "no_space": view.no_space, "docked_at": view.docked_at,
            "dock_since": view.dock_since,
            "retreat": None if view.retreat is None else {"since": view.retreat[0], "by": view.retreat[1]}}


def view_of_status(status: RobotStatus, standing: bool = False) -> RobotView:
    """What a robot's status tells the behaviour layer about it. ``standing`` (it stopped reporting),
    or a status without a behaviour state (a robot not coordinating by behaviours): a robot with no
    path, an obstacle to drive round, unless it is seen moving (then heading where it moves)."""
    b = status.behavior
    pos = (status.x, status.y)
    if standing or b is None:
        moving = not standing and math.hypot(status.vx, status.vy) > 1e-3
        ahead = (status.x + status.vx, status.y + status.vy) if moving else None
        return RobotView(status.id, pos, status.radius, next_waypoint=ahead)
    retreat = b.get("retreat")
    return RobotView(status.id, pos, status.radius, Behavior(b["name"]), b["next"], b["remaining"], b["straight"],
                     b["station"], b["partner"], b["no_space"], b["docked_at"], b["dock_since"],
                     None if retreat is None else (retreat["since"], retreat["by"]))


def samples_to_path(robot_id: str, radius: float, samples: Sequence[tuple[float, float, float]]) -> TimedPath:
    """A timed path through position samples ``(x, y, t)`` (sorted by t, repeated times dropped),
    keeping only the first and last sample of each stretch standing still: the same trajectory,
    with far fewer waypoints for the checker."""
    wp = np.array(sorted(samples, key=lambda p: p[2]), dtype=float).reshape(-1, 3)
    wp = wp[np.concatenate([[True], np.diff(wp[:, 2]) > 0])]
    moved = np.any(np.diff(wp[:, :2], axis=0) != 0, axis=1)
    keep = np.concatenate([[True], moved]) | np.concatenate([moved, [True]])
    return TimedPath(robot_id, radius, wp[keep])
