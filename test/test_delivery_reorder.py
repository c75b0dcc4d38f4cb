"""md's priority search in the live fleet (session 30, ``Planner.reorders_legs``): a new leg that arrives late
goes first past a robot driving in its way, whose leg is planned again behind it, when the two arrivals' sum
drops; once a leg is cut (turned to its station, or swapped), robots still waiting on a leg near it are planned
again from where they are. The runs stay valid (the independent checker); PRIOR keeps first come first served."""
from __future__ import annotations

import math

import pytest

from fleet_planner.delivery import central, delivery_problem
from fleet_planner.delivery.result import RunLimits
from fleet_planner.planners import get_planner
from fleet_planner.warehouse import generate_warehouse


@pytest.fixture(scope="module")
def tiny():
    """Four problems (seeds 0-3) of ten robots, twenty deliveries between the two chutes and four storing sites
    of a small warehouse (a swap or a re-timing is rare at this size: each problem has none or a few)."""
    wh = generate_warehouse(2, 2, 8, 2, 4, 0.5, "tiny")
    chutes = [s.name for s in wh.stations_of("chute")]
    sites = [s.name for s in wh.stations_of("storage")]
    stations = {n: wh.stations[n].pose for n in chutes + sites}
    return [delivery_problem(wh.grid, stations, 10, 20, seed=seed, pick=chutes, drop=sites) for seed in range(4)]


def _run(problem, method: str, options: dict | None = None):
    """A run with every swap and re-timing logged: (result, swaps, retimings). A swap: (r's first leg, the leg
    it drives, q's leg before, q's leg after, when, q's target kind); a re-timing: (now, the robot's leg before,
    after)."""
    run = central._CentralRun(problem, method, RunLimits(3600.0, 600.0, 120.0, 2.0, 600.0), options, None,
                              queue="near")
    swaps, retimes = [], []
    go_first, retime = run._go_first, run._retime

    def logged_go_first(r, leg, now):
        before = list(run.driving)
        out, swapped = go_first(r, leg, now)
        changed = [k for k, tp in enumerate(run.driving) if tp is not before[k] and len(tp.waypoints) > 1]
        if out is not leg:
            assert len(changed) == 1 and swapped is not None
            assert swapped[0] is run.robots[changed[0]] and swapped[1] is before[changed[0]]
            swaps.append((leg, out, before[changed[0]], run.driving[changed[0]], now,
                          run.robots[changed[0]].target_kind))
        else:
            assert swapped is None
        return out, swapped

    def logged_retime(q, old, now):
        before = list(run.driving)
        retime(q, old, now)
        retimes.extend((now, before[k], tp) for k, tp in enumerate(run.driving)
                       if tp is not before[k] and len(tp.waypoints) > 1)   # (not a robot just seen standing)

    run._go_first, run._retime = logged_go_first, logged_retime
    return run.run(), swaps, retimes


def test_a_late_leg_goes_first_and_robots_waiting_for_a_cut_leg_are_timed_again(tiny):
    all_swaps, all_retimes = [], []
    for problem in tiny:
        # on the map's cells: on md's finer lattice for legs (session 31) these small runs have too little
        # traffic left to swap
        result, swaps, retimes = _run(problem, "md", {"leg_lattice": 1})
        assert result.finished and result.completed == 20 and result.deadlocks == 0
        assert result.collisions == 0 and result.violations == []    # the independent checker, cut legs included
        assert result.extra["swaps"] == len(swaps) and result.extra["retimed"] == len(retimes)
        all_swaps += swaps
        all_retimes += retimes
    speed = tiny[0].max_speed
    assert all_swaps and all_retimes
    for mine, out, theirs, again, now, kind in all_swaps:
        assert mine.arrival_time - now - mine.length / speed > central.SWAP_AFTER_S
        assert out.arrival_time < mine.arrival_time - central.SWAP_GAIN_S     # r arrives sooner ...
        lost = 0.0 if kind == "park" else again.arrival_time - theirs.arrival_time   # (parking: no delivery left)
        assert mine.arrival_time - out.arrival_time - lost > central.SWAP_GAIN_S   # ... and the two of them too
        assert math.dist(again.waypoints[0, :2], theirs.position(now)) < 1e-6   # q goes on from where it is
    for now, old, new in all_retimes:
        assert new.arrival_time < old.arrival_time - central.RETIME_GAIN_S
        assert math.dist(new.waypoints[0, :2], old.position(now)) < 1e-6 and new.waypoints[0, 2] == now


@pytest.mark.parametrize("method, options", [("md", {"swaps": False}), ("prior", None)])
def test_without_reordering_every_leg_stays_as_planned(tiny, method, options):
    # control: md with swaps off, and PRIOR (first come first served, as in paper 002)
    assert get_planner(method, **(options or {})).reorders_legs is False
    for problem in tiny:
        result, swaps, retimes = _run(problem, method, options)
        assert result.finished and result.collisions == 0 and result.violations == []
        assert swaps == retimes == [] and result.extra["swaps"] == result.extra["retimed"] == 0
