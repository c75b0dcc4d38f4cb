"""The crowd planner (issue 11): LaCAM/PIBT over configurations, timed by precedence for discs.

The independent checker is the oracle of every case."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleet_planner.checker import check_plan, min_separation
from fleet_planner.grid import GridMap
from fleet_planner.model import Plan, PlanningError, RobotSpec, TimedPath
from fleet_planner.planners import get_planner
from fleet_planner.planners.crowd import CrowdPlanner
from fleet_planner.planners.crowd_lns import Refiner, prioritized_first
from fleet_planner.planners.crowd_pibt import CellGraph, ConfigSearch, _valid_step, remove_loops
from fleet_planner.planners.crowd_st import arrival_steps
from fleet_planner.planners.crowd_timing import time_moves

# a 1-cell aisle with one side pocket; two robots each way must pass each other
POCKET = ["@@@.@@@", "......."]
POCKET_ROBOTS = [RobotSpec("a", 0.40, 1.0, (0.5, 1.5), (6.5, 1.5)), RobotSpec("b", 0.45, 0.7, (6.5, 1.5), (0.5, 1.5)),
                 RobotSpec("c", 0.35, 0.8, (1.5, 1.5), (5.5, 1.5)), RobotSpec("d", 0.35, 0.9, (5.5, 1.5), (1.5, 1.5))]


def test_a_dense_aisle_that_prioritized_planning_refuses_is_solved():
    """Two robots each way in a 1-cell aisle with one side pocket: robots must step aside into the
    pocket and back, which no priority order can ask for (PRIOR fails in all 24 orders, md too)."""
    grid = GridMap.from_rows(POCKET)
    with pytest.raises(PlanningError):   # md v2 without its dense fallback (which is crowd)
        get_planner("md", fallback=None).plan(grid, POCKET_ROBOTS)
    for order in itertools.permutations(POCKET_ROBOTS):
        with pytest.raises(PlanningError):
            get_planner("prior", order="given", max_reorders=0, time_limit_s=5.0).plan(grid, list(order))
    plan = get_planner("crowd").plan(grid, POCKET_ROBOTS)
    assert plan.planner == "dense" and plan.info["solver"].startswith("dense")
    assert plan.info["first_plan"] == "lacam"     # its own prioritized first plan failed too
    assert check_plan(grid, POCKET_ROBOTS, plan) == []
    # somebody stepped aside into the pocket
    assert any(np.any(np.isclose(p.waypoints[:, 1], 0.5)) for p in plan.paths)
    # the plan's network: every link keeps the order of the discrete plan - the later robot enters
    # no earlier than the earlier one starts to leave (D <= the leader's move time; D > 0 only for a
    # robot following in the same direction)
    assert plan.network is not None and plan.network.links
    speed = {r.id: r.max_speed for r in POCKET_ROBOTS}
    assert all(link.D <= 1.0 / speed[link.i] + 1e-9 for link in plan.network.links)


@pytest.mark.parametrize("v_j", [1.0, 0.5])
def test_the_corner_case_point_agents_collide_our_discs_do_not(v_j):
    """j turns out of the cell B that i enters in the same step: driven in lock-step (what a
    point-agent MAPF plan means) the centres come 0.707 m close against r_i + r_j = 0.8 m. The
    precedence pass lets i start once j is far enough round the corner: with j a = (t - S_j) v_j
    along its way out and i b = t v_i along its way in (cells of 1 m, B at the origin), their gap
    is |(a, 1 - b)|, a line in t whose distance from the origin is (a0 v_i + v_j) / |(v_j, v_i)| for
    j's progress a0 when i starts; so i starts at a0 = (0.8 |(v_j, v_i)| - v_j) / v_i, and the two
    then touch exactly once (never closer)."""
    grid = GridMap.from_rows(["..", ".."])
    a, b, c = (0.5, 1.5), (1.5, 1.5), (1.5, 0.5)     # i: A -> B, j: B -> C (a right-angle turn)
    robots = [RobotSpec("i", 0.4, 1.0, a, b), RobotSpec("j", 0.4, v_j, b, c)]
    graph = CellGraph(grid, 0.4)
    starts, goals = [graph.cell(*a), graph.cell(*b)], [graph.cell(*b), graph.cell(*c)]
    configs = ConfigSearch(graph, starts, goals).solve(float("inf"))
    assert configs == [tuple(starts), tuple(goals)]   # one step: i follows j round the corner
    lockstep = Plan("points", [TimedPath("i", 0.4, [[*a, 0.0], [*b, 1.0]]),
                               TimedPath("j", 0.4, [[*b, 0.0], [*c, 1.0 / v_j]])])
    assert [v.kind for v in check_plan(grid, robots, lockstep)] == ["collision"]
    plan = CrowdPlanner(margin=0.0).plan(grid, robots)
    assert check_plan(grid, robots, plan) == []
    i, j = plan.by_id()["i"], plan.by_id()["j"]
    assert j.start_time == 0.0 and j.arrival_time == pytest.approx(1.0 / v_j)
    a0 = (0.8 * np.hypot(v_j, 1.0) - v_j) / 1.0       # 0.1314 of j's move at 1 m/s, 0.3944 at 0.5 m/s
    assert i.start_time == pytest.approx(a0 / v_j, abs=1e-5)            # 0.131 s, 0.789 s
    assert i.arrival_time == pytest.approx(a0 / v_j + 1.0, abs=1e-5)
    assert i.start_time < j.arrival_time                                 # no waiting for j's arrival
    gap = min_separation(plan.paths)[0]
    assert 0.0 <= gap < 1e-4                                            # they touch, never overlap
    # one step earlier and they would overlap: the rule is tight
    early = Plan("early", [TimedPath("i", 0.4, [[*a, i.start_time - 0.01], [*b, i.arrival_time - 0.01]]), j])
    assert [v.kind for v in check_plan(grid, robots, early)] == ["collision"]
    # with the default margin (0.02 m) the follower starts later and they never touch
    kept = CrowdPlanner().plan(grid, robots)
    assert kept.by_id()["i"].start_time > i.start_time
    assert min_separation(kept.paths)[0] == pytest.approx(0.02, abs=1e-4)


def test_trains_follow_and_collinear_moves_are_merged():
    grid = GridMap.from_rows(["." * 8])
    robots = [RobotSpec(f"r{k}", 0.45, 1.0, (k + 0.5, 0.5), (k + 4.5, 0.5)) for k in range(3)]
    plan = CrowdPlanner().plan(grid, robots)
    assert check_plan(grid, robots, plan) == []
    lead = plan.by_id()["r2"]
    assert lead.waypoints.tolist() == [[2.5, 0.5, 0.0], [6.5, 0.5, 4.0]]   # one straight segment
    assert all(p.arrival_time <= 6.0 + 1e-9 for p in plan.paths)


def test_timing_keeps_each_cell_order_and_own_speed():
    # two robots, one cell 0 -> 1 -> 2 in a row: r0 from 1 to 2, r1 from 0 to 1 (follows)
    configs = np.array([[1, 0], [2, 1]])
    timing = time_moves(configs, [2.0, 1.0])
    assert timing.start.tolist() == [0.0, 2.0] and timing.end.tolist() == [2.0, 3.0]
    assert timing.visits == [(0, 1)]
    # following in the same direction: the follower (1 m/s) may start once the slow leader (0.5 m/s)
    # starts 2 - 0.8 m before the leader arrives
    centres = np.array([[0.5, 0.5], [1.5, 0.5], [2.5, 0.5]])
    close = time_moves(configs, [2.0, 1.0], centres, [0.4, 0.4], 1.0)
    assert close.start.tolist() == pytest.approx([0.0, 0.8], abs=1e-5)
    grid = GridMap.from_rows(["..."])
    robots = [RobotSpec("r0", 0.4, 0.5, (1.5, 0.5), (2.5, 0.5)), RobotSpec("r1", 0.4, 1.0, (0.5, 0.5), (1.5, 0.5))]
    paths = [TimedPath("r0", 0.4, [[1.5, 0.5, 0.0], [2.5, 0.5, 2.0]]),
             TimedPath("r1", 0.4, [[0.5, 0.5, 0.8], [1.5, 0.5, 1.8]])]
    assert check_plan(grid, robots, Plan("by-hand", paths)) == []
    assert 0.0 <= min_separation(paths)[0] < 0.2   # close behind, never touching


def test_detours_are_cut_where_nobody_else_needs_the_cell():
    # r0 goes 5 -> 6 -> 5 -> 4; r1 passes through 6 meanwhile, nobody through 5
    configs = np.array([[5, 7], [6, 8], [5, 9], [4, 9]])
    assert remove_loops(configs)[:, 0].tolist() == [5, 5, 5, 4]
    # r1 uses 5 while r0 is away: r0's detour stays (r1's own 4 -> 5 -> 4 is cut: 4 stays free)
    busy = np.array([[5, 4], [6, 5], [5, 4], [4, 3]])
    assert remove_loops(busy).tolist() == [[5, 4], [6, 4], [5, 4], [4, 3]]


def test_no_rings_of_followers():
    # four robots round a 2x2 block, each into the next one's cell: a rotation
    assert not _valid_step([0, 1, 3, 2], [1, 3, 2, 0], _occ([0, 1, 3, 2], 4))
    assert _valid_step([0, 1], [1, 3], _occ([0, 1], 4))   # a chain is fine


def _occ(config, n):
    occ = [-1] * n
    for i, v in enumerate(config):
        occ[v] = i
    return occ


def test_refinement_keeps_the_rules_and_never_lengthens_the_plan():
    """LNS on a crowded room (20 robots on 44 cells): every step of the refined plan still obeys
    the transition rules, every robot ends on its goal and stays there, and the weighted sum of
    arrivals did not grow (here it shrinks)."""
    grid = GridMap.from_rows(["........", "..@..@..", "........", "..@..@..", "........", "........"])
    graph = CellGraph(grid, 0.45)
    rng = np.random.default_rng(3)
    starts, goals = rng.permutation(graph.n)[:20].tolist(), rng.permutation(graph.n)[:20].tolist()
    search = ConfigSearch(graph, starts, goals, seed=1)
    first = search.solve_array(float("inf"))
    weights = rng.uniform(1.0, 1.43, 20)
    ref = Refiner(graph, search.fields, search.grow, search.goals, first, weights, seed=2)
    before = ref.weighted_cost()
    ref.run(float("inf"), max_iterations=300)
    after = ref.configs()
    assert ref.iterations > 0 and ref.weighted_cost() <= before
    assert ref.weighted_cost() < before            # this instance has room to improve
    assert after[0].tolist() == starts and after[-1].tolist() == goals
    for q_from, q_to in zip(after[:-1], after[1:]):
        assert _valid_step(q_from.tolist(), q_to.tolist(), _occ(q_from.tolist(), graph.n))
    cost = ref.cost
    for i in range(20):
        assert np.all(after[cost[i]:, i] == goals[i]) and (cost[i] == 0 or after[cost[i] - 1, i] != goals[i])
    # and the timed plan of the refined steps is valid for discs
    robots = [RobotSpec(f"r{i}", 0.45 - 0.1 * (i % 2), 1.0 / weights[i], graph.centre(starts[i]),
                        graph.centre(goals[i])) for i in range(20)]
    plan = CrowdPlanner(refine_s=0.5).plan(grid, robots)
    assert check_plan(grid, robots, plan) == [] and plan.info["lns_iterations"] > 0


def test_the_dense_solver_by_name_with_its_options():
    grid = GridMap.from_rows(POCKET)
    plan = get_planner("dense").plan(grid, POCKET_ROBOTS)
    assert plan.planner == "dense" and "LaCAM" in plan.info["solver"]
    assert check_plan(grid, POCKET_ROBOTS, plan) == []
    quick = get_planner("dense", time_limit=5.0, refine_s=0.0).plan(grid, POCKET_ROBOTS)
    assert "lns_iterations" not in quick.info and check_plan(grid, POCKET_ROBOTS, quick) == []
    assert type(get_planner("crowd")) is type(get_planner("dense"))
    with pytest.raises(ValueError, match="time_limit"):
        get_planner("dense", time_limit=0.0)


def test_refusals_name_the_robots():
    grid = GridMap.from_rows(["....", "...."])
    with pytest.raises(PlanningError, match="r_i \\+ r_j <= the cell step"):
        CrowdPlanner().plan(grid, [RobotSpec("a", 0.6, 1.0, (0.5, 0.5), (3.5, 0.5)),
                                   RobotSpec("b", 0.45, 1.0, (0.5, 1.5), (3.5, 1.5))])
    with pytest.raises(PlanningError, match="not the centre of a free cell") as err:
        CrowdPlanner().plan(grid, [RobotSpec("a", 0.4, 1.0, (0.7, 0.5), (3.5, 0.5))])
    assert set(err.value.failures) == {"a"}
    walled = GridMap.from_rows([".@.."])
    with pytest.raises(PlanningError, match="cannot be reached"):
        CrowdPlanner().plan(walled, [RobotSpec("a", 0.4, 1.0, (0.5, 0.5), (3.5, 0.5))])
    swap = GridMap.from_rows(["...."])
    with pytest.raises(PlanningError, match="no plan exists"):
        CrowdPlanner().plan(swap, [RobotSpec("a", 0.4, 1.0, (0.5, 0.5), (3.5, 0.5)),
                                   RobotSpec("b", 0.4, 1.0, (3.5, 0.5), (0.5, 0.5))])


def test_a_leg_around_a_driven_trajectory():
    grid = GridMap.from_rows(["." * 8] * 3)
    planner = get_planner("crowd")
    first = planner.plan(grid, [RobotSpec("a", 0.4, 1.0, (0.5, 1.5), (7.5, 1.5))])
    leg = planner.plan_incremental(grid, [RobotSpec("b", 0.4, 1.0, (7.5, 0.5), (0.5, 0.5))], first.paths, 1.0)
    assert tuple(leg[0].waypoints[0]) == (7.5, 0.5, 1.0)
    assert min_separation(first.paths + leg)[0] >= -1e-6


@st.composite
def crowds(draw):
    w, h = draw(st.integers(4, 8)), draw(st.integers(3, 7))
    density = draw(st.sampled_from([0.0, 0.15, 0.3]))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    blocked = rng.random((h, w)) < density
    free = [(c, r) for r in range(h) for c in range(w) if not blocked[r, c]]
    crowd = draw(st.floats(0.25, 0.5))   # a quarter to half of the free cells hold a robot
    n = max(2, min(12, int(crowd * len(free))))
    grid = GridMap(blocked, 1.0, "crowd")
    if len(free) < n:
        return grid, []
    starts, goals = rng.permutation(len(free))[:n], rng.permutation(len(free))[:n]
    accel = draw(st.sampled_from([None, 0.5]))   # instant speed changes, or trapezoids
    robots = [RobotSpec(f"r{k}", float(rng.uniform(0.35, 0.45)), float(rng.uniform(0.7, 1.0)),
                        grid.centre(*free[starts[k]]), grid.centre(*free[goals[k]]),
                        max_accel=None if accel is None else float(rng.uniform(0.3, 1.0)))
              for k in range(n)]
    return grid, robots


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=crowds(), first=st.sampled_from(["auto", "discrete", "lacam"]))
def test_every_crowd_plan_is_valid(case, first):
    """Dense random crowds (2-12 discs of mixed radii and speeds, some with acceleration limits, on a
    quarter to half of the free cells, goals a random permutation, so robots must pass each other):
    a plan is valid by the checker, or a refusal names robots."""
    grid, robots = case
    try:
        plan = CrowdPlanner(time_limit_s=2.0, first=first).plan(grid, robots)
    except PlanningError as err:
        assert err.failures and set(err.failures) <= {r.id for r in robots}
        return
    assert check_plan(grid, robots, plan) == []


def test_acceleration_limits_give_trapezoids_and_stops_only_at_run_ends():
    """A robot with max_accel drives each straight run from standstill to standstill: 0.5 m/s^2 and
    1 m/s over 4 cells of 1 m ramp up over the first cell (2 s), cruise 2 cells (2 s, one merged
    segment) and brake over the last (2 s): 6 s instead of 4 s. In a crowd with accelerations the
    plan stays valid, and every hold follows a braking piece (no stop from cruise speed)."""
    grid = GridMap.from_rows(["." * 5])
    alone = [RobotSpec("a", 0.4, 1.0, (0.5, 0.5), (4.5, 0.5), max_accel=0.5)]
    plan = CrowdPlanner().plan(grid, alone)
    assert np.allclose(plan.paths[0].waypoints, [[0.5, 0.5, 0.0], [1.5, 0.5, 2.0], [3.5, 0.5, 4.0], [4.5, 0.5, 6.0]])
    assert check_plan(grid, alone, plan) == []
    crowd_grid = GridMap.from_rows(POCKET)
    robots = [RobotSpec(r.id, r.radius, r.max_speed, r.start, r.goal, max_accel=0.6) for r in POCKET_ROBOTS]
    plan = CrowdPlanner().plan(crowd_grid, robots)
    assert check_plan(crowd_grid, robots, plan) == []
    holds = 0
    for path, r in zip(plan.paths, robots):
        wp = path.waypoints
        speed = np.hypot(*np.diff(wp[:, :2], axis=0).T) / np.maximum(np.diff(wp[:, 2]), 1e-12)
        for k in range(1, len(speed) - 1):
            if speed[k] == 0.0:          # a hold: the piece before it brakes, the piece after it ramps up
                holds += 1
                # (0.6 m/s^2 brakes from top speed within 0.83 m: the cell before a stop is slower)
                assert speed[k - 1] < r.max_speed - 0.05 and speed[k + 1] < r.max_speed - 0.05
    assert holds > 0


def test_the_prioritized_first_plan_keeps_the_rules_and_gives_way_to_lacam_where_it_fails():
    """The first discrete plan by prioritized planning: every step obeys the transition rules (no
    vertex or swap conflicts, no rings), each robot ends on its goal, with a weighted sum of
    arrivals no longer than LaCAM's plan here; where no priority order works (the pocket aisle) it
    answers None and the planner says the configuration search planned."""
    grid = GridMap.from_rows(["........", "..@@.@..", "........", ".@..@@..", "........"])
    free = [(c, r) for r in range(5) for c in range(8) if not grid.blocked[r, c]]
    rng = np.random.default_rng(4)
    s, g = rng.permutation(len(free))[:10], rng.permutation(len(free))[:10]
    robots = [RobotSpec(f"r{k}", 0.4, float(rng.uniform(0.7, 1.0)), grid.centre(*free[s[k]]), grid.centre(*free[g[k]]))
              for k in range(10)]
    graph = CellGraph(grid, 0.4)
    starts = [graph.cell(*r.start) for r in robots]
    search = ConfigSearch(graph, starts, [graph.cell(*r.goal) for r in robots])
    weights = np.array([1.0 / r.max_speed for r in robots])
    configs = prioritized_first(graph, search.fields, search.grow, starts, search.goals, weights)
    assert configs is not None
    assert list(configs[0]) == starts and list(configs[-1]) == list(search.goals)
    for a, b in zip(configs[:-1], configs[1:]):
        assert len(set(b.tolist())) == len(b) and _valid_step(a.tolist(), b.tolist(), _occ(a, graph.n))
    lacam = search.solve_array(float("inf"))
    def weighted(c):
        return float(weights @ arrival_steps(c, search.goals))
    assert weighted(configs) <= weighted(lacam)
    plan = CrowdPlanner(first="discrete").plan(grid, robots)
    assert plan.info["first_plan"] == "prioritized" and check_plan(grid, robots, plan) == []

    pocket = GridMap.from_rows(POCKET)
    graph = CellGraph(pocket, 0.45)
    starts = [graph.cell(*r.start) for r in POCKET_ROBOTS]
    search = ConfigSearch(graph, starts, [graph.cell(*r.goal) for r in POCKET_ROBOTS])
    assert prioritized_first(graph, search.fields, search.grow, starts, search.goals, np.ones(4)) is None


def test_a_cutoff_below_the_lower_bound_gives_up_at_once_and_a_bad_one_is_named():
    """``cutoff``: the robots' hop distances at top speed bound any plan's sum of arrivals from
    below (a: 6 cells at 1.0, b: 6 at 0.7, c: 4 at 0.8, d: 4 at 0.9 = 24.02 s): asked to beat 24 s
    the solver gives up at once; asked to beat its own plan's sum plus a second it plans as before."""
    from fleet_planner.planners.md_crowd import sum_of_arrivals

    grid = GridMap.from_rows(POCKET)
    with pytest.raises(PlanningError, match="cutoff 24.0 s"):
        get_planner("dense", cutoff=24.0).plan(grid, POCKET_ROBOTS)
    plan = get_planner("dense").plan(grid, POCKET_ROBOTS)
    assert sum_of_arrivals(plan) >= 6 + 6 / 0.7 + 4 / 0.8 + 4 / 0.9 - 1e-9
    again = get_planner("dense", cutoff=sum_of_arrivals(plan) + 1.0).plan(grid, POCKET_ROBOTS)
    assert check_plan(grid, POCKET_ROBOTS, again) == []
    for bad in (float("nan"), "1", float("inf")):
        with pytest.raises(ValueError, match="cutoff"):
            get_planner("dense", cutoff=bad)
