""":class:`RobotView`: what a robot knows of itself or hears from a neighbour (position, path,
status), all that the traffic rules read of a robot.

Frames: a robot's *front frame* has its origin at the robot, axis ``u`` from the robot to its next
waypoint (its heading is ignored, as in Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision
Avoidance", ICRA 2014) and ``n`` = ``u`` turned +90 degrees; see :mod:`.areas`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

from ..model import Behavior, Point
from .params import EPS


@dataclass(frozen=True)
class RobotView:
    """What a robot knows of itself or hears from a neighbour: position, path, status.

    ``next_waypoint`` is None for a robot without a path (idle, or arrived): it stands still.
    ``remaining`` is the length of the rest of its path (for :func:`~.rules.low_order`), ``straight`` the
    length of the straight run of it ahead (up to the next turn or the goal).
    ``partner`` is the id of the robot its current behaviour is about (the one it waits for,
    avoids, exchanges with...); ``no_space`` says its Avoid / Exchange finds no free space.
    ``docked_at`` is the station it docks at (it may be leaving it for its next goal already),
    ``dock_since`` when it first asked to dock at its station (for :class:`~.docking.HeardDocking`).
    ``retreat`` is set while the robot backs out of a place where it could not pass (it re-planned
    away from a partner): ``(when the retreat wave began, the id that began it)``; robots it meets
    head-on without room to pass give way to the oldest wave (ours, see
    :meth:`~.controller.BehaviorController._yield_to_retreat`).
    """

    id: str
    position: Point
    radius: float
    behavior: Behavior = Behavior.FOLLOW_WAYPOINT
    next_waypoint: Point | None = None
    remaining: float = math.inf
    straight: float = math.inf
    station: str | None = None
    partner: str | None = None
    no_space: bool = False
    docked_at: str | None = None
    dock_since: float | None = None
    retreat: tuple[float, str] | None = None

    def __post_init__(self) -> None:
        # the travel direction, once per view (the rules read it many times a step): stored as
        # the cached properties' values, so reading them is a plain attribute look-up
        direction = None
        if self.next_waypoint is not None:
            dx = self.next_waypoint[0] - self.position[0]
            dy = self.next_waypoint[1] - self.position[1]
            d = math.hypot(dx, dy)
            if d >= EPS:
                direction = dx / d, dy / d
        self.__dict__["direction"] = direction
        self.__dict__["travelling"] = direction is not None

    @cached_property
    def direction(self) -> tuple[float, float] | None:
        """Unit vector from the position to the next waypoint (the travel direction), or None."""
        return self.__dict__["direction"]   # set at construction (see __post_init__)

    @cached_property
    def travelling(self) -> bool:
        """Has somewhere to go (a robot without a path is a standing obstacle to the others)."""
        return self.direction is not None
