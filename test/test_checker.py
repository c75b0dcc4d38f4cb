"""The independent checker, on trajectories whose answer is worked out by hand in each docstring."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fleet_planner import checker
from fleet_planner.checker import check_plan, min_separation
from fleet_planner.grid import GridMap
from fleet_planner.model import Plan, RobotSpec, TimedPath, timed_path_from_polyline

OPEN = GridMap(np.zeros((12, 12), dtype=bool))  # 12 m x 12 m, nothing in the way


def robot(rid, start, goal, radius=0.4, speed=1.0):
    return RobotSpec(rid, radius, speed, start, goal)


def drive(spec, *via, departure=0.0):
    """``spec`` driving start -> via... -> goal at its top speed after waiting ``departure``."""
    return timed_path_from_polyline(spec.id, spec.radius, [spec.start, *via, spec.goal], spec.max_speed, departure)


def kinds(violations):
    return sorted(v.kind for v in violations)


def only(violations, kind):
    found = [v for v in violations if v.kind == kind]
    assert len(found) == 1, violations
    return found[0]


# ---------------------------------------------------------------------------------------------
# collisions
# ---------------------------------------------------------------------------------------------
def test_head_on_on_a_line():
    """Centres 10 m apart closing at 2 m/s: contact (0.8 m) at t = 4.6, centres meet at t = 5."""
    a, b = robot("a", (1.5, 2.5), (11.5, 2.5)), robot("b", (11.5, 2.5), (1.5, 2.5))
    v = only(check_plan(OPEN, [a, b], Plan("t", [drive(a), drive(b)])), "collision")
    assert set(v.robots) == {"a", "b"}
    assert v.time == pytest.approx(4.6)
    assert "closest distance 0 m" in v.detail and "t=5 s" in v.detail


def test_right_angle_crossing_collides_without_delay():
    """a at (1.5 + t, 2.5), b at (5.5, 6.5 - t): distance sqrt(2)|t - 4|, contact at 4 - 0.4 sqrt(2)."""
    a, b = robot("a", (1.5, 2.5), (9.5, 2.5)), robot("b", (5.5, 6.5), (5.5, 0.5))
    v = only(check_plan(OPEN, [a, b], Plan("t", [drive(a), drive(b)])), "collision")
    assert v.time == pytest.approx(4 - 0.4 * math.sqrt(2))
    gap, *_ = min_separation([drive(a), drive(b)])
    assert gap == pytest.approx(-0.8)


@pytest.mark.parametrize("delay, valid", [(1.2, True), (1.0, False)])
def test_right_angle_crossing_with_a_delay(delay, valid):
    """b delayed by D: closest at t = 4 + D/2, distance D / sqrt(2); valid iff D >= 0.8 sqrt(2) = 1.131."""
    a, b = robot("a", (1.5, 2.5), (9.5, 2.5)), robot("b", (5.5, 6.5), (5.5, 0.5))
    paths = [drive(a), drive(b, departure=delay)]
    assert (check_plan(OPEN, [a, b], Plan("t", paths)) == []) == valid
    gap, ida, idb, t = min_separation(paths)
    assert {ida, idb} == {"a", "b"}
    assert gap == pytest.approx(delay / math.sqrt(2) - 0.8)
    assert t == pytest.approx(4 + delay / 2)


def test_robot_parked_at_its_goal_is_hit_by_a_later_robot():
    """a parks on (3.5, 2.5) from t = 2; b comes down x = 3.5 and is 0.8 m from it at t = 3.2."""
    a, b = robot("a", (1.5, 2.5), (3.5, 2.5)), robot("b", (3.5, 6.5), (3.5, 0.5))
    v = only(check_plan(OPEN, [a, b], Plan("t", [drive(a), drive(b, departure=0.0)])), "collision")
    assert v.time == pytest.approx(3.2)
    assert "t=4 s" in v.detail  # the closest moment: b passing over a's centre


def test_robot_parked_at_its_start_until_its_first_waypoint_time():
    """a's first waypoint has t = 10, so a sits on (5.5, 2.5) until then; b passes x = 5.5 at t = 4."""
    a, b = robot("a", (5.5, 2.5), (5.5, 8.5)), robot("b", (1.5, 2.5), (9.5, 2.5))
    late_a = TimedPath("a", 0.4, [[5.5, 2.5, 10.0], [5.5, 8.5, 16.0]])
    v = only(check_plan(OPEN, [a, b], Plan("t", [late_a, drive(b)])), "collision")
    assert v.time == pytest.approx(3.2)
    # the same robot leaving at t = 0 is long gone: a is at y >= 6.5 when b passes
    assert check_plan(OPEN, [a, b], Plan("t", [drive(a), drive(b)])) == []


def test_overlapping_from_the_start_is_reported_at_t0():
    a, b = robot("a", (2.0, 2.5), (2.0, 8.5)), robot("b", (2.5, 2.5), (9.5, 2.5))
    v = only(check_plan(OPEN, [a, b], Plan("t", [drive(a, departure=3.0), drive(b, departure=5.0)])), "collision")
    assert v.time == 0.0


def test_grazing_contact_is_valid_and_a_hair_closer_is_not():
    """Delay 0.8 sqrt(2) makes the closest distance exactly r_a + r_b; 2 mm less overlaps."""
    a, b = robot("a", (1.5, 2.5), (9.5, 2.5)), robot("b", (5.5, 6.5), (5.5, 0.5))
    touching = 0.8 * math.sqrt(2)
    assert check_plan(OPEN, [a, b], Plan("t", [drive(a), drive(b, departure=touching)])) == []
    near = check_plan(OPEN, [a, b], Plan("t", [drive(a), drive(b, departure=touching - 0.002)]))
    assert kinds(near) == ["collision"]
    # side by side at exactly 0.8 m for the whole run
    c, d = robot("c", (1.5, 2.5), (9.5, 2.5)), robot("d", (1.5, 3.3), (9.5, 3.3))
    assert check_plan(OPEN, [c, d], Plan("t", [drive(c), drive(d)])) == []


def test_following_at_a_safe_distance_is_valid():
    """Same lane, same speed, b 1 m behind a: never closer than 1 m > 0.8 m."""
    a, b = robot("a", (2.5, 2.5), (10.5, 2.5)), robot("b", (1.5, 2.5), (9.5, 2.5))
    assert check_plan(OPEN, [a, b], Plan("t", [drive(a), drive(b)])) == []
    assert min_separation([drive(a), drive(b)])[0] == pytest.approx(0.2)


def test_a_jump_in_zero_time_sweeps_its_segment():
    """b jumps from x = 1.5 to x = 9.5 at t = 2 across a parked a: too fast and through a."""
    a, b = robot("a", (5.5, 2.5), (5.5, 2.5)), robot("b", (1.5, 2.5), (9.5, 2.5))
    jump = TimedPath("b", 0.4, [[1.5, 2.5, 0.0], [1.5, 2.5, 2.0], [9.5, 2.5, 2.0]])
    found = check_plan(OPEN, [a, b], Plan("t", [drive(a), jump]))
    assert kinds(found) == ["collision", "speed"]
    assert only(found, "collision").time == pytest.approx(2.0)


# ---------------------------------------------------------------------------------------------
# per-robot rules
# ---------------------------------------------------------------------------------------------
def test_speed_violation_names_the_segment_and_the_speed():
    a = robot("a", (1.5, 2.5), (9.5, 2.5))
    fast = TimedPath("a", 0.4, [[1.5, 2.5, 0.0], [9.5, 2.5, 4.0]])  # 8 m in 4 s
    v = only(check_plan(OPEN, [a], Plan("t", [fast])), "speed")
    assert "2 m/s > max_speed 1 m/s" in v.detail


def test_top_speed_exactly_is_valid():
    a = robot("a", (1.5, 2.5), (9.5, 2.5), speed=0.7)
    assert check_plan(OPEN, [a], Plan("t", [drive(a)])) == []


def test_wall_violations():
    """A wall cell at (5, 2) (x in [5, 6], y in [2, 3]); discs of radius 0.4."""
    grid = GridMap.from_rows(["." * 12] * 2 + ["....." + "@" + "......"] + ["." * 12] * 9)
    a = robot("a", (1.5, 2.5), (9.5, 2.5))
    v = only(check_plan(grid, [a], Plan("t", [drive(a)])), "obstacle")
    assert "segment 0->1" in v.detail and "passes 0 m" in v.detail
    # detour 1 m above the wall's top edge: 1 m clearance
    assert check_plan(grid, [a], Plan("t", [drive(a, (4.5, 1.0), (6.5, 1.0))])) == []
    # detour with 0.3 m clearance along the wall's top edge: the swept disc scrapes it
    v = only(check_plan(grid, [a], Plan("t", [drive(a, (4.7, 1.7), (6.3, 1.7))])), "obstacle")
    assert "passes 0.3 m" in v.detail
    # the map edge counts as a wall
    b = robot("b", (0.3, 5.5), (0.3, 8.5))
    assert kinds(check_plan(grid, [b], Plan("t", [drive(b)]))) == ["obstacle"]


def test_a_hold_next_to_a_wall_is_checked():
    """A zero-length segment (a hold) 0.2 m from a wall; GEOS's dwithin misses such segments."""
    grid = GridMap.from_rows(["." * 12] * 2 + ["....." + "@" + "......"] + ["." * 12] * 9)
    a = robot("a", (1.5, 1.8), (1.5, 1.8))
    hold = TimedPath("a", 0.4, [[1.5, 1.8, 0.0], [5.5, 1.8, 4.0], [5.5, 1.8, 6.0], [1.5, 1.8, 10.0]])
    found = check_plan(grid, [a], Plan("t", [hold]))
    assert kinds(found) == ["obstacle"]


def test_missing_unknown_and_duplicate_paths():
    a, b = robot("a", (1.5, 2.5), (9.5, 2.5)), robot("b", (1.5, 5.5), (9.5, 5.5))
    ghost = TimedPath("ghost", 0.4, [[1.5, 8.5, 0.0]])
    found = check_plan(OPEN, [a, b], Plan("t", [drive(a), drive(a), ghost]))
    assert kinds(found) == ["missing", "missing", "missing"]
    assert {v.robots for v in found} == {("a",), ("b",), ("ghost",)}
    assert any("no path" in v.detail and v.robots == ("b",) for v in found)


def test_start_goal_time_and_radius_mismatches():
    a = robot("a", (1.5, 2.5), (9.5, 2.5))
    wrong_ends = TimedPath("a", 0.4, [[1.5, 3.0, 0.0], [9.0, 2.5, 8.0]])
    assert kinds(check_plan(OPEN, [a], Plan("t", [wrong_ends]))) == ["goal", "start"]
    backwards = TimedPath("a", 0.4, [[1.5, 2.5, 0.0], [5.5, 2.5, 5.0], [9.5, 2.5, 4.0]])
    assert "time" in kinds(check_plan(OPEN, [a], Plan("t", [backwards])))
    negative = TimedPath("a", 0.4, [[1.5, 2.5, -1.0], [9.5, 2.5, 8.0]])
    assert kinds(check_plan(OPEN, [a], Plan("t", [negative]))) == ["time"]
    thin = TimedPath("a", 0.3, drive(a).waypoints)
    assert kinds(check_plan(OPEN, [a], Plan("t", [thin]))) == ["radius"]


def test_the_scenario_radius_is_used_for_collisions_not_the_plans():
    """The plan claims r = 0.1 for both, the robots are 0.4: 0.5 m apart is a collision."""
    c, d = robot("c", (1.5, 2.5), (9.5, 2.5)), robot("d", (1.5, 3.0), (9.5, 3.0))
    thin = [TimedPath(s.id, 0.1, drive(s).waypoints) for s in (c, d)]
    assert kinds(check_plan(OPEN, [c, d], Plan("t", thin))) == ["collision", "radius", "radius"]


# ---------------------------------------------------------------------------------------------
# the sweep prunes without losing pairs: compare with a plain all-pairs reference
# ---------------------------------------------------------------------------------------------
def reference_gap(p: TimedPath, q: TimedPath) -> float:
    """Closest distance minus radii, all pairs of merged breakpoint intervals, no pruning."""
    times = np.union1d(p.waypoints[:, 2], q.waypoints[:, 2])
    best = math.inf
    for t0, t1 in zip(np.concatenate([[times[0]], times]), np.concatenate([times, [times[-1]]])):
        d0 = np.subtract(p.position(t0), q.position(t0))
        d1 = np.subtract(p.position(t1), q.position(t1))
        v = d1 - d0
        s = 0.0 if not v.any() else float(np.clip(-(d0 @ v) / (v @ v), 0, 1))
        best = min(best, float(np.hypot(*(d0 + s * v))))
    return best - p.radius - q.radius


def random_paths(seed: int, n: int) -> list[TimedPath]:
    rng = np.random.default_rng(seed)
    paths = []
    for i in range(n):
        pts = np.clip(np.cumsum(rng.normal(0, 2.0, size=(6, 2)), axis=0) + rng.uniform(2, 28, 2), 0.5, 29.5)
        speed = rng.uniform(0.5, 1.0)
        paths.append(timed_path_from_polyline(f"r{i}", rng.uniform(0.3, 0.5), pts, speed, rng.uniform(0, 10)))
    return paths


@pytest.mark.parametrize("chunk", [checker._CHUNK_PAIRS, 7])
def test_sweep_agrees_with_all_pairs_reference(monkeypatch, chunk):
    monkeypatch.setattr(checker, "_CHUNK_PAIRS", chunk)
    paths = random_paths(seed=3, n=40)
    specs = [RobotSpec(p.robot_id, p.radius, 1.0, tuple(p.waypoints[0, :2]), tuple(p.waypoints[-1, :2]))
             for p in paths]
    gaps = {(paths[i].robot_id, paths[j].robot_id): reference_gap(paths[i], paths[j])
            for i in range(len(paths)) for j in range(i + 1, len(paths))}
    expected = {pair for pair, gap in gaps.items() if gap < -1e-6}
    assert expected  # the instance must contain collisions to test anything
    grid = GridMap(np.zeros((30, 30), dtype=bool))
    found = {v.robots for v in check_plan(grid, specs, Plan("t", paths)) if v.kind == "collision"}
    assert found == expected
    gap, a, b, _ = min_separation(paths)
    assert gap == pytest.approx(min(gaps.values()), abs=1e-9)
    assert gaps[(a, b)] == pytest.approx(gap, abs=1e-9)


def test_min_separation_of_far_apart_robots_widens_its_search():
    far = [TimedPath("a", 0.4, [[1.0, 1.0, 0.0]]), TimedPath("b", 0.5, [[21.0, 1.0, 0.0]])]
    assert min_separation(far) == (pytest.approx(19.1), "a", "b", 0.0)
    assert min_separation(far[:1]) == (math.inf, None, None, None)
