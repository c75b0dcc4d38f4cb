"""The safety net of a robot that follows a central plan (``coordination:=central``):
:func:`safety_stop`, the robot it must wait for rather than drive into, by the critical area of
Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance" (ICRA 2014).
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import replace

from .areas import in_critical_area
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
    if step <= 0 or not me.travelling:
        return None
    area = BehaviorParams(front_length=me.radius + step, front_width=2 * me.radius, critical_margin=0.0)
    hit = []
    for o in others:
        if o.id == me.id:
            continue
        dx, dy = (sweep or {}).get(o.id, (0.0, 0.0))
        n = 1 + int(math.ceil(math.hypot(dx, dy) / _SWEEP_STEP))
        x, y = o.position
        if any(in_critical_area(me, replace(o, position=(x + dx * k / max(n - 1, 1), y + dy * k / max(n - 1, 1)),
                                            radius=o.radius + margin), area) for k in range(n)):
            hit.append(o)
    return min(hit, key=lambda o: math.dist(o.position, me.position), default=None)
