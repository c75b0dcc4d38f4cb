"""What a run is bounded by (:class:`RunLimits`), counts as it goes (:class:`RunTally`) and returns
(:class:`DeliveryResult`); the measures every method shares."""
from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ..checker import check_plan, min_separation
from ..model import Plan, RobotSpec, TimedPath
from .problem import DeliveryProblem

#: progress callback: (deliveries done, deliveries in total, simulated time)
SimProgress = Callable[[int, int, float], None]

#: why a run stopped: every delivery done, the simulated-time cap, nothing moved for long, the wall-clock cap
STOPS = ("done", "cap", "stall", "wall")


@dataclass(frozen=True)
class RunLimits:
    """When a run stops and how it waits (the meanings and defaults: :func:`~fleet_planner.delivery.simulate`)."""

    cap_s: float
    stall_s: float
    no_progress_s: float
    retry_s: float
    wall_cap_s: float


@dataclass
class RunTally:
    """The counters of a run, kept while it goes."""

    started: float = field(default_factory=time.perf_counter)   # wall clock at the start
    legs: int = 0                # legs started (planned, or assigned to the behaviour fleet)
    failed_plans: int = 0        # attempts that raised PlanningError
    decide_wall_s: float = 0.0   # wall time spent planning / deciding

    @contextmanager
    def deciding(self) -> Iterator[None]:
        """Counts the wall time of the block as planning / deciding time."""
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.decide_wall_s += time.perf_counter() - t0

    def wall_s(self) -> float:
        return time.perf_counter() - self.started


@dataclass
class DeliveryResult:
    """What one run measured. ``ctime`` is the completion time of the last delivery, or the
    simulated time at which the run stopped when ``stop`` is not "done"."""

    problem: str
    method: str
    n_robots: int
    n_deliveries: int
    completed: int
    stop: str                  # one of STOPS: "done", "cap" (simulated-time cap), "stall", "wall"
    ctime: float
    lower_bound: float
    avg_velocity: float
    decision_s: float          # planner wall s per planned leg, failed attempts included (central),
                               # or wall s per fleet step (behavior)
    decision_unit: str         # "leg" or "step"
    planner_wall_s: float      # all wall time spent planning / deciding
    legs: int                  # legs driven (planned and started)
    failed_plans: int          # planning attempts that raised PlanningError (retried later)
    collisions: int            # pairs of discs that overlapped (central), overlap events (behavior)
    min_gap: float             # smallest distance minus sum of radii seen over the run
    deadlocks: int             # robots with work left that made no progress for no_progress_s at the end
    wall_s: float
    violations: list[str] = field(default_factory=list)  # central: other plan-contract breaches
    trajectories: list[TimedPath] | None = None          # central: what every robot drove
    positions: np.ndarray | None = None                  # behavior with record=True: (steps + 1, N, 2)
    times: np.ndarray | None = None                      # the times of ``positions``
    extra: dict = field(default_factory=dict)

    @property
    def finished(self) -> bool:
        return self.stop == "done"


def mean_velocity(driven: Sequence[float] | np.ndarray, t: float) -> float:
    """Distance driven per robot, averaged over robots, divided by the run's time ``t``."""
    return float(np.mean(driven)) / t if t > 0 else 0.0


def distance_driven(wp: np.ndarray, t: float) -> float:
    """Distance driven along timed waypoints ``(x, y, t)`` until time t."""
    seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
    t0, t1 = wp[:-1, 2], wp[1:, 2]
    frac = np.clip((t - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
    frac = np.where(t1 > t0, frac, (t >= t1).astype(float))
    return float(np.sum(seg * frac))


def check_driven(problem: DeliveryProblem, paths: list[TimedPath]) -> tuple[int, float, list[str]]:
    """Overlapping pairs, the smallest gap, and every other breach of the plan contract, by the
    independent checker on what the robots drove."""
    specs = [RobotSpec(p.robot_id, problem.radius, problem.max_speed, tuple(p.waypoints[0, :2]),
                       tuple(p.waypoints[-1, :2])) for p in paths]
    found = check_plan(problem.grid, specs, Plan("sim", paths))
    collisions = sum(1 for v in found if v.kind == "collision")
    return collisions, min_separation(paths)[0], [str(v) for v in found if v.kind != "collision"]
