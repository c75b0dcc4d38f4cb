"""PRIOR (prioritized SIPP): valid plans on small maps, waiting, blocked starts, incremental planning.

Every plan is checked by an exact pairwise check written here (so these tests stand alone) and,
where it exists, by the project's independent checker.
"""
import math
import random

import numpy as np
import pytest
import shapely

from fleet_planner.grid import GridMap
from fleet_planner.model import Plan, PlanningError, RobotSpec, TimedPath
from fleet_planner.planners import get_planner
from fleet_planner.planners.prior import PriorPlanner, _bad_departures


# ---------------------------------------------------------------------------------------------
# an exact validity check of our own
# ---------------------------------------------------------------------------------------------
def _position(wp: np.ndarray, t: float) -> np.ndarray:
    if t <= wp[0, 2]:
        return wp[0, :2]
    if t >= wp[-1, 2]:
        return wp[-1, :2]
    k = int(np.searchsorted(wp[:, 2], t, side="right")) - 1
    t0, t1 = wp[k, 2], wp[k + 1, 2]
    return wp[k, :2] + (t - t0) / (t1 - t0) * (wp[k + 1, :2] - wp[k, :2])


def _closest(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest distance of two trajectories over all time: both are linear between the merged
    breakpoints, so on each piece the closest approach has a closed form."""
    times = np.unique(np.concatenate([a[:, 2], b[:, 2]]))
    best = float(np.hypot(*(_position(a, times[0]) - _position(b, times[0]))))
    for t0, t1 in zip(times[:-1], times[1:]):
        d0 = _position(a, t0) - _position(b, t0)
        d1 = _position(a, t1) - _position(b, t1)
        v = d1 - d0
        s = 0.0 if not v.any() else min(max(-float(d0 @ v) / float(v @ v), 0.0), 1.0)
        best = min(best, float(np.hypot(*(d0 + s * v))))
    return best


def assert_valid(grid: GridMap, robots: list[RobotSpec], plan: Plan) -> None:
    paths = plan.by_id()
    assert set(paths) == {r.id for r in robots}
    for r in robots:
        wp = paths[r.id].waypoints
        assert np.allclose(wp[0, :2], r.start) and np.allclose(wp[-1, :2], r.goal), r.id
        assert wp[0, 2] >= 0 and np.all(np.diff(wp[:, 2]) >= 0), r.id
        dt, dl = np.diff(wp[:, 2]), np.hypot(*np.diff(wp[:, :2], axis=0).T)
        assert np.all(dl <= r.max_speed * dt * (1 + 1e-9) + 1e-9), f"{r.id} too fast"
        line = shapely.LineString(wp[:, :2]) if len(wp) > 1 else shapely.Point(wp[0, :2])
        assert shapely.distance(grid.obstacle_geometry, line) >= r.radius - 1e-9, f"{r.id} hits an obstacle"
    for i, a in enumerate(robots):
        for b in robots[i + 1:]:
            gap = _closest(paths[a.id].waypoints, paths[b.id].waypoints) - a.radius - b.radius
            assert gap >= -1e-9, f"{a.id} and {b.id} overlap by {-gap:.3g} m"
    try:
        from fleet_planner.checker import check_plan
    except ImportError:
        return
    assert check_plan(grid, robots, plan) == []


def solo_arrival(grid: GridMap, robot: RobotSpec) -> float:
    return PriorPlanner().plan(grid, [robot]).paths[0].arrival_time


# ---------------------------------------------------------------------------------------------
# behaviour
# ---------------------------------------------------------------------------------------------
POCKET = ["#########",
          "#.......#",
          "####.####",
          "#########"]


def test_swap_through_a_corridor_with_a_side_pocket():
    grid = GridMap.from_rows(POCKET)
    robots = [RobotSpec("a", 0.4, 1.0, grid.centre(1, 1), grid.centre(7, 1)),
              RobotSpec("b", 0.4, 1.0, grid.centre(7, 1), grid.centre(1, 1))]
    plan = get_planner("prior").plan(grid, robots)
    assert plan.planner == "prior"
    assert_valid(grid, robots, plan)
    # one of them must have stepped into the pocket to let the other pass
    visited = np.vstack([p.waypoints[:, :2] for p in plan.paths])
    assert np.any(np.all(np.isclose(visited, grid.centre(4, 2)), axis=1))


def test_the_lower_robot_waits_at_a_crossing():
    grid = GridMap.from_rows(["###.###",
                              "###.###",
                              ".......",
                              "###.###",
                              "###.###"])
    a = RobotSpec("a", 0.4, 1.0, grid.centre(2, 2), grid.centre(6, 2))
    b = RobotSpec("b", 0.4, 1.0, grid.centre(3, 1), grid.centre(3, 4))
    plan = PriorPlanner().plan(grid, [a, b])
    assert_valid(grid, [a, b], plan)
    paths = plan.by_id()
    assert paths["a"].arrival_time == pytest.approx(solo_arrival(grid, a))   # the first one is not disturbed
    assert paths["b"].start_time > PriorPlanner().plan(grid, [b]).paths[0].start_time + 1.0
    assert paths["b"].arrival_time > solo_arrival(grid, b) + 1.0


BRANCH = ["........",
          "####.###"]


def test_a_start_in_the_only_way_fails_without_reordering():
    grid = GridMap.from_rows(BRANCH)
    robots = [RobotSpec("a", 0.4, 1.0, grid.centre(0, 0), grid.centre(7, 0)),
              RobotSpec("c", 0.4, 1.0, grid.centre(5, 0), grid.centre(4, 1))]
    with pytest.raises(PlanningError) as err:
        PriorPlanner(max_reorders=0).plan(grid, robots)
    assert set(err.value.failures) == {"a"}
    assert "'c'" in err.value.failures["a"] and "start" in err.value.failures["a"]
    assert err.value.blockers == {"a": "c"}


def test_a_start_in_the_only_way_is_left_in_time_with_reordering():
    grid = GridMap.from_rows(BRANCH)
    robots = [RobotSpec("a", 0.4, 1.0, grid.centre(0, 0), grid.centre(7, 0)),
              RobotSpec("c", 0.4, 1.0, grid.centre(5, 0), grid.centre(4, 1))]
    plan = PriorPlanner().plan(grid, robots)
    assert_valid(grid, robots, plan)
    assert plan.info["reorders"] >= 1


def test_a_robot_staying_put_steps_aside_and_comes_back():
    grid = GridMap.from_rows(BRANCH)
    robots = [RobotSpec("a", 0.4, 1.0, grid.centre(0, 0), grid.centre(7, 0)),
              RobotSpec("idle", 0.4, 1.0, grid.centre(5, 0), grid.centre(5, 0))]
    plan = PriorPlanner().plan(grid, robots)
    assert_valid(grid, robots, plan)
    idle = plan.by_id()["idle"].waypoints
    assert np.any(np.all(np.isclose(idle[:, :2], grid.centre(4, 1)), axis=1))


def test_no_way_at_all_names_the_robot_and_the_reason():
    grid = GridMap.from_rows(["...#...."])
    robots = [RobotSpec("a", 0.4, 1.0, grid.centre(0, 0), grid.centre(6, 0))]
    with pytest.raises(PlanningError) as err:
        PriorPlanner().plan(grid, robots)
    assert "no way from start to goal" in err.value.failures["a"]


def test_overlapping_starts_are_rejected():
    grid = GridMap.from_rows(["....."])
    robots = [RobotSpec("a", 0.4, 1.0, (0.5, 0.5), (4.5, 0.5)),
              RobotSpec("b", 0.4, 1.0, (1.1, 0.5), (3.5, 0.5))]
    with pytest.raises(PlanningError) as err:
        PriorPlanner().plan(grid, robots)
    assert "overlaps the start of robot 'b'" in err.value.failures["a"]


def _random_robots(grid: GridMap, n: int, seed: int, radii=(0.3, 0.45), speeds=(0.5, 1.2)):
    rng = random.Random(seed)
    free = [(c, r) for r in range(grid.height) for c in range(grid.width) if not grid.blocked[r, c]]
    starts, goals = rng.sample(free, n), rng.sample(free, n)
    return [RobotSpec(f"r{k}", rng.uniform(*radii), rng.uniform(*speeds), grid.centre(*s), grid.centre(*g))
            for k, (s, g) in enumerate(zip(starts, goals))]


def test_twenty_random_robots_on_an_open_map():
    grid = GridMap.from_rows(["." * 20] * 20)
    robots = _random_robots(grid, 20, seed=3)
    calls = []
    plan = PriorPlanner().plan(grid, robots, progress=lambda done, total, what: calls.append((done, total)))
    assert_valid(grid, robots, plan)
    assert calls[-1] == (20, 20)
    # straight runs are one segment, not one per cell
    assert max(len(p.waypoints) for p in plan.paths) < 20


def test_off_centre_starts_and_goals_and_the_order_options():
    grid = GridMap.from_rows(["......", "..##..", "......"])
    robots = [RobotSpec("a", 0.35, 0.9, (0.4, 0.6), (5.3, 2.6)),
              RobotSpec("b", 0.3, 0.6, (5.5, 0.45), (0.62, 2.5))]
    for order in ("given", "shortest", "longest"):
        assert_valid(grid, robots, PriorPlanner(order=order).plan(grid, robots))


def _from(path: TimedPath, t0: float) -> TimedPath:
    """The part of a trajectory from t0 on (standing where it is at t0 until then)."""
    wp = path.waypoints
    later = wp[wp[:, 2] > t0]
    return TimedPath(path.robot_id, path.radius, np.vstack([[*path.position(t0), t0], later]))


def test_incremental_planning_around_fixed_trajectories():
    grid = GridMap.from_rows(["." * 12] * 8)
    first = _random_robots(grid, 6, seed=5)
    planner = PriorPlanner()
    plan = planner.plan(grid, first)
    t0 = 4.0
    # three more robots appear at t0 on cells clear of everyone at t0 and of every goal
    taken = [np.array(p.position(t0)) for p in plan.paths] + [np.array(r.goal) for r in first]
    spare = [(c, r) for r in range(8) for c in range(12)
             if min(np.hypot(*(np.array(grid.centre(c, r)) - q)) for q in taken) > 1.0]
    cells = random.Random(1).sample(spare, 6)
    new = [RobotSpec(f"n{k}", 0.4, 0.8, grid.centre(*cells[k]), grid.centre(*cells[k + 3])) for k in range(3)]
    paths = planner.plan_incremental(grid, new, plan.paths, t0)
    assert [p.robot_id for p in paths] == ["n0", "n1", "n2"]
    assert all(p.waypoints[0, 2] == pytest.approx(t0) for p in paths)
    # everything from t0 on, the fixed robots starting where they are at t0
    fixed = [_from(p, t0) for p in plan.paths]
    specs = [RobotSpec(r.id, r.radius, r.max_speed, tuple(f.waypoints[0, :2]), r.goal) for r, f in zip(first, fixed)]
    assert_valid(grid, specs + new, Plan("prior", fixed + paths))


def test_incremental_rejects_a_robot_standing_in_a_fixed_robots_way():
    grid = GridMap.from_rows(["......"])
    fixed = [TimedPath("f", 0.4, np.array([[0.5, 0.5, 0.0], [5.5, 0.5, 5.0]]))]
    new = [RobotSpec("n", 0.4, 1.0, (2.5, 0.5), (3.5, 0.5))]
    with pytest.raises(PlanningError) as err:
        PriorPlanner().plan_incremental(grid, new, fixed, 2.0)
    assert "'f'" in err.value.failures["n"]


def test_incremental_names_a_fixed_robot_parked_in_the_only_way():
    grid = GridMap.from_rows(["......"])
    fixed = [TimedPath("f", 0.4, np.array([[3.5, 0.5, 0.0]]))]   # standing, for ever
    new = [RobotSpec("n", 0.4, 1.0, (0.5, 0.5), (5.5, 0.5))]
    with pytest.raises(PlanningError) as err:
        PriorPlanner().plan_incremental(grid, new, fixed, 1.0)
    assert "'f' parked" in err.value.failures["n"] and err.value.blockers == {"n": "f"}


def test_bad_options_are_named():
    with pytest.raises(ValueError, match="order"):
        PriorPlanner(order="random")
    with pytest.raises(ValueError, match="max_wait_s"):
        PriorPlanner(max_wait_s=0)


# ---------------------------------------------------------------------------------------------
# the geometry the search relies on
# ---------------------------------------------------------------------------------------------
def test_bad_departure_interval_matches_sampling():
    """Departure times at which a move comes within reach of a linear piece form one open
    interval; compare with a dense sampling of the distance."""
    rng = random.Random(7)
    for _ in range(300):
        ax, ay, d = rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(0.5, 2)
        ang = rng.choice([0.0, math.pi / 2, rng.uniform(0, 2 * math.pi)])
        wx, wy = math.cos(ang), math.sin(ang)
        ta = rng.uniform(-2, 4)
        tb = ta + rng.uniform(0.1, 3)
        v = rng.choice([0.0, 1.0, rng.uniform(0.3, 1.5)])
        ang2 = rng.choice([ang, ang + math.pi, rng.uniform(0, 2 * math.pi)])
        piece = (ta, tb, rng.uniform(-2, 2), rng.uniform(-2, 2), v * math.cos(ang2), v * math.sin(ang2), 0)
        reach = rng.uniform(0.5, 1.2)
        bad = _bad_departures(ax, ay, wx, wy, d, piece, reach)
        for tau in np.linspace(-6, 9, 151):
            lo, hi = max(tau, ta), min(tau + d, tb)
            if lo > hi:
                continue
            t = np.linspace(lo, hi, 801)
            me = np.column_stack([ax + wx * (t - tau), ay + wy * (t - tau)])
            other = np.column_stack([piece[2] + piece[4] * (t - ta), piece[3] + piece[5] * (t - ta)])
            dist = float(np.min(np.hypot(*(me - other).T)))
            inside = bad is not None and bad[0] < tau < bad[1]
            assert not (dist < reach - 1e-3 and not inside), (piece, tau, dist, bad)
            assert not (dist > reach + 1e-3 and inside), (piece, tau, dist, bad)
