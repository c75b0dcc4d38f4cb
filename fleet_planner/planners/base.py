"""One interface for every multi-robot planner (md, prior, ...), so the CLI, the fleet manager, the
delivery simulation, the benchmarks and the tests run the same body over all of them."""
from __future__ import annotations

import math
import time
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


#: a :class:`Budget` also runs out after this many times its CPU seconds of wall-clock time (so that a
#: starved process still stops)
WALL_BACKSTOP = 10.0


class Budget:
    """A planning budget in CPU seconds of the thread that plans (``time.thread_time``: a ROS node's
    other threads do not spend it), not wall-clock seconds: what a planner does with it does not
    depend on how loaded the machine is (the same md run and seed of the delivery benchmark ended
    at CTime 1170 and 1304 s under different loads with wall-clock budgets). As a backstop it also
    runs out once :data:`WALL_BACKSTOP` times as many wall-clock seconds have passed. ``None``: no
    bound.
    ``wall``: wall-clock seconds instead (PRIOR's own ``time_limit_s``, as published).

    :attr:`backstops` counts the CPU budgets that ran out on the backstop before their CPU seconds (a
    starved process: then what the planner did depends on the load; the delivery benchmark reports it)."""

    #: CPU budgets (of any instance, in this process) that ran out on the wall-clock backstop first
    backstops: ClassVar[int] = 0
    #: budgets (in this process) that ran out at all, on either clock (checked and found spent)
    spent: ClassVar[int] = 0

    def __init__(self, cpu_s: float | None, wall: bool = False):
        self.cpu_s = cpu_s
        self._cpu_end = math.inf if cpu_s is None or wall else time.thread_time() + cpu_s
        self._wall_end = math.inf if cpu_s is None else time.perf_counter() + (1.0 if wall else WALL_BACKSTOP) * cpu_s
        self._counted = False

    def passed(self) -> bool:
        """True once the budget is spent."""
        if time.thread_time() > self._cpu_end:
            self._count(backstop=False)
            return True
        if time.perf_counter() <= self._wall_end:
            return False
        self._count(backstop=self._cpu_end != math.inf)
        return True

    def _count(self, backstop: bool) -> None:
        if not self._counted:
            self._counted = True
            Budget.spent += 1
            Budget.backstops += backstop

    def left(self) -> float:
        """Seconds left (CPU, or wall-clock with ``wall``; 0 once spent, at the backstop too; infinite
        without a bound)."""
        if self.passed():
            return 0.0
        if self._cpu_end == math.inf:
            return max(self._wall_end - time.perf_counter(), 0.0)
        return max(self._cpu_end - time.thread_time(), 0.0)
