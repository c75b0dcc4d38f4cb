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

How it runs: the A* is done in compiled code, by SciPy's Dijkstra on reduced weights
(:mod:`fleet_planner._pathgraph`, exact: optimal for this move set); the move graph, its
components and the disc cuts are built once per map and move table and shared by every finder
with that table.  String pulling tests all its sight lines in one batch, each first by a cheap
exact rejection (a point of the segment inside a wall cell), then by the exact distance tests,
and keeps the shortest chain of vertices in sight of each other.
"""
from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from typing import NamedTuple

import numpy as np
import shapely

from ._pathgraph import DIRS as _DIRS
from ._pathgraph import MoveGraph, dilate
from .geometry import segment_point_distance
from .grid import GridMap

Point = tuple[float, float]
Disc = tuple[Point, float]


_SQRT2 = math.sqrt(2.0)
_TOL = 1e-9
_CUT_CACHE_SIZE = 100_000  # disc centres whose nearby moves are remembered per move graph
_CUT_HEADROOM = 1.25       # a centre's moves are computed out to this times the keep-out asked for
_RESULT_CACHE_SIZE = 256   # find() answers remembered per PathFinder (same inputs, same answer)
_PAIR_BATCH = 5000         # string pulling tests all vertex pairs at once up to this many pairs
_SAMPLES = 17              # points per segment of the cheap wall rejection
# bit d of a cell's move mask says move _DIRS[d] = (dcol, drow) is allowed
_BIT = {d: 1 << k for k, d in enumerate(_DIRS)}


class _ExtraWalls(NamedTuple):
    """The ``blocked_cells`` of one call: their boxes and the wall raster with them."""

    boxes: np.ndarray
    solid: np.ndarray


class _WallIndex:
    """The walls of a map for exact distance tests: one box per horizontal run of blocked cells
    in an STRtree (built in milliseconds; no union of the boxes is needed, since the distance to
    the walls is the smallest distance to a box), and the map's edge, tested analytically."""

    def __init__(self, grid: GridMap):
        res = grid.resolution
        runs = np.diff(np.pad(grid.blocked, ((0, 0), (1, 1))).astype(np.int8), axis=1)
        row, c0 = np.nonzero(runs == 1)
        _, c1 = np.nonzero(runs == -1)   # row-major order: the ends pair up with the starts
        self.tree = shapely.STRtree(shapely.box(c0 * res, row * res, c1 * res, (row + 1) * res))
        self.size = (grid.width * res, grid.height * res)

    @classmethod
    def of(cls, grid: GridMap) -> _WallIndex:
        index = grid.__dict__.get("_path_wall_index")
        if index is None:
            index = grid.__dict__["_path_wall_index"] = cls(grid)
        return index

    def near(self, a: np.ndarray, b: np.ndarray, geoms: np.ndarray, limit: float) -> np.ndarray:
        """True for segments ``a[i] -> b[i]`` (``geoms[i]``) within ``limit`` of a wall or the
        outside of the map.  Inside the (convex) map the distance to its edge is smallest at an
        end of the segment, and an end outside the map is at distance 0."""
        w, h = self.size
        edge = np.minimum(np.minimum(a, b).min(axis=1), np.minimum(w - np.maximum(a[:, 0], b[:, 0]),
                                                                  h - np.maximum(a[:, 1], b[:, 1])))
        out = edge <= limit
        out[self.tree.query(geoms, predicate="dwithin", distance=limit)[0]] = True
        return out


class PathFinder:
    """Shortest-ish collision-free polylines for discs of one radius on one map.

    The inflated free mask and the allowed moves of every cell are computed once here; the move
    graph for the compiled search is built at the first search and kept.  Each :meth:`find` then
    costs one compiled A* (the cut moves of its ``avoid`` discs and ``blocked_cells`` only change
    edge weights) and a few vectorised shapely calls for the smoothing.
    """

    def __init__(self, grid: GridMap, radius: float):
        if not (isinstance(radius, (int, float)) and math.isfinite(radius) and radius > 0):
            raise ValueError(f"PathFinder: radius must be a finite number > 0, got {radius!r}")
        self.grid = grid
        self.radius = float(radius)
        res = grid.resolution
        h, w = grid.height, grid.width
        self._wp = w + 2  # the move table has a one-cell border of non-traversable cells

        # A cell is traversable iff its centre's clearance (distance to the nearest blocked cell's
        # boundary or the map edge) is >= radius.  The distance from a centre to the cell
        # (dc, dr) away is exactly res * hypot(max(|dc|-.5, 0), max(|dr|-.5, 0)), so dilating the
        # walls by the offsets closer than the radius gives the exact mask (no sampling error:
        # a 1-cell aisle, clearance res/2, admits radius res/2 but nothing larger).
        k = int(math.ceil(self.radius / res + 0.5))
        dc, dr = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1))
        box_dist = res * np.hypot(np.maximum(np.abs(dc) - 0.5, 0), np.maximum(np.abs(dr) - 0.5, 0))
        self._kernel = box_dist < self.radius - _TOL
        kr, kc = np.nonzero(self._kernel)
        self._kernel_offsets = np.column_stack([kc - k, kr - k])  # (col, row) offsets
        walls = np.pad(grid.blocked, k, constant_values=True)  # the outside of the map is a wall
        near_wall = dilate(walls, self._kernel)[k:k + h, k:k + w]
        self.free: np.ndarray = ~near_wall  # free[row, col]: the disc fits at the cell centre

        free_p = np.pad(self.free, 1, constant_values=False)
        moves = np.zeros(free_p.shape, dtype=np.uint8)
        inner = free_p[1:-1, 1:-1]

        def shifted(dcol: int, drow: int) -> np.ndarray:
            return free_p[1 + drow:h + 1 + drow, 1 + dcol:w + 1 + dcol]

        for d in _DIRS:
            ok = inner & shifted(*d)
            if d[0] and d[1]:  # no corner cutting
                ok &= shifted(d[0], 0) & shifted(0, d[1])
            moves[1:-1, 1:-1] |= ok.astype(np.uint8) * np.uint8(_BIT[d])
        # a road map of directed lanes carried by the map (fleet_planner.roadmap.with_lanes): only
        # its moves remain, and paths are not straightened (that would leave the lanes)
        self._lanes = getattr(grid, "lanes", None)
        if self._lanes is not None and not self._lanes.restricts:   # no lane restricts a move: the map itself
            self._lanes = None
        if self._lanes is not None:
            moves[1:-1, 1:-1] &= self._lanes.move_mask((h, w))
        self._free_p = free_p
        #: padded wall cells (the outside of the map is a wall): a point inside one is not free
        self._solid = np.pad(grid.blocked, 1, constant_values=True)
        self._moves = moves.ravel()
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
        # undirected moves for disc clearing: (dcol, drow, direction at the tail, at the head)
        self._half_moves = [(dcol, drow, _DIRS.index((dcol, drow)), _DIRS.index((-dcol, -drow)))
                            for dcol, drow in ((1, 0), (0, 1), (1, 1), (-1, 1))]
        self._graph: MoveGraph | None = None
        self._walls = _WallIndex.of(grid)
        self._results: OrderedDict[tuple, np.ndarray | None] = OrderedDict()
        self._results_lock = threading.Lock()

    # -- public -------------------------------------------------------------------------------
    def find(self, start: Point, goal: Point, avoid: Sequence[Disc] = (),
             blocked_cells: Iterable[tuple[int, int]] = (), *, smooth: bool = True) -> np.ndarray | None:
        """A polyline ``(n, 2)`` from exactly ``start`` to exactly ``goal``, or None if there is none.

        ``avoid``: discs ``(centre, keep_out)`` the robot's centre must stay strictly outside; a disc
        that contains ``start`` or ``goal`` is ignored, since it cannot be avoided.
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
        return bool(self._free_many(pa[None], pb[None], _discs(avoid), None)[0])

    # -- the search ---------------------------------------------------------------------------
    def _find(self, start: np.ndarray, goal: np.ndarray, discs: np.ndarray, cells: np.ndarray,
              smooth: bool) -> np.ndarray | None:
        extra_walls = None
        if len(cells):
            res = self.grid.resolution
            boxes = shapely.box(cells[:, 0] * res, cells[:, 1] * res, (cells[:, 0] + 1) * res, (cells[:, 1] + 1) * res)
            solid = self._solid.copy()
            solid[cells[:, 1] + 1, cells[:, 0] + 1] = True
            extra_walls = _ExtraWalls(boxes, solid)

        if smooth and self._free_many(start[None], goal[None], discs, extra_walls)[0]:
            return np.array([start, goal])
        graph = self._move_graph()
        removed, walled = self._removed_edges(graph, discs, cells)
        sources = self._connect(start, walled, discs, extra_walls)
        targets = self._connect(goal, walled, discs, extra_walls)
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
                                 slack, removed)
        if cell_path is None:
            return None
        corners = _corners(np.array(cell_path))
        r, c = np.divmod(corners, self._wp)
        centres = np.column_stack([c - 0.5, r - 0.5]) * self.grid.resolution
        pts = np.vstack([start, centres, goal])
        pts = pts[np.concatenate([[True], np.any(pts[1:] != pts[:-1], axis=1)])]  # start/goal on a centre
        return self._pull_string(pts, discs, extra_walls) if smooth else pts

    def _move_graph(self) -> MoveGraph:
        """The move graph, built at the first search and shared (through the map object) by every
        path finder on this map with the same move table: radii that inflate the walls alike
        share the graph, its components and its cache of disc cuts."""
        if self._graph is None:
            shared = self.grid.__dict__.setdefault("_path_move_graphs", {})
            key = (self._free_p.tobytes(), self._moves.tobytes())
            if key not in shared:
                shared[key] = MoveGraph(self._free_p, self._moves, self._wp)
            self._graph = shared[key]
        return self._graph

    # -- geometry -----------------------------------------------------------------------------
    def _free_many(self, a: np.ndarray, b: np.ndarray, discs: np.ndarray,
                   extra_walls: _ExtraWalls | None) -> np.ndarray:
        """Vectorised :meth:`segment_free` over segments ``a[i] -> b[i]`` (and extra walls).

        A cheap exact rejection comes first: points sampled along each segment (every half cell)
        that fall in a wall cell prove it is not free.  The disc distances and the GEOS distance
        test, which decide, run only on the segments that remain.
        """
        ok = np.ones(len(a), dtype=bool)
        if not len(a):
            return ok
        ok &= ~self._crosses_wall(a, b, self._solid if extra_walls is None else extra_walls.solid)
        if len(discs) and ok.any():  # only discs reaching into the segments' bounding box can touch them
            idx = np.nonzero(ok)[0]
            sa, sb = a[idx], b[idx]
            lo, hi = np.minimum(sa, sb).min(axis=0), np.maximum(sa, sb).max(axis=0)
            reach = discs[:, 2:]
            discs = discs[np.all((discs[:, :2] >= lo - reach) & (discs[:, :2] <= hi + reach), axis=1)]
            if len(discs):
                dist = segment_point_distance(sa[:, None, :], sb[:, None, :], discs[None, :, :2])
                ok[idx] = np.all(dist > discs[None, :, 2], axis=1)
        if not ok.any():
            return ok
        idx = np.nonzero(ok)[0]
        sa, sb = a[idx], b[idx]
        # prepared dwithin is wrong for zero-length lines (GEOS 3.14), so those are points
        degenerate = np.all(sa == sb, axis=1)
        geoms = np.where(degenerate, shapely.points(sa),
                         shapely.linestrings(np.stack([sa, sb], axis=1)))
        limit = self.radius - _TOL
        free = ~self._walls.near(sa, sb, geoms, limit)
        if extra_walls is not None and free.any():
            free[free] = ~shapely.dwithin(extra_walls.boxes[None, :], geoms[free][:, None], limit).any(axis=1)
        ok[idx] = free
        return ok

    def _crosses_wall(self, a: np.ndarray, b: np.ndarray, solid: np.ndarray) -> np.ndarray:
        """True for segments with a sampled point in a wall cell of ``solid`` (padded): such a
        segment touches a wall, so it is not free.  Points are half a cell apart (ends included),
        at most ``_SAMPLES`` per segment: a long segment through the shelves is caught anyway, and
        what is missed is decided by the exact test."""
        res = self.grid.resolution
        count = np.minimum(np.ceil(np.hypot(*(b - a).T) / (0.5 * res)).astype(np.int64) + 1, _SAMPLES)
        first = np.concatenate([[0], np.cumsum(count)[:-1]])
        seg = np.repeat(np.arange(len(a)), count)
        t = (np.arange(int(count.sum())) - first[seg]) / np.maximum(count - 1, 1)[seg]
        p = a[seg] + t[:, None] * (b[seg] - a[seg])
        hp, wp = solid.shape
        col = np.clip(np.floor(p[:, 0] / res).astype(np.int64) + 1, 0, wp - 1)
        row = np.clip(np.floor(p[:, 1] / res).astype(np.int64) + 1, 0, hp - 1)
        return np.logical_or.reduceat(solid[row, col], first)

    def _pull_string(self, pts: np.ndarray, discs: np.ndarray, extra_walls: _ExtraWalls | None) -> np.ndarray:
        """String pulling: the shortest chain of vertices, each in free sight of the next.

        Consecutive vertices are joined by grid moves (or checked connector pieces), so keeping
        them is always allowed and the result is never less valid than the grid path.  The sight
        lines of all pairs of vertices are tested in one batch and the shortest chain over them
        is found by a compiled Dijkstra (never longer than jumping greedily to the farthest
        vertex in sight); for very long vertex lists the greedy jumps are kept, with the sight
        lines from each kept vertex tested in one batch.
        """
        n = len(pts)
        if n <= 2:
            return pts
        if n * (n - 1) // 2 > _PAIR_BATCH:
            out = [0]
            k = 0
            while k < n - 1:
                later = np.arange(k + 2, n)
                ok = self._free_many(np.repeat(pts[k:k + 1], len(later), axis=0), pts[later], discs, extra_walls)
                seen = later[ok]
                k = int(seen[-1]) if len(seen) else k + 1
                out.append(k)
            return pts[out]
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import dijkstra

        i, j = np.nonzero(np.triu(np.ones((n, n), dtype=bool), 2))
        ok = self._free_many(pts[i], pts[j], discs, extra_walls)
        i = np.concatenate([np.arange(n - 1), i[ok]])
        j = np.concatenate([np.arange(1, n), j[ok]])
        # lengths + a tiny cost per vertex: of equal chains, the one with fewer vertices
        length = np.hypot(*(pts[j] - pts[i]).T) + 1e-12
        _, pred = dijkstra(csr_matrix((length, (i, j)), shape=(n, n)), indices=0, return_predecessors=True)
        out = [n - 1]
        while out[-1] != 0:
            out.append(int(pred[out[-1]]))
        return pts[out[::-1]]

    # -- cut moves ----------------------------------------------------------------------------
    def _extra_cells(self, blocked_cells: Iterable[tuple[int, int]]) -> np.ndarray:
        cells = np.array(list(blocked_cells), dtype=float).reshape(-1, 2)
        if not len(cells):
            return np.zeros((0, 2), dtype=np.int64)
        if not np.all(cells == np.round(cells)):
            raise ValueError("blocked_cells: cells must be integer (col, row) pairs")
        cells = cells.astype(np.int64)
        inside = ((cells[:, 0] >= 0) & (cells[:, 0] < self.grid.width)
                  & (cells[:, 1] >= 0) & (cells[:, 1] < self.grid.height))
        return np.unique(cells[inside], axis=0)

    def _removed_edges(self, graph: MoveGraph, discs: np.ndarray,
                       cells: np.ndarray) -> tuple[np.ndarray, frozenset[int]]:
        """Edge ids of the moves lost to the extra walls (cells too close to them stop being
        traversable; their flat indices are returned too) and of every move through a disc."""
        h, w, wp = self.grid.height, self.grid.width, self._wp
        parts = [np.zeros(0, dtype=np.int64)]
        walled: frozenset[int] = frozenset()
        if len(cells):
            near = (cells[:, None, :] + self._kernel_offsets[None]).reshape(-1, 2)
            inside = (near[:, 0] >= 0) & (near[:, 0] < w) & (near[:, 1] >= 0) & (near[:, 1] < h)
            near = near[inside]
            near = near[self.free[near[:, 1], near[:, 0]]]
            flat = np.unique((near[:, 1] + 1) * wp + near[:, 0] + 1)
            walled = frozenset(flat.tolist())
            lost = np.zeros_like(self._moves)
            for rel, mask in self._lost:
                lost[flat + rel] |= np.uint8(mask)
            lost &= self._moves
            changed = np.nonzero(lost)[0]
            parts.append(graph.edges(changed, lost[changed]))
        if len(discs):
            parts.append(self._disc_edges(graph, discs))
        return np.concatenate(parts), walled

    def _disc_edges(self, graph: MoveGraph, discs: np.ndarray) -> np.ndarray:
        """Edge ids of every move passing within a disc (distance <= keep-out).

        The same centres (parked robots) come back in call after call with keep-outs that differ
        by the other robot's radius, so each centre's nearby moves and their distances to it are
        computed once (out to a little more than the keep-out asked for, in one vectorised batch
        for all new centres) and each call only compares those distances with its keep-outs.
        """
        keys = list(zip(discs[:, 0].tolist(), discs[:, 1].tolist()))
        keep_outs = discs[:, 2].tolist()
        new: dict[tuple[float, float], float] = {}
        for key, k in zip(keys, keep_outs):
            entry = graph.cuts.get(key)
            if entry is None or entry[0] < k:
                new[key] = max(new.get(key, 0.0), k * _CUT_HEADROOM)
        if new:
            if len(graph.cuts) + len(new) > _CUT_CACHE_SIZE:
                graph.cuts.clear()
            graph.cuts.update(self._compute_cuts(graph, new))
        entries = [graph.cuts[key] for key in keys]
        eids = np.concatenate([e[1] for e in entries])
        dist = np.concatenate([e[2] for e in entries])
        limit = np.repeat(discs[:, 2], [len(e[1]) for e in entries])
        return eids[dist <= limit]

    def _compute_cuts(self, graph: MoveGraph, want: dict[tuple[float, float], float]) -> dict:
        res, h, w, wp = self.grid.resolution, self.grid.height, self.grid.width, self._wp
        keys = list(want)
        centres = np.array(keys, dtype=float)
        keep = np.array([want[k] for k in keys])
        # a move (length <= sqrt(2) res) passing within k of P has both ends within k + sqrt(2) res
        reach = keep + _SQRT2 * res + _TOL
        span = int(math.ceil(float(reach.max()) / res)) + 1
        wc, wr = (a.ravel() for a in np.meshgrid(np.arange(-span, span + 1), np.arange(-span, span + 1)))
        base = np.floor(centres / res).astype(np.int64)
        col = (base[:, 0, None] + wc[None]).ravel()
        row = (base[:, 1, None] + wr[None]).ravel()
        which = np.repeat(np.arange(len(keys)), wc.size)
        tail = np.column_stack([(col + 0.5) * res, (row + 0.5) * res])
        near = ((col >= 0) & (col < w) & (row >= 0) & (row < h)
                & (np.hypot(*(tail - centres[which]).T) <= reach[which]))
        col, row, which, tail = col[near], row[near], which[near], tail[near]
        flat = (row + 1) * wp + col + 1
        out_eid, out_dist, out_which = [], [], []
        for dcol, drow, d_tail, d_head in self._half_moves:
            has = graph.has_move(flat, d_tail)  # moves are symmetric: the reverse edge exists too
            if not has.any():
                continue
            t, f, wh = tail[has], flat[has], which[has]
            dist = segment_point_distance(t, t + (dcol * res, drow * res), centres[wh])
            hit = dist <= keep[wh]
            fwd = graph.edge_ids(f[hit], d_tail)
            back = graph.edge_ids(f[hit] + dcol + drow * wp, d_head)
            out_eid += [fwd, back]
            out_dist += [dist[hit]] * 2
            out_which += [wh[hit]] * 2
        if not out_eid:
            empty = (np.zeros(0, dtype=np.int64), np.zeros(0))
            return {key: (want[key], *empty) for key in keys}
        all_eid, all_dist, all_which = (np.concatenate(x) for x in (out_eid, out_dist, out_which))
        order = np.argsort(all_which, kind="stable")
        bounds = np.searchsorted(all_which[order], np.arange(len(keys) + 1))
        all_eid, all_dist = all_eid[order], all_dist[order]
        return {key: (want[key], all_eid[bounds[n]:bounds[n + 1]], all_dist[bounds[n]:bounds[n + 1]])
                for n, key in enumerate(keys)}

    def _connect(self, p: np.ndarray, walled: frozenset[int], discs: np.ndarray,
                 extra_walls: _ExtraWalls | None) -> dict[int, float]:
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
            ok = self._free_many(np.repeat(p[None], len(centres), axis=0), centres, discs, extra_walls)
            found = {(r + 1) * self._wp + c + 1: float(np.hypot(*(centre - p))) / res
                     for (c, r), centre, good in zip(cand, centres, ok) if good}
            if found:
                return found
        return {}


def _corners(path: np.ndarray) -> np.ndarray:
    """The cells of a grid path (flat indices) where its direction changes (plus both ends)."""
    if len(path) <= 2:
        return path
    step = np.diff(path)
    return path[np.concatenate([[True], step[1:] != step[:-1], [True]])]


def _point(name: str, p) -> np.ndarray:
    arr = np.asarray(p, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected a finite (x, y) point, got {p!r}")
    return arr


def _discs(avoid: Sequence[Disc]) -> np.ndarray:
    """``avoid`` as an ``(n, 3)`` array of (x, y, keep_out)."""
    if not len(avoid):
        return np.zeros((0, 3))
    try:
        arr = np.array([(c[0], c[1], k) for c, k in avoid], dtype=float)
    except (TypeError, ValueError, IndexError) as exc:
        raise ValueError(f"avoid: expected ((x, y), keep_out) pairs ({exc})") from exc
    if not np.all(np.isfinite(arr)) or np.any(arr[:, 2] < 0):
        raise ValueError("avoid: centres must be finite and keep-out radii finite and >= 0")
    return arr
