"""The decentralised BBMRCA fleet as one steppable simulation: :class:`BehaviorFleet` (one
:class:`~.controller.BehaviorController` per robot, a shared :class:`~.docking.DockingArbiter`,
an exact safety layer) and its counters, :class:`FleetStats`.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np
from scipy.spatial import cKDTree

from ..grid import GridMap
from ..model import Behavior, Point
from ..paths import PathFinder
from .controller import BehaviorController
from .deadlock import WaitMessage
from .docking import DockingArbiter
from .params import DEFAULT_PARAMS, EPS, BehaviorParams
from .views import RobotView


@dataclass(frozen=True)
class FleetStats:
    """Counters of a :class:`BehaviorFleet` run."""

    time: float
    deadlocks: int            # wait cycles found by WaitMessages
    replans: int              # successful re-plans (deadlocks and behaviour failures)
    replan_failures: int      # re-plans that found no path (the robot kept its old one)
    refused_moves: int        # motions the safety layer refused
    stalled: tuple[str, ...]  # robots not closer to their goal for more than ``stall_time`` s, now
    longest_stall: float      # longest time any robot went without getting closer to its goal (s)


class BehaviorFleet:
    """The whole decentralised BBMRCA fleet, stepped in simulated time: one
    :class:`BehaviorController` per robot.

    Each robot plans its own path (A*, no schedule, other robots ignored), senses only robots
    within ``comm_range``, runs the front-area check and the traffic rules, and moves by its
    behaviour; WaitMessages reach robots within ``comm_range`` at the next step, and one shared
    :class:`~.docking.DockingArbiter` keeps the docking agreement. Beneath the behaviours a hard safety layer
    refuses any motion that would bring two discs closer than the sum of their radii (plus
    ``safety_margin`` unless moving apart) or a disc into a wall, so a simulated run never overlaps,
    whatever the rules decide.

    ``robots``: objects with ``id``, ``radius``, ``max_speed`` and ``start`` (e.g.
    :class:`~fleet_planner.model.RobotSpec`); they stand on their start until assigned a goal.
    """

    def __init__(self, grid: GridMap, robots: Sequence, params: BehaviorParams = DEFAULT_PARAMS):
        self.grid = grid
        self.params = params
        self.time = 0.0
        self._arbiter = DockingArbiter()
        self._robots: list[BehaviorController] = []
        self._index: dict[str, int] = {}
        finders: dict[float, PathFinder] = {}
        golden = (math.sqrt(5) - 1) / 2
        for k, spec in enumerate(robots):
            rid = str(spec.id)
            if rid in self._index:
                raise ValueError(f"robots[{k}].id: duplicate id {rid!r}")
            # robots' clocks are not synchronised: each sends WaitMessages at its own phase, the
            # first one within a period (a spread phase, so that waiting robots seldom send at once)
            tick = params.wait_msg_period * (1.0 - (k * golden) % 1.0)
            self._index[rid] = k
            self._robots.append(BehaviorController(grid, rid, spec.radius, spec.max_speed, spec.start, params,
                                                   docking=self._arbiter, finders=finders, first_message=tick))
        self._check_starts()
        self._inbox: list[tuple[str, str, WaitMessage]] = []   # (sender, receiver, message)
        self._refused = 0
        self._longest_stall = 0.0

    # -- public ---------------------------------------------------------------------------
    @property
    def ids(self) -> list[str]:
        return [r.id for r in self._robots]

    def controller(self, robot_id: str) -> BehaviorController:
        """The robot's controller (ValueError for an unknown id)."""
        try:
            return self._robots[self._index[robot_id]]
        except KeyError:
            raise ValueError(f"robot_id: unknown robot {robot_id!r}") from None

    def assign(self, robot_id: str, goal: Point, station: str | None = None) -> None:
        """Send a robot to ``goal`` (see :meth:`BehaviorController.assign`)."""
        self.controller(robot_id).assign(goal, station, self.time)

    def step(self, dt: float) -> None:
        """Advance every robot by ``dt`` seconds: messages, sensing and rules, then safe motion."""
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"step: dt must be a finite number > 0, got {dt!r}")
        near = self._neighbours()
        views = [r.view() for r in self._robots]
        self._deliver(near, views)
        sensed = [[views[j] for j in near[k]] for k in range(len(self._robots))]
        for k, r in enumerate(self._robots):
            r.decide(self.time, sensed[k], views[k])
        for r in self._robots:
            msg = r.wait_message(self.time)
            if msg is not None:
                self._inbox.append((r.id, *msg))
        self._move(dt, sensed)
        self.time += dt
        for r in self._robots:
            r.track_progress(self.time)
            self._longest_stall = max(self._longest_stall, self.time - r.progress_at)

    def positions(self) -> np.ndarray:
        """``(n, 2)`` robot positions, in the order of :attr:`ids`."""
        return np.array([r.pos for r in self._robots]).reshape(len(self._robots), 2)

    def behaviors(self) -> dict[str, Behavior]:
        return {r.id: r.behavior for r in self._robots}

    def arrived(self, robot_id: str) -> bool:
        """The robot reached the goal of its last assignment."""
        return self.controller(robot_id).arrived

    def view(self, robot_id: str) -> RobotView:
        """What the robot broadcasts about itself."""
        return self.controller(robot_id).view()

    def stats(self) -> FleetStats:
        p = self.params
        stalled = tuple(r.id for r in self._robots if self.time - r.progress_at > p.stall_time)
        return FleetStats(self.time, sum(r.deadlocks for r in self._robots), sum(r.replans for r in self._robots),
                          sum(r.replan_failures for r in self._robots), self._refused, stalled, self._longest_stall)

    # -- steps ----------------------------------------------------------------------------------
    def _check_starts(self) -> None:
        """ValueError when two robots' start discs overlap."""
        if self._robots:
            reach = 2 * max(r.radius for r in self._robots)
            for i, j in sorted(cKDTree(self.positions()).query_pairs(reach)):
                a, b = self._robots[i], self._robots[j]
                if math.dist(a.pos, b.pos) < a.radius + b.radius:
                    raise ValueError(f"robots {a.id!r} and {b.id!r}: start discs overlap")

    def _neighbours(self) -> list[list[int]]:
        """For each robot, the robots within communication range (a k-d tree, so the cost grows
        with the number of neighbours, not with the fleet squared)."""
        if not self._robots:
            return []
        tree = cKDTree(self.positions())
        return [[j for j in found if j != k]
                for k, found in enumerate(tree.query_ball_point(tree.data, self.params.comm_range))]

    def _deliver(self, near: list[list[int]], views: list[RobotView]) -> None:
        """Hand over last step's WaitMessages (only within communication range). ``views``: the
        robots' views, kept up to date (a robot that receives a message may re-plan)."""
        inbox, self._inbox = self._inbox, []
        comm = self.params.comm_range
        for sender, receiver, msg in inbox:
            k = self._index.get(receiver)
            if k is None or math.dist(self.controller(sender).pos, self._robots[k].pos) > comm:
                continue
            r = self._robots[k]
            forward = r.receive(self.time, msg, [views[j] for j in near[k]])
            views[k] = r.view()
            if forward is not None:
                self._inbox.append((r.id, *forward))

    def _move(self, dt: float, sensed: list[list[RobotView]]) -> None:
        """Move every robot by its behaviour through the safety layer (in index order)."""
        n = len(self._robots)
        old = self.positions()
        new = old.copy()
        radii = np.array([r.radius for r in self._robots])
        cell = 2 * float(radii.max(initial=0)) + 2 * max((r.max_speed for r in self._robots), default=0) * dt \
            + self.params.safety_margin + EPS
        grid_of: dict[tuple[int, int], list[int]] = {}
        for k in range(n):
            grid_of.setdefault((int(old[k, 0] // cell), int(old[k, 1] // cell)), []).append(k)

        def clear_of_robots(k: int, q: np.ndarray) -> bool:
            """The disc stays at least the sum of radii (plus the safety margin, unless the move
            increases the distance) from every other robot's position at the start of the step
            and, for robots moved already, its new one."""
            cx, cy = int(q[0] // cell), int(q[1] // cell)
            margin = self.params.safety_margin
            for j in (j for dx in (-1, 0, 1) for dy in (-1, 0, 1) for j in grid_of.get((cx + dx, cy + dy), ())):
                if j == k:
                    continue
                touch = radii[k] + radii[j]
                for pj in (old[j], new[j]):
                    d_new = math.dist(q, pj)
                    if d_new < touch or (d_new < touch + margin and d_new < math.dist(old[k], pj)):
                        return False
            return True

        for k, r in enumerate(self._robots):
            moved = r.move(self.time, dt, sensed[k], partial(clear_of_robots, k))
            if moved:
                new[k] = r.pos
            elif moved is False:
                self._refused += 1
