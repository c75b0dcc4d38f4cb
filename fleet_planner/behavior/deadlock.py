"""Deadlocks, found and left (section IV.C of Sun, Kleiner & Nebel, "Behavior-based Multi-Robot
Collision Avoidance", ICRA 2014).

* found: a waiting robot sends a :class:`WaitMessage` to the robot it waits for; each waiting robot
  adds its id and forwards it (:func:`on_wait_message`); a robot that finds its own id in the list
  is in a wait cycle;
* left: a robot in a wait cycle, or whose behaviour failed, re-plans to its goal with a *virtual
  wall* (:func:`virtual_wall_cells`) between it and its next waypoint.

Ours (issue 13, see :class:`~.controller.BehaviorController`): the wall runs a front length
ahead, not to a far waypoint of a straightened path; the re-plan also keeps out of the partner
the behaviour failed on; and a robot that re-planned away starts a retreat wave the robots it
meets head-on in a one-cell aisle join (``RobotView.retreat``).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ..grid import GridMap
from ..model import Point
from .params import EPS
from .views import RobotView


@dataclass(frozen=True)
class WaitMessage:
    """Sent every ``wait_msg_period`` by a waiting robot to its partner: the ids of the waiting
    robots the message has passed through, the sender first."""

    waiting: tuple[str, ...]


def on_wait_message(me: RobotView, msg: WaitMessage) -> tuple[bool, WaitMessage | None]:
    """What a robot does with a WaitMessage: ``(deadlock, message to forward to my partner)``.

    A robot that does not wait ignores it; a waiting robot whose id is already in the list has
    found a wait cycle (a deadlock: it must re-plan); otherwise it appends its id and forwards
    the message to the robot it waits for.
    """
    if not me.behavior.is_wait:
        return False, None
    if me.id in msg.waiting:
        return True, None
    if me.partner is None:
        return False, None
    return False, WaitMessage(msg.waiting + (me.id,))


def virtual_wall_cells(grid: GridMap, ahead: Sequence[Point], goal: Point, radius: float) -> list[tuple[int, int]]:
    """The virtual wall A* must not cross when re-planning: the cells the polyline ``ahead`` (the
    robot's position, then its next waypoint and possibly more of its path) passes through.

    Cells closer than ``radius`` to the robot or to its goal are left open (the search must start
    and end somewhere); diagonal steps also block both side cells, so the wall has no diagonal gap.
    """
    res = grid.resolution
    cells: list[tuple[int, int]] = []
    prev = None
    for (x0, y0), (x1, y1) in zip(ahead, ahead[1:]):
        n = max(1, int(math.ceil(math.hypot(x1 - x0, y1 - y0) / (res / 8))))
        for k in range(n + 1):
            c = grid.cell_of(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n)
            if c == prev:
                continue
            if prev is not None and c[0] != prev[0] and c[1] != prev[1]:
                cells += [(c[0], prev[1]), (prev[0], c[1])]
            cells.append(c)
            prev = c

    def near(c: tuple[int, int], p: Point) -> bool:
        dx = max(c[0] * res - p[0], 0.0, p[0] - (c[0] + 1) * res)
        dy = max(c[1] * res - p[1], 0.0, p[1] - (c[1] + 1) * res)
        return math.hypot(dx, dy) < radius + EPS

    return [c for c in dict.fromkeys(cells)
            if grid.in_bounds(*c) and not near(c, ahead[0]) and not near(c, goal)]
