"""PathFinder: valid polylines for a disc robot, checked against geometry built independently here."""
import math

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, Point, box

from fleet_planner.geometry import polyline_length
from fleet_planner.grid import GridMap
from fleet_planner.paths import PathFinder


def walls_of(grid: GridMap):
    """Blocked cells and everything outside the map, built cell by cell (not grid.obstacle_geometry)."""
    res = grid.resolution
    rows, cols = np.nonzero(grid.blocked)
    w, h = grid.width * res, grid.height * res
    outside = box(-10, -10, w + 10, h + 10).difference(box(0, 0, w, h))
    return shapely.union_all([box(c * res, r * res, (c + 1) * res, (r + 1) * res)
                              for r, c in zip(rows, cols)] + [outside])


def assert_valid(path, grid, radius, start, goal, avoid=()):
    assert path is not None
    assert path.shape[1] == 2 and len(path) >= 2
    assert tuple(path[0]) == tuple(start) and tuple(path[-1]) == tuple(goal)
    walls = walls_of(grid)
    for a, b in zip(path[:-1], path[1:]):
        seg = LineString([a, b]) if tuple(a) != tuple(b) else Point(a)
        assert seg.distance(walls) >= radius - 1e-7, f"segment {a}->{b} too close to a wall"
        for centre, keep_out in avoid:
            assert seg.distance(Point(centre)) > keep_out - 1e-9, f"segment {a}->{b} enters disc {centre}"


def random_map(rng, h, w, density):
    blocked = rng.random((h, w)) < density
    return GridMap(blocked)


def random_free_point(rng, grid, radius):
    while True:
        x, y = rng.uniform(0, grid.width), rng.uniform(0, grid.height)
        if grid.disc_is_free(x, y, radius):
            return (x, y)


def test_open_map_is_one_straight_segment_from_exact_start_to_exact_goal():
    grid = GridMap.from_rows(["." * 10] * 6)
    start, goal = (0.73, 0.61), (9.2, 5.37)
    path = PathFinder(grid, 0.4).find(start, goal)
    assert_valid(path, grid, 0.4, start, goal)
    assert len(path) == 2


def test_smoothing_pulls_the_staircase_tight_around_a_wall_end():
    rows = ["..........",
            "..........",
            "@@@@@@@...",
            "..........",
            ".........."]
    grid = GridMap.from_rows(rows)
    start, goal = (0.5, 0.5), (0.5, 4.5)
    path = PathFinder(grid, 0.4).find(start, goal)
    assert_valid(path, grid, 0.4, start, goal)
    # the best 8-connected grid path (no corner cutting) is 2 * (sqrt(2) + 6) + 2 long; pulled
    # tight through cell centres it is start -> (7.5, 1.5) -> (7.5, 3.5) -> goal
    grid_length = 2 * (math.sqrt(2) + 6) + 2
    pulled = 2 * math.hypot(7.0, 1.0) + 2
    assert len(path) <= 4
    assert polyline_length(path) <= pulled + 1e-9 < grid_length


def test_paths_on_random_maps_keep_the_disc_off_walls():
    rng = np.random.default_rng(7)
    for radius in (0.3, 0.45, 0.7):
        for _ in range(4):
            grid = random_map(rng, 14, 18, 0.18)
            finder = PathFinder(grid, radius)
            found = 0
            for _ in range(6):
                start, goal = random_free_point(rng, grid, radius), random_free_point(rng, grid, radius)
                for smooth in (True, False):
                    path = finder.find(start, goal, smooth=smooth)
                    if path is not None:
                        found += 1
                        assert_valid(path, grid, radius, start, goal)
            assert found or radius == 0.7


def test_off_centre_start_and_goal_join_a_neighbour_cell_when_their_own_is_too_tight():
    # radius 0.6: the centres of the edge columns are 0.5 from the map edge, the points are 0.95
    grid = GridMap.from_rows([".......",
                              ".......",
                              ".......",
                              "...@...",
                              ".......",
                              ".......",
                              "......."])
    start, goal = (0.95, 3.5), (6.05, 3.5)
    path = PathFinder(grid, 0.6).find(start, goal)
    assert_valid(path, grid, 0.6, start, goal)


def test_walled_off_goal_gives_none():
    rows = ["......",
            "...@@@",
            "...@..",
            "...@.."]
    finder = PathFinder(GridMap.from_rows(rows), 0.4)
    assert finder.find((0.5, 0.5), (4.5, 3.5)) is None
    assert finder.find((0.5, 0.5), (5.5, 0.5)) is not None


@pytest.mark.parametrize("res", [1.0, 0.5])
def test_one_cell_aisle_admits_half_a_cell_but_not_more(res):
    rows = ["@@@@@@",
            "......",
            "@@@@@@"]
    grid = GridMap.from_rows(rows, resolution=res)
    start, goal = (0.5 * res, 1.5 * res), (5.5 * res, 1.5 * res)
    for frac in (0.45, 0.5):
        path = PathFinder(grid, frac * res).find(start, goal)
        assert_valid(path, grid, frac * res, start, goal)
    assert PathFinder(grid, 0.55 * res).find(start, goal) is None


def test_one_cell_aisle_with_a_turn():
    rows = ["@@@@@@",
            "....@@",
            "@@@.@@",
            "@@@...",
            "@@@@@@"]
    grid = GridMap.from_rows(rows)
    start, goal = (0.5, 1.5), (5.5, 3.5)
    path = PathFinder(grid, 0.5).find(start, goal)
    assert_valid(path, grid, 0.5, start, goal)
    assert PathFinder(grid, 0.55).find(start, goal) is None


def test_avoid_discs_are_respected_and_forced_around():
    grid = GridMap.from_rows(["." * 12] * 7)
    start, goal = (0.5, 3.5), (11.5, 3.5)
    avoid = [((6.0, 3.5), 1.2), ((3.0, 1.0), 0.8), ((9.0, 5.5), 0.9)]
    path = PathFinder(grid, 0.4).find(start, goal, avoid=avoid)
    assert_valid(path, grid, 0.4, start, goal, avoid)
    assert polyline_length(path) > 11.0 + 0.1  # had to leave the straight line
    # the same discs as an (n, 3) array of rows (x, y, keep-out): the same answer; a wrong shape names avoid
    rows = np.array([(c[0], c[1], k) for c, k in avoid])
    assert np.array_equal(PathFinder(grid, 0.4).find(start, goal, avoid=rows), path)
    assert np.array_equal(PathFinder(grid, 0.4).find(start, goal, avoid=rows[:1]),
                          PathFinder(grid, 0.4).find(start, goal, avoid=avoid[:1]))
    with pytest.raises(ValueError, match="avoid"):
        PathFinder(grid, 0.4).find(start, goal, avoid=rows[:, :2])


@pytest.mark.parametrize("radius", [0.4, 0.6])
def test_avoid_discs_and_blocked_cells_on_random_maps(radius):
    rng = np.random.default_rng(3)
    found = 0
    for _ in range(6):
        grid = random_map(rng, 14, 18, 0.1)
        finder = PathFinder(grid, radius)
        for _ in range(5):
            start, goal = random_free_point(rng, grid, radius), random_free_point(rng, grid, radius)
            avoid = [(random_free_point(rng, grid, 0.0), float(rng.uniform(0.3, 1.0))) for _ in range(5)]
            kept = [(c, k) for c, k in avoid
                    if math.dist(c, start) > k and math.dist(c, goal) > k]
            virtual = {(int(c), int(r)) for c, r in rng.integers(0, (18, 14), size=(4, 2))}
            virtual -= {grid.cell_of(*start), grid.cell_of(*goal)}
            walled = grid.blocked.copy()
            for col, row in virtual:
                walled[row, col] = True
            for smooth in (True, False):  # the grid path itself must be valid, not only its shortcuts
                path = finder.find(start, goal, avoid=avoid, blocked_cells=virtual, smooth=smooth)
                if path is not None:
                    found += 1
                    assert_valid(path, GridMap(walled), radius, start, goal, kept)
    assert found >= 5


def test_grid_paths_around_discs_on_an_open_map():
    # no walls to lean on: every diagonal and straight move near a disc must be judged exactly
    grid = GridMap.from_rows(["." * 10] * 10)
    finder = PathFinder(grid, 0.3)
    rng = np.random.default_rng(5)
    for _ in range(40):
        avoid = [((float(rng.uniform(2, 8)), float(rng.uniform(2, 8))), float(rng.uniform(0.3, 1.5)))]
        start, goal = random_free_point(rng, grid, 0.3), random_free_point(rng, grid, 0.3)
        kept = [(c, k) for c, k in avoid if math.dist(c, start) > k and math.dist(c, goal) > k]
        path = finder.find(start, goal, avoid=avoid, smooth=False)
        assert_valid(path, grid, 0.3, start, goal, kept)


def test_discs_in_a_serpentine_aisle():
    # the path cannot be pulled straight here, so it keeps the grid moves: they must avoid the discs
    grid = GridMap.from_rows([".........",
                              "@@@@@@@@.",
                              ".........",
                              ".@@@@@@@@",
                              "........."])
    finder = PathFinder(grid, 0.45)
    start, goal = (0.5, 0.5), (8.5, 4.5)
    rng = np.random.default_rng(11)
    outcomes = set()
    for _ in range(60):
        centre, keep_out = (float(rng.uniform(0, 9)), float(rng.uniform(0, 5))), float(rng.uniform(0.05, 0.7))
        if math.dist(centre, start) <= keep_out or math.dist(centre, goal) <= keep_out:
            continue
        avoid = [(centre, keep_out)]
        path = finder.find(start, goal, avoid=avoid)
        outcomes.add(path is None)
        if path is not None:
            assert_valid(path, grid, 0.45, start, goal, avoid)
    assert outcomes == {True, False}


def test_disc_between_two_cell_centres_blocks_the_aisle():
    # no cell centre lies inside the disc, but every move along the aisle passes through it
    rows = ["@@@@@@",
            "......",
            "@@@@@@"]
    finder = PathFinder(GridMap.from_rows(rows), 0.4)
    assert finder.find((0.5, 1.5), (5.5, 1.5), avoid=[((3.0, 1.5), 0.45)]) is None


def test_disc_containing_start_or_goal_is_ignored():
    rows = ["@@@@@@",
            "......",
            "@@@@@@"]
    finder = PathFinder(GridMap.from_rows(rows), 0.4)
    start, goal = (0.5, 1.5), (5.5, 1.5)
    path = finder.find(start, goal, avoid=[(start, 0.8), ((5.0, 1.5), 0.9)])
    assert path is not None and tuple(path[-1]) == goal
    assert finder.find(start, goal, avoid=[((2.5, 1.5), 0.8)]) is None


def test_blocked_cells_force_a_detour_and_count_as_walls():
    rows = ["........",
            "........",
            "........"]
    grid = GridMap.from_rows(rows)
    finder = PathFinder(grid, 0.4)
    start, goal = (0.5, 1.5), (7.5, 1.5)
    assert len(finder.find(start, goal)) == 2
    virtual = [(4, 1), (4, 2)]
    path = finder.find(start, goal, blocked_cells=virtual)
    walled = grid.blocked.copy()
    for col, row in virtual:
        walled[row, col] = True
    assert_valid(path, GridMap(walled), 0.4, start, goal)
    assert polyline_length(path) > 7.0 + 0.1
    assert finder.find(start, goal, blocked_cells=[(4, 0), (4, 1), (4, 2)]) is None
    assert finder.find(start, goal) is not None  # a virtual wall lasts one call


def test_blocked_cells_are_inflated_like_walls():
    grid = GridMap.from_rows(["." * 9] * 5)
    start, goal = (0.8, 2.5), (8.2, 2.5)
    posts = [(4, 1), (4, 3)]  # leave a one-cell gap at (4, 2)
    assert PathFinder(grid, 0.6).find(start, goal) is not None
    assert PathFinder(grid, 0.6).find(start, goal, blocked_cells=posts) is None
    path = PathFinder(grid, 0.45).find(start, goal, blocked_cells=posts)
    walled = grid.blocked.copy()
    walled[[1, 3], [4, 4]] = True
    assert_valid(path, GridMap(walled), 0.45, start, goal)


def test_segment_free():
    grid = GridMap.from_rows(["....",
                              ".@..",
                              "...."])
    finder = PathFinder(grid, 0.4)
    assert finder.segment_free((0.5, 0.5), (3.5, 0.5)) is True  # 0.5 from the block
    assert not PathFinder(grid, 0.55).segment_free((0.5, 0.5), (3.5, 0.5))
    assert finder.segment_free((2.5, 0.5), (3.5, 2.5))
    assert not finder.segment_free((0.5, 2.5), (3.5, 0.5))
    assert not finder.segment_free((2.5, 0.5), (3.5, 2.5), avoid=[((3.0, 1.5), 0.2)])
    assert finder.segment_free((2.5, 0.5), (2.5, 0.5))


def test_bad_input_is_named():
    grid = GridMap.from_rows(["...."])
    with pytest.raises(ValueError, match="radius"):
        PathFinder(grid, 0.0)
    finder = PathFinder(grid, 0.3)
    with pytest.raises(ValueError, match="start"):
        finder.find((float("nan"), 0.5), (3.5, 0.5))
    with pytest.raises(ValueError, match="avoid"):
        finder.find((0.5, 0.5), (3.5, 0.5), avoid=[((1.0, 0.5), -1.0)])


# -- the compiled search is exact: grid paths as short as an independent Dijkstra finds -------
def shortest_grid_length(grid, radius, start_cell, goal_cell, avoid=(), virtual=()):
    """Length of the shortest 8-connected path between two cell centres, built here from
    geometry alone: a cell is traversable when its centre is >= radius from every wall (blocked,
    virtual or outside); a diagonal needs both cells it passes traversable; a move must keep
    strictly outside every disc. Plain Dijkstra with heapq. None when unreachable."""
    import heapq

    res = grid.resolution
    walls = walls_of(grid)
    if virtual:
        walls = walls.union(shapely.union_all([box(c * res, r * res, (c + 1) * res, (r + 1) * res)
                                               for c, r in virtual]))
    ok = {(c, r) for r in range(grid.height) for c in range(grid.width)
          if Point((c + 0.5) * res, (r + 0.5) * res).distance(walls) >= radius - 1e-9}

    def move_ok(a, b):
        if b not in ok or (a[0] != b[0] and a[1] != b[1] and ((a[0], b[1]) not in ok or (b[0], a[1]) not in ok)):
            return False
        seg = LineString([((a[0] + 0.5) * res, (a[1] + 0.5) * res), ((b[0] + 0.5) * res, (b[1] + 0.5) * res)])
        return all(seg.distance(Point(c)) > k for c, k in avoid)

    if start_cell not in ok or goal_cell not in ok:
        return None
    dist, heap = {start_cell: 0.0}, [(0.0, start_cell)]
    while heap:
        d, a = heapq.heappop(heap)
        if a == goal_cell:
            return d * res
        if d > dist[a]:
            continue
        for dc in (-1, 0, 1):
            for dr in (-1, 0, 1):
                b = (a[0] + dc, a[1] + dr)
                if (dc or dr) and move_ok(a, b):
                    nd = d + (math.sqrt(2) if dc and dr else 1.0)
                    if nd < dist.get(b, math.inf):
                        dist[b] = nd
                        heapq.heappush(heap, (nd, b))
    return None


@pytest.mark.parametrize("radius, density", [(0.3, 0.2), (0.45, 0.2), (0.7, 0.04)])
def test_grid_paths_are_as_short_as_an_independent_dijkstra_finds(radius, density):
    rng = np.random.default_rng(17)
    compared = found = 0
    for _ in range(5):
        grid = random_map(rng, 12, 16, density)
        finder = PathFinder(grid, radius)
        cells = [(c, r) for r in range(grid.height) for c in range(grid.width) if not grid.blocked[r, c]]
        for _ in range(6):
            s, g = (cells[i] for i in rng.choice(len(cells), 2, replace=False))
            start, goal = grid.centre(*s), grid.centre(*g)
            avoid = [((float(rng.uniform(0, 16)), float(rng.uniform(0, 12))), float(rng.uniform(0.2, 1.0)))
                     for _ in range(int(rng.integers(0, 5)))]
            kept = [(c, k) for c, k in avoid if math.dist(c, start) > k and math.dist(c, goal) > k]
            virtual = {tuple(int(v) for v in c) for c in rng.integers(0, (16, 12), size=(int(rng.integers(0, 3)), 2))}
            virtual -= {s, g}
            want = shortest_grid_length(grid, radius, s, g, kept, sorted(virtual))
            path = finder.find(start, goal, avoid=avoid, blocked_cells=virtual, smooth=False)
            compared += 1
            assert (path is None) == (want is None), (s, g, avoid, virtual)
            if path is not None:
                found += 1
                assert polyline_length(path) == pytest.approx(want, abs=1e-9)
                pulled = finder.find(start, goal, avoid=avoid, blocked_cells=virtual)
                assert polyline_length(pulled) <= want + 1e-9
    assert found >= 5 and compared == 30


def test_a_long_detour_is_still_shortest_and_a_sealed_goal_is_none():
    # the only way round is far longer than the straight line: the search's limit must grow
    # several times; then a disc seals the one gap and the search must give up
    rows = ["." * 40] * 3 + ["@" * 39 + "."] + ["." * 40] * 3
    grid = GridMap.from_rows(rows)
    finder = PathFinder(grid, 0.4)
    start, goal = grid.centre(0, 1), grid.centre(0, 5)
    path = finder.find(start, goal, smooth=False)
    assert polyline_length(path) == pytest.approx(shortest_grid_length(grid, 0.4, (0, 1), (0, 5)), abs=1e-9)
    assert polyline_length(path) > 70
    assert_valid(finder.find(start, goal), grid, 0.4, start, goal)
    assert finder.find(start, goal, avoid=[((39.5, 3.5), 0.3)]) is None
    assert finder.find(start, goal, blocked_cells=[(39, 2)]) is None


def test_many_corners_are_pulled_to_a_valid_chain_no_longer_than_the_grid_path():
    # a serpentine of 60 aisles: over a hundred corners (the dynamic programme over sight lines)
    rows = []
    for k in range(60):
        rows.append("......")
        rows.append("@@@@@." if k % 2 == 0 else ".@@@@@")
    rows.append("......")
    grid = GridMap.from_rows(rows)
    start, goal = (0.5, 0.5), (0.5, len(rows) - 0.5)
    finder = PathFinder(grid, 0.3)
    pulled = finder.find(start, goal)
    assert_valid(pulled, grid, 0.3, start, goal)
    grid_path = finder.find(start, goal, smooth=False)
    assert len(grid_path) > 100
    assert polyline_length(pulled) <= polyline_length(grid_path) + 1e-9


def test_sight_lines_agree_with_exact_geometry_on_random_segments():
    # the compiled sight-line test against GEOS distances to the union of the wall cells
    rng = np.random.default_rng(3)
    blocked = rng.random((14, 18)) < 0.12
    grid = GridMap(blocked, resolution=0.5)
    walls = shapely.union_all([box(c * 0.5, r * 0.5, (c + 1) * 0.5, (r + 1) * 0.5)
                               for r, c in zip(*np.nonzero(blocked))])
    finder = PathFinder(grid, 0.3)
    w, h = 18 * 0.5, 14 * 0.5
    a = rng.random((3000, 2)) * (w, h)
    b = a + rng.normal(0.0, 1.0, (3000, 2))
    b[::50] = a[::50]   # points
    disc = ((4.0, 3.0), 0.6)
    got = finder._free_many(a, b, np.array([[4.0, 3.0, 0.6]]))
    for i in range(len(a)):
        geom = LineString([a[i], b[i]]) if np.any(a[i] != b[i]) else Point(a[i])
        inside = bool(np.all(np.minimum(a[i], b[i]) > 0.3 - 1e-9)) and bool(
            np.all(np.maximum(a[i], b[i]) < (w - 0.3 + 1e-9, h - 0.3 + 1e-9)))
        want = (inside and geom.distance(walls) > 0.3 - 1e-9
                and geom.distance(Point(disc[0])) > disc[1])
        assert got[i] == want, (a[i], b[i])
    assert 300 < got.sum() < len(a) - 300   # both answers are common


def test_radii_that_inflate_alike_share_one_move_graph():
    grid = GridMap.from_rows(["." * 10, "....@@....", "." * 10, "." * 10, "." * 10])
    small, large, wide = PathFinder(grid, 0.35), PathFinder(grid, 0.45), PathFinder(grid, 0.6)
    for finder in (small, large, wide):
        assert finder.find((2.5, 2.5), (7.5, 2.5), avoid=[((5.0, 2.6), 0.3)]) is not None
    assert small._move_graph() is large._move_graph()
    assert wide._move_graph() is not small._move_graph()


def test_a_returned_path_can_be_changed_without_changing_the_next_answer():
    rows = ["..........", "..........", "@@@@@@@...", "..........", ".........."]
    finder = PathFinder(GridMap.from_rows(rows), 0.4)
    first = finder.find((0.5, 0.5), (0.5, 4.5))
    kept = first.copy()
    first[:] = -1.0
    assert np.array_equal(finder.find((0.5, 0.5), (0.5, 4.5)), kept)


def test_path_finding_does_not_import_scipy_ndimage():
    import subprocess
    import sys

    code = ("import sys\n"
            "from fleet_planner.grid import GridMap\n"
            "from fleet_planner.paths import PathFinder\n"
            "grid = GridMap.from_rows(['......', '.@@@..', '......'])\n"
            "assert PathFinder(grid, 0.4).find((0.5, 0.5), (0.5, 2.5), avoid=[((3.0, 2.5), 0.2)]) is not None\n"
            "assert 'scipy.ndimage' not in sys.modules\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_dilate_is_an_exact_binary_dilation():
    from fleet_planner._pathgraph import dilate

    rng = np.random.default_rng(2)
    for k in (1, 2, 3):
        for _ in range(4):
            mask = rng.random((9, 13)) < 0.15
            kernel = rng.random((2 * k + 1, 2 * k + 1)) < 0.6
            kernel = kernel | kernel[::-1, ::-1]        # symmetric, rows may have gaps
            want = np.zeros_like(mask)
            for dr, dc in zip(*np.nonzero(kernel)):
                for r, c in zip(*np.nonzero(mask)):
                    rr, cc = r - (dr - k), c - (dc - k)
                    if 0 <= rr < mask.shape[0] and 0 <= cc < mask.shape[1]:
                        want[rr, cc] = True
            assert np.array_equal(dilate(mask, kernel), want)


def test_threads_sharing_a_move_graph_get_the_answers_of_sequential_calls():
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng(23)
    grid = random_map(rng, 14, 18, 0.15)
    finders = [PathFinder(grid, 0.35), PathFinder(grid, 0.45)]   # one move graph at 1 m cells
    queries = []
    for k in range(40):
        radius = (0.35, 0.45)[k % 2]
        start, goal = random_free_point(rng, grid, radius), random_free_point(rng, grid, radius)
        avoid = [(random_free_point(rng, grid, 0.0), float(rng.uniform(0.3, 0.8))) for _ in range(3)]
        queries.append((k % 2, start, goal, avoid))

    def run(q):
        which, start, goal, avoid = q
        return PathFinder(grid, (0.35, 0.45)[which]).find(start, goal, avoid=avoid)

    sequential = [run(q) for q in queries]
    with ThreadPoolExecutor(4) as pool:
        threaded = list(pool.map(lambda q: finders[q[0]].find(q[1], q[2], avoid=q[3]), queries * 3))
    for got, want in zip(threaded, sequential * 3):
        assert (got is None) == (want is None)
        if got is not None:
            assert polyline_length(got) == pytest.approx(polyline_length(want), abs=1e-9)


def _compare_with_dijkstra(finder: PathFinder, rng: np.random.Generator, trials: int, discs_n: int,
                           radii: tuple[float, float]) -> int:
    """Shortest grid paths round random discs against SciPy's Dijkstra over the same moves, those
    passing within a disc removed up front (the oracle); returns how many pairs had a path."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    from fleet_planner.geometry import segment_point_distance

    graph = finder._move_graph()
    rows, cols = finder.free.shape
    tails, dirs = np.nonzero(np.isfinite(graph.weights))
    heads = graph.heads[tails, dirs]
    w_all = np.where(dirs >= 4, np.sqrt(2.0), 1.0)
    centre = np.column_stack([graph.col - 0.5, graph.row - 0.5])
    free = np.argwhere(finder.free)
    compared = 0
    for _ in range(trials):
        (r0, c0), (r1, c1) = free[rng.choice(len(free), 2, replace=False)]
        start, goal = (c0 + 0.5, r0 + 0.5), (c1 + 0.5, r1 + 0.5)
        discs = [((float(x), float(y)), float(k)) for x, y, k in
                 zip(rng.random(discs_n) * cols, rng.random(discs_n) * rows, rng.uniform(*radii, discs_n))]
        discs = [d for d in discs if np.hypot(*np.subtract(d[0], start)) > d[1]
                 and np.hypot(*np.subtract(d[0], goal)) > d[1]]
        keep = np.ones(len(tails), dtype=bool)
        for (x, y), k in discs:
            keep &= segment_point_distance(centre[tails], centre[heads], np.array([x, y])) > k
        matrix = csr_matrix((w_all[keep], (tails[keep], heads[keep])), shape=(graph.n_cells, graph.n_cells))
        s, g = (graph.node_of[(r + 1) * graph.wp + c + 1] for r, c in ((r0, c0), (r1, c1)))
        want = dijkstra(matrix, indices=s)[g]
        path = finder.find(start, goal, avoid=discs, smooth=False)
        if not np.isfinite(want):
            assert path is None
            continue
        compared += 1
        assert abs(polyline_length(path) - want) < 1e-6
    return compared


def test_compiled_search_finds_the_shortest_grid_path_around_discs():
    rng = np.random.default_rng(5)
    finder = PathFinder(GridMap(rng.random((16, 22)) < 0.18), 0.3)
    assert _compare_with_dijkstra(finder, rng, 40, 6, (0.3, 0.9)) > 20


def test_landmark_bounds_keep_the_search_exact_on_a_warehouse_map():
    # the landmarks (ALT) are made only on maps of LANDMARKS_FROM traversable cells or more: a
    # warehouse of racks and aisles (where the octile distance misses the detours round the racks),
    # with discs cut out of it; oracle: SciPy's Dijkstra over the same moves, cut moves removed up front
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    from fleet_planner import _path_kernels as K
    from fleet_planner._pathgraph import LANDMARKS

    blocked = np.zeros((46, 73), dtype=bool)
    for top in range(3, 43, 4):               # racks 2 rows high, 10 cells wide, 2-cell aisles
        for left in range(3, 69, 12):
            blocked[top:top + 2, left:left + 10] = True
    rng = np.random.default_rng(8)
    blocked |= rng.random(blocked.shape) < 0.02
    finder = PathFinder(GridMap(blocked), 0.4)
    graph = finder._move_graph()
    assert graph.landmarks().shape == (graph.n_cells, LANDMARKS)
    tails, dirs = np.nonzero(np.isfinite(graph.weights))
    full = csr_matrix((np.where(dirs >= 4, np.sqrt(2.0), 1.0), (tails, graph.heads[tails, dirs])),
                      shape=(graph.n_cells, graph.n_cells))
    assert np.array_equal(K.distances(graph.heads, graph.weights, 7), dijkstra(full, indices=7))
    assert _compare_with_dijkstra(finder, rng, 30, 12, (0.5, 1.5)) > 20


def test_component_labels_are_scipys_weak_components_numbered_by_first_node():
    # the path finder prunes a search whose start and goal have different labels, so the labels
    # must never part two nodes joined by a path: on the map's own moves (symmetric) and on moves
    # with no reverse (one-way lanes, not strongly connected) they are the weakly connected parts
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    from fleet_planner import _path_kernels as K

    rng = np.random.default_rng(5)
    counts = []
    for density in (0.1, 0.3, 0.45):
        graph = PathFinder(random_map(rng, 30, 40, density), 0.45)._move_graph()
        for drop in (0.0, 0.6):            # then more than half of the moves one-way
            weights = np.where(rng.random(graph.weights.shape) < drop, np.inf, graph.weights)
            tails, dirs = np.nonzero(np.isfinite(weights))
            adj = csr_matrix((np.ones(len(tails)), (tails, graph.heads[tails, dirs])),
                             shape=(graph.n_cells, graph.n_cells))
            count, want = connected_components(adj, directed=True, connection="weak")
            got = K.components(graph.heads, np.ascontiguousarray(weights))
            first = np.unique(want, return_index=True)[1]          # each part's first node
            renumber = np.empty(count, dtype=np.int64)
            renumber[np.argsort(first)] = np.arange(count)
            assert np.array_equal(got, renumber[want]), (density, drop)
            counts.append(count)
    assert max(counts) > 5          # maps of many parts among them
