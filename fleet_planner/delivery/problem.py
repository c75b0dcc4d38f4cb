"""The delivery problem: a map, its stations, one seeded sequence of deliveries, the robots' homes.

:func:`delivery_problem` draws the deliveries and places the parking spots (with
:func:`~fleet_planner.delivery.layout.choose_spots`); :func:`warehouse_problem` does it for a
:class:`~fleet_planner.warehouse.Warehouse`, loading at its chutes and unloading at its storing sites.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..grid import GridMap
from ..model import Point
from .layout import ROBOT_RADIUS, choose_spots

if TYPE_CHECKING:
    from ..warehouse import Warehouse

#: top speed of the robots (m/s)
TOP_SPEED = 0.8
#: docking time at a station, to load or unload (s)
DOCK_S = 5.0


@dataclass(frozen=True)
class Delivery:
    """One delivery: load at station ``pick``, unload at station ``drop``."""

    pick: str
    drop: str


@dataclass
class DeliveryProblem:
    """Map, stations, the delivery sequence and where the robots start.

    ``spots`` are the parking spots, the robots' homes first (robot i starts on ``spots[i]``).
    """

    name: str
    grid: GridMap
    stations: dict[str, Point]
    deliveries: list[Delivery]
    spots: list[Point]
    n_robots: int
    radius: float = ROBOT_RADIUS
    max_speed: float = TOP_SPEED
    dock_s: float = DOCK_S

    def __post_init__(self) -> None:
        if self.n_robots < 1:
            raise ValueError(f"{self.name}: n_robots must be >= 1 (got {self.n_robots})")
        if len(self.spots) < self.n_robots:
            raise ValueError(f"{self.name}: {len(self.spots)} parking spots for {self.n_robots} robots")
        for k, delivery in enumerate(self.deliveries):
            for s in (delivery.pick, delivery.drop):
                if s not in self.stations:
                    raise ValueError(f"{self.name}: deliveries[{k}] names unknown station {s!r}")
        if not (self.dock_s >= 0 and math.isfinite(self.dock_s)):
            raise ValueError(f"{self.name}: dock_s must be a finite number >= 0 (got {self.dock_s!r})")

    @property
    def homes(self) -> list[Point]:
        return self.spots[:self.n_robots]

    def robot_ids(self) -> list[str]:
        return [f"r{i}" for i in range(self.n_robots)]


def delivery_problem(grid: GridMap, stations: dict[str, Point], n_robots: int, n_deliveries: int, seed: int,
                     pick: Sequence[str] | None = None, drop: Sequence[str] | None = None,
                     name: str | None = None, queue_spots: int | None = None, radius: float = ROBOT_RADIUS,
                     max_speed: float = TOP_SPEED, dock_s: float = DOCK_S) -> DeliveryProblem:
    """A seeded delivery problem: each delivery loads at a station of ``pick`` and unloads at a
    different one of ``drop`` (both default to all stations). Parking spots: one home per robot,
    plus ``queue_spots`` (default N/2 + 8) close to the stations, shared out by how often the
    deliveries visit each station (at most 4 per station), plus up to N/2 spare ones where the map
    has room (a robot on its way to a spot holds two). When the map cannot hold that many homes
    spread out, they are packed (``choose_spots(..., packed=True)``): the same problem as before for
    every size that fits."""
    if n_deliveries < 1:
        raise ValueError(f"n_deliveries: must be >= 1 (got {n_deliveries})")
    pick = list(stations) if pick is None else list(pick)
    drop = list(stations) if drop is None else list(drop)
    if not pick or not drop or (len(pick) == 1 and pick == drop):
        raise ValueError("stations: need at least two stations to deliver between")
    rng = np.random.default_rng(seed)
    deliveries: list[Delivery] = []
    while len(deliveries) < n_deliveries:
        k, l = pick[int(rng.integers(len(pick)))], drop[int(rng.integers(len(drop)))]
        if k != l:
            deliveries.append(Delivery(k, l))
    visits = {s: 0 for s in stations}
    for delivery in deliveries:
        visits[delivery.pick] += 1
        visits[delivery.drop] += 1
    quota = {s: 0 for s in stations}
    for _ in range(n_robots // 2 + 8 if queue_spots is None else queue_spots):
        open_ = [s for s in stations if quota[s] < 4 and visits[s]]
        if not open_:
            break
        best = max(open_, key=lambda s: visits[s] / (quota[s] + 1))   # D'Hondt: by demand
        quota[best] += 1
    try:
        spots = choose_spots(grid, n_robots, seed, list(stations.values()), radius, list(quota.values()),
                             spare=n_robots // 2)
    except ValueError:
        # ours: a crowd the spread homes cannot hold (200 robots on `large`): homes packed in rows along
        # the walls, closer to the stations, no queue spots (the behaviour fleet needs none)
        spots = choose_spots(grid, n_robots, seed, list(stations.values()), radius, spare=n_robots // 2,
                             packed=True)
    return DeliveryProblem(name or grid.name, grid, dict(stations), deliveries, spots, n_robots, radius,
                           max_speed, dock_s)


def warehouse_problem(warehouse: Warehouse, n_robots: int, n_deliveries: int, seed: int,
                      **options) -> DeliveryProblem:
    """A delivery problem on a :class:`~fleet_planner.warehouse.Warehouse`: load at its chutes,
    unload at its storing sites (chargers are left out)."""
    chutes = [s.name for s in warehouse.stations_of("chute")]
    sites = [s.name for s in warehouse.stations_of("storage")]
    used = {n: warehouse.stations[n].pose for n in chutes + sites}
    options.setdefault("name", warehouse.name)
    return delivery_problem(warehouse.grid, used, n_robots, n_deliveries, seed, chutes or None, sites or None,
                            **options)
