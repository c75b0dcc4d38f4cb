"""Simulated people walking in the warehouse, the moving obstacles of the demo and the tests: what
the intelligent space would report of them, as ``fleet/obstacle@1`` records. Pure (no rclpy); the
node that publishes them is :mod:`fleet_planner.ros.people`.

A :class:`Walker` walks a polyline at its speed, to and fro (a person on a fixed round, as in the
crossing test), or, with a random generator, from one random free point of the map to another on
the map's shortest path for its disc, pausing a moment at each. No walker walks into a robot that
stands still: it stops short of its disc (grown by :data:`YIELD_M`) and, after waiting
:data:`GIVE_UP_S`, turns back or walks elsewhere. A walker that ``yields`` does so for moving
robots too, as people do; one that does not walks on, blind to them: the moving robots alone must
keep clear of it.
"""
from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from msg_schemas.records import ObstacleRecord

from ..grid import GridMap
from ..model import Point
from ..paths import PathFinder

#: a yielding walker keeps this much (m) beyond the sum of radii from every robot
YIELD_M = 0.3
#: a robot slower than this (m/s) stands still: no walker walks into it
STANDING_MPS = 0.05
#: a yielding walker that waited this long (s) for a robot turns back (a round) or walks elsewhere
GIVE_UP_S = 4.0
#: a walker on random walks pauses this long (s) at each goal
PAUSE_S = (1.0, 4.0)
#: a person comes in (at the first point of its route, after ``start_s``) only with no robot this near (m)
ENTRY_M = 3.0
#: a person's disc (m) and walking speed (m/s)
PERSON_RADIUS, WALKING_SPEED = 0.3, 1.0


@dataclass
class Walker:
    """One person: ``route`` (at least one point; walked to and fro, or with ``once`` walked once,
    after which the person is gone) or random walks on ``grid`` with ``rng``; ``yields``: stops for
    robots; ``start_s``: the person comes in (at the route's first point) at this time, or as soon
    after it as no robot is within :data:`ENTRY_M` of that point."""

    id: str
    route: np.ndarray
    speed: float = WALKING_SPEED
    radius: float = PERSON_RADIUS
    yields: bool = True
    rng: random.Random | None = None
    grid: GridMap | None = None
    once: bool = False
    start_s: float = 0.0
    gone: bool = field(default=False, init=False)
    entered: bool = field(default=False, init=False)
    x: float = field(init=False)
    y: float = field(init=False)
    vx: float = field(default=0.0, init=False)
    vy: float = field(default=0.0, init=False)
    _k: int = field(default=1, init=False)          # the route point it walks to
    _waited: float = field(default=0.0, init=False)
    _pause_until: float = field(default=-math.inf, init=False)

    def __post_init__(self) -> None:
        self.route = np.asarray(self.route, dtype=float).reshape(-1, 2)
        if len(self.route) == 0:
            raise ValueError(f"walker {self.id!r}: route needs at least one point")
        if not (math.isfinite(self.speed) and self.speed > 0 and math.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"walker {self.id!r}: speed and radius must be finite numbers > 0")
        self.x, self.y = (float(v) for v in self.route[0])

    @property
    def pos(self) -> Point:
        return self.x, self.y

    def step(self, t: float, dt: float, robots: Sequence[tuple[float, float, float, float]] = ()) -> None:
        """Walk from ``t`` for ``dt`` s; ``robots``: (x, y, radius, speed) of every robot, for yielding."""
        self.vx = self.vy = 0.0
        if not self.entered and t >= self.start_s:  # comes in by a door robots are not passing
            self.entered = all(math.hypot(rx - self.x, ry - self.y) >= ENTRY_M for rx, ry, _, _ in robots)
        if dt <= 0 or len(self.route) < 2 or t < self._pause_until or not self.entered or self.gone:
            return
        target = self.route[self._k]
        dx, dy = float(target[0]) - self.x, float(target[1]) - self.y
        dist = math.hypot(dx, dy)
        move = min(dist, self.speed * dt)
        nx, ny = (self.x + dx / dist * move, self.y + dy / dist * move) if dist > 1e-12 else (self.x, self.y)
        if self._blocked(nx, ny, robots):
            self._waited += dt
            if self._waited >= GIVE_UP_S:
                self._turn(t)
            return
        self._waited = 0.0
        self.vx, self.vy = (nx - self.x) / dt, (ny - self.y) / dt
        self.x, self.y = nx, ny
        if dist - move <= 1e-9:
            self._arrived(t + dt)

    def _blocked(self, nx: float, ny: float, robots: Sequence[tuple[float, float, float, float]]) -> bool:
        """The step to (nx, ny) brings it closer to a robot it is already near (that stands still,
        unless it yields)."""
        for rx, ry, rr, speed in robots:
            if not self.yields and speed > STANDING_MPS:
                continue
            keep = self.radius + rr + YIELD_M
            after = math.hypot(nx - rx, ny - ry)
            if after < keep and after < math.hypot(self.x - rx, self.y - ry):
                return True
        return False

    def _arrived(self, t: float) -> None:
        if self.rng is not None and self.grid is not None:
            self._pause_until = t + self.rng.uniform(*PAUSE_S)
            self._new_walk()
            return
        self._k += 1
        if self._k == len(self.route) and self.once:
            self.gone = True
        elif self._k == len(self.route):   # to and fro
            self.route = self.route[::-1].copy()
            self._k = 1

    def _turn(self, t: float) -> None:
        """Gave up waiting: back the way it came (a round), or a new random walk."""
        self._waited = 0.0
        if self.rng is not None and self.grid is not None:
            self._new_walk()
            return
        back = np.vstack([[self.x, self.y], self.route[:self._k][::-1]])
        self.route, self._k = back, 1

    def _new_walk(self) -> None:
        assert self.rng is not None and self.grid is not None
        for _ in range(50):
            goal = random_free_point(self.grid, self.radius, self.rng)
            path = _finder(self.grid, self.radius).find((self.x, self.y), goal)
            if path is not None and len(path) >= 2:
                self.route, self._k = np.asarray(path, dtype=float), 1
                return
        self.route, self._k = np.array([[self.x, self.y]]), 1

    @property
    def present(self) -> bool:
        """In the warehouse (it came in and is not gone)."""
        return self.entered and not self.gone

    def record(self, stamp: float) -> ObstacleRecord:
        """What the intelligent space reports of this person at ``stamp``."""
        return ObstacleRecord(id=self.id, kind="person", x=self.x, y=self.y, vx=self.vx, vy=self.vy,
                              radius=self.radius, stamp=stamp)


def random_free_point(grid: GridMap, radius: float, rng: random.Random) -> Point:
    """A random point of the map where a disc of ``radius`` fits (a cell centre)."""
    w, h = grid.size_m
    res = grid.resolution
    for _ in range(10_000):
        x = (rng.randrange(int(round(w / res))) + 0.5) * res
        y = (rng.randrange(int(round(h / res))) + 0.5) * res
        if grid.disc_is_free(x, y, radius):
            return x, y
    raise ValueError(f"no free place on the map for a disc of radius {radius:g} m")


_FINDERS: dict[tuple[int, float], tuple[GridMap, PathFinder]] = {}


def _finder(grid: GridMap, radius: float) -> PathFinder:
    """One path finder per map and radius (the last one asked for: people share one)."""
    key = (id(grid), radius)
    if key not in _FINDERS:
        _FINDERS.clear()
        _FINDERS[key] = (grid, PathFinder(grid, radius))   # the grid is kept: its id stays its own
    return _FINDERS[key][1]


def random_people(grid: GridMap, count: int, seed: int, *, speed: float = WALKING_SPEED,
                  radius: float = PERSON_RADIUS, avoid: Sequence[Point] = (),
                  keep: float = ENTRY_M + 0.5) -> list[Walker]:
    """``count`` yielding people on random walks, starting at random free points at least ``keep``
    m from every point of ``avoid`` (the robots' starts)."""
    rng = random.Random(seed)
    people = []
    for i in range(count):
        for _ in range(1000):
            p = random_free_point(grid, radius, rng)
            if all(math.dist(p, a) >= keep for a in avoid):
                break
        w = Walker(f"person_{i + 1}", np.array([p]), speed, radius, True, random.Random(rng.random()), grid)
        w._new_walk()
        people.append(w)
    return people
