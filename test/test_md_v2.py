"""md v2 (issue 8): priority search when greedy re-ordering gives up, the dense fallback, the time
budget and its options. Plans are judged by the independent checker (fleet_planner/checker.py).

The dense case: a comb of 1-cell aisles (rack rows of 3 cells, 1-cell gaps) with six robots of
radius 0.4 m on 55 free cells. The paper's greedy re-ordering (``md-departure``) gives up on it
("blocked by r4, which parks on its goal in the way"), although 420 of the 720 priority orders of
these robots work for it; the priority search finds one.
"""
import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleet_planner import cli
from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap
from fleet_planner.model import PlanningError, RobotSpec
from fleet_planner.planners import get_planner
from fleet_planner.planners.md import MDPlanner
from fleet_planner.planners.md_search import PrioritySearch

COMB = GridMap.from_rows(["...........",
                          ".@@@.@@@.@.",
                          "...........",
                          ".@@@.@@@.@.",
                          "..........."])


def _robots(n: int, seed: int) -> list[RobotSpec]:
    free = [(c, r) for r in range(COMB.height) for c in range(COMB.width) if not COMB.blocked[r, c]]
    cells = np.random.default_rng(seed).permutation(len(free))
    return [RobotSpec(f"r{i}", 0.4, 1.0, COMB.centre(*free[cells[i]]), COMB.centre(*free[cells[n + i]]))
            for i in range(n)]


DENSE = _robots(6, 8)


def test_greedy_re_ordering_refuses_the_dense_case():
    with pytest.raises(PlanningError, match="parks on its goal in the way"):
        get_planner("md-departure").plan(COMB, DENSE)


@pytest.mark.parametrize("holds", ["none", "anywhere"])
def test_the_priority_search_solves_it_without_the_fallback(holds):
    plan = get_planner("md", holds=holds, fallback=None, time_limit=60).plan(COMB, DENSE)
    assert check_plan(COMB, DENSE, plan) == []
    assert "fallback" not in plan.info
    if holds == "none":   # md with departure delays only: the search is what solved it
        assert plan.info["search"]["attempts"] > 1
        assert plan.info["search"]["priorities"] >= 1


def test_where_the_search_fails_the_dense_solver_plans_and_the_plan_says_so():
    robots = _robots(12, 0)   # 12 robots on the comb: no priority order of md's paths works
    with pytest.raises(PlanningError):
        get_planner("md", fallback=None, time_limit=1.0).plan(COMB, robots)
    plan = get_planner("md", time_limit=1.0, crowded=False).plan(COMB, robots)
    assert plan.info["fallback"] in ("crowd", "dense") and plan.planner == "md"
    assert plan.info["search"]["attempts"] >= 1 and plan.info["why"]
    assert check_plan(COMB, robots, plan) == []


def test_a_crowded_instance_goes_to_the_dense_solver_before_md_plans_a_path():
    """19 of the 12 robots' 24 starts and goals lie in the comb's 17 one-lane aisles (1.12 per
    aisle): md hands the instance over at once instead of spending its budget first."""
    from fleet_planner.planners import md_crowd

    robots = _robots(12, 0)
    measured = md_crowd.crowding(COMB, robots, 0.02)
    assert (measured.aisles, measured.in_lanes) == (17, 19)
    assert md_crowd.crowding(COMB, DENSE, 0.02).crowded() is None   # 6 robots: md's own case
    plan = get_planner("md", time_limit=30.0).plan(COMB, robots)
    assert plan.info["fallback"] in ("crowd", "dense") and plan.info["search"]["attempts"] == 0
    # with departure delays only (the paper's method) md searches first, the dense solver only after
    late = get_planner("md", holds="none", time_limit=1.0).plan(COMB, robots)
    assert not late.info.get("why", "").startswith("crowded") and late.info["search"]["attempts"] >= 1
    assert plan.info["why"].startswith("crowded: 19 starts and goals in 17 one-lane aisles")
    assert check_plan(COMB, robots, plan) == []


def test_a_crowded_instance_counts_md_s_own_time_in_the_dense_budget(monkeypatch):
    """On a crowded instance md hands the dense solver the CPU clock of its own start (``cpu_start``),
    so its crowding check counts towards the dense solver's budgets (issue 8: md 400 robots <= 2 s;
    the compiled kernels are loaded before, by the warm-up); the dense solver counts from the
    earlier of that and its own start. Control: called directly, the dense solver gets no ``cpu_start``."""
    from fleet_planner.planners import crowd

    seen = []
    plain = crowd.CrowdPlanner.plan

    def spy(self, grid, robots, progress=None):
        seen.append((self.cpu_start, time.process_time()))
        return plain(self, grid, robots, progress)

    monkeypatch.setattr(crowd.CrowdPlanner, "plan", spy)
    before = time.process_time()
    plan = get_planner("md", time_limit=30.0).plan(COMB, _robots(12, 0))
    assert plan.info["why"].startswith("crowded:") and check_plan(COMB, _robots(12, 0), plan) == []
    (start, called), = seen
    assert start is not None and before <= start <= called
    seen.clear()
    get_planner("dense").plan(COMB, _robots(12, 0))
    assert seen[0][0] is None


def test_two_wide_aisles_are_not_lanes_and_many_robots_are_crowded():
    from fleet_planner.planners import md_crowd

    rows = ["..........", "..@@..@@..", "..@@..@@..", ".........."]
    wide = GridMap.from_rows([rows[0]] + rows + [rows[0]])   # 2-cell aisles between the racks and around them
    robots = [RobotSpec("a", 0.45, 1.0, wide.centre(4, 2), wide.centre(5, 3))]
    assert md_crowd.crowding(wide, robots).aisles == 0
    narrow = GridMap.from_rows(rows)   # 1-cell cross aisles above and below the racks
    assert md_crowd.crowding(narrow, robots).aisles == 4   # above and below each of the two racks
    many = md_crowd.Crowding(robots=800, aisles=0, in_lanes=0)
    assert "800 robots" in many.crowded() and many.crowded(robots=801) is None


def test_a_busy_instance_goes_to_the_dense_solver_with_small_budgets(monkeypatch):
    """Below the crowded load but from LANE_LOAD_BUSY starts and goals per one-lane aisle, md's plan would
    lose the comparison: the dense solver plans first, before md plans a path, its refinements
    bounded by BUSY_REFINE_S; with compare_above=None (no comparison) md plans itself. Control: just
    below the threshold, md plans first."""
    from fleet_planner.planners import md_crowd
    from fleet_planner.planners.md import MDPlanner

    # the MovingAI 1-cell-aisle warehouse's measures at 100 robots (busy) and at 50 (md's)
    assert md_crowd.Crowding(robots=100, aisles=390, in_lanes=95).busy() is not None
    assert md_crowd.Crowding(robots=50, aisles=390, in_lanes=53).busy() is None
    assert md_crowd.Crowding(robots=100, aisles=0, in_lanes=0).busy() is None   # no lanes: never busy
    robots = _robots(12, 0)
    load = md_crowd.crowding(COMB, robots, 0.02).lane_load
    monkeypatch.setattr(md_crowd, "LANE_LOAD", load + 1)   # not crowded
    calls = []

    def dense(self, grid, robots, t_start, deadline, attempts, why, **options):
        calls.append((why, options))
        raise PlanningError({"r0": "stub"})

    monkeypatch.setattr(MDPlanner, "_dense", dense)

    def first_call(busy_from: float, **kw):
        monkeypatch.setattr(md_crowd, "LANE_LOAD_BUSY", busy_from)
        calls.clear()
        try:
            get_planner("md", time_limit=1.0, **kw).plan(COMB, robots)
        except PlanningError:
            pass
        return calls[0] if calls else (None, {})

    why, options = first_call(load)
    assert why.startswith("crowded:") and "the dense plan would win" in why
    assert options == {"refine_s": pytest.approx(md_crowd.BUSY_REFINE_S * 0.12)} | {
        "timed_refine_s": pytest.approx(md_crowd.BUSY_REFINE_S * 0.12)}
    assert not str(first_call(load, compare_above=None)[0]).startswith("crowded:")   # md plans itself
    assert not str(first_call(load + 0.01)[0]).startswith("crowded:")                # control


def test_md_keeps_the_dense_plan_only_when_it_is_better(monkeypatch):
    """compare_above=1 (and no minimum fleet): the dense solver plans too on the 6-robot comb;
    whichever plan comes back has the lower sum of arrival times of the two, and it is valid."""
    from fleet_planner.planners import md_crowd
    from fleet_planner.planners.md_crowd import sum_of_arrivals

    monkeypatch.setattr(md_crowd, "MIN_ROBOTS", 0)

    alone = get_planner("md", compare_above=None, time_limit=30.0).plan(COMB, DENSE)
    dense = get_planner("dense").plan(COMB, DENSE)
    both = get_planner("md", compare_above=1.0, time_limit=30.0).plan(COMB, DENSE)
    assert check_plan(COMB, DENSE, both) == []
    assert sum_of_arrivals(both) == pytest.approx(min(sum_of_arrivals(alone), sum_of_arrivals(dense)), abs=1e-6)
    assert ("fallback" in both.info) == (sum_of_arrivals(dense) < sum_of_arrivals(alone) - 1e-6)


def test_the_papers_methods_do_not_search():
    for name in ("md-departure", "md-box"):
        planner = get_planner(name)
        assert planner.search is False and planner.fallback is None and planner.holds == "none"
        assert planner.improve == 0


def _warehouse(n: int, seed: int):
    """The benchmark's generated warehouse (1-cell aisles) with n random start/goal pairs."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
    import bench_md

    inst = bench_md.generated_instance(n, seed)
    return inst.grid, inst.robots


def _sum(plan) -> float:
    return sum(p.arrival_time for p in plan.paths)


def test_the_improvement_search_moves_a_waiting_robot_ahead_and_lowers_the_sum():
    """25 robots (seed 2): md's first plan sums 1447.9 s of arrivals; moving the robot that waits
    longest just ahead of the robot it waits for lowers it (measured 1414.0 s)."""
    grid, robots = _warehouse(25, 2)
    first = get_planner("md", improve=0, compare_above=None).plan(grid, robots)
    better = get_planner("md", compare_above=None).plan(grid, robots)
    for plan in (first, better):
        assert check_plan(grid, robots, plan) == []
    assert better.info["improved"] >= 1
    assert _sum(better) < _sum(first) - 10.0


def test_the_improvement_search_starts_no_move_once_its_cpu_budget_is_spent(monkeypatch):
    """The search is anytime within a share of the first plan's CPU: with none, no move is tried and
    the plan is md's first plan (control: the test above, where the default share keeps a move)."""
    from fleet_planner.planners import md

    grid, robots = _warehouse(25, 2)
    first = get_planner("md", improve=0, compare_above=None).plan(grid, robots)
    monkeypatch.setattr(md, "IMPROVE_CPU_SHARE", 0.0)
    monkeypatch.setattr(md, "IMPROVE_MIN_CPU_S", 0.0)
    spent = get_planner("md", compare_above=None).plan(grid, robots)
    assert spent.info["improved"] == 0
    assert _sum(spent) == pytest.approx(_sum(first), abs=1e-9)


def test_md_budgets_count_cpu_seconds_not_wall_clock_seconds():
    """A Budget is not spent while its thread waits (wall-clock time passes, no CPU), is spent by
    computing, and runs out at its wall-clock backstop (WALL_BACKSTOP x its seconds) all the same."""
    import threading
    import time

    from fleet_planner.budget import WALL_BACKSTOP, Budget

    budget = Budget(0.2)   # (its backstop, 2 s wall, leaves room for a loaded machine)
    threading.Event().wait(0.3)   # more than the budget in wall-clock time, no CPU
    assert not budget.passed() and budget.left() > 0.15
    end = time.perf_counter() + 2 * WALL_BACKSTOP   # bounded: 0.2 s of CPU or the backstop come before
    while not budget.passed() and time.perf_counter() < end:
        sum(range(1000))
    assert budget.passed() and budget.left() == 0.0
    starved = Budget(0.01)
    threading.Event().wait(0.02 * WALL_BACKSTOP)
    assert starved.passed()
    assert not Budget(None).passed()


def test_a_live_fleet_paces_md_legs_in_wall_clock_seconds():
    """md's leg budget counts CPU seconds, or wall-clock seconds with leg_clock "wall", which the fleet
    manager's default md uses (its legs are paced in real time)."""
    import threading

    from fleet_planner.fleet import FleetManager
    from fleet_planner.robots import load_kinds
    from fleet_planner.warehouse import generate_warehouse

    cpu, wall = MDPlanner(leg_time_limit=0.2), MDPlanner(leg_time_limit=0.2, leg_clock="wall")
    budgets = cpu._leg_budget(), wall._leg_budget()
    threading.Event().wait(0.3)
    assert [b.passed() for b in budgets] == [False, True]
    fleet = FleetManager(generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4), load_kinds())
    assert fleet.planner.leg_clock == "wall"


def test_a_move_that_does_not_pay_is_undone_exactly(monkeypatch):
    """Every move refused (the sum never drops): the plan is exactly the plan without the search, so
    everything a move changed (order, paths, collision model, timing) was put back."""
    from fleet_planner.planners import md

    grid, robots = _warehouse(25, 2)
    first = get_planner("md", improve=0, compare_above=None).plan(grid, robots)
    monkeypatch.setattr(md._Session, "_arrivals", lambda self: 0.0)
    undone = get_planner("md", compare_above=None).plan(grid, robots)
    assert undone.info["improved"] == 0
    for a, b in zip(first.paths, undone.paths):
        assert a.robot_id == b.robot_id
        np.testing.assert_array_equal(a.waypoints, b.waypoints)
    assert [(k.i, k.j, k.k, k.M, k.D) for k in first.network.links] == \
        [(k.i, k.j, k.k, k.M, k.D) for k in undone.network.links]


@settings(max_examples=12, deadline=None)
@given(n=st.integers(8, 25), seed=st.integers(0, 10_000))
def test_the_improvement_search_never_makes_a_plan_worse_or_invalid(n, seed):
    """Property (the checker as oracle): with the search, the plan is valid and its sum of arrival
    times is never above the first plan's."""
    grid, robots = _warehouse(n, seed)
    first = get_planner("md", improve=0, compare_above=None).plan(grid, robots)
    plan = get_planner("md", compare_above=None).plan(grid, robots)
    assert check_plan(grid, robots, plan) == []
    assert _sum(plan) <= _sum(first) + 1e-6


def test_the_md_planner_holds_en_route_where_a_delay_costs_more():
    """The hand-worked case of test_md_holds (arrival 15 + sqrt 2 with a hold at (6, 11), 17 + sqrt 2
    with a departure delay) through md v2 and md --holds none."""
    from test_md_holds import GRID, SPECS

    held = get_planner("md", order="given", margin=0.0).plan(GRID, SPECS)
    delayed = get_planner("md", holds="none", order="given", margin=0.0).plan(GRID, SPECS)
    for plan in (held, delayed):
        assert check_plan(GRID, SPECS, plan) == []
    assert held.by_id()["j"].arrival_time == pytest.approx(15 + math.sqrt(2))
    assert held.by_id()["j"].start_time == pytest.approx(0.0)
    assert delayed.by_id()["j"].arrival_time == pytest.approx(17 + math.sqrt(2))
    assert delayed.by_id()["j"].start_time == pytest.approx(2 + math.sqrt(2))


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 9), seed=st.integers(0, 10_000), steps=st.integers(1, 12))
def test_the_search_order_is_a_permutation_that_keeps_every_learnt_priority(n, seed, steps):
    rng = np.random.default_rng(seed)
    search = PrioritySearch(seed)
    order = list(rng.permutation(n))
    for _ in range(steps):
        j, i = (int(v) for v in rng.choice(n, 2, replace=False))
        order = search.next_order(order, j, i)
        assert sorted(order) == list(range(n))
        rank = {x: k for k, x in enumerate(order)}
        assert rank[j] < rank[i]                       # the newest priority always holds
        assert all(rank[a] < rank[b] for a, b in search.constraints)


def test_bad_options_are_refused_naming_the_option(capsys, tmp_path):
    for bad in (-1, 0, math.inf, math.nan, True):
        with pytest.raises(ValueError, match="time_limit: must be a finite number of seconds > 0"):
            MDPlanner(time_limit=bad)
    with pytest.raises(ValueError, match="leg_time_limit"):
        MDPlanner(leg_time_limit=-1)
    with pytest.raises(ValueError, match="leg_clock: must be 'cpu' or 'wall'"):
        MDPlanner(leg_clock="sundial")
    with pytest.raises(ValueError, match="fallback: must be"):
        MDPlanner(fallback="lacam")
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="improve: must be an integer >= 0"):
            MDPlanner(improve=bad)
    with pytest.raises(ValueError, match="improve: needs holds 'anywhere'"):
        MDPlanner(holds="none", improve=4)
    for bad in (0.9, math.nan, "1.1", True):
        with pytest.raises(ValueError, match="compare_above: must be a finite number >= 1 or None"):
            MDPlanner(compare_above=bad)
    scen = tmp_path / "s.yaml"
    scen.write_text("map:\n  rows: ['........', '........']\n  resolution: 1.0\nrobots:\n"
                    "  - {id: a, radius: 0.4, max_speed: 1.0, start: [0.5, 0.5], goal: [7.5, 0.5]}\n")
    out = tmp_path / "p.json"
    for argv, option in ((["--time-limit", "-1"], "--time-limit"), (["--time-limit", "soon"], "--time-limit"),
                         (["--mode", "boxes"], "--mode"), (["--holds", "sometimes"], "--holds")):
        with pytest.raises(SystemExit) as stop:
            cli.main([str(scen), "--out", str(out), *argv])
        assert stop.value.code == 2
        assert option in capsys.readouterr().err
    assert cli.main([str(scen), "--out", str(out), "--time-limit", "2.5", "--quiet"]) == cli.EXIT_OK
    assert cli.main([str(scen), "--out", str(out), "--planner", "prior", "--time-limit", "2"]) == cli.EXIT_INPUT
    assert "does not take that option" in capsys.readouterr().err


def test_the_benchmark_refuses_bad_options_naming_them(capsys):
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
    import bench_md

    for argv, message in ((["--time-limit", "-1"], "--time-limit: must be a finite number of seconds > 0"),
                          (["--time-limit", "nan"], "--time-limit: must be"),
                          (["--planners", "md,nope"], "--planners: unknown"), (["--timeout", "0"], "--timeout: must"),
                          (["--suite", "issue9"], "--suite"),
                          (["--maps-dir", "/nonexistent/maps"], "--maps-dir: /nonexistent/maps is not a directory")):
        with pytest.raises(SystemExit) as stop:
            bench_md._args(argv)
        assert stop.value.code == 2
        assert message in capsys.readouterr().err
    args = bench_md._args(["--suite", "issue8", "--time-limit", "5"])
    assert args.planners == ["md", "md-departure", "prior"] and args.sizes == [100, 200, 400, 500]
    assert args.extra == {"warehouse-10-20-10-2-2": [1000], "warehouse-20-40-10-2-2": [1000]}
    assert args.time_limit == 5.0


@settings(max_examples=10, deadline=None)
@given(n=st.integers(3, 9), seed=st.integers(0, 10_000), holds=st.sampled_from(["none", "anywhere"]),
       ramps=st.booleans())
def test_every_plan_of_the_search_is_valid(n, seed, holds, ramps):
    """The priority search on dense combs (where greedy re-ordering often gives up), without the
    fallback, with and without acceleration ramps: a plan is valid for the checker or a refusal
    names the robots."""
    robots = _robots(n, seed)
    if ramps:
        robots = [RobotSpec(r.id, r.radius, r.max_speed, r.start, r.goal, max_accel=0.5) for r in robots]
    try:
        plan = get_planner("md", holds=holds, fallback=None, time_limit=0.5).plan(COMB, robots)
    except PlanningError as err:
        assert err.failures and set(err.failures) <= {r.id for r in robots}
        return
    assert check_plan(COMB, robots, plan) == []


@pytest.mark.parametrize("early", [False, True])
def test_early_holds_keep_the_arrival_and_wait_further_back(early):
    """The hand-worked case of test_md_holds (robot 2 crosses j's line x = 3 at t = 4, robot 1 crosses
    x = 11 at t = 10; j must pass each crossing at least sqrt 2 s away from them). The earliest
    arrival rushes to (10, 11), 1 m before robot 1's crossing, and waits there until 10 + sqrt 2 - 1.
    With ``early_holds`` the waits move back, the arrival stays 15 + sqrt 2: j leaves its start as
    late as it can and still pass x = 3 before robot 2 (2 + d <= 4 - sqrt 2: d = 2 - sqrt 2), waits
    just past that crossing at (4, 11) (reached at d + 3 = 5 - sqrt 2) and leaves it at
    10 + sqrt 2 - 7 = 3 + sqrt 2 (7 m to robot 1's crossing)."""
    from test_md_holds import GRID, SPECS

    # worked out with a place to wait at every cell (one-shot plans default to one every few cells)
    plan = get_planner("md", order="given", margin=0.0, early_holds=early, detours=0,
                       hold_step=GRID.resolution).plan(GRID, SPECS)
    assert check_plan(GRID, SPECS, plan) == []
    j = plan.by_id()["j"]
    assert j.arrival_time == pytest.approx(15 + math.sqrt(2))
    s2 = math.sqrt(2)
    if early:
        assert j.waypoints[:, :2].tolist() == [[1, 11], [1, 11], [4, 11], [4, 11], [16, 11]]
        assert j.waypoints[:, 2] == pytest.approx([0, 2 - s2, 5 - s2, 3 + s2, 15 + s2])
    else:
        assert j.waypoints[:, :2].tolist() == [[1, 11], [10, 11], [10, 11], [16, 11]]
        assert j.waypoints[:, 2] == pytest.approx([0, 9, 9 + s2, 15 + s2])


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(2, 12), crowded=st.booleans())
def test_every_plan_through_the_dense_solver_is_valid(seed, n, crowded):
    """Property (the checker as oracle) over md's two uses of the dense solver on the comb: every
    instance treated as crowded, or md's plan always compared with the dense one."""
    from fleet_planner.planners import md_crowd

    robots = _robots(n, seed)
    old = md_crowd.LANE_LOAD, md_crowd.MIN_ROBOTS
    md_crowd.LANE_LOAD, md_crowd.MIN_ROBOTS = (0.0 if crowded else old[0]), 0
    try:
        plan = get_planner("md", compare_above=1.0, time_limit=2.0).plan(COMB, robots)
    except PlanningError as err:
        assert err.failures and set(err.failures) <= {r.id for r in robots}
        return
    finally:
        md_crowd.LANE_LOAD, md_crowd.MIN_ROBOTS = old
    assert check_plan(COMB, robots, plan) == []
