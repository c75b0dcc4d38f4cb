"""The geometry of traffic: a robot's front area and critical area, the paper's FrontAreaCheck,
and the class of a path collision (rear-end / head-on / side, by the angle between the travel
directions), after Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance"
(ICRA 2014), section IV.

Frames: a robot's *front frame* has its origin at the robot, axis ``u`` from the robot to its next
waypoint (its heading is ignored, as in the paper) and ``n`` = ``u`` turned +90 degrees. ``s`` is the
distance ahead along ``u``, ``l`` the lateral offset along ``n``. Where the paper leaves a choice
open, the choice and its reason are written where it is made ("Interpretation").
"""
from __future__ import annotations

import enum
import math
from collections.abc import Iterable

from .params import DEFAULT_PARAMS, BehaviorParams
from .views import RobotView

#: Collision classes by the angle between the two robots' travel directions (documented thresholds):
#: below 45 degrees the robots go the same way (rear-end), above 135 degrees opposite ways (head-on),
#: in between their paths cross (side).
REAR_END_MAX_ANGLE_DEG = 45.0
HEAD_ON_MIN_ANGLE_DEG = 135.0
_COS_REAR = math.cos(math.radians(REAR_END_MAX_ANGLE_DEG))
_COS_HEAD = math.cos(math.radians(HEAD_ON_MIN_ANGLE_DEG))


def front_coords(me: RobotView, other: RobotView) -> tuple[float, float] | None:
    """``(s, l)`` of the other robot's centre in my front frame, or None if I have no direction."""
    d = me.direction
    if d is None:
        return None
    rx, ry = other.position[0] - me.position[0], other.position[1] - me.position[1]
    return rx * d[0] + ry * d[1], -rx * d[1] + ry * d[0]


def in_front_area(me: RobotView, other: RobotView, params: BehaviorParams = DEFAULT_PARAMS) -> bool:
    """The other disc overlaps my front area: a ``front_length`` x ``front_width`` rectangle
    starting at my position, pointing at my next waypoint (the other's centre must be ahead).

    Interpretation: the area is cut short (to my radius beyond it) where my path turns or ends.
    The paper's A* paths have a waypoint per cell, ours are straightened polylines; a robot
    beyond my next turn is not in my way, and waiting for it blocked narrow crossings.
    """
    c = front_coords(me, other)
    if c is None or other.id == me.id:
        return False
    s, l = c
    length = min(params.front_length, me.straight + me.radius)
    return 0.0 <= s <= length + other.radius and abs(l) <= params.front_width / 2 + other.radius


def in_critical_area(me: RobotView, other: RobotView, params: BehaviorParams = DEFAULT_PARAMS) -> bool:
    """The other disc overlaps my drive channel (width ``2 * radius + critical_margin``) inside
    my front area: driving straight on, I would touch it (when the margin is 0)."""
    if not in_front_area(me, other, params):
        return False
    _, l = front_coords(me, other)  # type: ignore[misc]
    return abs(l) < me.radius + params.critical_margin / 2 + other.radius


def robots_in_front(me: RobotView, others: Iterable[RobotView],
                    params: BehaviorParams = DEFAULT_PARAMS) -> list[RobotView]:
    """The robots in my front area, closest first."""
    return [o for o, _ in scan_front_area(me, others, params)]


def scan_front_area(me: RobotView, others: Iterable[RobotView],
              params: BehaviorParams) -> list[tuple[RobotView, bool]]:
    """``(robot, in my critical area)`` for the robots in my front area, closest first: the
    arithmetic of :func:`in_front_area` and :func:`in_critical_area` inlined (the same operations
    in the same order, so the same results), as this runs for every robot at every step."""
    d = me.direction
    if d is None:
        return []
    (mx, my), (ux, uy) = me.position, d
    length = min(params.front_length, me.straight + me.radius)
    half = params.front_width / 2
    channel = me.radius + params.critical_margin / 2
    found = []
    for o in others:
        if o.id == me.id:
            continue
        ox, oy = o.position
        rx, ry = ox - mx, oy - my
        s = rx * ux + ry * uy
        r = o.radius
        if not 0.0 <= s <= length + r:
            continue
        lat = abs(-rx * uy + ry * ux)
        if lat <= half + r:
            found.append((math.dist(o.position, me.position), o, lat < channel + r))
    if len(found) > 1:
        found.sort(key=lambda f: f[0])
    return [(o, critical) for _, o, critical in found]


def front_area_check(me: RobotView, others: Iterable[RobotView],
                     params: BehaviorParams = DEFAULT_PARAMS) -> RobotView | None:
    """The paper's FrontAreaCheck: the robot in my front area closest to me, where robots in the
    critical area come first (if any robot is in it, those outside it are ignored)."""
    in_front = scan_front_area(me, others, params)
    return next((o for o, critical in in_front if critical), in_front[0][0] if in_front else None)


class Collision(enum.Enum):
    """The class of a path collision, by the paper's names (see :func:`collision_type`)."""

    NONE = "none"
    REAR_END = "rearEndCollision"
    HEAD_ON = "headOnCollision"
    SIDE = "sideCollision"


def _enters_channel(me: RobotView, other: RobotView, params: BehaviorParams) -> bool:
    """The other robot's travel ray crosses my drive channel ahead of me within a front length."""
    c = front_coords(me, other)
    d_me, d_o = me.direction, other.direction
    if c is None or d_me is None or d_o is None:
        return False
    s, l = c
    ds = d_o[0] * d_me[0] + d_o[1] * d_me[1]   # its direction in my frame
    dl = -d_o[0] * d_me[1] + d_o[1] * d_me[0]
    half = me.radius + params.critical_margin / 2 + other.radius
    if abs(l) < half:
        t = 0.0
    elif l * dl < 0:
        t = (abs(l) - half) / abs(dl)
    else:
        return False
    return t <= params.front_length and -half <= s + ds * t <= params.front_length + other.radius


def collision_type(me: RobotView, other: RobotView, params: BehaviorParams = DEFAULT_PARAMS) -> Collision:
    """How my path collides with the other robot's, if it does.

    There is a path collision when the other is in my critical area or its travel direction takes
    it into my drive channel within a front length; its class is then given by the angle between
    the two travel directions (see :data:`REAR_END_MAX_ANGLE_DEG`, :data:`HEAD_ON_MIN_ANGLE_DEG`).
    Interpretation: a standing robot (no path) in my channel is a rear-end collision (I would run
    into it from behind), elsewhere no collision.
    """
    d_me, d_o = me.direction, other.direction
    if d_me is None:
        return Collision.NONE
    if not (in_critical_area(me, other, params) or _enters_channel(me, other, params)):
        return Collision.NONE
    if d_o is None:
        return Collision.REAR_END
    cos = d_me[0] * d_o[0] + d_me[1] * d_o[1]
    if cos >= _COS_REAR:
        return Collision.REAR_END
    if cos <= _COS_HEAD:
        return Collision.HEAD_ON
    return Collision.SIDE
