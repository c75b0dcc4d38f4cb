"""The behaviour fleet's fast paths (issue 13: a 100-robot step was too slow to finish runs) give
the answers of the plain definitions they replace: the wall clearance from the blocked cells
around a point (:class:`~fleet_planner.behavior.clearance.Clearance`) against the map's GEOS
distance, and the one-pass front-area scan against :func:`in_front_area` / :func:`in_critical_area`.
"""
from __future__ import annotations

import math

import numpy as np

from fleet_planner.behavior import Behavior, BehaviorParams, RobotView, in_critical_area, in_front_area
from fleet_planner.behavior.areas import front_area_check, scan_front_area
from fleet_planner.behavior.clearance import Clearance
from fleet_planner.grid import GridMap


def _grid(resolution: float) -> GridMap:
    return GridMap.from_rows(["..........@@",
                              "..@@@......@",
                              "..@@@...@...",
                              "........@...",
                              "@.....@@@..."], resolution=resolution)


def test_clearance_is_the_maps_distance_to_its_walls_below_the_reach_and_a_lower_bound_beyond():
    for resolution in (0.5, 1.0):
        grid = _grid(resolution)
        fast = Clearance(grid, reach=resolution)
        w, h = grid.size_m
        rng = np.random.default_rng(7)
        points = rng.uniform((-0.3, -0.3), (w + 0.3, h + 0.3), size=(1500, 2))
        exact = np.array([grid.clearance(*p) for p in points])
        mine = np.array([fast(*p) for p in points])
        cap = fast.cells * fast.res
        near = exact < cap - 1e-12
        assert near.sum() > 500 and (~near).sum() > 10
        assert np.max(np.abs(mine[near] - exact[near])) < 1e-12
        assert np.all(mine[~near] >= cap - 1e-12) and np.all(mine[~near] <= exact[~near] + 1e-12)
        for radius in (0.35, 1.7):   # beyond the reach too: disc_is_free widens its window
            assert all(fast.disc_is_free(*p, radius) == grid.disc_is_free(*p, radius) for p in points[:400])


def test_clearance_broken_by_one_blocked_cell_fails():
    """Control: the comparison above sees a wrong wall (a cell the fast path does not know of)."""
    grid = _grid(1.0)
    fast = Clearance(grid)
    fast.blocked = fast.blocked.copy()
    assert math.isclose(fast(3.5, 3.5), grid.clearance(3.5, 3.5))
    fast.blocked[3, 3] = True
    assert not math.isclose(fast(3.5, 3.5), grid.clearance(3.5, 3.5))


def test_one_pass_front_area_scan_is_the_definitions():
    params = BehaviorParams()
    rng = np.random.default_rng(3)
    me_checked = 0
    for _ in range(300):
        pos = tuple(rng.uniform(0, 4, 2))
        nxt = tuple(rng.uniform(0, 4, 2)) if rng.random() < 0.9 else None
        me = RobotView("me", pos, 0.35, Behavior.FOLLOW_WAYPOINT, nxt, straight=float(rng.uniform(0, 3)))
        others = [RobotView(f"o{k}", tuple(rng.uniform(0, 4, 2)), float(rng.uniform(0.2, 0.5)),
                            next_waypoint=tuple(rng.uniform(0, 4, 2))) for k in range(8)] + [me]
        scanned = scan_front_area(me, others, params)
        want = sorted((o for o in others if in_front_area(me, o, params)), key=lambda o: math.dist(o.position, pos))
        assert [o.id for o, _ in scanned] == [o.id for o in want]
        assert [c for _, c in scanned] == [in_critical_area(me, o, params) for o in want]
        critical = [o for o in want if in_critical_area(me, o, params)]
        expect = (critical or want or [None])[0]
        assert front_area_check(me, others, params) is expect
        me_checked += bool(want)
    assert me_checked > 50


def test_view_direction_is_computed_at_construction():
    v = RobotView("a", (1.0, 1.0), 0.3, next_waypoint=(4.0, 5.0))
    assert v.direction == (3.0 / 5.0, 4.0 / 5.0) and v.travelling
    assert RobotView("a", (1.0, 1.0), 0.3, next_waypoint=(1.0, 1.0)).direction is None
    assert not RobotView("a", (1.0, 1.0), 0.3).travelling
