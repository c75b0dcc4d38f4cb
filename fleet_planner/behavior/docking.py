"""Docking one robot at a time per station (section IV.A of Sun, Kleiner & Nebel,
"Behavior-based Multi-Robot Collision Avoidance", ICRA 2014).

* :class:`DockingArbiter` - the agreement written down once, shared by the robots of one
  simulation (:class:`~.fleet.BehaviorFleet`);
* :class:`HeardDocking` - the same agreement kept by one robot from what it hears, for robots
  running on their own (the agent node);
* :class:`Docking` - the interface both offer to :class:`~.controller.BehaviorController`.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Protocol

from ..model import Behavior
from .rules import id_key
from .views import RobotView

B = Behavior


class Docking(Protocol):
    """What a robot asks of the docking agreement (:class:`DockingArbiter`, :class:`HeardDocking`)."""

    def holder(self, station: str) -> str | None: ...

    def first_waiting(self, station: str) -> str | None: ...

    def request(self, station: str, robot_id: str, time: float) -> bool: ...

    def withdraw(self, station: str, robot_id: str) -> None: ...

    def release(self, station: str, robot_id: str) -> None: ...

    def keeps(self, station: str, robot_id: str) -> bool: ...


class DockingArbiter:
    """One robot docks at a station at a time (IV.A): the first to reach the docking region is
    served first; robots arriving at the same time go by priority (smaller id first).

    The robots near a station agree on this among themselves in the paper; the arbiter is that
    agreement written down (it only ever compares robots that reached the same docking region).
    """

    def __init__(self) -> None:
        self._holder: dict[str, str] = {}
        self._queue: dict[str, dict[str, tuple[float, tuple]]] = {}

    def holder(self, station: str) -> str | None:
        """The robot docking at the station now."""
        return self._holder.get(station)

    def first_waiting(self, station: str) -> str | None:
        """The robot next in line at the station."""
        queue = self._queue.get(station)
        return min(queue, key=queue.__getitem__) if queue else None

    def request(self, station: str, robot_id: str, time: float) -> bool:
        """The robot is in the docking region at ``time``; True when it may dock (now or already).

        The first request records the robot's arrival time; later ones only ask again.
        """
        if self._holder.get(station) == robot_id:
            return True
        queue = self._queue.setdefault(station, {})
        queue.setdefault(robot_id, (float(time), id_key(robot_id)))
        if station not in self._holder and self.first_waiting(station) == robot_id:
            del queue[robot_id]
            self._holder[station] = robot_id
            return True
        return False

    def withdraw(self, station: str, robot_id: str) -> None:
        """The robot gave up waiting (it will queue again, as a new arrival, when it comes back)."""
        self._queue.get(station, {}).pop(robot_id, None)

    def release(self, station: str, robot_id: str) -> None:
        """The docked robot left the docking region."""
        if self._holder.get(station) == robot_id:
            del self._holder[station]

    def keeps(self, station: str, robot_id: str) -> bool:
        """The robot still docks at the station (the arbiter never takes a station back)."""
        return self._holder.get(station) == robot_id


class HeardDocking:
    """The docking agreement of IV.A kept by one robot from what it hears, for robots running on
    their own (:meth:`~.controller.BehaviorController.step`): every robot broadcasts the station it
    docks at (``RobotView.docked_at``) and since when it asked to (``RobotView.dock_since``).

    A robot may dock when nobody it hears docks at the station and no robot it hears waiting for
    it asked earlier (same time: the smaller id). Two robots that granted themselves the station
    before hearing of each other find out at the next step: the later one (by the same order)
    gives it up and waits (:meth:`keeps`). Same interface as :class:`DockingArbiter`.
    """

    def __init__(self, robot_id: str) -> None:
        self.id = robot_id
        self._heard: list[RobotView] = []
        self._since: dict[str, float] = {}

    def hear(self, views: Iterable[RobotView]) -> None:
        """The robots heard this step (the views they broadcast)."""
        self._heard = [v for v in views if v.id != self.id]

    def _key(self, station: str) -> tuple:
        return self._since.get(station, math.inf), id_key(self.id)

    @staticmethod
    def _order(v: RobotView) -> tuple:
        return -math.inf if v.dock_since is None else v.dock_since, id_key(v.id)

    def holder(self, station: str) -> str | None:
        held = [v for v in self._heard if v.docked_at == station]
        return min(held, key=self._order).id if held else None

    def first_waiting(self, station: str) -> str | None:
        queue = [v for v in self._heard if v.behavior is B.WAIT_FOR_DOCKING and v.station == station]
        first = min(queue, key=self._order, default=None)
        if first is None or (station in self._since and self._key(station) < self._order(first)):
            return self.id if station in self._since else None
        return first.id

    def request(self, station: str, robot_id: str, time: float) -> bool:
        self._since.setdefault(station, float(time))
        return self.holder(station) is None and self.first_waiting(station) == self.id

    def keeps(self, station: str, robot_id: str) -> bool:
        """False when a robot that asked earlier docks at the station too (a race lost)."""
        mine = self._key(station)
        return not any(v.docked_at == station and self._order(v) < mine for v in self._heard)

    def withdraw(self, station: str, robot_id: str) -> None:
        self._since.pop(station, None)

    def release(self, station: str, robot_id: str) -> None:
        self._since.pop(station, None)
