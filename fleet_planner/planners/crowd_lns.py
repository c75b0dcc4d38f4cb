"""Quality for the dense-crowd solver: large neighbourhood search over its discrete plan.

LaCAM's first plan (PIBT steps) is feasible but long: robots give way by wandering. Following
Li, Chen, Harabor, Stuckey and Koenig, "Anytime Multi-Agent Path Finding via Large Neighborhood
Search" (IJCAI 2021), we repeatedly take a few robots out of the plan, re-plan each of them in
space-time against all the others (A* over (step, cell), :func:`.crowd_kernels.st_search`, under
the same transition rules as the configuration search: no vertex or swap conflicts, no rings of
followers, goals held for ever once reached) and keep the new paths when the weighted sum of
arrivals did not grow. A robot's weight is its time per cell (1 / top speed), so the discrete sum
tracks the timed sum of arrivals the plan is judged by.

Neighbourhoods: a robot drawn with probability growing with its delay over its hop distance,
together with the robots standing on its shortest path at the steps it would pass there (the
ones in its way), or a few delayed robots drawn at random; the two kinds are picked adaptively by
how often each improved the plan. Every accepted plan satisfies the transition rules, so the
refinement can stop at any time.
"""
from __future__ import annotations

import time

import numpy as np

from . import crowd_st as st

NIL = -1
#: the kernels' heap keys leave 16 bits for the step
MAX_HORIZON = 30_000


class LNSStats:
    """What both large neighbourhood searches (:class:`Refiner`, :class:`.crowd_sipp.TimedRefiner`)
    count in their ``stats`` array, which their compiled iterations update: [iterations, accepted, ...]."""

    stats: np.ndarray

    @property
    def iterations(self) -> int:
        return int(self.stats[0])

    @property
    def accepted(self) -> int:
        return int(self.stats[1])


class Refiner(LNSStats):
    """LNS over a discrete plan ``configs`` ((steps + 1, robots) cells) on ``graph``; ``fields`` /
    ``grow`` are the goal distance fields of the configuration search; ``weights`` per robot (its
    time per cell); ``size`` robots per neighbourhood. The iterations are compiled
    (:func:`.crowd_st.lns_iterations`); :meth:`run` calls them in small batches until its deadline."""

    def __init__(self, graph, fields: np.ndarray, grow: np.ndarray, goals: np.ndarray, configs: np.ndarray,
                 weights: np.ndarray, seed: int = 0, size: int = 4, weight10: int = 15):
        self.graph = graph
        self.fields, self.grow = fields, grow
        self.goals = np.asarray(goals, dtype=np.int32)
        steps = configs.shape[0] - 1
        self.n = configs.shape[1]
        self.lb = fields[grow, configs[0]].astype(np.int64)
        self.horizon = min(MAX_HORIZON, steps + max(64, steps // 3))
        h = self.horizon
        self.paths = np.empty((h + 1, self.n), dtype=np.int32)
        self.paths[:steps + 1] = configs
        self.paths[steps + 1:] = configs[-1]
        self.occ = np.full((h + 1, graph.n), NIL, dtype=np.int32)
        self.occ[np.arange(h + 1)[:, None], self.paths] = np.arange(self.n, dtype=np.int32)[None, :]
        self.cost = st.arrival_steps(self.paths, self.goals)
        self.weights = np.asarray(weights, dtype=float)
        self.size = max(2, min(int(size), self.n))
        self.stamp = np.zeros((h + 1) * graph.n, dtype=np.int32)
        self.parent = np.zeros((h + 1) * graph.n, dtype=np.int32)
        self.out = np.empty(h + 1, dtype=np.int32)
        self.gen = 0
        self.stats = np.zeros(2, dtype=np.int64)      # iterations, accepted
        self.strategy = np.ones(2)
        self.expansion_limit = 4 * graph.n
        self.weight10 = int(weight10)
        st.seed_rng(int(seed))

    def weighted_cost(self) -> float:
        return float(np.dot(self.weights, self.cost))

    def configs(self) -> np.ndarray:
        """The current plan, cut after the last arrival."""
        return self.paths[:int(self.cost.max(initial=0)) + 1].copy()

    def run(self, deadline: float, max_iterations: int = 1_000_000, batch: int = 16, patience: int = 0,
            cpu_s: float = float("inf")) -> None:
        """Improve the plan until ``deadline`` (perf_counter), ``cpu_s`` seconds of this process's CPU
        time or ``max_iterations``, until no robot is delayed, or until ``patience`` iterations in a
        row did not lower the weighted sum (default: 50 + the number of robots)."""
        g = self.graph
        cpu_end = time.process_time() + cpu_s
        patience = patience or 50 + self.n
        best, best_at = self.weighted_cost(), self.iterations
        while (self.iterations < max_iterations and time.perf_counter() < deadline
               and time.process_time() < cpu_end):
            if self.iterations - best_at >= patience:
                return
            if not np.any(self.cost > self.lb):
                return
            if self.gen > 2**31 - 1 - batch * self.size - 1:
                self.stamp[:] = 0
                self.gen = 0
            before = self.iterations
            self.gen = int(st.lns_iterations(min(batch, max_iterations - self.iterations), self.paths, self.occ,
                                             self.cost, self.lb, self.weights, self.goals, self.fields, self.grow,
                                             g.nb, g.deg, self.stamp, self.gen, self.parent, self.out, self.size,
                                             self.expansion_limit, self.weight10, self.horizon, self.strategy,
                                             self.stats))
            if self.iterations == before:
                return
            now = self.weighted_cost()
            if now < best - 1e-9:
                best, best_at = now, self.iterations


def prioritized_first(graph, fields: np.ndarray, grow: np.ndarray, starts, goals: np.ndarray, weights: np.ndarray,
                      tries: int = 3, hold: int = 3, cpu_s: float = float("inf"),
                      give_up: int = 20) -> np.ndarray | None:
    """A first discrete plan by prioritized planning (:func:`.crowd_st.prioritized`), far shorter than
    LaCAM's (warehouse-10-20-10-2-1, 400 robots: speed-weighted sum 1.23 over free-space arrivals
    against LaCAM's 1.96): robots with the shortest weighted distance first, each by the space-time
    search against the ones before it and the start cells of the ones after it for ``hold`` steps.
    Where a few robots find no path (parked robots can shut a 1-cell aisle), the failed robots go
    first and the plan is made again, at most ``tries`` times or ``cpu_s`` CPU seconds; None when
    none succeeded or more than one robot in ``give_up`` failed in a pass (prioritized planning is
    not complete: the configuration search then plans; on warehouse-10-20-10-2-1 at 1000 robots a
    tenth of them failed pass after pass)."""
    starts = np.asarray(starts, dtype=np.int32)
    n = len(starts)
    lb = fields[grow, starts].astype(np.int64)
    h = int(3 * lb.max(initial=0) + 64)
    if h >= MAX_HORIZON or n == 0:
        return None
    cpu_end = time.process_time() + cpu_s
    order = np.argsort(lb * np.asarray(weights, dtype=float), kind="stable").astype(np.int64)
    size = (h + 1) * graph.n
    stamp = np.zeros(size, dtype=np.int32)
    parent = np.zeros(size, dtype=np.int32)
    out = np.empty(h + 1, dtype=np.int32)
    failed = np.empty(n, dtype=np.int64)
    max_failed = max(2, n // give_up)
    gen = 0
    for _ in range(tries):
        paths = np.tile(starts, (h + 1, 1))
        occ = np.full((h + 1, graph.n), NIL, dtype=np.int32)
        cost = np.zeros(n, dtype=np.int64)
        if gen > 2**31 - 1 - 2 * n:
            stamp[:] = 0
            gen = 0
        gen, nf = st.prioritized(order, hold, paths, occ, cost, goals, fields, grow, graph.nb, graph.deg, stamp, gen,
                                 parent, out, 4 * graph.n, 15, failed, max_failed)
        if nf == 0:
            return paths[:int(cost.max(initial=0)) + 1].copy()
        if nf > max_failed or time.process_time() > cpu_end:
            return None
        first = failed[:nf]
        order = np.concatenate([first, order[~np.isin(order, first)]])
    return None
