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


def test_a_focused_model_has_exactly_the_focus_pairs_of_the_full_one():
    """The live fleet's legs (focus: the robots being planned) need only the pairs with those
    robots: exactly the full model's pieces and regions for those pairs, none of the others, also
    after updates of focused robots."""
    rng = np.random.default_rng(12)
    n = 16
    paths = [np.cumsum(rng.uniform(-3, 3, (6, 2)), axis=0) + rng.uniform(0, 8, 2) for _ in range(n)]
    paths[3] = paths[3][:1]   # parked
    radii = rng.uniform(0.3, 0.5, n)

    def times(p):
        return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])

    focus = [2, 9, 13]
    model = CollisionModel(paths, radii, 0.05, times=[times(p) for p in paths], fast_merge=True, focus=focus)
    for step in range(4):
        full = CollisionModel(paths, radii, 0.05, times=[times(p) for p in paths], fast_merge=True)
        wanted = {pair for pair in full.pairs() if set(pair) & set(focus)}
        assert len(wanted) > 5 and len(wanted) < len(list(full.pairs()))
        assert set(model.pairs()) == wanted
        for x in focus:
            assert set(model.neighbours(x)) == set(full.neighbours(x))
        for pair in wanted:
            np.testing.assert_array_equal(model.pieces(*pair), full.pieces(*pair))
            assert model.regions(*pair) == full.regions(*pair)
        x = focus[step % len(focus)]
        paths[x] = np.cumsum(rng.uniform(-3, 3, (5, 2)), axis=0) + rng.uniform(0, 8, 2)
        model.set_paths({x: (paths[x], times(paths[x]))})


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


# ---------------------------------------------------------------------------------------------
# the compiled pieces (fleet_planner._md_kernels.segment_pieces) against the numpy code they
# replaced (issue 8, speed), transcribed here as it was: the very same numbers
# ---------------------------------------------------------------------------------------------
def _circle_interval(w: np.ndarray, u: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameters s with |w + s*u| < R for unit u: roots of s^2 + 2 s (u.w) + |w|^2 - R^2."""
    b = np.einsum("ij,ij->i", u, w)
    c = np.einsum("ij,ij->i", w, w) - R * R
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0.0))
    lo, hi = -b - root, -b + root
    empty = disc <= 0
    return np.where(empty, np.inf, lo), np.where(empty, -np.inf, hi)


def capsule_interval(p0: np.ndarray, u: np.ndarray, length: np.ndarray,
                     q0: np.ndarray, v: np.ndarray, qlen: np.ndarray, R: np.ndarray):
    """For each row: the interval [lo, hi] of s in [0, length] such that the point p0 + s*u lies within
    R of the segment q0 + t*v, t in [0, qlen] (u, v unit vectors). Empty rows have lo > hi.

    The capsule is convex, so its intersection with a line is one interval: the union of the two
    end discs' intervals and the slab's."""
    w0 = p0 - q0
    lo_a, hi_a = _circle_interval(w0, u, R)
    lo_b, hi_b = _circle_interval(w0 - v * qlen[:, None], u, R)
    # slab: perpendicular distance to q's line < R and projection within [0, qlen]
    cross0 = v[:, 0] * w0[:, 1] - v[:, 1] * w0[:, 0]
    cross1 = v[:, 0] * u[:, 1] - v[:, 1] * u[:, 0]
    proj0 = np.einsum("ij,ij->i", v, w0)
    proj1 = np.einsum("ij,ij->i", v, u)
    with np.errstate(divide="ignore", invalid="ignore"):
        # |cross0 + s*cross1| < R
        s1 = (-R - cross0) / cross1
        s2 = (R - cross0) / cross1
        perp_lo = np.where(cross1 != 0, np.minimum(s1, s2), np.where(np.abs(cross0) < R, -np.inf, np.inf))
        perp_hi = np.where(cross1 != 0, np.maximum(s1, s2), np.where(np.abs(cross0) < R, np.inf, -np.inf))
        # 0 <= proj0 + s*proj1 <= qlen
        t1 = -proj0 / proj1
        t2 = (qlen - proj0) / proj1
        inside = (proj0 >= 0) & (proj0 <= qlen)
        proj_lo = np.where(proj1 != 0, np.minimum(t1, t2), np.where(inside, -np.inf, np.inf))
        proj_hi = np.where(proj1 != 0, np.maximum(t1, t2), np.where(inside, np.inf, -np.inf))
    slab_lo = np.maximum(perp_lo, proj_lo)
    slab_hi = np.minimum(perp_hi, proj_hi)
    slab_empty = slab_lo >= slab_hi
    slab_lo = np.where(slab_empty, np.inf, slab_lo)
    slab_hi = np.where(slab_empty, -np.inf, slab_hi)
    lo = np.minimum(np.minimum(lo_a, lo_b), slab_lo)
    hi = np.maximum(np.maximum(hi_a, hi_b), slab_hi)
    return np.maximum(lo, 0.0), np.minimum(hi, length)


def _piece_table(p0, u, lp, offp, tp, vx, q0, v, lq, offq, tq, vy, R) -> np.ndarray:
    """Exact extents of the convex set S = {(a, b) in [0, lp] x [0, lq] : |p0 + a u - q0 - b v| < R}
    per row: the range of phi(a, b) = (tp + a/vx) - (tq + b/vy) over S, and S's edge intervals.

    A linear function's extremes over a convex set lie on its boundary: on the square's edges (the
    ends of the four edge intervals) or where the ellipse boundary is tangent to phi's level lines."""
    n = len(p0)
    out = np.zeros((n, 28))

    def clip(lo, hi, length):
        lo, hi = np.maximum(lo, 0.0), np.minimum(hi, length)
        return np.where(lo <= hi, lo, np.inf), np.where(lo <= hi, hi, -np.inf)

    p1, q1 = p0 + u * lp[:, None], q0 + v * lq[:, None]
    xs = clip(*_circle_interval(q0 - p0, v, R), lq)   # b-range with x at its segment start
    xe = clip(*_circle_interval(q0 - p1, v, R), lq)   # ... at its segment end
    ys = clip(*_circle_interval(p0 - q0, u, R), lp)   # a-range with y at its segment start
    ye = clip(*_circle_interval(p0 - q1, u, R), lp)
    phi = lambda a, b: (tp + a / vx) - (tq + b / vy)  # noqa: E731
    zero = np.zeros(n)
    cands = [phi(zero, xs[0]), phi(zero, xs[1]), phi(lp, xe[0]), phi(lp, xe[1]),
             phi(ys[0], zero), phi(ys[1], zero), phi(ye[0], lq), phi(ye[1], lq)]
    valid = [np.isfinite(xs[0])] * 2 + [np.isfinite(xe[0])] * 2 + [np.isfinite(ys[0])] * 2 + [np.isfinite(ye[0])] * 2
    # tangent points: y = w + A z with A = [u, -v]; phi = c + g.z, g = (1/vx, -1/vy)
    det = u[:, 0] * (-v[:, 1]) - (-v[:, 0]) * u[:, 1]
    ok = np.abs(det) > 1e-12
    sdet = np.where(ok, det, 1.0)
    # A^-1 = [[-v1, v0], [-u1, u0]] / det ; h = A^-T g
    inv = np.stack([np.stack([-v[:, 1], v[:, 0]], 1), np.stack([-u[:, 1], u[:, 0]], 1)], 1) / sdet[:, None, None]
    g = np.stack([1.0 / vx, -1.0 / vy], 1)
    h = np.einsum("nji,nj->ni", inv, g)
    hn = np.hypot(h[:, 0], h[:, 1])
    hn = np.where(hn > 0, hn, 1.0)
    w = p0 - q0
    for sign in (1.0, -1.0):
        y = sign * R[:, None] * h / hn[:, None]
        z = np.einsum("nij,nj->ni", inv, y - w)
        inside = ok & (z[:, 0] >= 0) & (z[:, 0] <= lp) & (z[:, 1] >= 0) & (z[:, 1] <= lq)
        cands.append(phi(z[:, 0], z[:, 1]))
        valid.append(inside)
    c = np.stack(cands, 1)
    m = np.stack(valid, 1)
    out[:, C.P_PHI_LO] = np.where(m, c, np.inf).min(1)
    out[:, C.P_PHI_HI] = np.where(m, c, -np.inf).max(1)
    out[:, C.P_XS_LO], out[:, C.P_XS_HI] = offq + xs[0], offq + xs[1]
    out[:, C.P_XE_LO], out[:, C.P_XE_HI] = offq + xe[0], offq + xe[1]
    out[:, C.P_YS_LO], out[:, C.P_YS_HI] = offp + ys[0], offp + ys[1]
    out[:, C.P_YE_LO], out[:, C.P_YE_HI] = offp + ye[0], offp + ye[1]
    out[:, C.P_X_OFF], out[:, C.P_X_T0], out[:, C.P_X_V] = offp, tp, vx
    out[:, C.P_Y_OFF], out[:, C.P_Y_T0], out[:, C.P_Y_V] = offq, tq, vy
    return out



def _take(segs: C._Segs, rows: np.ndarray) -> C._Segs:
    return C._Segs(*(col[rows] for col in segs))


def _swap(a: C._Segs, b: C._Segs, swap: np.ndarray) -> tuple[C._Segs, C._Segs]:
    """The two sides of segment pairs exchanged where ``swap``."""
    def pick(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.where(swap[:, None] if x.ndim == 2 else swap, y, x)

    return C._Segs(*(pick(x, y) for x, y in zip(a, b))), C._Segs(*(pick(y, x) for x, y in zip(a, b)))


def _numpy_pieces(A, B, radii, margin):
    """What CollisionModel._compute did with candidate pairs A[r], B[r] before it was compiled."""
    swap = A.owner > B.owner
    if swap.any():
        A, B = _swap(A, B, swap)
    R = radii[A.owner] + radii[B.owner] + margin
    a_lo, a_hi = capsule_interval(A.p0, A.u, A.length, B.p0, B.u, B.length, R)
    b_lo, b_hi = capsule_interval(B.p0, B.u, B.length, A.p0, A.u, A.length, R)
    hit = (a_lo <= a_hi) & (b_lo <= b_hi)
    A, B, R = _take(A, hit), _take(B, hit), R[hit]
    pieces = _piece_table(A.p0, A.u, A.length, A.offset, A.t0, A.speed,
                          B.p0, B.u, B.length, B.offset, B.t0, B.speed, R)
    pieces[:, C.P_X], pieces[:, C.P_Y] = A.owner, B.owner
    pieces[:, C.P_A_LO], pieces[:, C.P_A_HI] = A.offset + a_lo[hit], A.offset + a_hi[hit]
    pieces[:, C.P_B_LO], pieces[:, C.P_B_HI] = B.offset + b_lo[hit], B.offset + b_hi[hit]
    pieces[:, C.P_X_FIRST], pieces[:, C.P_X_LAST] = A.first, A.last
    pieces[:, C.P_Y_FIRST], pieces[:, C.P_Y_LAST] = B.first, B.last
    pieces[:, C.P_X_SEG], pieces[:, C.P_Y_SEG] = A.seg, B.seg
    return pieces


@pytest.mark.parametrize("grid", [False, True])
def test_the_compiled_pieces_are_the_numbers_of_the_numpy_ones(grid):
    from fleet_planner import _md_kernels as K

    rng = np.random.default_rng(11 + grid)
    paths, times = [], []
    for _ in range(12):   # random polylines; on a grid: axis-parallel, parallel and collinear pairs, stops
        k = int(rng.integers(1, 7))
        pts = rng.integers(0, 6, (k, 2)).astype(float) if grid else rng.uniform(0, 6, (k, 2))
        paths.append(pts)
        times.append(np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 2.0, len(pts) - 1))]))
    radii = rng.uniform(0.3, 0.6, len(paths))
    segs = C._cat([C._robot_segments(x, p, t) for x, (p, t) in enumerate(zip(paths, times))])
    qi, ti = np.nonzero(segs.owner[:, None] != segs.owner[None, :])   # every pair, both orientations
    expect = _numpy_pieces(_take(segs, qi), _take(segs, ti), radii, 0.05)
    got = K.segment_pieces(qi, ti, *C._kernel_cols(segs), *C._kernel_cols(segs), radii, 0.05, 28)
    assert len(expect) > 50
    np.testing.assert_array_equal(got, expect)
