"""One interface for every multi-robot planner (md, prior, ...), so tests and benchmarks run the same
body over all of them."""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Callable, ClassVar, Sequence

from ..grid import GridMap
from ..model import Plan, RobotSpec, TimedPath

#: progress callback: (done, total, what) - e.g. a progress bar in the CLI or a benchmark
Progress = Callable[[int, int, str], None]


class Planner(ABC):
    """Turns a map and robots (start, goal, radius, speed) into a :class:`Plan`.

    ``plan`` returns a valid plan (every disc in free space, no two discs overlapping at any
    instant, parked robots included, no speed above ``max_speed``) or raises
    :class:`~fleet_planner.model.PlanningError` naming the robots it could not serve and why.
    It never returns an invalid plan.
    """

    name: ClassVar[str]

    @abstractmethod
    def plan(self, grid: GridMap, robots: Sequence[RobotSpec], progress: Progress | None = None) -> Plan:
        ...

    def plan_incremental(self, grid: GridMap, robots: Sequence[RobotSpec], fixed: Sequence[TimedPath],
                         t0: float) -> list[TimedPath]:
        """Timed paths (absolute times) for ``robots`` leaving their starts no earlier than ``t0``,
        around the ``fixed`` trajectories being driven (unchanged; each robot stays on its last
        waypoint for ever); raises :class:`~fleet_planner.model.PlanningError` like :meth:`plan`."""
        raise NotImplementedError(f"{type(self).__name__} does not plan incrementally")
