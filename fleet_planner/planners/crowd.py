"""The dense-crowd solver (registered as ``dense`` and ``crowd``): dense crowds of disc robots on the
grid graph (issue 11).

Prioritized planning (md, PRIOR) fails by construction where robots must step aside for each other
in 1-cell aisles. This planner searches the space of configurations instead and makes the result
safe for discs in continuous time:

0. **A timed first plan** where every robot drives at constant top speed: prioritized safe-interval
   planning at each robot's own speed on the cell graph under the timing's holding rule
   (:meth:`.crowd_sipp.TimedRefiner.from_scratch`), refined by the timed LNS of step 2b and re-timed
   by step 3's precedence pass; steps 1-2 are then skipped (plan info ``first_plan: "timed"``). A
   plan of unit steps makes every robot move one cell per step, so timed at mixed speeds the fast
   ones queue behind the slow ones (~0.10 of SoC/free at 400 robots); this plan never does. Ours on
   top: 1-cell corridors are soft one-way lanes (:func:`.crowd_sipp.one_way`), and a robot whose goal
   robots parked on theirs shut off is planned at once before them (:func:`.crowd_sipp.prioritized`).
   Where it fails (or with acceleration limits), the discrete pipeline below plans.
1. **A first plan**: prioritized planning on the same graph under the same rules where it
   succeeds (:func:`.crowd_lns.prioritized_first`: a far shorter first plan than LaCAM's), else
   the **configuration search** (:mod:`.crowd_pibt`): LaCAM (Okumura, "LaCAM: Search-Based Algorithm
   for Quick Multi-Agent Pathfinding", AAAI 2023) with PIBT (Okumura et al., "Priority Inheritance
   with Backtracking for Iterative Multi-agent Path Finding", AIJ 2022) as the successor generator,
   on the 4-connected graph of cell centres, with transition rules for discs (no vertex or swap
   conflicts, no rings of robots following each other). The PIBT step is compiled
   (:mod:`.crowd_kernels`, numba).
2. **Refinement** (:mod:`.crowd_lns`): large neighbourhood search (Li et al., IJCAI 2021) re-plans
   a few robots at a time in space-time against the others under the same rules and keeps what
   lowers the speed-weighted sum of arrivals, for ``refine_s`` CPU seconds; then detours are cut
   where a robot could have waited instead (:func:`.crowd_pibt.remove_loops`).
2b. **Speed-aware refinement** (:mod:`.crowd_sipp`): the discrete plan moves everyone one cell per
   step, so timed at mixed speeds fast robots queue behind slow ones; an LNS over the *timed* plan
   re-plans a few robots at a time by safe-interval search at their own speeds against the others'
   timed cell holdings (``timed_refine_s`` CPU seconds, in two rounds each re-timed by step 3's
   precedence pass; only without acceleration limits).
3. **Timing by precedence** (:mod:`.crowd_timing`): the order in which the discrete plan visits each
   cell is kept as (M,D)-network links with a chosen order (docs/ARCHITECTURE.md, "The (M,D)
   vocabulary"); each robot's earliest times along its cell path follow by a longest-path pass
   over those precedences at its own top speed, with trapezoids where it has ``max_accel``; a
   robot following another into a cell starts as soon as their gap provably stays >= r_i + r_j
   (closed forms for the same direction and for the corner case); collinear moves at one speed
   without a stop are merged.
4. **Diagonal steps** (ours). Up to :data:`DIAGONAL_MAX` robots at top speed with radii <= half a cell, the
   timed searches of steps 0 and 2b take diagonal steps themselves (:func:`.crowd_sipp.sipp`: a step
   between the corners of a free 2x2 block holds its source to its end and its two side cells while it
   drives, the rule below, re-timed exactly by step 3's pass); measured on bench_dense, 400 robots on
   warehouse-10-20-10-2-1, seeds 0-4 at load 6: SoC/free 1.158/1.147/1.172/1.149/1.159 (post-pass) ->
   1.141/1.140/1.155/1.138/1.140 at 1.65-1.81 s CPU. Otherwise a post-pass (:mod:`.crowd_smooth`): where the
   grid has room (free 2x2 blocks), windows
   of each robot's timed path are replaced by shorter octile paths whose diagonal steps hold the two
   side cells they sweep, when that fits the others' holdings; re-timed by step 3's pass with the
   sweeps as visits, which can only make robots earlier (measured on bench_dense, 400 robots on
   warehouse-10-20-10-2-1: SoC/free -0.02; only without acceleration limits, radii <= half a cell).

Why the result is valid (the independent checker, ``checker.check_plan``, is the judge of every
test and benchmark): no cell is ever held by two robots at once except by a follower whose gap is
computed exactly, and two robots on distinct cells of the lattice are at least one cell step
apart, which is >= r_i + r_j - the planner refuses (PlanningError) pairs with a larger sum, starts
and goals off cell centres, and goals that cannot be reached. The plan's info names the solver
(``solver``) and how it went (first plan's steps, configurations, LNS iterations).

``plan_incremental`` plans new legs around driven trajectories: on the lattice (the dense solver's
own plans) by safe-interval search against the exact cell holdings of the driven robots
(:mod:`.crowd_incremental`), otherwise with PRIOR's space-time search (a configuration search cannot
move robots that are not its own, and any-angle trajectories have no exact cell holdings).
"""
from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from ..grid import GridMap
from ..model import Plan, PlanningError, RobotSpec, TimedPath
from . import crowd_kernels as kern
from . import crowd_sipp, crowd_smooth, crowd_st
from .base import Planner, Progress, incremental_problem
from .crowd_lns import MAX_HORIZON, Refiner, prioritized_first
from .crowd_pibt import NIL, CellGraph, ConfigSearch, SearchFailed, remove_loops
from .crowd_sipp import TimedRefiner
from .crowd_timing import network, time_move_list, time_moves, timed_paths

#: what the plan's info names as the solver that ran
SOLVER = "dense: LaCAM/PIBT configuration search + LNS refinement, timed by precedence"


class CrowdPlanner(Planner):
    """LaCAM/PIBT on the grid graph, refined by LNS, timed by precedence (see the module docstring).

    ``time_limit`` (alias ``time_limit_s``): budget of the whole plan in seconds (the configuration
    search must find a first plan within it); ``refine_s``: at most this much CPU time (seconds: the
    same on a loaded machine) is spent improving the first plan (large neighbourhood search,
    :mod:`.crowd_lns`; 0 switches it off; None: what is left of 1.1 s after the first plan up to 400
    robots, 1 s more per 150 beyond, at least 0.2 s); ``seed``:
    tie-breaking; ``network``: also return the (M,D) network of the chosen order (``Plan.network``);
    ``margin``: what a robot following another into a cell keeps on top of r_i + r_j (robots on
    distinct cells keep the cell step, >= r_i + r_j); ``timed_refine_s``: CPU seconds of the
    speed-aware refinement of the timed plan (:mod:`.crowd_sipp`; None: 0.5 s up to 500 robots, else 0;
    it runs only where no robot has ``max_accel``: its safe intervals are at constant top speed).
    ``first``: the first plan: "auto" tries the timed prioritized plan (module docstring, step 0; only
    without ``max_accel``; its timed LNS then gets what is left of :data:`TIMED_BUDGET_S` CPU seconds
    unless ``timed_refine_s`` is given, and ``refine_s`` is not used), then discrete prioritized
    planning (:func:`.crowd_lns.prioritized_first`; skipped when the timed one failed for more than one
    robot in 20: it fails there too), each at most 0.5 s + 1 ms per robot of CPU, and lets the
    configuration search plan when both fail; "discrete" starts with the discrete prioritized plan;
    "lacam" always the configuration search (the plan's info says which: ``first_plan`` "timed",
    "prioritized" or "lacam").
    ``cutoff`` (None: off): a sum of arrival times (s) to beat; when the robots' hop distances on
    the grid graph at top speed (a lower bound of this solver's sum of arrivals before its diagonal
    steps: every plan moves along the graph's edges, one cell step each, at most at top speed) already
    sum to at least it, the solver gives up at once with PlanningError (md's comparison: its plan
    cannot lose, up to what diagonal steps in open floor would have saved).
    ``diagonal``: shorten the timed plan by diagonal steps where they fit (:mod:`.crowd_smooth`; up to
    :data:`DIAGONAL_MAX` robots; with :data:`DIAGONAL_SEARCH` the timed searches take diagonal steps
    themselves and the post-pass is skipped after them).
    ``cpu_start``: the ``time.process_time()`` at which the caller's planning began (md: its crowding
    check then counts towards the CPU budgets of the timed plan; the compiled kernels are loaded
    before, by :meth:`warm_up`, as once per process and not planning).
    ``get_planner("dense")`` with the defaults is the dense solver of issue 11.
    """

    name = "dense"
    #: which search answered the last ``plan_incremental``: "dense" (on the lattice) or "prior"
    last_incremental = ""

    def __init__(self, time_limit: float | None = None, refine_s: float | None = None, seed: int = 0,
                 network: bool = True, time_limit_s: float | None = None, margin: float = 0.02,
                 timed_refine_s: float | None = None, first: str = "auto", cutoff: float | None = None,
                 diagonal: bool = True, cpu_start: float | None = None):
        if time_limit is not None and time_limit_s is not None and time_limit != time_limit_s:
            raise ValueError("time_limit and time_limit_s: give one of them")
        limit = time_limit if time_limit is not None else time_limit_s if time_limit_s is not None else 30.0
        if not limit > 0:
            raise ValueError(f"time_limit: must be > 0 (got {limit!r})")
        if refine_s is not None and not refine_s >= 0:
            raise ValueError(f"refine_s: must be >= 0 (got {refine_s!r})")
        if timed_refine_s is not None and not timed_refine_s >= 0:
            raise ValueError(f"timed_refine_s: must be >= 0 (got {timed_refine_s!r})")
        self.timed_refine_s = None if timed_refine_s is None else float(timed_refine_s)
        if first not in ("auto", "discrete", "lacam"):
            raise ValueError(f"first: 'auto', 'discrete' or 'lacam' (got {first!r})")
        self.first = first
        self.diagonal = bool(diagonal)
        self.cpu_start = None if cpu_start is None else float(cpu_start)
        if cutoff is not None and not (isinstance(cutoff, (int, float)) and math.isfinite(cutoff)):
            raise ValueError(f"cutoff: must be a finite number or None (got {cutoff!r})")
        self.cutoff = None if cutoff is None else float(cutoff)
        self.time_limit_s = float(limit)
        self.refine_s = None if refine_s is None else float(refine_s)
        self.seed = int(seed)
        self.with_network = bool(network)
        if not (margin >= 0 and np.isfinite(margin)):
            raise ValueError(f"margin: must be a finite number >= 0 (got {margin!r})")
        self.margin = float(margin)

    def warm_up(self) -> None:
        kern.warm_up()   # compiled kernels (numba's cache): not part of any planning budget
        crowd_st.warm_up()
        crowd_sipp.warm_up()

    def plan(self, grid: GridMap, robots: Sequence[RobotSpec], progress: Progress | None = None) -> Plan:
        self.warm_up()
        t_start, c_start = time.perf_counter(), time.process_time()
        if self.cpu_start is not None:   # ... unless the caller counts them (md)
            c_start = min(c_start, self.cpu_start)
        deadline = t_start + self.time_limit_s
        robots = list(robots)
        if not robots:
            return Plan(self.name, [], 0.0, {"solver": SOLVER, "steps": 0, "configurations": 0})
        _check_radii(grid, robots)
        graph = CellGraph(grid, max(r.radius for r in robots))
        starts, goals = _cells(graph, robots)
        if progress:
            progress(0, 3, "configuration search")
        search = ConfigSearch(graph, starts, goals, self.seed)
        cut = search.unreachable()
        if cut:
            raise PlanningError({robots[i].id: "its goal cannot be reached from its start on the grid graph "
                                 "of cells its disc fits on" for i in cut})
        durations = np.array([grid.resolution / r.max_speed for r in robots])
        if self.cutoff is not None:
            bound = float(search.lower_bounds() @ durations)
            if bound >= self.cutoff:
                raise PlanningError({r.id: f"dense solver: its lower bound {bound:.1f} s on the sum of arrivals "
                                     f"is not below the cutoff {self.cutoff:.1f} s" for r in robots})
        res = grid.resolution
        centres = np.column_stack([(graph.cols + 0.5) * res, (graph.rows + 0.5) * res])
        radii = [r.radius for r in robots]
        accels = [r.max_accel for r in robots]
        at_top_speed = all(a is None for a in accels)
        # diagonal steps in the timed searches (crowd_sipp): at top speed, radii <= half the cell step
        diagonals = crowd_sipp.diagonal_table(graph.index, graph.rows, graph.cols) \
            if self.diagonal and DIAGONAL_SEARCH and len(robots) <= DIAGONAL_MAX and at_top_speed \
            and max(radii) <= res / 2 + 1e-12 else None
        hopeless = False
        if self.first == "auto" and at_top_speed:
            # speed-aware from the start: each robot planned at its own speed (no fast robot queued behind a
            # slow one by a plan of unit steps); measured on bench_dense (3 seeds, loaded machine), warehouse-10-20-
            # 10-2-1 400 robots: SoC/free 1.242 -> 1.20 at the same CPU (1.8-2.0 s); 20-40-10-2-2 2000: 1.243 -> 1.116
            # and 13.3 -> 9.8 s; 100 robots: 1.061 either way
            wrong = crowd_sipp.one_way(graph.index, graph.rows, graph.cols, graph.nb, graph.deg)
            timed_first, hopeless = TimedRefiner.from_scratch(
                starts, search.goals, durations, search.fields, search.grow, graph.nb, graph.deg, graph.n,
                self.seed, release=crowd_sipp.RELEASE, cpu_s=0.5 + len(robots) / 1000,
                repair=crowd_sipp.REPAIR,
                wrong=wrong, lane=crowd_sipp.LANE, diagonals=diagonals)
            if timed_first is None:
                # (the discrete pipeline's budget below as without the attempt: at 1000 robots on
                # warehouse-10-20-10-2-1 the attempt fails after ~0.9 s, and LaCAM's plan needs its LNS time)
                c_start = time.process_time()
            else:
                t_first = time.perf_counter() - t_start
                if progress:
                    progress(1, 3, "refinement (timed LNS)")
                timed_first.lane_lns = crowd_sipp.LANE_LNS
                whole = TIMED_BUDGET_DIAG_S if diagonals is not None else TIMED_BUDGET_S
                budget = self.timed_refine_s if self.timed_refine_s is not None else \
                    max(0.2, whole * min(1.0, 0.25 + len(robots) / 500) - (time.process_time() - c_start))
                timing, stats = _timed_rounds(timed_first, deadline, budget, starts, search, graph, durations,
                                              centres, radii, res, accels, self.margin, self.seed)
                timed_info = {"solver": SOLVER, "first_plan": "timed", "configurations": 0,
                              "search_s": round(t_first, 3), "diagonal_search": diagonals is not None, **stats}
                return self._finish(timing, centres, starts, robots, res, t_start, timed_info, progress, graph,
                                    durations)
        configs = None
        if self.first in ("auto", "discrete") and not hopeless:
            configs = prioritized_first(graph, search.fields, search.grow, starts, search.goals, durations,
                                        cpu_s=0.5 + len(robots) / 1000)
        first = "prioritized" if configs is not None else "lacam"
        if configs is None:
            try:
                configs = search.solve_array(deadline)
            except SearchFailed as exc:
                raise PlanningError({r.id: f"dense solver: {exc.reason}" for r in robots}) from None
        t_search = time.perf_counter() - t_start
        info: dict = {"solver": SOLVER, "first_plan": first, "steps_first": int(configs.shape[0] - 1),
                      "configurations": search.expanded, "search_s": round(t_search, 3)}
        # (the default: the first plan and its refinement share 1.1 s of CPU up to 400 robots, 1 s more per 150
        # beyond, and the refinement gets at least 0.2 s)
        refine_s = self.refine_s if self.refine_s is not None else \
            max(0.2, 1.1 + max(0, len(robots) - 400) / 150.0 - (time.process_time() - c_start))
        if refine_s > 0 and len(robots) > 1 and configs.shape[0] + 64 < MAX_HORIZON:
            if progress:
                progress(1, 3, "refinement (LNS)")
            # plain A* re-plans after the prioritized first plan from 200 robots (measured, 5 speed seeds at 400:
            # SoC/free 1.250 -> 1.243; 2000 on warehouse-20-40-10-2-2: 1.265 -> 1.245; at 100 no gain: 1.0624 ->
            # 1.0628), weight 1.5 otherwise and after LaCAM's long first plan (plain A* hits its expansion limit
            # there: 1000 robots 3.43 -> 3.77)
            plain = first == "prioritized" and len(robots) >= 200
            refiner = Refiner(graph, search.fields, search.grow, search.goals, configs, durations, self.seed,
                              weight10=10 if plain else 15)
            refiner.run(deadline, cpu_s=refine_s)
            configs = refiner.configs()
            info.update(lns_iterations=refiner.iterations, lns_accepted=refiner.accepted)
        if progress:
            progress(2, 3, "timing by precedence")
        timing = time_moves(remove_loops(configs), durations, centres, radii, res, accels, self.margin)
        # (measured on bench_dense: 400 robots SoC/free 1.341 -> ~1.29; at 1000 and 2000 no gain: there the
        # discrete plan's own delays dominate)
        timed_s = self.timed_refine_s if self.timed_refine_s is not None else 0.5 if len(robots) <= 500 else 0.0
        if timed_s > 0 and len(robots) > 1 and at_top_speed:
            # speed-aware: each robot re-planned at its own speed against the others' timed cells
            timed = TimedRefiner(timing, starts, search.goals, durations, search.fields, search.grow, graph.nb,
                                 graph.deg, graph.n, self.seed, release=crowd_sipp.RELEASE, diagonals=diagonals)
            timing, stats = _timed_rounds(timed, deadline, timed_s, starts, search, graph, durations, centres,
                                          radii, res, accels, self.margin, self.seed, timing)
            info.update(stats)
        info.update(steps=int(configs.shape[0] - 1))
        return self._finish(timing, centres, starts, robots, res, t_start, info, progress, graph, durations)

    def _finish(self, timing, centres, starts, robots, res, t_start, info, progress, graph, durations) -> Plan:
        """The timed paths (and the network) of ``timing``, with diagonal steps where they fit
        (:mod:`.crowd_smooth`; only without acceleration limits and for radii <= half the cell step)."""
        radii = [r.radius for r in robots]
        if self.diagonal and len(robots) <= DIAGONAL_MAX and all(r.max_accel is None for r in robots) \
                and max(radii) <= res / 2 + 1e-12 and not info.get("diagonal_search"):
            c0 = time.process_time()
            before = _arrival_sum(timing)
            timing = crowd_smooth.smooth(timing, starts, graph, durations, centres, radii, res, self.margin,
                                         cpu_s=DIAGONAL_S)
            info.update(diagonal_s=round(time.process_time() - c0, 3),
                        diagonal_gain_s=round(before - _arrival_sum(timing), 3))
        paths = timed_paths(timing, centres, starts, [r.id for r in robots], radii)
        net = network(timing, [r.id for r in robots], res) if self.with_network else None
        if progress:
            progress(3, 3, "done")
        info.update(precedences=len(timing.visits))
        return Plan(self.name, paths, time.perf_counter() - t_start, info, net)

    def plan_incremental(self, grid: GridMap, robots: Sequence[RobotSpec], fixed: Sequence[TimedPath],
                         t0: float) -> list[TimedPath]:
        """New legs around driven trajectories (:mod:`.crowd_incremental`): where every driven
        trajectory lies on the lattice of cell centres (the dense solver's own plans) and the new
        robots start and end on cell centres, each new robot is planned by safe-interval search at its
        own speed against the exact cell holdings of the others; otherwise (any-angle legs of md or
        PRIOR, robots between centres, radius sums over the cell step) PRIOR's space-time search (van
        den Berg & Overmars) plans them against the continuous trajectories. ``last_incremental`` says
        which one answered. A robot the safe-interval search cannot serve (its way shut for good by a
        robot parked in a 1-cell aisle) is refused with PlanningError."""
        from . import crowd_incremental as inc
        from .prior import PriorPlanner

        robots = incremental_problem(robots, fixed, t0)
        if not robots:
            self.last_incremental = "dense"
            return []
        step = grid.resolution
        widest = max(r.radius for r in robots)
        others = [r.radius for r in robots] + [p.radius for p in fixed]
        others.remove(widest)          # the widest new robot's widest partner, new or driven
        if widest + max(others, default=0.0) <= step + 1e-9:
            kern.warm_up()
            crowd_sipp.warm_up()
            graph = CellGraph(grid, widest)
            try:
                cells: tuple[list[int], list[int]] | None = _cells(graph, robots)
            except PlanningError:
                cells = None
            if cells is not None and not ConfigSearch(graph, *cells).unreachable():
                holdings = inc.lattice_holdings(fixed, graph, float(t0))
                if holdings is not None:
                    # no leg here is no leg for PRIOR either: one robot's safe-interval search is complete on
                    # the cell graph against fixed holdings, and PRIOR plans the new robots one by one too
                    self.last_incremental = "dense"
                    return inc.plan_legs(graph, robots, cells[0], cells[1], holdings, float(t0), self.seed)
        self.last_incremental = "prior"
        return PriorPlanner().plan_incremental(grid, robots, fixed, t0)


#: CPU seconds of a whole plan (first plan and timed LNS) after a timed first plan from 375 robots on,
#: less below (0.25 + N / 500 of it: at 100 robots SoC/free is reached after ~0.5 s), unless
#: ``timed_refine_s`` says otherwise. More LNS time helps little (bench_dense --timed-refine, 400 robots on
#: warehouse-10-20-10-2-1, seeds 0/1/2, SoC/free mean: the default ~1.15 s 1.176, 2.3 s 1.168, 4.6 s 1.163,
#: 9.2 s 1.158): a faster LNS alone cannot bring it to 1.15; the first plan's robots parked in 1-cell aisles
#: are most of the excess (robots vanishing on arrival: first plan 1.10 instead of 1.19, floor 1.064).
#: 1.5 -> 1.2 with the diagonal steps (crowd_smooth, ~0.25 s CPU at 400 robots for SoC/free -0.02; the last
#: 0.3 s of LNS bought ~0.003)
TIMED_BUDGET_S = 1.2
#: the same with diagonal steps in the timed searches (DIAGONAL_SEARCH): the post-pass's ~0.3 s go to the LNS
TIMED_BUDGET_DIAG_S = 1.5
#: CPU seconds of the diagonal steps' search for rewrites (crowd_smooth; the re-timing of what it found comes
#: on top): at 400 robots it needs ~0.3 s
DIAGONAL_S = 0.4
#: diagonal steps up to this many robots (like the timed LNS's default). Beyond, unbounded they cost too much
#: (seed 0, load 15: LaCAM's long plans at 1000 robots on warehouse-10-20-10-2-1 2.4 s for SoC/free 3.338 ->
#: 3.297; 2000 on warehouse-20-40-10-2-2 8.9 s for 1.116 -> 1.090), and within DIAGONAL_S they gained
#: nothing (2000: 10.74 s against 9.92, SoC/free 1.116 either way; 1000: 7.44 s against 6.61, 3.330 -> 3.327)
DIAGONAL_MAX = 500
#: rounds of the timed LNS, each re-timed by the precedence pass (robots that no longer wait for the
#: re-planned ones move up, which gives the next round room)
TIMED_ROUNDS = 3
#: diagonal steps in the timed searches themselves (crowd_sipp), up to DIAGONAL_MAX robots
DIAGONAL_SEARCH = True


def _timed_rounds(refiner: TimedRefiner, deadline: float, cpu_s: float, starts, search, graph, durations, centres,
                  radii, res, accels, margin, seed, timing=None):
    """The timed LNS in :data:`TIMED_ROUNDS` rounds of ``cpu_s`` in all, each started from the
    precedence pass's timing of the last; returns the best timing re-timed (the refiner's own times
    use its release model, the precedence pass the exact rules: the sum of arrivals is judged after
    re-timing, so the result is never worse than ``timing``) and the LNS counts for the plan's info."""
    starts = np.asarray(starts)

    def retimed(r: TimedRefiner):
        robot, key, src, dst = r.moves()
        sides = r.sides(src, dst)
        return time_move_list(starts, robot, key, src, dst, durations, centres, radii, res, accels, margin,
                              sides=sides if np.any(sides != NIL) else None)

    def total(t) -> float:
        arrival = np.zeros(len(starts))
        np.maximum.at(arrival, t.robot, t.end)
        return float(arrival.sum())

    if timing is None:
        timing = retimed(refiner)
    best, best_sum = timing, total(timing)
    iterations = accepted = 0
    for k in range(TIMED_ROUNDS):
        if k > 0:
            refiner = TimedRefiner(timing, starts, search.goals, durations, search.fields, search.grow, graph.nb,
                                   graph.deg, graph.n, seed + k, release=crowd_sipp.RELEASE, wrong=refiner.wrong,
                                   lane=refiner.lane_lns, diagonals=(refiner.dnb, refiner.dside, refiner.ddeg))
        refiner.run(deadline, cpu_s=cpu_s / TIMED_ROUNDS)
        iterations, accepted = iterations + refiner.iterations, accepted + refiner.accepted
        if not refiner.accepted:
            if len(starts) > DIAGONAL_MAX:
                break      # (2000 robots on warehouse-20-40-10-2-2: one batch of a round overshoots its share, +1.5 s)
            continue   # (the next round from the same timing, another seed: the round's budget is not lost)
        timing = retimed(refiner)
        now = total(timing)
        if now < best_sum - 1e-9:
            best, best_sum = timing, now
    return best, {"timed_lns_iterations": iterations, "timed_lns_accepted": accepted}


def _arrival_sum(timing) -> float:
    """The sum of the robots' last move ends (robots without moves count 0)."""
    arrival = np.zeros(len(timing.first) - 1)
    np.maximum.at(arrival, timing.robot, timing.end)
    return float(arrival.sum())


def _check_radii(grid: GridMap, robots: Sequence[RobotSpec]) -> None:
    """Distinct cells are one step apart: every pair's radius sum must fit in that."""
    step = grid.resolution
    widest = max(r.radius for r in robots)
    second = sorted(r.radius for r in robots)[-2] if len(robots) > 1 else 0.0
    if widest + second > step + 1e-9:
        wide = {}
        for r in robots:
            other = second if r.radius == widest else widest
            if r.radius + other > step + 1e-9:
                wide[r.id] = (f"radius {r.radius:g} m: the dense solver needs r_i + r_j <= the cell step "
                              f"{step:g} m for every pair")
        raise PlanningError(wide)


def _cells(graph: CellGraph, robots: Sequence[RobotSpec]) -> tuple[list[int], list[int]]:
    failures: dict[str, str] = {}
    starts, goals = [], []
    for r in robots:
        s, g = graph.cell(*r.start), graph.cell(*r.goal)
        if s == NIL:
            failures[r.id] = f"start {r.start} is not the centre of a free cell its disc fits on"
        elif g == NIL:
            failures[r.id] = f"goal {r.goal} is not the centre of a free cell its disc fits on"
        starts.append(s)
        goals.append(g)
    for what, cells in (("start", starts), ("goal", goals)):
        seen: dict[int, str] = {}
        for r, c in zip(robots, cells):
            if c != NIL and c in seen:
                failures[r.id] = f"its {what} cell is {seen[c]}'s {what} cell too"
            seen.setdefault(c, r.id)
    if failures:
        raise PlanningError(failures)
    return starts, goals


#: the dense solver's name in the registry (``crowd`` is the same planner under its first name)
DensePlanner = CrowdPlanner

__all__ = ["SOLVER", "CrowdPlanner", "DensePlanner"]
