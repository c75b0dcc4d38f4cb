"""One interface for every multi-robot planner (md, prior, ...), so the CLI, the fleet manager, the
delivery simulation, the benchmarks and the tests run the same body over all of them."""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import ClassVar

from ..grid import GridMap
from ..model import Plan, RobotSpec, TimedPath

#: progress callback: (done, total, what) - e.g. a progress bar in the CLI or a benchmark
Progress = Callable[[int, int, str], None]


class Planner(ABC):
    """Turns a map and robots (start, goal, radius, speed) into timed paths, in one of two ways:

    * :meth:`plan` - one-shot: every robot from its start at t = 0, a whole :class:`Plan`;
    * :meth:`plan_incremental` - new legs for some robots around trajectories that other robots
      are already driving (the fleet manager and the delivery simulation, one leg at a time).

    Both return valid timed paths only (every disc in free space, no two discs overlapping at any
    instant, parked robots included, no speed above ``max_speed``) or raise
    :class:`~fleet_planner.model.PlanningError` naming the robots they could not serve and why.
    They never return an invalid plan. Planners are built by name from the registry
    (:func:`fleet_planner.planners.get_planner`).
    """

    name: ClassVar[str]
    #: a run driving this planner's legs may re-order two of them in flight (a new leg goes first past a
    #: robot already driving, whose leg is then planned again around it): md's priority search in the live
    #: fleet. False: first come first served, every leg planned once stays (PRIOR)
    reorders_legs: bool = False

    @abstractmethod
    def plan(self, grid: GridMap, robots: Sequence[RobotSpec], progress: Progress | None = None) -> Plan:
        """A plan for ``robots``: each sits on its start from t = 0 until it departs and on its goal
        for ever after it arrives. ``progress`` is called now and then with (done, total, what)."""

    @abstractmethod
    def plan_incremental(self, grid: GridMap, robots: Sequence[RobotSpec], fixed: Sequence[TimedPath],
                         t0: float) -> list[TimedPath]:
        """New legs for ``robots`` around trajectories being driven.

        Each robot of ``robots`` stands on its ``start`` at ``t0`` and leaves it no earlier than
        ``t0``. ``fixed`` are the trajectories of the other robots in absolute time; they stay as
        they are (each robot parked on its last waypoint for ever after it), so only the new legs
        give way. Returns one timed path per robot, in the order of ``robots``, in absolute time,
        starting with the waypoint ``(start, t0)``. Raises
        :class:`~fleet_planner.model.PlanningError` (with ``blockers``, the robot in the way, where
        one is known) when a robot cannot be served, ``ValueError`` when the input is not a planning
        problem this planner takes (e.g. a robot both fixed and to be planned)."""


    def warm_up(self) -> None:
        """Load (or compile) the compiled code this planner runs, once per process, so that no
        planning budget is spent on it: the fleet manager calls it when it is set up, and planners
        whose kernels are compiled call it before their budgets start. Nothing to do by default."""
        return None


def incremental_problem(robots: Sequence[RobotSpec], fixed: Sequence[TimedPath], t0: float) -> list[RobotSpec]:
    """``robots`` as a list, once the arguments of :meth:`Planner.plan_incremental` are a problem
    it takes: ``t0`` finite and no robot both fixed and to be planned (else ``ValueError`` naming
    the argument)."""
    if not math.isfinite(t0):
        raise ValueError(f"t0: must be finite (got {t0!r})")
    robots = list(robots)
    clash = {r.id for r in robots} & {p.robot_id for p in fixed}
    if clash:
        raise ValueError(f"fixed: robots {sorted(clash)} are both fixed and to be planned")
    return robots


