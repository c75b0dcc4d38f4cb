"""Delivery simulation in the style of section V of Sun, Kleiner & Nebel, "Behavior-based
Multi-Robot Collision Avoidance": N robots serve a fixed sequence of deliveries.

A *delivery* is "drive to station k, dock there, drive to station l, dock there". Every robot takes
the next delivery of one seeded sequence whenever it has finished its previous one; when the
sequence is used up it drives back to its home parking spot (or the closest free one). The run ends
when every delivery is done (its completion time is CTime), at a cap on simulated time, or when
nothing has moved for a long time (a stall). Everything runs in simulated time, much faster than
real time, without ROS.

Methods (:data:`METHODS`):

* ``md`` / ``md-box`` - central (:mod:`.central`): each time a robot needs a new leg, the (M,D)
  planner of You & Ji, "Design of a Multi-robot Bin Packing System in an Automatic Warehouse"
  (:class:`~fleet_planner.planners.md.MDPlanner`) plans it around the trajectories every other
  robot is driving; robots follow their timed paths exactly. ``md-box`` uses the paper's collision
  boxes, ``md`` the exact regions.
* ``prior`` - the same flow with :class:`~fleet_planner.planners.prior.PriorPlanner`; every other
  planner of the registry (``md-departure``, ``md-holds``, ``md-routes``, ``crowd``) runs the
  same central flow through its ``plan_incremental``.
* ``behavior`` - BBMRCA (:mod:`.behavior_run`): :class:`~fleet_planner.behavior.BehaviorFleet`,
  each robot plans its own A* path and the behaviours resolve conflicts locally, stepped with a
  fixed ``dt``.

Where the robots go - the delivery sequence, station claims and queues, parking spots - is the same
for every method (:mod:`.stations`, which describes the station discipline of the central
methods). Parking spots are chosen so that a robot parked on one never cuts a passage
(:func:`choose_spots`, :mod:`.layout`).

Measured per run (:class:`DeliveryResult`): CTime, a lower bound (each robot's own deliveries
driven alone: shortest-path legs at top speed plus docking, maximum over robots), the average
velocity (distance driven / CTime, averaged over robots), planner or decision wall time, the
number of pairs of discs that ever overlap (exactly on the executed trajectories for the central
methods, at every step for ``behavior``) and the robots left deadlocked.

Modules: :mod:`.problem` (the problem and its generators), :mod:`.layout` (stations and parking
spots on a map), :mod:`.stations` (who goes where), :mod:`.central`, :mod:`.behavior_run` (the
two kinds of run), :mod:`.result` (limits, tally, result).
"""
from __future__ import annotations

import math

from ..planners import planner_names
from .behavior_run import simulate_behavior
from .central import simulate_central
from .layout import ROBOT_RADIUS, choose_spots, driving_distances, spread_stations
from .problem import DOCK_S, TOP_SPEED, Delivery, DeliveryProblem, delivery_problem, warehouse_problem
from .result import DeliveryResult, RunLimits, SimProgress
from .stations import DEFAULT_QUEUE, QUEUE_RULES

#: every registered planner (central: ``plan_incremental`` per leg), the behaviour fleet, and ARMO
#: (the behaviour fleet driving along ARMO's road map of directed lanes, :func:`armo_problem`)
METHODS = (*planner_names(), "behavior", "armo")


def armo_problem(problem: DeliveryProblem, **options) -> tuple[DeliveryProblem, object]:
    """The problem on ARMO's road map for its demand (:func:`fleet_planner.roadmap.armo_roadmap`):
    every method run on it plans along the lanes, laid out round the robots' homes (where they park).
    Returns (problem, the program's info)."""
    from dataclasses import replace

    from ..roadmap import armo_roadmap, demand_of, with_lanes

    lanes, info = armo_roadmap(problem.grid, problem.radius, problem.stations,
                               demand_of(problem.deliveries, list(problem.stations)),
                               **{"parked": problem.homes, **options})
    return replace(problem, grid=with_lanes(problem.grid, lanes)), info


def lanes_problem(problem: DeliveryProblem, lanes) -> DeliveryProblem:
    """The problem on a given road map (:class:`fleet_planner.roadmap.RoadMap`, e.g. a lanes file)."""
    from dataclasses import replace

    from ..roadmap import with_lanes

    return replace(problem, grid=with_lanes(problem.grid, lanes))


def simulate(problem: DeliveryProblem, method: str, *, dt: float = 0.1, cap_s: float = 4 * 3600.0,
             stall_s: float = 600.0, no_progress_s: float = 120.0, retry_s: float = 2.0,
             wall_cap_s: float = math.inf, record: bool = False, planner_options: dict | None = None,
             progress: SimProgress | None = None, queue: str = DEFAULT_QUEUE) -> DeliveryResult:
    """Run the deliveries of ``problem`` with ``method`` (one of :data:`METHODS`).

    ``dt``: step of the behaviour simulation (the central methods are event-driven and exact).
    ``cap_s``: stop at this simulated time; ``stall_s``: stop when no robot made progress for this
    long (a deadlock nobody resolves); ``no_progress_s``: at the end, robots with a delivery left
    that made no progress for this long count as deadlocked. ``retry_s``: a leg that could not be
    planned is tried again this much later (once another robot got a new leg; at the latest 15
    times as late). ``wall_cap_s``: stop after this much wall-clock time (stop "wall").
    ``record``: keep the behaviour fleet's positions at every step. ``planner_options``: keyword
    options of the central method's planner (:func:`~fleet_planner.planners.get_planner`). ``queue``: the
    central methods' queue rule, ``spots`` (robots wait for a station on parking spots near it), ``near``
    (on queue places a few metres from it, moving up; ours, :mod:`.stations`), ``close`` (near's, with the
    busy loading stations' places placed first; ours) or ``auto`` (close where every busy loading station gets
    enough places, else spots; ours; the default since session 28); the behaviour fleet has its own.
    """
    if method not in METHODS:
        raise ValueError(f"method: must be one of {', '.join(METHODS)} (got {method!r})")
    if queue not in QUEUE_RULES:
        raise ValueError(f"queue: must be one of {', '.join(QUEUE_RULES)} (got {queue!r})")
    for name, value in (("dt", dt), ("cap_s", cap_s), ("stall_s", stall_s), ("no_progress_s", no_progress_s),
                        ("retry_s", retry_s)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name}: must be a finite number > 0 (got {value!r})")
    if not wall_cap_s > 0:
        raise ValueError(f"wall_cap_s: must be > 0 (got {wall_cap_s!r})")
    limits = RunLimits(cap_s=cap_s, stall_s=stall_s, no_progress_s=no_progress_s, retry_s=retry_s,
                       wall_cap_s=wall_cap_s)
    if method == "armo":   # ARMO: robots plan along the road map, the behaviours keep them apart
        from ..roadmap import lanes_of

        if lanes_of(problem.grid) is None:
            problem = armo_problem(problem)[0]
        res = simulate_behavior(problem, limits, dt=dt, record=record, progress=progress)
        res.method = "armo"
        return res
    if method == "behavior":
        return simulate_behavior(problem, limits, dt=dt, record=record, progress=progress)
    return simulate_central(problem, method, limits, planner_options, progress, queue)


__all__ = ["DEFAULT_QUEUE", "DOCK_S", "METHODS", "QUEUE_RULES", "armo_problem", "lanes_problem",
           "ROBOT_RADIUS", "TOP_SPEED", "Delivery", "DeliveryProblem", "DeliveryResult",
           "RunLimits", "SimProgress", "choose_spots", "delivery_problem", "driving_distances", "simulate",
           "spread_stations", "warehouse_problem"]
