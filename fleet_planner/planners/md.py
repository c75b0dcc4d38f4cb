"""The (M,D) collision-model planner of You & Ji, "Design of a Multi-robot Bin Packing System in an
Automatic Warehouse", with what we measured it needs (docs/ARCHITECTURE.md, measured facts 1-5).

1. Safe paths: each robot's path avoids the start discs of lower-priority robots and the goal discs
   of higher-priority robots where the map allows (falling back to goals only, then to nothing).
   Robots with ``max_accel`` drive it with speed ramps (:func:`~fleet_planner.model.drive_profile`).
2. The (M,D) network over those paths and priority-ordered departure delays (Eq. 3), with the
   paper's collision boxes (``mode="box"``) or the exact regions (``mode="exact"``, default);
   with exact regions and ``holds="anywhere"``, waits at any vertex of the path instead of at the start only
   (``holds="anywhere"``: an earliest-arrival search against the higher robots' timed
   trajectories, see :mod:`fleet_planner.scheduler`; paths get a vertex about every grid cell so
   that there is somewhere to wait). ``holds="none"`` is the departure-only method.
3. Where a delay cannot help (a higher robot parks on its goal in the way, or passes a lower
   robot's start while it is still parked), the robot that moves is first re-routed around the
   disc in the way, else the blocked robot is moved just ahead of its blocker; only the paths
   whose avoidance changed are re-planned, only their collision regions recomputed and only the
   robots whose constraints changed re-scheduled.
"""
from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..budget import Budget
from ..collision import CollisionModel
from ..geometry import polyline_keeps_off, polyline_passes_near
from ..grid import GridMap
from ..model import (
    COLLISION_TESTS,
    Network,
    Plan,
    PlanningError,
    RobotSpec,
    TimedPath,
    drive_profile,
    timed_path_from_profile,
)
from ..scheduler import HOLDS, Blocked, DelayScheduler
from . import md_crowd
from .base import Planner, Progress
from .md_crowd import crowding, sum_of_arrivals
from .md_search import PrioritySearch

if TYPE_CHECKING:
    from ..paths import PathFinder

_MAX_TRIES = 3   # per blocked pair: re-route, re-order, re-order j to the front; then give up
ORDERS = ("shortest", "longest", "given", "parking")
#: moves of the improvement search over priorities tried by default (holds anywhere; ours, see
#: :meth:`_Session.improve`)
IMPROVE_TRIES = 8
#: ... not tried when the dense plan md compares with is already this much lower than md's first
#: plan (measured at 100 robots: the search lowers md's sum by 0.3-2.1%; warehouse-10-20-10-2-1:
#: dense 6% below md's first plan, md's after the search still 4.6% above it)
IMPROVE_GAIN = 0.04
#: ... nor when md's first plan's sum of arrivals is within this share of its routes driven alone: the
#: search can gain at most that and costs about as much CPU as the plan (measured at 100 robots, 3 seeds,
#: sum of arrivals / free before -> after the search: warehouse-20-40-10-2-2 waits 0.8% and 1.1% of the
#: drive: 1.0090 -> 1.0057 and 1.0116 -> 1.0053 for 0.30 and 0.37 s CPU; at 2.2%: 1.0232 -> 1.0066 in 0.19
#: s; warehouse-10-20-10-2-2 waits 4.7-6.2%: 1.053-1.066 -> 1.025-1.043 in 0.17-0.28 s)
IMPROVE_ABOVE = 0.015
#: ... and its CPU budget: this share of the CPU seconds md's first plan took (ours). Relative to the
#: first plan, so that the number of moves tried does not depend on the machine or its load (CPU
#: seconds grow under load too: the same plan took 0.40 and 0.70 s). Measured at 100 robots on
#: warehouse-10-20-10-2-2 (first plan about 0.31 s CPU, load 6; moves cost about 0.02 s each):
#: 0, 2, 4, 8 moves SoC/free 1.053, 1.045, 1.035, 1.025 for 0.31, 0.35, 0.39, 0.46 s CPU: the 8 moves take
#: about 0.5 of the first plan's CPU (with 0.5, 6-7 of them were tried under load 6-15: 1.027)
IMPROVE_CPU_SHARE = 0.75
#: ... but never less than this many CPU s (ours): a small instance's first plan takes a few ms, less
#: still once numba's kernels are loaded, so the share alone tried fewer moves in a warm process than
#: in a fresh one, and the same scenario gave two plans (the pinned plan files of test_plan_file)
IMPROVE_MIN_CPU_S = 0.25
#: the dense solver's two refinement budgets (CPU s per 100 robots each) when md compares plans
#: (measured with 0.2: 100 robots on warehouse-10-20-10-2-1, SoC/free 1.0627 against 1.0617 with the
#: dense solver's defaults, 0.6-0.9 s less CPU; 200 robots on it and on warehouse-10-20-10-2-2: 1.1003 /
#: 1.1123 against 1.0995 / 1.1121, 0.6 s less)
COMPARE_REFINE_S = 0.2
#: with holds, one-shot plans (:meth:`MDPlanner.plan`): a place to wait at least every this many grid
#: cells along a path (ours). Each path was cut into one-cell pieces: about 150 segments per path at
#: 100 robots, and the segment-pair pieces, the hold constraints and every re-scheduling grow with
#: them. Measured at 100 robots (SoC/free, CPU s in one process, load ~20): 1 cell 1.0365 / 1.0106 on
#: warehouse-10-20-10-2-2 / 20-40-10-2-2; 3 cells 1.0324 / 1.0060; 4 cells 1.0253 / 1.0057 (0.65 / 0.83
#: s against 1.15 / 1.67); 6 cells 1.0262 / 1.0050; 8 cells 1.0390 / 1.0043; only the string-pulled
#: corners 1.0366 / 1.0060. Legs (plan_incremental) keep one cell (not measured in the delivery
#: benchmark with more).
HOLD_CELLS = 4
#: route choice in one-shot plans (:meth:`MDPlanner.plan`; ours): a robot tries a detour when it waits
#: more than this many seconds in all (``detour_min``), and a further one, after a detour that paid or
#: in a later re-scheduling, only when it still waits more than :data:`DETOUR_AGAIN_S`. Measured on
#: the tries themselves (100 robots, warehouse-10-20-10-2-2 and 20-40-10-2-2, seeds 0-2, 378 tries):
#: tries of robots waiting 2-3 s in all saved 17 s of the 4550 s that detours saved; second tries of
#: robots waiting under 5 s: 27 tries, 4 kept, 8 s saved (under 10 s: 40, 6, 17 s, and SoC/free of
#: 10-20-10-2-2 seed 0 went 1.026 -> 1.033 with that bound); each try costs a path search, the robot's
#: collision pieces and its schedule (about 1 ms). Plans (seed 0): 10-20-10-2-2 188 -> 171 path
#: searches, SoC/free 1.0253 -> 1.0260; 20-40-10-2-2 118 -> 116, 1.0091 -> 1.0092.
DETOUR_MIN_S = 3.0
DETOUR_AGAIN_S = 5.0
#: ... in legs (:meth:`MDPlanner.plan_incremental`): one robot plans at a time, every try is cheap
DETOUR_MIN_LEG_S = 2.0
#: legs (:meth:`MDPlanner.plan_incremental`) with ``leg_lattice="auto"``: planned on cells this many times finer
#: than the map's when the map's cells are narrower than the robots' diameter (ours, session 31). On a 0.5 m grid
#: 0.354 m discs pass each other only with their centres a cell and a half apart, which the map's lattice does not
#: have: a queue standing in the chute row of the default warehouse left one lane under it for both directions, a
#: robot docking in a 2 m rack aisle closed it. On cells of 1/6 m both have two lanes. Delivery benchmark, default
#: warehouse, md, mean of seeds 0-4: 40 robots CTime 403 -> 355 s (CTime / bound 1.33 -> 1.26), 50 robots 452 -> 383
#: (1.42 -> 1.23), CPU per leg about 3.5x (docs/BENCHMARKS.md, session 31)
LEG_LATTICE = 3


class _SearchFailed(Exception):
    """md found no plan within its budget: the last refusal and how many attempts were made."""

    def __init__(self, error: PlanningError, attempts: int):
        super().__init__(str(error))
        self.error, self.attempts = error, attempts


@dataclass
class DepartureSchedule:
    """Result of scheduling fixed paths: delays by robot index, the network, the final order."""

    order: list[int]
    delays: np.ndarray
    network: Network
    blocked: Blocked | None
    #: the timed paths (ids in the given order), holds included
    paths: list[TimedPath] = field(default_factory=list)


def schedule_paths(ids: Sequence[str], paths: Sequence[np.ndarray], radii: Sequence[float],
                   speeds: Sequence[float], order: Sequence[int] | None = None,
                   margin: float = 0.0, mode: str = "box", holds: str = "none") -> DepartureSchedule:
    """Departure delays for robots on the given paths (no re-planning): the bare method of the paper.

    ``order`` lists robot indices from highest to lowest priority (default: as given); ``mode`` is
    "box" (the paper's collision boxes) or "exact" (the regions themselves, see the scheduler);
    ``holds`` "none" (departure delays only, the paper) or "anywhere" (waits at any vertex)."""
    order = list(range(len(ids))) if order is None else list(order)
    model = CollisionModel(paths, radii, margin, speeds)
    sched = DelayScheduler(model, mode, holds)
    blocked = sched.schedule(order)
    if holds == "anywhere":
        timed = [_held_path(ids[x], radii[x], model.paths[x], sched.arr[x], sched.dep[x]) for x in range(len(ids))]
    else:
        timed = [timed_path_from_profile(ids[x], radii[x], model.paths[x], model.times[x], float(sched.delays[x]))
                 for x in range(len(ids))]
    return DepartureSchedule(order, sched.delays.copy(), sched.network(order, ids), blocked, timed)


class MDPlanner(Planner):
    """Central planner (md v2, issue 8): safe paths, the (M,D) network, holds anywhere along the
    path, route choice in time, priority search; the paper's departure-only method with
    ``holds="none"`` (registered as ``md-departure``), its boxes with ``mode="box"`` (``md-box``).

    ``margin`` (m) is added to every pair's sum of radii; ``order`` is the initial priority:
    "shortest" (default; the best sum of arrival times on every map we measured, measured fact 4) and
    "longest" sort by straight-line distance to the goal (longest first tends to the shorter
    makespan), "given" keeps the list order, "parking" puts first the robots whose start lies on
    many others' shortest paths and last those whose goal does (fewest re-orderings in crowds);
    ``max_reorders`` bounds the re-ordering attempts of one attempt (default 4 N); ``mode`` picks
    the collision test: "exact" (default; robots may follow each other) or "box" (You & Ji as
    written); ``holds`` where a robot may wait on its path: "anywhere" (the default with exact
    regions: at any vertex, an earliest-arrival search against the higher robots' timed
    trajectories) or "none" (only before it departs, the paper's departure delays; the default and
    only choice with boxes). Robots with ``max_accel`` wait only before they depart in either case
    (a stop en route would need braking and accelerating ramps their drive profile does not have).
    ``hold_step`` (m, default :data:`HOLD_CELLS` grid cells in :meth:`plan`, one in
    :meth:`plan_incremental`): with holds, paths get a vertex at least this often, so that there is
    somewhere to wait. ``early_holds``: move waits back along the path as far as the
    arrival allows, to where the robot already stands (default: in :meth:`plan_incremental` only;
    measured: the delivery benchmark finishes sooner with them, one-shot sums of arrivals are
    slightly worse).
    ``detours`` (default 2 with holds, else 0): route choice in time: a robot that waits more than
    ``detour_min`` s in all (default :data:`DETOUR_MIN_S` in :meth:`plan`, :data:`DETOUR_MIN_LEG_S` in
    :meth:`plan_incremental`) is re-planned up to this many times around the stretch after its longest
    wait and takes the candidate with the earliest arrival under holds (in :meth:`plan`, a further try
    only while it waits more than :data:`DETOUR_AGAIN_S`). ``search`` (default on):
    when greedy re-ordering gives up, the priority search of :mod:`.md_search` tries further orders
    until ``time_limit`` s of CPU have been spent since planning began (at most 10 + 2 N attempts;
    md's budgets are CPU seconds, :class:`~fleet_planner.budget.Budget`, so that its plans do not depend on the load);
    ``fallback`` (default "crowd"; a registered ``dense`` planner is preferred when there is one):
    the dense solver that plans when the search fails, named in the plan's ``info["fallback"]``;
    None refuses instead (and switches off the two uses of the dense solver that follow; so do
    ``holds="none"`` and boxes: the paper's methods).
    ``crowded`` (default on): an instance crowded for prioritized planning (many starts and goals in
    aisles too narrow for two robots to pass, or very many robots: :mod:`.md_crowd`) goes to the
    dense solver first, with the whole budget, before any path is planned; md plans only if the dense
    solver refuses; so does a *busy* one (fewer starts and goals in one-lane aisles, but enough that md's
    plan would lose the comparison below: :data:`~.md_crowd.LANE_LOAD_BUSY`), with small refinement
    budgets, unless ``compare_above`` is None. ``compare_above`` (default 1.05; None: never): from 10
    robots, when the sum of
    arrival times of md's first plan exceeds this multiple of its routes driven alone (its robots
    wait a lot), the dense solver plans too, with small refinement budgets (:data:`COMPARE_REFINE_S`)
    within what is left of the time budget, and the plan with the lower sum of arrival times is
    returned (md's on a tie); either way under md's name, ``info["fallback"]`` naming the dense
    solver when its plan won, ``info["compared"]`` its sum when md's did. The live fleet's legs
    (:meth:`plan_incremental`) stop trying detours and re-orderings once
    ``leg_time_limit`` s (default 0.5; CPU seconds, or wall-clock seconds with ``leg_clock="wall"``:
    a live fleet that paces its legs in real time) are spent (a late re-ordering refuses the leg, which the
    fleet manager re-plans later). ``improve`` (default :data:`IMPROVE_TRIES` with holds, else 0;
    one-shot plans only): moves of a large-neighbourhood search over priorities after a plan is
    found (the robot that waits longest goes just ahead of the robot it waits for; kept when the
    sum of arrival times drops; ours, not the paper's), within the time budget and
    :data:`IMPROVE_CPU_SHARE` of the CPU seconds the first plan took (at least
    :data:`IMPROVE_MIN_CPU_S`), when md's first plan's robots wait more than :data:`IMPROVE_ABOVE` of
    their routes' driving time in all. ``swaps`` (default on, with holds): a run driving md's legs one at a
    time may re-order two of them in flight (:attr:`reorders_legs`; the delivery simulation's
    :meth:`~fleet_planner.delivery.central._CentralRun._go_first`): a late new leg goes first past a robot
    driving in its way, whose leg is planned again behind it, and robots that waited for a leg that was cut
    are timed again. ``leg_lattice`` (default "auto"): legs are planned on cells this many times finer than
    the map's (odd, so that the map's cell centres stay on the lattice; the one-shot :meth:`plan` keeps the
    map's cells, and so does a map with lanes: they are laid on its cells); "auto" takes :data:`LEG_LATTICE` when
    the map's cells are narrower than the robots' diameter (two of them cannot pass on neighbouring cells), else 1."""

    name = "md"

    def __init__(self, margin: float = 0.02, order: str = "shortest", max_reorders: int | None = None,
                 mode: str = "exact", holds: str | None = None, hold_step: float | None = None,
                 detours: int | None = None, detour_min: float | None = None, early_holds: bool | None = None,
                 time_limit: float = 10.0, search: bool = True, fallback: str | None = "crowd",
                 leg_time_limit: float = 0.5, crowded: bool = True, compare_above: float | None = 1.05,
                 improve: int | None = None, leg_clock: str = "cpu", swaps: bool = True,
                 leg_lattice: int | str = "auto"):
        if leg_clock not in ("cpu", "wall"):
            raise ValueError(f"leg_clock: must be 'cpu' or 'wall' (got {leg_clock!r})")
        self.leg_clock = leg_clock
        if holds is None:
            holds = "anywhere" if mode == "exact" else "none"
        if detours is None:
            detours = 2 if holds == "anywhere" else 0
        if mode not in COLLISION_TESTS:
            raise ValueError(f"mode: must be one of {', '.join(COLLISION_TESTS)} (got {mode!r})")
        self.mode = mode
        if holds not in HOLDS:
            raise ValueError(f"holds: must be one of {', '.join(HOLDS)} (got {holds!r})")
        if holds == "anywhere" and mode != "exact":
            raise ValueError(f"holds: 'anywhere' needs mode 'exact' (got mode {mode!r})")
        self.holds = holds
        if hold_step is not None and not (math.isfinite(hold_step) and hold_step > 0):
            raise ValueError(f"hold_step: must be a finite number > 0 (got {hold_step!r})")
        self.hold_step = hold_step
        if isinstance(detours, bool) or not isinstance(detours, int) or detours < 0:
            raise ValueError(f"detours: must be an integer >= 0 (got {detours!r})")
        if detours and holds != "anywhere":
            raise ValueError("detours: route choice needs holds 'anywhere'")
        if detour_min is not None and not (math.isfinite(detour_min) and detour_min >= 0):
            raise ValueError(f"detour_min: must be a finite number >= 0 (got {detour_min!r})")
        self.detours = detours
        self.detour_min = None if detour_min is None else float(detour_min)
        if improve is None:
            improve = IMPROVE_TRIES if holds == "anywhere" else 0
        if isinstance(improve, bool) or not isinstance(improve, int) or improve < 0:
            raise ValueError(f"improve: must be an integer >= 0 (got {improve!r})")
        if improve and holds != "anywhere":
            raise ValueError("improve: needs holds 'anywhere'")
        self.improve = improve
        self.early_holds = early_holds if early_holds is None else bool(early_holds)
        if isinstance(time_limit, bool) or not isinstance(time_limit, (int, float)) \
                or not (math.isfinite(time_limit) and time_limit > 0):
            raise ValueError(f"time_limit: must be a finite number of seconds > 0 (got {time_limit!r})")
        self.time_limit = float(time_limit)
        if isinstance(leg_time_limit, bool) or not isinstance(leg_time_limit, (int, float)) \
                or not (math.isfinite(leg_time_limit) and leg_time_limit > 0):
            raise ValueError(f"leg_time_limit: must be a finite number of seconds > 0 (got {leg_time_limit!r})")
        self.leg_time_limit = float(leg_time_limit)
        self.search = bool(search)
        self.reorders_legs = bool(swaps) and holds == "anywhere"
        if leg_lattice != "auto" and (isinstance(leg_lattice, bool) or not isinstance(leg_lattice, int)
                                      or leg_lattice < 1 or leg_lattice % 2 == 0):
            raise ValueError(f"leg_lattice: must be 'auto' or an odd integer >= 1 (got {leg_lattice!r})")
        self.leg_lattice = leg_lattice
        if fallback is not None and fallback not in ("crowd", "dense"):
            raise ValueError(f"fallback: must be 'crowd', 'dense' or None (got {fallback!r})")
        self.fallback = fallback
        self.crowded = bool(crowded)
        if compare_above is not None and (isinstance(compare_above, bool) or not isinstance(compare_above, (int, float))
                                          or not (math.isfinite(compare_above) and compare_above >= 1)):
            raise ValueError(f"compare_above: must be a finite number >= 1 or None (got {compare_above!r})")
        self.compare_above = None if compare_above is None else float(compare_above)
        if order not in ORDERS:
            raise ValueError(f"order: must be one of {', '.join(ORDERS)} (got {order!r})")
        if not margin >= 0:
            raise ValueError(f"margin: must be >= 0 (got {margin!r})")
        self.margin = float(margin)
        self.order = order
        self.max_reorders = max_reorders
        self._finders = _FinderCache()

    # ------------------------------------------------------------------------------------------
    def warm_up(self) -> None:
        """Load (or compile) the compiled kernels of md's legs - path finding, the collision pieces
        and the hold search - once per process, before any budget starts (ours: with numba's cache
        cold, the first leg of the delivery benchmark spent 11.4 s CPU compiling, inside its 0.5 s
        budget, later legs up to 0.6 s; with the cache on disk, the first leg 0.06 s loading it; the
        first kernel a process loads also starts numba: 0.35 s). :meth:`plan` also warms the dense
        solver's kernels (legs never hand over to it; cold, they compile for about 40 s)."""
        self._warm_up(dense=False)

    def _warm_up(self, dense: bool) -> None:
        """:meth:`warm_up`; the dense solver's kernels too with ``dense`` (one-shot plans). Each
        module's warm-up runs once per process and returns at once after."""
        from .. import _md_kernels, paths

        paths.warm_up()
        _md_kernels.warm_up()
        if dense and self.fallback is not None and self.holds == "anywhere":
            from . import get_planner

            get_planner(self._dense_name()).warm_up()

    def plan(self, grid: GridMap, robots: Sequence[RobotSpec], progress: Progress | None = None) -> Plan:
        self._warm_up(dense=True)
        t_start, cpu0 = time.perf_counter(), time.process_time()
        deadline = Budget(self.time_limit)
        robots = list(robots)
        _check_endpoints(robots, self.margin)
        # md v2's two uses of the dense solver; the paper's methods (holds "none", boxes) plan alone
        v2 = self.fallback is not None and self.holds == "anywhere"
        if v2 and self.crowded:
            crowd = crowding(grid, robots, self.margin)
            # (the dense solver's CPU budgets then count from md's start: the crowding check is part of
            # md's time; the compiled kernels were loaded before it, by _warm_up)
            why, options = crowd.crowded(), {"cpu_start": cpu0}
            if why is None and self.compare_above is not None:
                # md's plan would lose the comparison: the dense solver plans first, with small budgets
                why = crowd.busy()
                budget = md_crowd.BUSY_REFINE_S * len(robots) / 100
                options = {"refine_s": budget, "timed_refine_s": budget}
            if why is not None:   # md would fail, run out of time or lose: the dense solver plans first
                try:
                    return self._dense(grid, robots, t_start, deadline, 0, f"crowded: {why}", **options)
                except PlanningError:
                    pass   # e.g. robots off cell centres: md tries with what is left
        c_start = time.thread_time()
        try:
            session, search = self._prioritized(grid, robots, progress, deadline)
        except _SearchFailed as failed:
            return self._fallback(grid, robots, failed.error, failed.attempts, t_start, deadline)
        c_first = time.thread_time() - c_start
        first = session._arrivals()
        drive = session.drive()
        other: Plan | None = None
        # (a few robots: md's own plan; the hand-worked cases stay md's)
        if v2 and self.compare_above is not None and len(robots) >= md_crowd.MIN_ROBOTS \
                and first > self.compare_above * drive:
            # md's robots wait a lot: the dense solver's plan may be better; the lower sum of arrivals
            # wins (it gives up at once when its lower bound says it cannot beat md's first plan: cutoff)
            budget = COMPARE_REFINE_S * len(robots) / 100
            try:
                other = self._dense(grid, robots, t_start, deadline, search[0],
                                    f"md's sum of arrivals {first:.1f} s is {first / drive:.3f} x its routes "
                                    "driven alone", cutoff=first, refine_s=budget, timed_refine_s=budget)
            except PlanningError:
                other = None
        theirs = math.inf if other is None else sum_of_arrivals(other)
        improved = 0
        # (unless the dense plan is far better: the search cannot catch up; or md's robots hardly wait)
        if self.improve and theirs >= (1 - IMPROVE_GAIN) * first and first > (1 + IMPROVE_ABOVE) * drive:
            improved = session.improve(self.improve, deadline, Budget(
                min(max(IMPROVE_CPU_SHARE * c_first, IMPROVE_MIN_CPU_S), deadline.left())))
        plan = self._plan_of(session, search, improved, t_start)
        ours = sum_of_arrivals(plan)
        if other is not None and theirs < ours - 1e-6:
            other.info["md"] = {"sum_of_arrivals": round(ours, 3), **plan.info}
            other.info["why"] += f"; the dense plan's {theirs:.1f} s is lower"
            other.planning_time_s = time.perf_counter() - t_start
            return other
        if other is not None:
            plan.info["compared"] = {other.info["fallback"]: round(theirs, 3)}
        plan.planning_time_s = time.perf_counter() - t_start
        return plan

    def _prioritized(self, grid: GridMap, robots: list[RobotSpec], progress: Progress | None,
                     deadline: Budget) -> tuple[_Session, tuple[int, int]]:
        """md itself: safe paths, holds, route choice, greedy re-ordering, and the priority search when
        that gives up, until ``deadline``; the session that found a plan and (attempts, learnt
        priorities); or _SearchFailed."""
        shortest: dict[int, np.ndarray] = {}
        order = self._initial_order(grid, robots, shortest)
        search = PrioritySearch(seed=0)
        ids = {r.id: x for x, r in enumerate(robots)}
        attempts = 0
        must: dict[int, dict[int, list]] = {}   # discs each robot was found to block, kept across attempts
        while True:
            attempts += 1
            session = _Session(self, grid, robots, list(order), fixed=0, hints=dict(shortest),
                               deadline=deadline if attempts > 1 or self.fallback is not None else None, must=must,
                               # the first attempt's route choice is not cut short (its quality is md's)
                               free_detours=attempts == 1)
            try:
                session.route(progress)
                session.resolve(progress)
                return session, (attempts, len(search.constraints))
            except PlanningError as exc:
                blocked = next(iter(exc.blockers.items()), None)
                if (not self.search or blocked is None or deadline.passed()
                        or attempts >= 10 + 2 * len(robots) or blocked[0] not in ids or blocked[1] not in ids):
                    raise _SearchFailed(exc, attempts) from None
                order = search.next_order(session.order, ids[blocked[0]], ids[blocked[1]])
                if progress:
                    progress(attempts, attempts + 1, "priority search")

    def _plan_of(self, session: _Session, search: tuple[int, int], improved: int, t_start: float) -> Plan:
        """md's plan from the session that found it (its network, what the planner did in ``info``)."""
        network = session.sched.network(session.order, [r.id for r in session.robots])
        info: dict[str, Any] = {"reorders": session.reorders, "reroutes": session.reroutes,
                                "regions": session.model.region_count}
        if self.improve:
            info["improved"] = improved
        if self.detours:
            info["detours"] = session.detoured
        if search[0] > 1:
            info["search"] = {"attempts": search[0], "priorities": search[1]}
        return Plan("md", session.timed_paths(), time.perf_counter() - t_start, info, network)

    def _fallback(self, grid: GridMap, robots: list[RobotSpec], failure: PlanningError, attempts: int,
                  t_start: float, deadline: Budget) -> Plan:
        """When prioritized planning finds no plan: the registered dense solver (``dense`` if there
        is one, else ``crowd``) with what is left of the time budget (at least half of it), its
        plan under md's name with ``info["fallback"]`` saying which; or the refusal, saying what
        the search and the fallback tried."""
        if self.fallback is None:
            raise failure
        why = "; ".join(f"{rid}: {w}" for rid, w in list(failure.failures.items())[:3])
        try:
            return self._dense(grid, robots, t_start, deadline, attempts, why)
        except PlanningError as exc:
            name = self._dense_name()
            why = "; ".join(f"{rid}: {w}" for rid, w in list(exc.failures.items())[:3])
            raise PlanningError({rid: f"{w} (priority search: {attempts} attempt(s); fallback {name}: {why})"
                                 for rid, w in failure.failures.items()}, failure.blockers) from exc

    def _dense_name(self) -> str:
        from . import planner_names

        return "dense" if "dense" in planner_names() else str(self.fallback)

    def _dense(self, grid: GridMap, robots: list[RobotSpec], t_start: float, deadline: Budget, attempts: int,
               why: str, **options) -> Plan:
        """The dense solver's plan under md's name, with ``info["fallback"]`` naming the solver and
        ``info["why"]`` saying why it planned; with what is left of the time budget (at least half
        of it); ``options`` go to the dense solver when it takes them. PlanningError when it cannot plan."""
        from . import get_planner

        name = self._dense_name()
        budget = max(deadline.left(), 0.5 * self.time_limit)
        try:
            dense = get_planner(name, time_limit_s=budget, margin=self.margin, **options)
        except TypeError:
            dense = get_planner(name)
        plan = dense.plan(grid, robots)
        info = dict(plan.info)
        info.update({"fallback": name, "search": {"attempts": attempts}, "why": why})
        return Plan("md", plan.paths, time.perf_counter() - t_start, info, plan.network)

    def plan_incremental(self, grid: GridMap, robots: Sequence[RobotSpec], fixed: Sequence[TimedPath],
                         t0: float) -> list[TimedPath]:
        """Plan new legs for ``robots`` (starting at ``t0`` from their ``start``) around trajectories
        that are already being driven and stay as they are (``fixed``, absolute times; a robot on
        its last waypoint stays there). The fixed robots rank above the new ones, so only the new
        ones are delayed, re-routed or re-ordered among themselves. Returns timed paths in absolute
        time, or raises PlanningError (with ``blockers``) naming who is in the way.

        With holds, route choice in time for legs: when the legs arrive more than 2 s later in all
        than on their shortest paths on an empty map (or cannot be planned), a space-time search
        over the grid against the fixed trajectories (the safe-interval search of
        :class:`~fleet_planner.planners.prior.PriorPlanner`, given 4 ``leg_time_limit`` of its own)
        proposes other routes; md times them with its own exact scheduler (within
        ``leg_time_limit``) and keeps whichever arrives first in all. A leg thus takes at most about
        six ``leg_time_limit`` plus two scheduling passes. Measured in the delivery benchmark:
        without it md's legs waited 4-5x longer than PRIOR's on the same situations (they stay on
        the shortest path and queue behind the traffic in it)."""
        self._warm_up(dense=False)
        robots = list(robots)
        grid = self._leg_grid(grid, robots)
        deadline = self._leg_budget()
        failure: PlanningError | None = None
        best: list[TimedPath] | None = None
        try:
            best = self._legs(grid, robots, fixed, t0, deadline)
        except PlanningError as exc:
            failure = exc
        late = best is None or self._lateness(grid, best, robots, t0) > _LEG_ROUTES_AFTER_S
        if self.holds == "anywhere" and _LEG_ROUTES and late:
            routes, timed = self._space_time_routes(grid, robots, fixed, t0)
            if routes:
                try:
                    other = self._legs(grid, robots, fixed, t0, self._leg_budget(), routes)
                except PlanningError:
                    other = None
                if other is not None and (best is None or _total_arrival(other) < _total_arrival(best) - 1e-6):
                    best = other
            if timed is not None and (best is None or _total_arrival(timed) < _total_arrival(best) - 1e-6):
                best = timed   # the search's own timing arrives sooner than md's timing of its routes
        if best is None:
            assert failure is not None
            raise failure
        return best

    def _leg_grid(self, grid: GridMap, robots: Sequence[RobotSpec]) -> GridMap:
        """The map legs are planned on (``leg_lattice``): ``grid``, or ``grid`` on finer cells (cached)."""
        k = self.leg_lattice
        if k == "auto":
            narrow = bool(robots) and grid.resolution < 2 * min(r.radius for r in robots)
            k = LEG_LATTICE if narrow else 1
        if k == 1 or getattr(grid, "lanes", None) is not None:   # (lanes are laid on the map's cells)
            return grid
        return self._finders.refined(grid, int(k))

    def _leg_budget(self) -> Budget:
        return Budget(self.leg_time_limit, wall=self.leg_clock == "wall")

    def _legs(self, grid: GridMap, robots: list[RobotSpec], fixed: Sequence[TimedPath], t0: float,
              deadline: Budget, routes: dict[int, np.ndarray] | None = None) -> list[TimedPath]:
        """One try of :meth:`plan_incremental`: ``routes`` (robot index -> polyline) are taken as
        the first paths of those robots (re-routing, if needed, plans them as usual)."""
        held = [_remaining_held(tp, t0) for tp in fixed] if self.holds == "anywhere" else []
        kept = [(poly, times, float(dep[0]) if len(dep) > 1 else 0.0) for poly, times, _, dep in held] \
            if self.holds == "anywhere" else [_remaining(tp, t0) for tp in fixed]
        nf = len(kept)
        specs = [RobotSpec(tp.robot_id, tp.radius, _top_speed(poly, times), tuple(poly[0]), tuple(poly[-1]))
                 for tp, (poly, times, _) in zip(fixed, kept)] + robots
        _check_endpoints(specs[nf:], self.margin)
        shortest: dict[int, np.ndarray] = {}
        order = list(range(nf)) + [nf + x for x in self._initial_order(grid, robots, shortest)]
        session = _LegSession(self, grid, specs, order, fixed=nf,
                              fixed_paths=[(poly, times) for poly, times, _ in kept],
                              hints={nf + x: path for x, path in shortest.items()},
                              deadline=deadline, incremental=True)
        session.forced = {nf + x: path for x, path in (routes or {}).items()}
        session.route()
        session.sched.delays[:nf] = [delay for _, _, delay in kept]
        for x, (_, _, arr, dep) in enumerate(held):
            session.sched.set_timing(x, 0.0, arr, dep)
        session.resolve()
        out = session.legs()
        for tp in out:
            tp.waypoints[:, 2] += t0
        return out

    def _lateness(self, grid: GridMap, legs: list[TimedPath], robots: list[RobotSpec], t0: float) -> float:
        """Seconds the legs arrive later in all than driving their shortest paths on the empty map
        straight off at top speed (their waits and their detours)."""
        late = 0.0
        for tp, r in zip(legs, robots):
            path = self._finders.of(grid).get(r.radius).find(r.start, r.goal)
            length = tp.length if path is None else float(np.hypot(*np.diff(path, axis=0).T).sum())
            late += tp.arrival_time - t0 - length / r.max_speed
        return late

    def _space_time_routes(self, grid: GridMap, robots: list[RobotSpec], fixed: Sequence[TimedPath],
                           t0: float) -> tuple[dict[int, np.ndarray], list[TimedPath] | None]:
        """Routes for the legs from a safe-interval search in space-time against the fixed
        trajectories (md times the routes itself); empty when the search fails or takes longer than
        ``_LEG_SEARCH_LIMITS`` times ``leg_time_limit``. Second, the search's own timed legs when
        they are valid as they are (else None): the robots drive without acceleration ramps (the
        search has none) and every leg stays inside its corridor (below).

        The search sees only the fixed trajectories that come near the legs' corridors
        (:func:`_fixed_near`), so a leg costs what its neighbourhood holds, not the fleet: a route
        is a proposal, which :meth:`_legs` times exactly against every fixed trajectory. A timed leg
        whose waypoints all lie in its corridor (the box round its start, goal and shortest path,
        grown by :data:`_LEG_CORRIDOR_M`) is valid against every fixed trajectory: the search kept
        it clear of those it saw, and one it did not see never comes within the pair's keep-out
        distance of the corridor (ours: md's timing of the same route was later than the search's own
        on 8 of 376 delivery legs, 13.7 s each on average)."""
        from .prior import PriorPlanner

        searcher = getattr(self, "_route_search", None)
        if searcher is None or searcher.margin != self.margin:
            searcher = self._route_search = PriorPlanner(margin=self.margin)
        searcher.time_limit_s = _LEG_SEARCH_LIMITS * self.leg_time_limit
        searcher.cpu_time = self.leg_clock == "cpu"   # the clock of md's own leg budgets
        lo, hi = _corridors(self._finders.of(grid), robots)
        near = _fixed_near(robots, lo, hi, fixed, t0, self.margin)
        try:
            found = searcher.plan_incremental(grid, robots, [fixed[k] for k in near], t0)
        except (PlanningError, ValueError):
            return {}, None
        routes = {}
        for x, tp in enumerate(found):
            pts = tp.waypoints[:, :2]
            keep = np.concatenate([[True], np.hypot(*np.diff(pts, axis=0).T) > 1e-9])
            if keep.sum() >= 2:
                routes[x] = pts[keep].copy()
        inside = all(r.max_accel is None and bool(np.all((tp.waypoints[:, :2] >= lo[x] - 1e-9)
                                                         & (tp.waypoints[:, :2] <= hi[x] + 1e-9)))
                     for x, (r, tp) in enumerate(zip(robots, found)))
        return routes, (found if inside and len(found) == len(robots) else None)

    def _initial_order(self, grid: GridMap, robots: list[RobotSpec],
                       shortest: dict[int, np.ndarray] | None = None) -> list[int]:
        """The initial priority order; with ``shortest``, the "parking" order also leaves there
        each robot's shortest path (a first guess the safe-path search can keep)."""
        idx = list(range(len(robots)))
        if self.order == "given" or len(robots) < 2:
            return idx
        if self.order == "parking":
            return _parking_order(self._finders.of(grid), robots, self.margin, shortest)
        dist = [float(np.hypot(r.goal[0] - r.start[0], r.goal[1] - r.start[1])) for r in robots]
        return sorted(idx, key=lambda x: dist[x], reverse=self.order == "longest")


def _parking_order(finders: _Finders, robots: list[RobotSpec], margin: float,
                   shortest: dict[int, np.ndarray] | None = None) -> list[int]:
    """Priority from where robots park (measured fact 1 turned into an order): score = how many other
    robots' shortest paths pass a robot's start disc minus how many pass its goal disc; the
    highest score goes first, ties keep the list order. Robots standing in busy aisles then
    leave before the others come through, and robots parking in them arrive after."""
    import shapely

    lines, owners = [], []
    for x, r in enumerate(robots):
        path = finders.get(r.radius).find(r.start, r.goal)
        if shortest is not None and path is not None:
            shortest[x] = path
        if path is not None and len(path) > 1:
            lines.append(shapely.LineString(path))
            owners.append(x)
    if not lines:
        return list(range(len(robots)))
    owner = np.array(owners)
    tree = shapely.STRtree(lines)
    reach = 2 * max(r.radius for r in robots) + margin
    radii = np.array([r.radius for r in robots])
    score = np.zeros(len(robots))
    for what, sign in (("start", 1.0), ("goal", -1.0)):
        pts = np.array([getattr(r, what) for r in robots], dtype=float)
        qi, ti = tree.query(shapely.box(pts[:, 0] - reach, pts[:, 1] - reach, pts[:, 0] + reach, pts[:, 1] + reach))
        other = owner[ti]
        keep = other != qi
        qi, ti, other = qi[keep], ti[keep], other[keep]
        near = (shapely.distance(shapely.points(pts[qi]), np.asarray(lines, dtype=object)[ti])
                < radii[qi] + radii[other] + margin)
        np.add.at(score, qi[near], sign)
    return sorted(range(len(robots)), key=lambda x: -score[x])


class _Session:
    """One planning problem being solved: robots (the first ``fixed`` of them keep their paths and
    delays), their paths, the priority order, the collision model and the scheduler."""

    def __init__(self, planner: MDPlanner, grid: GridMap, robots: list[RobotSpec], order: list[int],
                 fixed: int, fixed_paths: Sequence[tuple[np.ndarray, np.ndarray]] = (),
                 hints: dict[int, np.ndarray] | None = None, deadline: Budget | None = None,
                 must: dict[int, dict[int, list[tuple[tuple[float, float], float]]]] | None = None,
                 incremental: bool = False, free_detours: bool = False):
        self.planner, self.robots, self.order, self.fixed = planner, robots, order, fixed
        #: the budget after which re-ordering gives up (CPU seconds; None: no bound)
        self.deadline = deadline
        #: and after which route choice stops trying (``free_detours``: never)
        self.detour_deadline = None if free_detours else deadline
        #: waits moved back along the path: the planner's choice, by default in legs only (fixed robots)
        self.early_holds = planner.early_holds if planner.early_holds is not None else incremental
        self.margin = planner.margin
        self.rank = {x: k for k, x in enumerate(order)}
        self.finder = planner._finders.of(grid)
        #: with holds: longest stretch of a path without a vertex to wait at (m)
        self.hold_step = (grid.resolution * (1 if incremental else HOLD_CELLS) if planner.hold_step is None
                          else planner.hold_step)
        #: route choice: a robot tries a detour when it waits more than this (s) in all, a further
        #: one (after a detour that paid) when it still waits more than ``detour_again``
        self.detour_min: float = (planner.detour_min if planner.detour_min is not None
                                  else DETOUR_MIN_LEG_S if incremental else DETOUR_MIN_S)
        self.detour_again: float = self.detour_min if incremental else max(self.detour_min, DETOUR_AGAIN_S)
        #: per robot its path and the times (from its departure) at which it passes the vertices
        self.paths: list[np.ndarray | None] = [p for p, _ in fixed_paths] + [None] * (len(robots) - fixed)
        self.times: list[np.ndarray | None] = [t for _, t in fixed_paths] + [None] * (len(robots) - fixed)
        #: per robot, discs it was found to block and must keep off, by the robot whose start or
        #: goal they are
        self.must: dict[int, dict[int, list[tuple[tuple[float, float], float]]]] = {} if must is None else must
        self.reorders = self.reroutes = self.detoured = 0
        #: robots' starts, goals and radii as arrays (:meth:`_parked`), made at first use
        self._ends: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.detour_tries: dict[int, int] = {}
        #: during an improvement move: each robot's wait before it (a robot that comes to wait
        #: longer tries its route choice again)
        self.waits_before: dict[int, float] = {}
        #: shortest paths already known (robot -> path): kept when they avoid what they must
        self.hints: dict[int, np.ndarray] = {} if hints is None else hints

    def keep_out(self, x: int, y: int) -> float:
        return self.robots[x].radius + self.robots[y].radius + self.margin

    def _parked(self, x: int) -> tuple[np.ndarray, np.ndarray]:
        """The discs x keeps off first (measured fact 1), as rows (x, y, keep-out) in robot order:
        the starts of the robots below x, the goals of those above it."""
        if self._ends is None:
            self._ends = (np.array([r.start for r in self.robots], dtype=float).reshape(-1, 2),
                          np.array([r.goal for r in self.robots], dtype=float).reshape(-1, 2),
                          np.array([r.radius for r in self.robots], dtype=float))
        starts, goals, radii = self._ends
        rank = np.empty(len(self.robots), dtype=np.int64)
        rank[np.asarray(self.order, dtype=np.int64)] = np.arange(len(self.robots))
        keep = (radii[x] + radii) + self.margin
        below, above = rank > rank[x], rank < rank[x]
        return (np.column_stack([starts[below], keep[below]]), np.column_stack([goals[above], keep[above]]))

    def route(self, progress: Progress | None = None) -> None:
        """Safe paths for every robot that is not fixed, then the collision model and scheduler."""
        free = self.order[self.fixed:]
        for k, x in enumerate(free):
            self._set_route(x, self.safe_path(x))
            if progress:
                progress(k + 1, len(free), "paths")
        missing = {self.robots[x].id: "no path from start to goal on this map for its radius"
                   for x in free if self.paths[x] is None}
        if missing:
            raise PlanningError(missing)
        routes = [self.route_of(x) for x in range(len(self.robots))]
        self.model = CollisionModel([p for p, _ in routes], [r.radius for r in self.robots], self.margin,
                                    times=[t for _, t in routes], fast_merge=self.planner.holds == "anywhere",
                                    focus=range(self.fixed, len(self.robots)) if self.fixed else None)
        self.sched = DelayScheduler(self.model, self.planner.mode, self.planner.holds,
                                    start_only=[x for x, r in enumerate(self.robots) if r.max_accel is not None],
                                    early_holds=self.early_holds)
        if self.planner.detours:
            self.sched.after = self._detour

    def _set_route(self, x: int, path: np.ndarray | None) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Give robot x this path, driven from standstill to standstill with its acceleration."""
        if path is None:
            self.paths[x] = self.times[x] = None
            return {}
        r = self.robots[x]
        if self.planner.holds == "anywhere" and r.max_accel is None:
            path = _subdivide(path, self.hold_step)   # places to wait
        points, times = drive_profile(path, r.max_speed, r.max_accel)
        self.paths[x], self.times[x] = points, times
        return {x: (points, times)}

    def route_of(self, x: int) -> tuple[np.ndarray, np.ndarray]:
        """Robot x's path and the times at which it passes the vertices (once it has a path)."""
        path, times = self.paths[x], self.times[x]
        assert path is not None and times is not None, f"robot {self.robots[x].id!r} has no path yet"
        return path, times

    def safe_path(self, x: int, partner: int | None = None) -> np.ndarray | None:
        """Measured fact 1 (docs/ARCHITECTURE.md): avoid lower robots' starts and higher robots'
        goals; else goals only; else none. Discs that x was found to block (``must``) are kept in
        those attempts; when they are too many to avoid together, as many as possible are kept,
        those of ``partner`` (the robot of the conflict being resolved) first."""
        me = self.robots[x]
        starts, goals = self._parked(x)
        by_owner = self.must.get(x, {})
        must = _disc_rows([d for discs in by_owner.values() for d in discs])
        finder = self.finder.get(me.radius)

        def find(avoid):
            return finder.find(me.start, me.goal, avoid=avoid)

        hint = self.hints.pop(x, None)
        if hint is not None and _keeps_off(hint, np.vstack([starts, goals, must]), me.start, me.goal):
            return hint
        tries = ([np.vstack([starts, goals, must]), np.vstack([goals, must]), must] if len(must)
                 else [np.vstack([starts, goals]), goals])
        for avoid in tries:
            path = find(avoid)
            if path is not None:
                return path
        # not all of ``must`` at once: keep as much of it as possible, the partner's discs first,
        # then the others, most recently added first
        owners = sorted(by_owner, key=lambda o: (o != partner, -list(by_owner).index(o)))
        best = find([])
        kept: list[tuple[tuple[float, float], float]] = []
        for owner in owners:
            path = find(kept + by_owner[owner])
            if path is not None:
                best, kept = path, kept + by_owner[owner]
        return best

    def resolve(self, progress: Progress | None = None) -> None:
        """Schedule; where a delay cannot help, first re-route around the disc in the way, then
        move the blocked robot just ahead of its blocker (measured fact 2), re-planning only the paths
        whose avoidance changed and re-scheduling only what that changes."""
        self._repair(self.sched.schedule(self.order, start_at=self.fixed), progress)

    def _repair(self, blocked: Blocked | None, progress: Progress | None = None) -> None:
        """:meth:`resolve` from a schedule that stopped at ``blocked``; PlanningError when re-routing
        and re-ordering do not help."""
        robots, n = self.robots, len(self.robots)
        limit = 4 * n if self.planner.max_reorders is None else self.planner.max_reorders
        tries: dict[tuple[int, int], int] = {}
        while blocked is not None:
            j, i = blocked.j, blocked.blocker
            tries[(j, i)] = tries.get((j, i), 0) + 1
            why = f"blocked by {robots[i].id}, which {blocked.why}"
            late = self.deadline is not None and self.deadline.passed()
            if tries[(j, i)] > _MAX_TRIES or self.reorders >= limit or late:
                raise PlanningError({robots[j].id: f"{why}; re-routing and re-ordering did not help"},
                                    {robots[j].id: robots[i].id})
            # 1. re-route: the robot that moves keeps off the disc where the other one is parked
            mover, disc = (i, robots[j].start) if blocked.kind == "start" else (j, robots[i].goal)
            other = j if mover == i else i
            if tries[(j, i)] == 1 and mover >= self.fixed and self._reroute(mover, other, (disc, self.keep_out(i, j))):
                blocked = self.sched.schedule(self.order, start_at=self.rank[mover],
                                              dirty=_apply(self.model, {mover: self.route_of(mover)}, mover))
                continue
            # 2. re-order: j goes just ahead of i (never ahead of a fixed robot)
            if i < self.fixed:
                raise PlanningError({robots[j].id: why}, {robots[j].id: robots[i].id})
            self.reorders += 1
            # moving just ahead did not stick: try j ahead of everyone
            blocked = self._move_ahead(j, self.fixed if tries[(j, i)] == 3 else self.rank[i])
            if progress:
                progress(self.reorders, limit, "re-ordering")

    def _move_ahead(self, j: int, pos: int) -> Blocked | None:
        """Robot j moved up to place ``pos`` of the order; the robots it passes that cross its goal
        re-plan their paths (they now have j above them), and everything that changes is re-scheduled."""
        robots = self.robots
        old_j = self.rank[j]
        self.order.insert(pos, self.order.pop(old_j))
        self.rank = {x: k for k, x in enumerate(self.order)}
        replan = [j] + [x for x in self.order[pos + 1:old_j + 1]
                        if polyline_passes_near(self.route_of(x)[0], robots[j].goal, self.keep_out(x, j))]
        changed = {}
        for x in replan:
            path = self.safe_path(x)
            if path is None:
                raise PlanningError({robots[x].id: "no path from start to goal on this map for its radius"})
            changed.update(self._set_route(x, path))
        return self.sched.schedule(self.order, start_at=pos, dirty=_apply(self.model, changed, j))

    # -- improvement of a plan found (ours, not the paper's) -----------------------------------
    def improve(self, tries: int, deadline: Budget | None = None, budget: Budget | None = None) -> int:
        """Large-neighbourhood search over the priorities of a plan found (ours): up to ``tries``
        times, the robot that waits longest in all (not tried yet) moves just ahead of the robot
        whose trajectory ends its longest wait, and what that changes is re-planned and
        re-scheduled as in a re-ordering; the move stays when the sum of arrival times drops,
        else everything is put back as it was. Anytime: no move starts once ``deadline`` or
        ``budget`` is spent (the plan is the best found so far). Returns how many moves stayed.

        Measured at 100 robots (sum of arrivals / free, md's own plan, CPU under load 6-8): 8 tries
        warehouse-10-20-10-2-2 1.059 -> 1.037 (6 moves kept, +0.4 s), warehouse-20-40-10-2-2 1.014
        -> 1.011, warehouse-10-20-10-2-1 1.131 -> 1.112; 12 tries 1.033 / 1.009 / 1.101 for about
        twice the extra time. Without route choice again for the robots a move makes wait longer:
        1.042 / 1.010 / 1.118 at 12 tries; with it for every robot below the moved one: 1.037 /
        - / 1.085 at 1.5-2x the time. A robot moved to the front instead ruined the plans as often
        as it helped (full re-plans: up to 1.133)."""
        kept, tried = 0, set()
        total = self._arrivals()
        for _ in range(tries):
            if (deadline is not None and deadline.passed()) or (budget is not None and budget.passed()):
                break
            waits = {x: w for x, w in self._waits().items() if x not in tried}
            if not waits:
                break
            x = max(waits, key=lambda y: waits[y])
            if waits[x] <= self.detour_min:
                break
            tried.add(x)
            ahead_of = self._waits_for(x)
            if ahead_of is None or ahead_of < self.fixed:
                continue
            state = self._checkpoint()
            # the moved robot has a new rank: its route choice is tried again, and so is the route
            # choice of every robot the move makes wait longer
            self.detour_tries.pop(x, None)
            self.waits_before = self._waits()
            try:
                self._repair(self._move_ahead(x, self.rank[ahead_of]))
                better = self._arrivals() < total - 1e-6
            except PlanningError:
                better = False
            self.waits_before = {}
            if better:
                total = self._arrivals()
                kept += 1
            else:
                self._rollback(state)
        return kept

    def _waits(self) -> dict[int, float]:
        """Each robot's waits in all (s), of those that are not fixed and move."""
        return {x: float(self.sched.arr[x][-1] - self.route_of(x)[1][-1])
                for x in range(self.fixed, len(self.robots)) if len(self.sched.arr[x]) > 1}

    def _arrivals(self) -> float:
        """Sum of the robots' arrival times as scheduled."""
        return float(sum(a[-1] for a in self.sched.arr if len(a) > 1))

    def drive(self) -> float:
        """Sum of the robots' times to drive their routes without waiting."""
        return float(sum(self.route_of(x)[1][-1] for x in range(len(self.robots))))

    def _waits_for(self, x: int) -> int | None:
        """The higher robot whose trajectory ends x's longest wait: of the constraints on the
        stretch from that wait on, the one x clears by the least margin."""
        arr, dep = self.sched.arr[x], self.sched.dep[x]
        higher = [i for i in self.model.neighbours(x) if self.rank[i] < self.rank[x]]
        if not higher or len(arr) < 2:
            return None
        k = int(np.argmax(dep[:-1] - arr[:-1]))
        (g_key, g_lo, g_hi, g_own), (f_key, f_lo, f_hi, f_own) = self.sched.hold_constraints(x, higher)
        span = 6   # vertices after the wait in which the binding constraint is looked for
        g = (g_key >= k) & (g_key < k + span)
        f = (f_key > k) & (f_key <= k + span)
        slack = np.concatenate([dep[g_key[g]] - g_hi[g], arr[f_key[f]] - f_hi[f]])
        owner = np.concatenate([g_own[g], f_own[f]])
        ok = slack >= -1e-6
        if not ok.any():
            return None
        return int(owner[ok][np.argmin(slack[ok])])

    def _checkpoint(self) -> tuple:
        return (list(self.order), dict(self.rank), list(self.paths), list(self.times),
                {x: {o: list(d) for o, d in by.items()} for x, by in self.must.items()}, dict(self.hints),
                dict(self.detour_tries), self.reorders, self.reroutes, self.detoured,
                self.model.checkpoint(), self.sched.checkpoint())

    def _rollback(self, state: tuple) -> None:
        (order, rank, paths, times, must, hints, detour_tries, self.reorders, self.reroutes, self.detoured,
         model, sched) = state
        self.order[:] = order
        self.rank = dict(rank)
        self.paths[:], self.times[:] = paths, times
        self.must.clear()
        self.must.update(must)
        self.hints, self.detour_tries = dict(hints), dict(detour_tries)
        self.model.rollback(model)
        self.sched.rollback(sched)

    def _detour(self, x: int) -> bool:
        """Route choice in time: if robot x (just scheduled with holds) waits long, try paths around
        the stretch after its longest wait (keeping what x must avoid) and keep the one with the
        earliest arrival; True if x's path changed."""
        if x < self.fixed or (self.detour_deadline is not None and self.detour_deadline.passed()):
            return False
        me, sched = self.robots[x], self.sched
        changed = False
        before = self.waits_before.pop(x, None)
        if before is not None and float(sched.arr[x][-1] - self.route_of(x)[1][-1]) > before + self.detour_min:
            self.detour_tries.pop(x, None)   # an improvement move made x wait longer: its route choice again
        # at most ``detours`` tries per robot in a session: a re-ordering re-schedules everyone
        # below, and trying the same detours again rarely pays
        while self.detour_tries.get(x, 0) < self.planner.detours:
            self.detour_tries[x] = self.detour_tries.get(x, 0) + 1
            arr, dep = sched.arr[x], sched.dep[x]
            if len(arr) < 3:
                return changed
            wait = dep[:-1] - arr[:-1]
            if float(wait.sum()) <= (self.detour_min if self.detour_tries[x] == 1 else self.detour_again):
                return changed
            v = int(np.argmax(wait))
            old_path, old_times = self.route_of(x)
            reach = me.radius + 0.05
            ends = np.array([me.start, me.goal], dtype=float)
            ahead = [p for p in old_path[v + 1:v + 4] if np.hypot(*(ends - p).T).min() > reach + me.radius]
            if not ahead:
                return changed
            must = [d for discs in self.must.get(x, {}).values() for d in discs]
            avoid = np.vstack([*self._parked(x), _disc_rows(must),
                               _disc_rows([((float(p[0]), float(p[1])), reach) for p in ahead])])
            path = self.finder.get(me.radius).find(me.start, me.goal, avoid=avoid)
            if path is None:
                return changed
            before = float(arr[-1])
            old_arr, old_dep = arr.copy(), dep.copy()
            snap = self.model.snapshot(x)
            self.model.set_paths(self._set_route(x, path))
            if sched.schedule_robot(x, self.rank) is None and float(sched.arr[x][-1]) < before - 1e-6:
                self.detoured += 1
                changed = True
                continue
            self.paths[x], self.times[x] = old_path, old_times
            self.model.restore(snap)
            sched.set_timing(x, 0.0, old_arr, old_dep)
            return changed
        return changed

    def _reroute(self, x: int, owner: int, disc: tuple[tuple[float, float], float]) -> bool:
        """Re-plan x to keep off ``disc`` (the start or goal of ``owner``); True if x's path changed."""
        self.must.setdefault(x, {}).setdefault(owner, []).append(disc)
        path = self.safe_path(x, partner=owner)
        if path is None or polyline_passes_near(path, disc[0], disc[1]):
            return False
        self._set_route(x, path)
        self.reroutes += 1
        return True

    def timed_paths(self) -> list[TimedPath]:
        if self.planner.holds == "anywhere":
            return [_held_path(r.id, r.radius, self.route_of(x)[0], self.sched.arr[x], self.sched.dep[x])
                    for x, r in enumerate(self.robots)]
        return [timed_path_from_profile(r.id, r.radius, *self.route_of(x), float(self.sched.delays[x]))
                for x, r in enumerate(self.robots)]


class _LegSession(_Session):
    """A session of :meth:`MDPlanner.plan_incremental` whose robots may be given their first
    routes (``forced``: robot -> polyline, used once; a re-route plans as usual)."""

    forced: dict[int, np.ndarray]

    def safe_path(self, x: int, partner: int | None = None) -> np.ndarray | None:
        path = self.forced.pop(x, None) if getattr(self, "forced", None) else None
        return path if path is not None else super().safe_path(x, partner)

    def legs(self) -> list[TimedPath]:
        """The timed paths of the robots planned (:meth:`timed_paths` without the fixed ones,
        which are not built: at 100 robots that was 6% of a leg)."""
        if self.planner.holds == "anywhere":
            return [_held_path(r.id, r.radius, self.route_of(x)[0], self.sched.arr[x], self.sched.dep[x])
                    for x, r in enumerate(self.robots) if x >= self.fixed]
        return [timed_path_from_profile(r.id, r.radius, *self.route_of(x), float(self.sched.delays[x]))
                for x, r in enumerate(self.robots) if x >= self.fixed]


#: plan_incremental: try space-time routes when the legs arrive late (off: md's own routes only)
_LEG_ROUTES = True
#: ... later in all than this many seconds after driving their shortest paths on the empty map
_LEG_ROUTES_AFTER_S = 2.0
#: the space-time search of a leg may take this many ``leg_time_limit`` (CPU seconds; measured on the
#: delivery benchmark's large map at 20 robots under load 30 on 2 cores: 1.6 s wall, about 0.1 s CPU)
_LEG_SEARCH_LIMITS = 4
#: ... and sees the fixed trajectories that come within this much (m, beyond the keep-out distance)
#: of the box round a leg's start, goal and shortest path (a detour through a neighbouring aisle)
_LEG_CORRIDOR_M = 4.0




def _corridors(finders: _Finders, robots: list[RobotSpec]) -> tuple[np.ndarray, np.ndarray]:
    """Each leg's corridor as rows of lows and highs (legs, 2): the bounding box of its start, its
    goal and its shortest path on the empty map, grown by :data:`_LEG_CORRIDOR_M` (room for a detour
    through a neighbouring aisle)."""
    lo, hi = np.zeros((len(robots), 2)), np.zeros((len(robots), 2))
    for x, r in enumerate(robots):
        pts = [np.asarray([r.start, r.goal], dtype=float)]
        path = finders.get(r.radius).find(r.start, r.goal)
        if path is not None:
            pts.append(np.asarray(path, dtype=float)[:, :2])
        xy = np.vstack(pts)
        lo[x], hi[x] = xy.min(axis=0) - _LEG_CORRIDOR_M, xy.max(axis=0) + _LEG_CORRIDOR_M
    return lo, hi


def _fixed_near(robots: list[RobotSpec], corridor_lo: np.ndarray, corridor_hi: np.ndarray,
                fixed: Sequence[TimedPath], t0: float, margin: float) -> list[int]:
    """Indices of the ``fixed`` trajectories that, from ``t0`` on (parked on their last waypoint
    for ever after), come within the pair's keep-out distance of a leg's corridor
    (:func:`_corridors`)."""
    if not fixed or not robots:
        return list(range(len(fixed)))
    grow = np.array([[r.radius + margin] for r in robots])
    lo, hi = corridor_lo - grow, corridor_hi + grow   # (legs, 2)
    out = []
    for k, tp in enumerate(fixed):
        wp = tp.waypoints
        j = max(0, int(np.searchsorted(wp[:, 2], t0, side="right")) - 1)
        ahead = wp[j:, :2]  # the piece driven at t0 on, and the rest (bounded by its waypoints)
        if len(ahead) > 1:
            a, b = ahead[:-1], ahead[1:]
            smin, smax = np.minimum(a, b), np.maximum(a, b)
        else:
            smin = smax = ahead
        # a segment's box against each leg's box (grown by the fixed robot's radius)
        g = tp.radius
        hit = np.all((smin[:, None, :] <= hi[None] + g) & (smax[:, None, :] >= lo[None] - g), axis=2)
        if hit.any():
            out.append(k)
    return out


def _total_arrival(legs: list[TimedPath]) -> float:
    return sum(tp.arrival_time for tp in legs)


class _Finders:
    """One path finder per distinct radius of one map (its inflated map is computed once)."""

    def __init__(self, grid: GridMap):
        self.grid = grid
        self._by_radius: dict[float, PathFinder] = {}
        self._keys: dict[float, float] = {}     # radius -> the radius of its finder

    def get(self, radius: float) -> PathFinder:
        """A finder for a disc of ``radius`` or a slightly larger one: radii rounded up to the centimetre
        share one finder (valid for the smaller disc; at 100 robots of radii 0.35-0.45 m, ten finders instead
        of a hundred), unless the rounding inflates the map more than the radius itself does - then the
        radius's own. (Until session 30 always rounded: on a 0.5 m grid the 0.354 m robots became 0.36 m
        ones, for which every cell diagonal to a rack corner is blocked, and md's legs were 0.98 m longer
        than the shortest path on `large`, 0.32 m on the default warehouse, over 60 random legs on the empty
        map; PRIOR's -0.03 and 0.20 m.)"""
        from ..paths import PathFinder, inflation_kernel

        key = self._keys.get(radius)
        if key is None:
            key = math.ceil(radius * 100 - 1e-9) / 100
            res = self.grid.resolution
            if key != radius and not np.array_equal(inflation_kernel(res, key), inflation_kernel(res, radius)):
                key = float(radius)
            self._keys[radius] = key
        if key not in self._by_radius:
            self._by_radius[key] = PathFinder(self.grid, key)
        return self._by_radius[key]


class _FinderCache:
    """The path finders of the maps a planner has planned on, owned by the planner: every call on
    the same map (the fleet manager plans a leg many times a minute) reuses the inflated maps and
    disc caches. Keyed by map content, resolution and lanes, as the prior planner keys its roadmaps (a
    GridMap is a mutable dataclass, so neither hashable nor a weak key, and the finders refer to
    their map, which would keep a weak key alive); the few most recent maps are kept."""

    MAX_MAPS = 4

    def __init__(self) -> None:
        self._by_map: dict[tuple, _Finders] = {}
        self._fine: dict[tuple, GridMap] = {}

    def of(self, grid: GridMap) -> _Finders:
        key = self._key(grid)
        finders = self._by_map.get(key)
        if finders is None:
            if len(self._by_map) >= self.MAX_MAPS:
                self._by_map.clear()
            finders = self._by_map[key] = _Finders(grid)
        return finders

    def refined(self, grid: GridMap, k: int) -> GridMap:
        """``grid.refined(k)``, the same object for the same map (so are its finders)."""
        key = (self._key(grid), k)
        fine = self._fine.get(key)
        if fine is None:
            if len(self._fine) >= self.MAX_MAPS:
                self._fine.clear()
            fine = self._fine[key] = grid.refined(k)
        return fine

    @staticmethod
    def _key(grid: GridMap) -> tuple:
        lanes = getattr(grid, "lanes", None)   # a map with lanes plans only along them: its own finders
        return (grid.blocked.shape, grid.resolution, grid.blocked.tobytes(),
                None if lanes is None else lanes.allowed.tobytes())


def _apply(model: CollisionModel, changed: dict[int, tuple[np.ndarray, np.ndarray]], moved: int) -> set[int]:
    """Give the model the re-planned paths; return the robots whose constraints changed: the moved
    robot, the re-planned ones, and everyone who was or is now their neighbour."""
    dirty = {moved, *changed}
    for x in (moved, *changed):
        dirty.update(model.neighbours(x))
    model.set_paths(changed)
    for x in (moved, *changed):
        dirty.update(model.neighbours(x))
    return dirty


def _remaining(tp: TimedPath, t0: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The part of a hold-then-drive timed path still ahead at ``t0``: (polyline from the robot's
    position at t0, the times from then on at which it passes the vertices, delay from t0 until it
    moves). A path that holds again after it has started moving is not of this form and is
    refused (the md planner never makes one)."""
    wp = tp.waypoints
    seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
    moving = seg > 1e-9
    if not moving.any():
        return wp[-1:, :2].copy(), np.zeros(1), 0.0
    first, last = int(np.argmax(moving)), len(moving) - 1 - int(np.argmax(moving[::-1]))
    if not moving[first:last + 1].all() or np.any(np.diff(wp[first:last + 2, 2]) <= 0):
        raise ValueError(f"fixed path of {tp.robot_id!r}: holds after it starts moving; cannot be kept as is")
    depart, arrive = float(wp[first, 2]), float(wp[last + 1, 2])
    if t0 <= depart:
        return wp[first:last + 2, :2].copy(), wp[first:last + 2, 2] - depart, depart - t0
    if t0 >= arrive:
        return wp[last + 1:last + 2, :2].copy(), np.zeros(1), 0.0
    k = int(np.searchsorted(wp[:, 2], t0, side="right"))   # next vertex ahead of t0
    here = np.array(tp.position(t0))
    return np.vstack([here, wp[k:last + 2, :2]]), np.concatenate([[0.0], wp[k:last + 2, 2] - t0]), 0.0


def _subdivide(path: np.ndarray, step: float) -> np.ndarray:
    """The polyline with extra vertices, so that no segment is longer than ``step``."""
    pts = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(pts) < 2:
        return pts
    d = pts[1:] - pts[:-1]
    k = np.maximum(1, np.ceil(np.hypot(d[:, 0], d[:, 1]) / step - 1e-9).astype(np.int64))
    seg = np.repeat(np.arange(len(d)), k)   # the segment of each new vertex, and its step along it
    step_no = np.arange(len(seg)) - np.repeat(np.cumsum(k) - k, k) + 1
    return np.vstack([pts[:1], pts[:-1][seg] + d[seg] * (step_no / k[seg])[:, None]])


def _held_path(robot_id: str, radius: float, points: np.ndarray, arr: np.ndarray, dep: np.ndarray) -> TimedPath:
    """A timed path through ``points``, reaching vertex k at ``arr[k]`` and leaving it at
    ``dep[k]`` (two waypoints where it holds; the last vertex is the goal, parked for ever).
    Vertices passed without a hold in a straight line at the same speed are left out (the same
    motion; the extra vertices were only places where the robot might have waited)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    keep = np.ones(len(pts), dtype=bool)
    if len(pts) > 2:
        a, b = pts[1:-1] - pts[:-2], pts[2:] - pts[1:-1]
        la, lb = np.hypot(*a.T), np.hypot(*b.T)
        ta, tb = arr[1:-1] - dep[:-2], arr[2:] - dep[1:-1]
        with np.errstate(divide="ignore", invalid="ignore"):
            straight = (np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) <= 1e-9 * la * lb) & ((a * b).sum(1) > 0)
            same_speed = np.abs(la * tb - lb * ta) <= 1e-9 * np.maximum(la * tb, 1e-12)
        keep[1:-1] = ~(straight & same_speed & (dep[1:-1] <= arr[1:-1]) & (la > 0) & (lb > 0) & (ta > 0) & (tb > 0))
    rows = []
    for k in np.nonzero(keep)[0]:
        x, y = pts[k]
        rows.append((x, y, arr[k]))
        if k < len(pts) - 1 and dep[k] > arr[k]:
            rows.append((x, y, dep[k]))
    return TimedPath(robot_id, radius, np.array(rows, dtype=float))


def _remaining_held(tp: TimedPath, t0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The part of a timed path (holds anywhere) still ahead at ``t0``: (polyline from the robot's
    position at t0, its drive profile: the times at which it would pass the vertices without holds,
    the times from t0 at which it reaches and leaves each vertex)."""
    wp = tp.waypoints
    # collapse repeated points into one vertex with its arrival and departure
    same = np.concatenate([[False], np.hypot(*np.diff(wp[:, :2], axis=0).T) <= 1e-9])
    first = np.nonzero(~same)[0]
    pts = wp[first, :2]
    arr = wp[first, 2] - t0
    dep = np.concatenate([wp[first[1:] - 1, 2], [np.inf]]) - t0
    arr[0] = -np.inf
    if len(pts) > 1 and arr[-1] > 0:
        k = int(np.searchsorted(dep, 0.0, side="right"))   # first vertex the robot leaves after t0
        if arr[k] <= 0:   # holding on vertex k at t0 (or parked on its start)
            pts, arr, dep = pts[k:], arr[k:], dep[k:]
        else:             # on the segment from vertex k - 1 to k
            here = np.array(tp.position(t0))
            pts = np.vstack([here, pts[k:]])
            arr, dep = np.concatenate([[0.0], arr[k:]]), np.concatenate([[0.0], dep[k:]])
    else:
        pts, arr, dep = pts[-1:], np.zeros(1), np.array([np.inf])
    arr[0] = 0.0
    dep[0] = max(dep[0], 0.0)
    moving = arr[1:] - dep[:-1]
    times = np.concatenate([[0.0], np.cumsum(moving)])
    return pts, times, arr, dep


def _top_speed(path: np.ndarray, times: np.ndarray) -> float:
    """Fastest segment speed of a driven path (1 for a robot that stands still)."""
    if len(path) < 2:
        return 1.0
    return float(np.max(np.hypot(*np.diff(path, axis=0).T) / np.maximum(np.diff(times), 1e-12)))


def _disc_rows(discs: list) -> np.ndarray:
    """Discs (centre, keep-out) as an (n, 3) array of rows (x, y, keep-out)."""
    return np.array([(c[0], c[1], k) for c, k in discs], dtype=float).reshape(-1, 3)


def _keeps_off(path: np.ndarray, discs: np.ndarray, start, goal) -> bool:
    """True if the polyline keeps off every disc (rows x, y, keep-out), except discs containing the
    start or the goal, which no path can avoid (the path finder ignores them too)."""
    if not len(discs):
        return True
    c, r = discs[:, :2], discs[:, 2]
    ends = np.array([start, goal], dtype=float)
    unavoidable = (np.hypot(*(c[:, None, :] - ends[None, :, :]).transpose(2, 0, 1)) < r[:, None]).any(1)
    return polyline_keeps_off(path, c[~unavoidable], r[~unavoidable])


def _check_endpoints(robots: list[RobotSpec], margin: float) -> None:
    """Two robots whose start discs (or goal discs) overlap can never both be served."""
    ids = [r.id for r in robots]
    if len(set(ids)) != len(ids):
        raise PlanningError({rid: "duplicate robot id" for rid in ids if ids.count(rid) > 1})
    radii = np.array([r.radius for r in robots])
    for what in ("start", "goal"):
        pts = np.array([getattr(r, what) for r in robots], dtype=float).reshape(-1, 2)
        failures = {}
        for a in range(0, len(pts), 512):   # blocks of rows keep memory small for big fleets
            d = np.hypot(*(pts[a:a + 512, None, :] - pts[None, :, :]).transpose(2, 0, 1))
            rows, cols = np.nonzero(d < radii[a:a + 512, None] + radii[None, :])
            for r, c in zip(rows + a, cols):
                if r < c:
                    failures[ids[c]] = f"its {what} disc overlaps the {what} disc of {ids[r]}"
        if failures:
            raise PlanningError(failures)
