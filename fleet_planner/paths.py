"""Single-robot path finding for a disc robot on a :class:`~fleet_planner.grid.GridMap`.

:class:`PathFinder` runs an 8-connected A* over the cells whose centre keeps the disc clear of
walls, then straightens the cell path by string pulling in continuous geometry.  Both steps keep
the same guarantee, so the answer is never less valid than the grid path:

* walls: every output segment stays at least ``radius`` from every blocked cell and the map edge;
* ``avoid`` discs: the robot's centre stays strictly outside each keep-out disc along the whole
  polyline (these are other robots parked on their start or goal);
* ``blocked_cells``: extra cells treated exactly like walls (BBMRCA's "virtual walls").

Why grid moves are safe without a continuous check: cells and walls are aligned on the same
lattice, so along a move between two neighbouring centres the distance to any wall cell is smallest
at an end of the move or of a side of the 2x2 block it crosses; requiring both orthogonal
neighbours of a diagonal move to be traversable (no corner cutting) therefore keeps the whole move
as clear as its cells.  Keep-out discs are not on the lattice, so moves that pass within a disc are
removed exactly (segment-to-centre distance), not only the cells whose centre lies inside it.

How it runs (issue 8): the A* is compiled (numba, :mod:`fleet_planner._path_kernels`, exact:
optimal for this move set); the move graph and its components are built once per map and move
table and shared by every finder with that table; the moves through the ``avoid`` discs are cut
in place by the search.  String pulling is a compiled dynamic programme for the shortest chain of
vertices in sight of each other, where a sight line is tested by its exact distance to the wall
cells it passes near (no GEOS, no SciPy: neither is imported by a search).
"""
from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Iterable, Sequence

import numpy as np

from . import _path_kernels as K
from ._pathgraph import DIRS as _DIRS
from ._pathgraph import MoveGraph, dilate
from .grid import GridMap

Point = tuple[float, float]
Disc = tuple[Point, float]


_SQRT2 = math.sqrt(2.0)
_TOL = 1e-9
_NO_CELLS = np.zeros((0, 2), dtype=np.int64)   # no extra wall cells (read-only)
_NO_CELLS.flags.writeable = False
_RESULT_CACHE_SIZE = 256   # find() answers remembered per PathFinder (same inputs, same answer)
# bit d of a cell's move mask says move _DIRS[d] = (dcol, drow) is allowed
_BIT = {d: 1 << k for k, d in enumerate(_DIRS)}


def inflation_kernel(resolution: float, radius: float) -> np.ndarray:
    """The cell offsets (a (2k+1) x (2k+1) boolean mask round the centre) whose box lies closer than
    ``radius`` to a cell's centre: a cell is traversable for a disc of ``radius`` iff none of them is a wall
    (:class:`PathFinder`). Two radii with equal kernels inflate every map of this resolution alike."""
    k = int(math.ceil(radius / resolution + 0.5))
    dc, dr = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1))
    box_dist = resolution * np.hypot(np.maximum(np.abs(dc) - 0.5, 0), np.maximum(np.abs(dr) - 0.5, 0))
    return box_dist < radius - _TOL


class PathFinder:
    """Shortest-ish collision-free polylines for discs of one radius on one map.

    The inflated free mask and the allowed moves of every cell are computed once here; the move
    graph for the compiled search is built at the first search and kept.  Each :meth:`find` then
    costs one compiled A* (the cut moves of its ``avoid`` discs and ``blocked_cells`` are marked
    per search) and one compiled string pulling.
    """

    def __init__(self, grid: GridMap, radius: float):
        if not (isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0):
            raise ValueError(f"PathFinder: radius must be a finite number > 0, got {radius!r}")
        self.grid = grid
        self.radius = float(radius)
        res = grid.resolution
        self._wp = grid.width + 2  # the move table has a one-cell border of non-traversable cells

        # A cell is traversable iff its centre's clearance (distance to the nearest blocked cell's
        # boundary or the map edge) is >= radius.  The distance from a centre to the cell
        # (dc, dr) away is exactly res * hypot(max(|dc|-.5, 0), max(|dr|-.5, 0)), so dilating the
        # walls by the offsets closer than the radius gives the exact mask (no sampling error:
        # a 1-cell aisle, clearance res/2, admits radius res/2 but nothing larger).
        self._kernel = inflation_kernel(res, self.radius)
        k = self._kernel.shape[0] // 2
        kr, kc = np.nonzero(self._kernel)
        self._kernel_offsets = np.column_stack([kc - k, kr - k])  # (col, row) offsets
        # a road map of directed lanes carried by the map (fleet_planner.roadmap.with_lanes): only
        # its moves remain, and paths are not straightened (that would leave the lanes)
        self._lanes = getattr(grid, "lanes", None)
        if self._lanes is not None and not self._lanes.restricts:   # no lane restricts a move: the map itself
            self._lanes = None
        #: padded wall cells (the outside of the map is a wall): a point inside one is not free
        self._blocked = np.ascontiguousarray(grid.blocked, dtype=bool)
        # the inflated mask and the move table depend on the radius only through the kernel: finders
        # of radii with the same kernel on the same map share them (kept on the map object, as the
        # move graphs are; keyed by the walls too, since a GridMap may be changed in place). Radii
        # rounded to the centimetre (md) made ten finders of one kernel at 100 robots: 25-30 ms of
        # every plan on the benchmark maps.
        shared = grid.__dict__.setdefault("_path_move_tables", {}) if self._lanes is None else {}
        key = (self._kernel.shape, self._kernel.tobytes(), self._blocked.shape, self._blocked.tobytes())
        if key not in shared:
            if len(shared) >= 8:
                shared.clear()
            shared[key] = self._move_table(k)
        self.free, self._free_p, self._moves = shared[key]
        # when a cell b stops being traversable, its neighbour at b + rel loses these moves:
        # the move into b, and the diagonal moves that cut b's corner
        self._lost = []
        for rel in [(dcol, drow) for drow in (-1, 0, 1) for dcol in (-1, 0, 1)]:
            if rel == (0, 0):
                mask = 0xFF
            else:
                mask = _BIT[(-rel[0], -rel[1])]
                if rel[1] == 0:
                    mask |= _BIT[(-rel[0], 1)] | _BIT[(-rel[0], -1)]
                if rel[0] == 0:
                    mask |= _BIT[(1, -rel[1])] | _BIT[(-1, -rel[1])]
            self._lost.append((rel[0] + rel[1] * self._wp, mask))
        self._graph: MoveGraph | None = None
        self._results: OrderedDict[tuple, np.ndarray | None] = OrderedDict()
        self._results_lock = threading.Lock()

    def _move_table(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(free mask, padded free mask, padded move table) for this finder's kernel (half-width
        ``k``) on its map: read-only arrays, shared by the finders whose kernel is the same."""
        h, w = self.grid.height, self.grid.width
        walls = np.pad(self._blocked, k, constant_values=True)  # the outside of the map is a wall
        near_wall = dilate(walls, self._kernel)[k:k + h, k:k + w]
        free = ~near_wall  # free[row, col]: the disc fits at the cell centre
        free_p = np.pad(free, 1, constant_values=False)
        moves = np.zeros(free_p.shape, dtype=np.uint8)
        inner = free_p[1:-1, 1:-1]

        def shifted(dcol: int, drow: int) -> np.ndarray:
            return free_p[1 + drow:h + 1 + drow, 1 + dcol:w + 1 + dcol]

        for d in _DIRS:
            ok = inner & shifted(*d)
            if d[0] and d[1]:  # no corner cutting
                ok &= shifted(d[0], 0) & shifted(0, d[1])
            moves[1:-1, 1:-1] |= ok.astype(np.uint8) * np.uint8(_BIT[d])
        if self._lanes is not None:
            moves[1:-1, 1:-1] &= self._lanes.move_mask((h, w))
        flat = moves.ravel()
        for arr in (free, free_p, flat):
            arr.flags.writeable = False
        return free, free_p, flat

    # -- public -------------------------------------------------------------------------------
    def find(self, start: Point, goal: Point, avoid: Sequence[Disc] | np.ndarray = (),
             blocked_cells: Iterable[tuple[int, int]] = (), *, smooth: bool = True) -> np.ndarray | None:
        """A polyline ``(n, 2)`` from exactly ``start`` to exactly ``goal``, or None if there is none.

        ``avoid``: discs ``(centre, keep_out)`` the robot's centre must stay strictly outside (or an
        ``(n, 3)`` array of rows ``(x, y, keep_out)``); a disc that contains ``start`` or ``goal`` is
        ignored, since it cannot be avoided.
        ``blocked_cells``: extra ``(col, row)`` cells treated as walls (cells off the map are
        walls already and are skipped).
        ``smooth=False`` returns the grid path itself (start, the cells where it turns, goal), to
        inspect or plot what the smoothing started from.
        """
        a, b = _point("start", start), _point("goal", goal)
        smooth = smooth and self._lanes is None
        discs = _discs(avoid)
        if len(discs):
            keep = ((np.hypot(*(discs[:, :2] - a).T) > discs[:, 2])
                    & (np.hypot(*(discs[:, :2] - b).T) > discs[:, 2]))
            discs = discs[keep]
        cells = self._extra_cells(blocked_cells)
        key = (a.tobytes(), b.tobytes(), discs.tobytes(), cells.tobytes(), smooth)
        with self._results_lock:
            hit = key in self._results
            if hit:
                self._results.move_to_end(key)
                found = self._results[key]
        if not hit:
            found = self._find(a, b, discs, cells, smooth)
            with self._results_lock:
                self._results[key] = found
                if len(self._results) > _RESULT_CACHE_SIZE:
                    self._results.popitem(last=False)
        return None if found is None else found.copy()

    def segment_free(self, a: Point, b: Point, avoid: Sequence[Disc] = ()) -> bool:
        """True when a disc of this radius can sweep from ``a`` to ``b`` in a straight line.

        The disc stays at least ``radius`` from walls and the map edge, and its centre strictly
        outside every ``avoid`` disc ``(centre, keep_out)`` (no disc is ignored here).
        """
        pa, pb = _point("a", a), _point("b", b)
        return bool(self._free_many(pa[None], pb[None], _discs(avoid))[0])

    # -- the search ---------------------------------------------------------------------------
    def _find(self, start: np.ndarray, goal: np.ndarray, discs: np.ndarray, cells: np.ndarray,
              smooth: bool) -> np.ndarray | None:
        walls = self._blocked   # the wall cells, with the extra walls of this call
        if len(cells):
            walls = walls.copy()
            walls[cells[:, 1], cells[:, 0]] = True
        if smooth and self._free_many(start[None], goal[None], discs, walls)[0]:
            return np.array([start, goal])
        graph = self._move_graph()
        removed, walled = self._removed_edges(graph, cells)
        sources = self._connect(start, walled, discs, walls)
        targets = self._connect(goal, walled, discs, walls)
        if not sources or not targets:
            return None
        # extra walls and discs only cut the static map further: different static parts = no path
        labels = graph.labels()
        src_comps = {int(labels[i]) for i in sources}
        if not any(int(labels[i]) in src_comps for i in targets):
            return None
        goal_col, goal_row = self.grid.cell_of(*goal)
        g_flat = (goal_row + 1) * self._wp + goal_col + 1
        # targets other than the goal's own cell are its neighbours: shrink the heuristic by the
        # longest step so it stays admissible
        slack = 0.0 if list(targets) == [g_flat] else _SQRT2
        start_col, start_row = self.grid.cell_of(*start)
        cell_path = graph.search(sources, targets, (start_col + 1, start_row + 1), (goal_col + 1, goal_row + 1),
                                 slack, removed, discs, self.grid.resolution)
        if cell_path is None:
            return None
        corners = _corners(np.array(cell_path))
        r, c = np.divmod(corners, self._wp)
        centres = np.column_stack([c - 0.5, r - 0.5]) * self.grid.resolution
        pts = np.vstack([start, centres, goal])
        pts = pts[np.concatenate([[True], np.any(pts[1:] != pts[:-1], axis=1)])]  # start/goal on a centre
        return self._pull_string(pts, discs, walls) if smooth else pts

    def _move_graph(self) -> MoveGraph:
        """The move graph, built at the first search and shared (through the map object) by every
        path finder on this map with the same move table: radii that inflate the walls alike
        share the graph, its components and its cache of disc cuts."""
        if self._graph is None:
            shared = self.grid.__dict__.setdefault("_path_move_graphs", {})
            key = (self._free_p.tobytes(), self._moves.tobytes())
            if key not in shared:
                # the map's own moves are symmetric (a move and its reverse test the same cells)
                shared[key] = MoveGraph(self._free_p, self._moves, self._wp,
                                        symmetric=True if self._lanes is None else None)
            self._graph = shared[key]
        return self._graph

    # -- geometry -----------------------------------------------------------------------------
    def _free_many(self, a: np.ndarray, b: np.ndarray, discs: np.ndarray,
                   walls: np.ndarray | None = None) -> np.ndarray:
        """Vectorised :meth:`segment_free` over segments ``a[i] -> b[i]``, against the wall cells
        ``walls`` (``blocked[row, col]``; the map's own by default): exact distances to the wall
        cells each segment passes near, in compiled code (:func:`fleet_planner._path_kernels.segment_free`)."""
        if not len(a):
            return np.ones(0, dtype=bool)
        discs = _discs_near(discs, np.vstack([a, b]))
        return K.segments_free(np.ascontiguousarray(a, dtype=float), np.ascontiguousarray(b, dtype=float),
                               self._blocked if walls is None else walls, float(self.grid.resolution),
                               self.radius - _TOL, np.ascontiguousarray(discs, dtype=float).reshape(-1, 3))

    def _pull_string(self, pts: np.ndarray, discs: np.ndarray, walls: np.ndarray) -> np.ndarray:
        """String pulling: the shortest chain of vertices, each in free sight of the next.

        Consecutive vertices are joined by grid moves (or checked connector pieces), so keeping
        them is always allowed and the result is never less valid than the grid path.  The chain
        is a dynamic programme over the vertices in compiled code, which tests a sight line only
        where it would shorten the chain (:func:`fleet_planner._path_kernels.pull_string`).
        """
        if len(pts) <= 2:
            return pts
        keep = K.pull_string(np.ascontiguousarray(pts, dtype=float), walls, float(self.grid.resolution),
                             self.radius - _TOL, _discs_near(discs, pts))
        return pts[keep]

    # -- cut moves ----------------------------------------------------------------------------
    def _extra_cells(self, blocked_cells: Iterable[tuple[int, int]]) -> np.ndarray:
        if isinstance(blocked_cells, (tuple, list)) and not blocked_cells:
            return _NO_CELLS
        cells = np.array(list(blocked_cells), dtype=float).reshape(-1, 2)
        if not len(cells):
            return _NO_CELLS
        if not np.all(cells == np.round(cells)):
            raise ValueError("blocked_cells: cells must be integer (col, row) pairs")
        cells = cells.astype(np.int64)
        inside = ((cells[:, 0] >= 0) & (cells[:, 0] < self.grid.width)
                  & (cells[:, 1] >= 0) & (cells[:, 1] < self.grid.height))
        return np.unique(cells[inside], axis=0)

    def _removed_edges(self, graph: MoveGraph, cells: np.ndarray) -> tuple[np.ndarray, frozenset[int]]:
        """Edge ids of the moves lost to the extra walls (cells too close to them stop being
        traversable; their flat indices are returned too).  The moves through the ``avoid`` discs
        are cut by the search itself (:func:`fleet_planner._path_kernels.astar`)."""
        h, w, wp = self.grid.height, self.grid.width, self._wp
        if not len(cells):
            return np.zeros(0, dtype=np.int64), frozenset()
        near = (cells[:, None, :] + self._kernel_offsets[None]).reshape(-1, 2)
        inside = (near[:, 0] >= 0) & (near[:, 0] < w) & (near[:, 1] >= 0) & (near[:, 1] < h)
        near = near[inside]
        near = near[self.free[near[:, 1], near[:, 0]]]
        flat = np.unique((near[:, 1] + 1) * wp + near[:, 0] + 1)
        lost = np.zeros_like(self._moves)
        for rel, mask in self._lost:
            lost[flat + rel] |= np.uint8(mask)
        lost &= self._moves
        changed = np.nonzero(lost)[0]
        return graph.edges(changed, lost[changed]), frozenset(flat.tolist())

    def _connect(self, p: np.ndarray, walled: frozenset[int], discs: np.ndarray,
                 walls: np.ndarray) -> dict[int, float]:
        """Cells a point joins the grid at, with the connector length in cells.

        The point's own cell if the straight piece to its centre is free, else those of the 8
        neighbours with a free straight piece (a point off-centre near a wall may need that).
        """
        res = self.grid.resolution
        col, row = (int(v) for v in np.floor(p / res))
        own = (row + 1) * self._wp + col + 1
        if (self.grid.in_bounds(col, row) and self.free[row, col] and own not in walled
                and p[0] == (col + 0.5) * res and p[1] == (row + 0.5) * res):
            # at its cell's centre: the connector is that point, clear of the walls (the cell is
            # traversable) and of the extra walls (not walled); the discs around it were dropped
            return {own: 0.0}
        for ring in (((0, 0),), _DIRS):
            cand = [(col + dc, row + dr) for dc, dr in ring
                    if self.grid.in_bounds(col + dc, row + dr) and self.free[row + dr, col + dc]
                    and (row + dr + 1) * self._wp + col + dc + 1 not in walled]
            if not cand:
                continue
            centres = (np.array(cand, dtype=float) + 0.5) * res
            ok = self._free_many(np.repeat(p[None], len(centres), axis=0), centres, discs, walls)
            found = {(r + 1) * self._wp + c + 1: float(np.hypot(*(centre - p))) / res
                     for (c, r), centre, good in zip(cand, centres, ok) if good}
            if found:
                return found
        return {}


_WARM = False


def warm_up() -> None:
    """Load (or compile: numba's on-disk cache) every kernel of path finding with the argument types
    of real searches, once per process, so that no planning budget is spent on it (a cold cache
    compiles for seconds): a search round a wall with a keep-out disc, one with an extra wall cell,
    a straight sight line, the graph's components and a distance field, the aisle count of
    :mod:`fleet_planner.planners.md_crowd`."""
    global _WARM
    if _WARM:
        return
    blocked = np.zeros((5, 7), dtype=bool)
    blocked[:4, 3] = True   # a wall with a gap at the top row
    finder = PathFinder(GridMap(blocked, 1.0, "warm-up"), 0.3)
    finder.find((0.5, 0.5), (6.5, 0.5), avoid=[((1.5, 4.5), 0.4)])
    finder.find((0.5, 0.5), (6.5, 0.5), blocked_cells=[(0, 4)])
    finder.find((0.5, 4.5), (6.5, 4.5))
    graph = finder._move_graph()
    graph.labels()
    K.distances(graph.heads, graph.weights, 0)
    K.count_components4(np.ascontiguousarray(blocked))
    _WARM = True


def _corners(path: np.ndarray) -> np.ndarray:
    """The cells of a grid path (flat indices) where its direction changes (plus both ends)."""
    if len(path) <= 2:
        return path
    step = np.diff(path)
    return path[np.concatenate([[True], step[1:] != step[:-1], [True]])]


def _discs_near(discs: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """The discs (rows x, y, keep-out) that reach into the bounding box of ``pts``: the only ones
    a segment between two of those points can come within keep-out of."""
    discs = np.ascontiguousarray(discs, dtype=float).reshape(-1, 3)
    if len(discs) < 8:
        return discs
    (x0, y0), (x1, y1) = pts.min(axis=0).tolist(), pts.max(axis=0).tolist()
    x, y, reach = discs[:, 0], discs[:, 1], discs[:, 2]
    return discs[(x >= x0 - reach) & (x <= x1 + reach) & (y >= y0 - reach) & (y <= y1 + reach)]


def _point(name: str, p) -> np.ndarray:
    arr = np.asarray(p, dtype=float)
    if arr.shape != (2,) or not (math.isfinite(arr[0]) and math.isfinite(arr[1])):
        raise ValueError(f"{name}: expected a finite (x, y) point, got {p!r}")
    return arr


def _discs(avoid: Sequence[Disc] | np.ndarray) -> np.ndarray:
    """``avoid`` as an ``(n, 3)`` array of (x, y, keep_out) (given as such an array, or as pairs)."""
    if not len(avoid):
        return np.zeros((0, 3))
    if isinstance(avoid, np.ndarray):
        if avoid.ndim != 2 or avoid.shape[1] != 3:
            raise ValueError(f"avoid: expected an (n, 3) array of (x, y, keep_out) rows, got shape {avoid.shape}")
        arr = np.asarray(avoid, dtype=float)
    else:
        try:
            arr = np.array([(c[0], c[1], k) for c, k in avoid], dtype=float)
        except (TypeError, ValueError, IndexError) as exc:
            raise ValueError(f"avoid: expected ((x, y), keep_out) pairs ({exc})") from exc
    if not np.all(np.isfinite(arr)) or np.any(arr[:, 2] < 0):
        raise ValueError("avoid: centres must be finite and keep-out radii finite and >= 0")
    return arr
