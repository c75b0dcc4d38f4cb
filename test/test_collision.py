"""Collision regions against brute force: the closed forms must agree with dense sampling."""
import numpy as np
import pytest

from fleet_planner import collision as C
from fleet_planner.collision import CollisionModel


def _brute_piece(p0, p1, q0, q1, R, vx, vy, n=801):
    """Sample (a, b) on a fine grid; return a-range, b-range and the range of a/vx - b/vy inside."""
    lp, lq = np.hypot(*(p1 - p0)), np.hypot(*(q1 - q0))
    a = np.linspace(0, lp, n)[:, None]
    b = np.linspace(0, lq, n)[None, :]
    u = (p1 - p0) / lp if lp else np.array([1.0, 0.0])
    v = (q1 - q0) / lq if lq else np.array([1.0, 0.0])
    dx = p0[0] + a * u[0] - q0[0] - b * v[0]
    dy = p0[1] + a * u[1] - q0[1] - b * v[1]
    inside = dx * dx + dy * dy < R * R
    if not inside.any():
        return None
    aa, bb = np.broadcast_to(a, inside.shape)[inside], np.broadcast_to(b, inside.shape)[inside]
    phi = aa / vx - bb / vy
    return (aa.min(), aa.max(), bb.min(), bb.max(), phi.min(), phi.max()), max(lp, lq) / (n - 1)


@pytest.mark.parametrize("seed", range(25))
def test_piece_extents_match_sampling(seed):
    rng = np.random.default_rng(seed)
    p0, p1, q0, q1 = (rng.uniform(0, 6, 2) for _ in range(4))
    R, vx, vy = rng.uniform(0.5, 2.0), rng.uniform(0.5, 1.5), rng.uniform(0.5, 1.5)
    model = CollisionModel([np.array([p0, p1]), np.array([q0, q1])], [R / 2, R / 2], 0.0, [vx, vy])
    brute = _brute_piece(p0, p1, q0, q1, R, vx, vy)
    pieces = model.pieces(0, 1)
    if brute is None:
        assert len(pieces) == 0 or pieces[0, C.P_A_HI] - pieces[0, C.P_A_LO] < 0.05
        return
    (a_lo, a_hi, b_lo, b_hi, f_lo, f_hi), step = brute
    assert len(pieces) == 1
    row = pieces[0]
    tol = 2 * step
    assert row[C.P_A_LO] == pytest.approx(a_lo, abs=tol) and row[C.P_A_HI] == pytest.approx(a_hi, abs=tol)
    assert row[C.P_B_LO] == pytest.approx(b_lo, abs=tol) and row[C.P_B_HI] == pytest.approx(b_hi, abs=tol)
    assert row[C.P_PHI_LO] == pytest.approx(f_lo, abs=tol * 3) and row[C.P_PHI_HI] == pytest.approx(f_hi, abs=tol * 3)


def test_parked_robot_has_a_region_with_a_robot_driving_past():
    """A one-point path (a robot that stays) is a zero-length segment; it must not be missed."""
    model = CollisionModel([np.array([[5.0, 0.0]]), np.array([[0.0, 0.0], [10.0, 0.0]])], [0.4, 0.4])
    (region,) = model.regions(0, 1)
    assert (region.a_lo, region.a_hi) == (0.0, 0.0)
    assert (region.b_lo, region.b_hi) == pytest.approx((4.2, 5.8))


def test_regions_are_components_in_travelled_length_space():
    line = np.array([[0.0, 0.0], [20.0, 0.0]])
    zigzag = np.array([[5.0, -5.0], [5.0, 5.0], [15.0, 5.0], [15.0, -5.0]])
    assert len(CollisionModel([line, zigzag], [0.5, 0.5]).regions(0, 1)) == 2
    # crossing the same spot twice is two regions: the second robot is there at two different times
    hairpin = np.array([[5.0, -5.0], [5.0, 5.0], [5.5, 5.0], [5.5, -5.0]])
    first, second = CollisionModel([line, hairpin], [0.5, 0.5]).regions(0, 1)
    assert first.a_hi > second.a_lo and first.b_hi < second.b_lo
    # driving along the line over several segments is one region
    along = np.array([[2.0, 0.5], [6.0, 0.3], [9.0, 0.6], [12.0, 0.2]])
    (region,) = CollisionModel([line, along], [0.5, 0.5]).regions(0, 1)
    assert region.b_lo == 0.0 and region.b_hi == pytest.approx(np.sum(np.hypot(*np.diff(along, axis=0).T)))


def test_incremental_update_equals_rebuild():
    rng = np.random.default_rng(7)
    paths = [np.cumsum(rng.uniform(-3, 3, (4, 2)), axis=0) + rng.uniform(0, 8, 2) for _ in range(12)]
    radii = rng.uniform(0.3, 0.5, 12)
    model = CollisionModel(paths, radii, 0.05)
    new = {3: paths[3][::-1].copy(), 8: paths[8] + 0.7}
    model.set_paths({x: (p, np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))]))
                     for x, p in new.items()})
    fresh = CollisionModel([new.get(k, p) for k, p in enumerate(paths)], radii, 0.05)
    assert set(model.pairs()) == set(fresh.pairs())
    for pair in fresh.pairs():
        assert model.regions(*pair) == fresh.regions(*pair)
        np.testing.assert_allclose(model.pieces(*pair), fresh.pieces(*pair))


def test_ramped_profiles_are_scheduled_exactly():
    """Robots that accelerate: the plan (with ramp pieces) is still valid by the exact checker,
    and a follower may trail its leader down a corridor without waiting for it to leave."""
    from fleet_planner.checker import check_plan
    from fleet_planner.grid import GridMap
    from fleet_planner.model import RobotSpec
    from fleet_planner.planners.md import MDPlanner

    grid = GridMap.from_rows(["." * 30, "." * 30])
    robots = [RobotSpec("lead", 0.4, 1.0, (2.5, 0.5), (29.5, 0.5), max_accel=0.5),
              RobotSpec("follow", 0.4, 1.2, (0.5, 0.5), (27.5, 0.5), max_accel=0.5),
              RobotSpec("cross", 0.4, 0.8, (14.5, 1.5), (0.5, 1.5), max_accel=0.3)]
    plan = MDPlanner(order="given").plan(grid, robots)
    assert check_plan(grid, robots, plan) == []
    lead, follow = plan.by_id()["lead"], plan.by_id()["follow"]
    assert follow.start_time < lead.arrival_time - 10   # trails it, does not wait for it to arrive
    # the ramp is in the plan: the first piece is slower than the top speed
    wp = lead.waypoints[lead.waypoints[:, 2] >= lead.start_time]
    first_speed = np.hypot(*(wp[1, :2] - wp[0, :2])) / (wp[1, 2] - wp[0, 2])
    assert first_speed < 0.5


@pytest.mark.parametrize("share", [0.0, 0.2, 10.0])
def test_many_incremental_updates_equal_a_rebuild(monkeypatch, share):
    """Successive updates of one or two robots (parked ones too), with the fleet's segment index
    rebuilt after every update, after some, or never: always the pairs and pieces of a fresh model."""
    monkeypatch.setattr(CollisionModel, "REBUILD_SHARE", share)
    rng = np.random.default_rng(11)
    n = 14
    paths = [np.cumsum(rng.uniform(-3, 3, (5, 2)), axis=0) + rng.uniform(0, 8, 2) for _ in range(n)]
    paths[4] = paths[4][:1]   # parked
    radii = rng.uniform(0.3, 0.5, n)

    def times(p):
        return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])

    model = CollisionModel(paths, radii, 0.05, times=[times(p) for p in paths])
    for step in range(12):
        who = rng.choice(n, size=1 + step % 2, replace=False)
        for x in who:
            k = int(rng.integers(1, 6))
            paths[x] = np.cumsum(rng.uniform(-3, 3, (k, 2)), axis=0) + rng.uniform(0, 8, 2)
        model.set_paths({int(x): (paths[x], times(paths[x])) for x in who})
        fresh = CollisionModel(paths, radii, 0.05, times=[times(p) for p in paths])
        assert set(model.pairs()) == set(fresh.pairs())
        for x in range(n):
            assert set(model.neighbours(x)) == set(fresh.neighbours(x))
        for pair in fresh.pairs():
            np.testing.assert_allclose(model.pieces(*pair), fresh.pieces(*pair))
            assert model.regions(*pair) == fresh.regions(*pair)


def test_the_batched_merge_finds_the_regions_of_the_sequential_one():
    from fleet_planner.collision import _merge_boxes, _merge_boxes_batch

    rng = np.random.default_rng(3)
    chunks = []
    for _ in range(30):
        lo = rng.uniform(0, 20, (int(rng.integers(1, 25)), 2))
        size = rng.uniform(0.1, 3, lo.shape)
        boxes = np.stack([lo[:, 0], lo[:, 0] + size[:, 0], lo[:, 1], lo[:, 1] + size[:, 1]], 1)
        chunks.append(boxes[np.argsort(boxes[:, 0])])
    for boxes, merged in zip(chunks, _merge_boxes_batch(chunks)):
        np.testing.assert_allclose(sorted(merged), sorted(_merge_boxes(boxes)))


def test_a_snapshot_restores_a_robots_pairs():
    rng = np.random.default_rng(5)
    paths = [np.cumsum(rng.uniform(-3, 3, (4, 2)), axis=0) + rng.uniform(0, 8, 2) for _ in range(10)]
    radii = rng.uniform(0.3, 0.5, 10)
    model = CollisionModel(paths, radii, 0.05)
    before = {pair: model.pieces(*pair).copy() for pair in model.pairs()}
    snap = model.snapshot(3)
    other = paths[3][::-1] + 1.5
    model.set_paths({3: (other, np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(other, axis=0).T))]))})
    model.restore(snap)
    assert set(model.pairs()) == set(before)
    for pair, chunk in before.items():
        np.testing.assert_array_equal(model.pieces(*pair), chunk)
    model.set_paths({5: (paths[5] + 0.3, np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(paths[5], axis=0).T))]))})
    paths[5] = paths[5] + 0.3
    fresh = CollisionModel(paths, radii, 0.05)
    assert set(model.pairs()) == set(fresh.pairs())
