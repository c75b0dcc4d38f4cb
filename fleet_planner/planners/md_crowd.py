"""When the md planner hands an instance to the dense solver (issue 8): crowding measured before
any path is planned, and the comparison of two plans.

Prioritized planning fails by construction where robots park in aisles too narrow for two of them
to pass (one robot's start or goal disc then blocks every path through the aisle: docs/ARCHITECTURE.md,
measured fact 1), and md's safe paths alone cost seconds at several hundred robots (8.7 s CPU at 400
robots on warehouse-10-20-10-2-1, before the first conflict is even seen). So the planner looks at
the instance first: the *lanes* are the free cells where the free run across (in the row or the
column) is too short for two of the widest discs side by side; they group into aisles
(4-connected). The instance is crowded when robots' starts and goals in lanes are many per aisle
(``lane_load``, measured on the MovingAI warehouse with 1-cell aisles: 0.24 at 100 robots, 0.49 at
200 - md plans both - 0.90 at 400 and 1.12 at 500, which md refuses and the dense solver plans in
about 1.3 s CPU), or when there are simply many robots (``crowd_robots``: md took more than
90 s at 1000; at 400 and 500 robots on warehouse-10-20-10-2-2 and warehouse-20-40-10-2-2 md
planned in 5-12 s CPU and the dense solver's plan, planned after it, had the lower sum of
arrivals on all four (1.13-1.16 over free; md's own 1.139 against 1.128 at 400 on
warehouse-20-40-10-2-2), so md's plan there only spent the budget: 9-18 s CPU in all).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .. import _path_kernels
from ..grid import GridMap
from ..model import Plan, RobotSpec

#: starts and goals in lanes per aisle from which an instance is crowded (see the module docstring)
LANE_LOAD = 0.7
#: robots from which md hands the instance to the dense solver at once
CROWD_ROBOTS = 400
#: starts and goals in lanes per aisle from which an instance is busy: md's plan would only lose the
#: comparison with the dense solver's, so the dense solver plans first, with small refinement budgets
#: (:data:`BUSY_REFINE_S`). Measured on warehouse-10-20-10-2-1 (SoC/free, md's own plan before the
#: comparison, the dense plan with 0.05 s refinements): 50 robots (lane load 0.14) md 1.011, dense
#: 1.054; 55 md 1.020, dense 1.052; 60 (0.162) md's first plan lost to dense 1.050, as at 70 (0.177),
#: 85 (0.205) and 100 (0.244: md 1.098-1.131 against 1.062). The 2-cell-aisle maps have no lanes.
LANE_LOAD_BUSY = 0.16
#: the dense solver's two refinement budgets (CPU s per 100 robots each) on a busy instance (measured
#: at 100 robots on warehouse-10-20-10-2-1: no refinement 1.0645 in 0.08 s CPU, 0.05 s 1.0617 in 0.18 s,
#: 0.2 s 1.0611 in 0.36 s, the solver's defaults 1.0608 in 0.75 s)
BUSY_REFINE_S = 0.05
#: fewer robots than this are never crowded and md's plan is not compared with the dense solver's:
#: md is cheap there, and small hand-worked cases stay md's
MIN_ROBOTS = 10


@dataclass(frozen=True)
class Crowding:
    """How crowded an instance is for prioritized planning."""

    robots: int
    #: aisles (connected groups of lane cells) and the starts and goals in them
    aisles: int
    in_lanes: int

    @property
    def lane_load(self) -> float:
        return self.in_lanes / self.aisles if self.aisles else 0.0

    def crowded(self, lane_load: float | None = None, robots: int | None = None) -> str | None:
        """Why the dense solver should plan this instance first, or None (thresholds: the module's
        LANE_LOAD and CROWD_ROBOTS unless given)."""
        lane_load = LANE_LOAD if lane_load is None else lane_load
        robots = CROWD_ROBOTS if robots is None else robots
        if self.robots < MIN_ROBOTS:
            return None
        if self.robots >= robots:
            return f"{self.robots} robots (md hands {robots} or more to the dense solver)"
        if self.aisles and self.lane_load >= lane_load:
            return (f"{self.in_lanes} starts and goals in {self.aisles} one-lane aisles "
                    f"({self.lane_load:.2f} per aisle, >= {lane_load:g})")
        return None

    def busy(self, lane_load: float | None = None) -> str | None:
        """Why the dense solver's plan would be the better one (it then plans first, with small
        refinement budgets), or None (threshold: the module's LANE_LOAD_BUSY unless given)."""
        lane_load = LANE_LOAD_BUSY if lane_load is None else lane_load
        if self.robots < MIN_ROBOTS or not self.aisles or self.lane_load < lane_load:
            return None
        return (f"{self.in_lanes} starts and goals in {self.aisles} one-lane aisles "
                f"({self.lane_load:.2f} per aisle, >= {lane_load:g}: the dense plan would win)")


def crowding(grid: GridMap, robots: Sequence[RobotSpec], margin: float = 0.0) -> Crowding:
    """Measure the instance (compiled code only: runs counted by NumPy, aisles labelled by a numba kernel)."""
    if not robots:
        return Crowding(0, 0, 0)
    free = ~np.asarray(grid.blocked, dtype=bool)
    two = 4 * max(r.radius for r in robots) + 2 * margin   # two widest discs side by side
    # runs of free cells along each row and each column, too short for two discs side by side
    lanes = free & ((_run_lengths(free) * grid.resolution < two) | (_run_lengths(free.T).T * grid.resolution < two))
    count = _path_kernels.count_components4(np.ascontiguousarray(lanes))   # aisles: 4-connected lanes
    if not count:
        return Crowding(len(robots), 0, 0)
    pts = np.array([p for r in robots for p in (r.start, r.goal)], dtype=float)
    cols = np.clip(np.floor(pts[:, 0] / grid.resolution).astype(int), 0, grid.width - 1)
    rows = np.clip(np.floor(pts[:, 1] / grid.resolution).astype(int), 0, grid.height - 1)
    return Crowding(len(robots), int(count), int(np.count_nonzero(lanes[rows, cols])))


def _run_lengths(free: np.ndarray) -> np.ndarray:
    """Per cell, the length (cells) of the run of free cells along its row that holds it (0 where
    blocked)."""
    h, w = free.shape
    flat = np.zeros((h, w + 1), dtype=bool)
    flat[:, :w] = free   # a blocked column after each row: runs never wrap
    flat = flat.ravel()
    ids = np.cumsum(flat & ~np.concatenate([[False], flat[:-1]]))
    counts = np.bincount(ids, weights=flat)
    return np.where(flat, counts[ids], 0.0).reshape(h, w + 1)[:, :w]


def sum_of_arrivals(plan: Plan) -> float:
    return float(sum(p.arrival_time for p in plan.paths))
