"""The dense solver's speed-aware refinement and its new legs around driven trajectories (issue 11).

The independent checker is the oracle of every case."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap
from fleet_planner.model import Plan, RobotSpec, TimedPath
from fleet_planner.planners.crowd import CrowdPlanner

# an aisle where a slow robot leads two fast ones the same way: the timed LNS lets them by
AISLE = ["." * 10, "." * 10]


@st.composite
def crowds(draw):
    w, h = draw(st.integers(5, 9)), draw(st.integers(3, 6))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    blocked = rng.random((h, w)) < draw(st.sampled_from([0.0, 0.2]))
    free = [(c, r) for r in range(h) for c in range(w) if not blocked[r, c]]
    n = max(2, min(12, int(draw(st.floats(0.2, 0.45)) * len(free))))
    grid = GridMap(blocked, 1.0, "crowd")
    if len(free) < n:
        return grid, []
    starts, goals = rng.permutation(len(free))[:n], rng.permutation(len(free))[:n]
    robots = [RobotSpec(f"r{k}", float(rng.uniform(0.35, 0.45)), float(rng.uniform(0.5, 1.0)),
                        grid.centre(*free[starts[k]]), grid.centre(*free[goals[k]])) for k in range(n)]
    return grid, robots


def _soc(plan: Plan) -> float:
    return sum(p.arrival_time for p in plan.paths)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=crowds(), first=st.sampled_from(["auto", "discrete"]))
def test_the_timed_refinement_is_valid_and_never_worse(case, first):
    """Same first plan (timed, or discrete without the discrete LNS, so both runs start alike): with
    the timed LNS the plan is valid by the checker and its sum of arrivals is no larger than the
    precedence timing's of the first plan alone."""
    grid, robots = case
    if len(robots) < 2:
        return
    try:
        plain = CrowdPlanner(time_limit_s=5.0, refine_s=0, timed_refine_s=0, first=first, diagonal=False).plan(
            grid, robots)
    except Exception:   # noqa: BLE001 - unreachable goals: not this test's business
        return
    refined = CrowdPlanner(time_limit_s=5.0, refine_s=0, timed_refine_s=0.05, first=first, diagonal=False).plan(
        grid, robots)
    assert refined.info["first_plan"] == plain.info["first_plan"]
    assert check_plan(grid, robots, refined) == []
    assert _soc(refined) <= _soc(plain) + 1e-6


def test_fast_robots_are_not_kept_behind_a_slow_one():
    """A slow robot (0.5 m/s) in front of two fast ones (1 m/s) on a 2-row strip, all going right:
    the discrete plan moves them in lock-step, so timed by precedence alone the fast ones crawl
    behind; the timed LNS sends them by on the other row and lowers the sum of arrivals."""
    grid = GridMap.from_rows(AISLE)
    robots = [RobotSpec("slow", 0.4, 0.5, (2.5, 0.5), (9.5, 0.5)),
              RobotSpec("f1", 0.4, 1.0, (1.5, 0.5), (8.5, 0.5)),
              RobotSpec("f2", 0.4, 1.0, (0.5, 0.5), (7.5, 0.5))]
    plain = CrowdPlanner(refine_s=0, timed_refine_s=0, first="discrete").plan(grid, robots)
    refined = CrowdPlanner(refine_s=0, timed_refine_s=0.2, first="discrete").plan(grid, robots)
    assert check_plan(grid, robots, refined) == []
    assert _soc(refined) < _soc(plain) - 1.0, (_soc(plain), _soc(refined))
    # the timed first plan drives each robot at its own speed from the start: no LNS needed (4-connected as
    # the discrete plan: with diagonal steps in its search the fast ones change rows on the diagonal, holding
    # both rows for sqrt 2 steps, and the slow one, planned last, waits longer: 41.07 s against 39.32)
    timed = CrowdPlanner(timed_refine_s=0, diagonal=False).plan(grid, robots)
    assert timed.info["first_plan"] == "timed" and check_plan(grid, robots, timed) == []
    assert _soc(timed) < _soc(plain) - 1.0, (_soc(plain), _soc(timed))


def test_a_crowd_on_a_shelf_floor_gets_a_valid_timed_first_plan_unless_robots_ramp():
    """20 robots of mixed speeds among 1-cell shelf aisles: the timed first plan (prioritized
    safe-interval search at each robot's own speed, re-timed by precedence) is the one used and is
    valid by the checker, as is the plan after its timed LNS; with acceleration limits the discrete
    pipeline plans (the safe intervals are at constant top speed)."""
    rows = ["." * 23] + [".." + "@@@@@@@@@@" + "." + "@@@@@@@@@@"] * 2 + ["." * 23]
    grid, robots, _free, _pick = _crowd(rows * 3 + ["." * 23], 20, seed=1, slowest=0.7)
    first = CrowdPlanner(timed_refine_s=0, diagonal=False).plan(grid, robots)
    refined = CrowdPlanner(timed_refine_s=0.2, diagonal=False).plan(grid, robots)
    for plan in (first, refined):
        assert plan.info["first_plan"] == "timed" and check_plan(grid, robots, plan) == []
    assert _soc(refined) <= _soc(first) + 1e-6
    ramps = [RobotSpec(r.id, r.radius, r.max_speed, r.start, r.goal, max_accel=0.5) for r in robots]
    assert CrowdPlanner(timed_refine_s=0).plan(grid, ramps).info["first_plan"] != "timed"


def _crowd(rows: list[str], n: int, seed: int, slowest: float):
    """n robots (radius 0.35-0.45 m, ``slowest``-1.0 m/s) from distinct random free cells of ``rows``
    to distinct others; also the free cells and their random order (the cells after the first 2n are
    spare)."""
    grid = GridMap.from_rows(rows)
    free = [(c, r) for r in range(len(rows)) for c in range(len(rows[0])) if rows[r][c] == "."]
    rng = np.random.default_rng(seed)
    pick = rng.permutation(len(free))
    robots = [RobotSpec(f"r{k}", float(rng.uniform(0.35, 0.45)), float(rng.uniform(slowest, 1.0)),
                        grid.centre(*free[pick[k]]), grid.centre(*free[pick[n + k]])) for k in range(n)]
    return grid, robots, free, pick


def _joined(before: TimedPath, leg: TimedPath, t0: float) -> TimedPath:
    """A robot's whole trajectory: its old path up to t0 (parked on its goal), then its new leg."""
    old = before.waypoints[before.waypoints[:, 2] <= t0]
    return TimedPath(before.robot_id, before.radius, np.vstack([old, leg.waypoints]))


def test_a_burst_of_new_legs_in_a_crowd_is_planned_on_the_lattice_and_checked(monkeypatch):
    """A crowd of 12 planned by the dense solver among shelves; at t0 the robots that have
    arrived get new goals (a burst of legs in the crowded zone). They are planned natively (safe
    intervals against the exact cell holdings of the robots still driving), and the whole fleet -
    driven paths, the parked part before t0 and the new legs - passes the checker. (The first plan
    without diagonal steps in its search: with them this seed's burst has a robot that no order of
    the legs serves - r9, which followed a driven robot into its goal cell, stays shut in by the
    other new legs; alone its leg is found.)"""
    from fleet_planner.planners import crowd

    monkeypatch.setattr(crowd, "DIAGONAL_SEARCH", False)
    rows = ["..........", ".@@..@@...", "..........", "..........", "...@@..@@.", ".........."]
    n = 12
    grid, robots, free, pick = _crowd(rows, n, seed=0, slowest=0.6)
    planner = CrowdPlanner(refine_s=0.2, timed_refine_s=0.1)
    plan = planner.plan(grid, robots)
    assert check_plan(grid, robots, plan) == []
    arrivals = sorted(p.arrival_time for p in plan.paths)
    t0 = arrivals[n // 2]
    done = [k for k, p in enumerate(plan.paths) if p.arrival_time <= t0]
    driving = [k for k in range(n) if k not in done]
    taken = {tuple(plan.paths[k].waypoints[-1, :2]) for k in range(n)}
    spare = [grid.centre(*free[i]) for i in pick[2 * n:] if grid.centre(*free[i]) not in taken]
    assert len(done) >= 4 and len(spare) >= len(done)
    new = [RobotSpec(robots[k].id, robots[k].radius, robots[k].max_speed, robots[k].goal, spare[x])
           for x, k in enumerate(done)]
    legs = planner.plan_incremental(grid, new, [plan.paths[k] for k in driving], t0)
    assert planner.last_incremental == "dense"
    assert [leg.robot_id for leg in legs] == [r.id for r in new]
    assert all(tuple(leg.waypoints[0]) == (*r.start, t0) for leg, r in zip(legs, new))
    whole = {k: plan.paths[k] for k in driving}
    whole.update({k: _joined(plan.paths[k], legs[x], t0) for x, k in enumerate(done)})
    specs = [robots[k] if k in driving else RobotSpec(robots[k].id, robots[k].radius, robots[k].max_speed,
                                                      robots[k].start, spare[done.index(k)]) for k in range(n)]
    assert check_plan(grid, specs, Plan("dense", [whole[k] for k in range(n)], 0.0, {})) == []


@pytest.mark.parametrize("end, answer", [((3.5, 2.5), "prior"), ((3.5, 3.5), "dense")])
def test_legs_around_any_angle_trajectories_go_to_prior(end, answer):
    """A driven trajectory off the lattice (a line at 34 degrees) has no exact cell holdings: PRIOR
    plans; one of diagonal steps (the dense solver's own, crowd_smooth) has them, side cells included:
    the lattice planner plans, and the checker passes both."""
    grid = GridMap.from_rows(["." * 6] * 4)
    driven = TimedPath("a", 0.4, np.array([[0.5, 0.5, 0.0], [*end, 5.0]]))
    planner = CrowdPlanner()
    legs = planner.plan_incremental(grid, [RobotSpec("b", 0.4, 1.0, (5.5, 0.5), (0.5, 3.5))], [driven], 0.0)
    assert planner.last_incremental == answer
    assert check_plan(grid, [RobotSpec("a", 0.4, 1.0, (0.5, 0.5), end),
                             RobotSpec("b", 0.4, 1.0, (5.5, 0.5), (0.5, 3.5))],
                      Plan("x", [driven] + legs, 0.0, {})) == []


# a ring: two 1-cell corridors, rows 0 and 3 (lanes: even rows east, odd rows west), joined by 2-cell wide ends
RING = ["." * 9, ".." + "@" * 5 + "..", ".." + "@" * 5 + "..", "." * 9]


def test_one_way_lanes_send_robots_round_a_ring_of_corridors_with_its_lanes():
    """Both ways round the ring are 11 cells: the east-bound robot takes the east lane (row 0), the
    west-bound one the west lane (row 3) - each alone, so only the lanes decide (control, ``LANE`` 0:
    the search's tie-break sends one of them the other way)."""
    from fleet_planner.planners import crowd_pibt, crowd_sipp

    grid = GridMap.from_rows(RING)
    graph = crowd_pibt.CellGraph(grid, 0.45)
    wrong = crowd_sipp.one_way(graph.index, graph.rows, graph.cols, graph.nb, graph.deg)
    corridor = {(c, r) for r in (0, 3) for c in range(2, 7)}
    for v in range(graph.n):
        for e in range(graph.deg[v]):
            w = graph.nb[v, e]
            here, there = (graph.cols[v], graph.rows[v]), (graph.cols[w], graph.rows[w])
            dc = there[0] - here[0]
            against = here[1] == there[1] and (here in corridor or there in corridor) and \
                dc == (-1 if here[1] == 0 else 1)
            assert wrong[v, e] == against, (here, there)
    east = RobotSpec("east", 0.4, 1.0, grid.centre(0, 1), grid.centre(8, 2))
    west = RobotSpec("west", 0.4, 1.0, grid.centre(8, 1), grid.centre(0, 2))
    for robot, row in ((east, 0), (west, 3)):
        plan = CrowdPlanner(timed_refine_s=0).plan(grid, [robot])
        assert plan.info["first_plan"] == "timed" and check_plan(grid, [robot], plan) == []
        ys = plan.paths[0].waypoints[:, 1]
        assert np.any(np.isclose(ys, grid.centre(0, row)[1])), (robot.id, plan.paths[0].waypoints)


def test_a_robot_shut_off_by_a_parked_robot_is_repaired_in_the_same_pass(monkeypatch):
    """A dead-end aisle (row 2, open at column 10): robot "near" parks at column 6 long before robot
    "deep" from the far corner comes for column 2. Planned shortest first, "deep" finds its goal shut;
    the repair plans it at once and "near" again after it (one pass of prioritized planning, valid,
    "near" waits for "deep" to pass); without the repair ("REPAIR" 0, the control) it takes a second
    pass with "deep" first."""
    from fleet_planner.planners import crowd_sipp

    rows = ["." * 11, "@" * 10 + ".", "." * 11, "@" * 10 + ".", "." * 11]
    grid = GridMap.from_rows(rows)
    robots = [RobotSpec("near", 0.4, 1.0, grid.centre(9, 0), grid.centre(6, 2)),
              RobotSpec("deep", 0.4, 1.0, grid.centre(0, 4), grid.centre(2, 2))]
    passes = []
    plain = crowd_sipp.prioritized

    def counted(*args):
        passes.append(args[0].tolist())
        return plain(*args)

    monkeypatch.setattr(crowd_sipp, "prioritized", counted)
    for repair, expected in ((4, [[0, 1]]), (0, [[0, 1], [1, 0]])):
        monkeypatch.setattr(crowd_sipp, "REPAIR", repair)
        passes.clear()
        plan = CrowdPlanner(timed_refine_s=0).plan(grid, robots)
        assert passes == expected
        assert plan.info["first_plan"] == "timed" and check_plan(grid, robots, plan) == []
        near, deep = plan.paths
        wp = deep.waypoints
        passed = [t0 + (x0 - 6.5) / (x0 - x1) * (t1 - t0) for (x0, y0, t0), (x1, y1, t1) in zip(wp[:-1], wp[1:])
                  if y0 == y1 == 2.5 and x1 < 6.5 <= x0]
        assert len(passed) == 1 and near.arrival_time > passed[0], (near.waypoints, wp)


def test_the_dense_benchmark_passes_the_timed_lns_budget_to_the_solver(capsys):
    """bench_dense --timed-refine S gives the dense solver timed_refine_s = S (the LNS budget curve of
    issue 11 is measured with it); without it the solver keeps its own budget; a negative one is refused."""
    import sys
    from pathlib import Path

    import pytest

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
    import bench_dense

    given_budget = bench_dense.dense_options(bench_dense._args(["--timed-refine", "2.5", "--dense-timeout", "40"]))
    assert given_budget == {"time_limit": 40.0, "timed_refine_s": 2.5}
    assert "timed_refine_s" not in bench_dense.dense_options(bench_dense._args([]))      # (control)
    with pytest.raises(SystemExit) as stop:
        bench_dense._args(["--timed-refine", "-1"])
    assert stop.value.code == 2
    assert "--timed-refine: must be >= 0" in capsys.readouterr().err
    assert CrowdPlanner(**given_budget).timed_refine_s == 2.5


def test_a_robot_trapped_on_its_start_names_the_first_robots_through_it():
    """The first plan's second repair (ours): a robot not sealed off from its goal that finds no path
    is trapped on its start by robots that drive through it before it can leave; the repair re-plans
    the first planned ones through it (by time, at most as many as it has room for), never itself
    nor robots not planned yet. (On warehouse-10-20-10-2-1, 400 robots, seeds 0 and 2 the first pass
    then succeeds: without it one robot failed and a second whole pass ran.)"""
    from fleet_planner.planners import crowd_sipp

    h_who = np.full((2, 8), -1, dtype=np.int32)
    h_lo, h_hi, h_n = np.zeros((2, 8)), np.zeros((2, 8)), np.zeros(2, dtype=np.int32)
    # cell 0: robot 0 (the trapped one) from 0, then 3 (not planned), 1, 2, 1 again, 4, 5 - sorted by start
    for who, lo in ((0, 0.0), (3, 1.0), (1, 2.0), (2, 3.0), (1, 4.0), (4, 5.0), (5, 6.0)):
        crowd_sipp._put(0, who, lo, lo + 0.5, h_who, h_lo, h_hi, h_n)
    planned = np.array([True, True, True, False, True, True])
    out = np.full(3, -1, dtype=np.int32)
    assert crowd_sipp._through_start(0, 0, planned, h_who, h_n, out) == 3 and out.tolist() == [1, 2, 4]
    out = np.full(8, -1, dtype=np.int32)
    assert crowd_sipp._through_start(0, 0, planned, h_who, h_n, out) == 4 and out[:4].tolist() == [1, 2, 4, 5]
    assert crowd_sipp._through_start(0, 1, planned, h_who, h_n, out) == 0          # nobody through cell 1
