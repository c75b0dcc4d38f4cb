"""The safety net of a robot that follows a central plan (``coordination:=central``):
:func:`safety_stop`, the robot it must wait for rather than drive into, by the critical area of
Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance" (ICRA 2014).
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from .params import BehaviorParams
from .views import RobotView

_SWEEP_STEP = 0.05  # m between the discs standing for a swept disc


def safety_stop(me: RobotView, others: Iterable[RobotView], step: float, margin: float,
                sweep: Mapping[str, tuple[float, float]] | None = None) -> RobotView | None:
    """The robot a robot following a timed path must wait for (WaitKeepDistance) rather than drive
    ``step`` metres on, or None: the closest one whose disc, grown by ``margin`` and swept along
    ``sweep[id]`` (where it may have driven by the end of the step, from its reported position: it
    may have stopped anywhere on the way), lies in my critical area reaching ``step`` beyond my
    own disc (``me.next_waypoint``: where my path goes next). The area is the paper's rectangle,
    so a disc at its front corners stops me a little earlier than it strictly has to.
    """
    if step <= 0:
        return None
    d = me.direction
    if d is None:
        return None
    front_length, front_width = me.radius + step, 2 * me.radius
    if not (math.isfinite(front_length) and front_length > 0 and math.isfinite(front_width) and front_width > 0):
        BehaviorParams(front_length=front_length, front_width=front_width, critical_margin=0.0)  # raises
    # areas.in_critical_area of each swept disc against that area, its arithmetic inlined (no
    # RobotView per disc: this runs for every robot at every control step)
    (mx, my), (ux, uy) = me.position, d
    length = min(front_length, me.straight + me.radius)
    hit = []
    for o in others:
        if o.id == me.id:
            continue
        dx, dy = (sweep or {}).get(o.id, (0.0, 0.0))
        n = 1 + int(math.ceil(math.hypot(dx, dy) / _SWEEP_STEP))
        x, y = o.position
        r = o.radius + margin
        last = max(n - 1, 1)
        for k in range(n):
            rx, ry = x + dx * k / last - mx, y + dy * k / last - my
            s, lat = rx * ux + ry * uy, -rx * uy + ry * ux
            if 0.0 <= s <= length + r and abs(lat) <= front_width / 2 + r and abs(lat) < me.radius + 0.0 / 2 + r:
                hit.append(o)
                break
    return min(hit, key=lambda o: math.dist(o.position, me.position), default=None)
