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
"""
from __future__ import annotations

import heapq
import math
from typing import Iterable, Sequence

import numpy as np
import shapely
from scipy import ndimage

from .geometry import segment_point_distance
from .grid import GridMap

Point = tuple[float, float]
Disc = tuple[Point, float]


_SQRT2 = math.sqrt(2.0)
_TOL = 1e-9
_CUT_CACHE_SIZE = 100_000  # discs whose move cuts are remembered per PathFinder
# the 8 moves as (dcol, drow); bit d of a cell's move mask says move d is allowed
_DIRS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))
_BIT = {d: 1 << k for k, d in enumerate(_DIRS)}


class PathFinder:
    """Shortest-ish collision-free polylines for discs of one radius on one map.

    The inflated free mask and the allowed moves of every cell are computed once here; each
    :meth:`find` then costs one A* (plus one copy of the move table when it has ``avoid`` discs
    or ``blocked_cells``) and a few vectorised shapely calls for the smoothing.
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
        near_wall = ndimage.binary_dilation(walls, structure=self._kernel)[k:k + h, k:k + w]
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
        self._moves = moves.ravel()
        self._moves_list: list[int] = self._moves.tolist()
        # for every move mask, the moves it allows as (flat offset, cost in cells)
        steps = [(dcol + drow * self._wp, _SQRT2 if dcol and drow else 1.0) for dcol, drow in _DIRS]
        self._steps_of = [tuple(steps[b] for b in range(8) if m >> b & 1) for m in range(256)]
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
        # undirected moves for disc clearing: (dcol, drow, bit at the tail, bit at the head)
        self._half_moves = [(dcol, drow, _BIT[(dcol, drow)], _BIT[(-dcol, -drow)])
                            for dcol, drow in ((1, 0), (0, 1), (1, 1), (-1, 1))]
        self._component = ndimage.label(self.free)[0]  # 4-connected = reachable without corner cuts
        grid.obstacle_geometry  # build the (cached) wall geometry now, not inside the first find()
        self._cut_cache: dict[tuple[float, float, float], tuple[np.ndarray, np.ndarray]] = {}

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
        start = _point("start", start)
        goal = _point("goal", goal)
        discs = _discs(avoid)
        if len(discs):
            keep = ((np.hypot(*(discs[:, :2] - start).T) > discs[:, 2])
                    & (np.hypot(*(discs[:, :2] - goal).T) > discs[:, 2]))
            discs = discs[keep]
        cells = self._extra_cells(blocked_cells)
        extra_walls = None
        if len(cells):
            res = self.grid.resolution
            extra_walls = shapely.union_all(shapely.box(cells[:, 0] * res, cells[:, 1] * res,
                                                        (cells[:, 0] + 1) * res, (cells[:, 1] + 1) * res))
            shapely.prepare(extra_walls)

        if smooth and self._free_many(start[None], goal[None], discs, extra_walls)[0]:
            return np.array([start, goal])
        moves, walled = self._moves_list, frozenset()
        if len(discs) or len(cells):
            moves, walled = self._moves_with(discs, cells)
        sources = self._connect(start, walled, discs, extra_walls)
        targets = self._connect(goal, walled, discs, extra_walls)
        if not sources or not targets:
            return None
        # extra walls and discs only cut the static map further: different static parts = no path
        comps = self._component.ravel()
        src_comps = {comps[self._unpad(i)] for i in sources}
        if not any(comps[self._unpad(i)] in src_comps for i in targets):
            return None
        goal_cell = self.grid.cell_of(*goal)
        cell_path = self._astar(moves, sources, targets, goal_cell)
        if cell_path is None:
            return None
        pts = np.array([start] + [self._centre(i) for i in _corners(cell_path)] + [goal])
        pts = pts[np.concatenate([[True], np.any(pts[1:] != pts[:-1], axis=1)])]  # start/goal on a centre
        return self._pull_string(pts, discs, extra_walls) if smooth else pts

    def segment_free(self, a: Point, b: Point, avoid: Sequence[Disc] = ()) -> bool:
        """True when a disc of this radius can sweep from ``a`` to ``b`` in a straight line.

        The disc stays at least ``radius`` from walls and the map edge, and its centre strictly
        outside every ``avoid`` disc ``(centre, keep_out)`` (no disc is ignored here).
        """
        a, b = _point("a", a), _point("b", b)
        return bool(self._free_many(a[None], b[None], _discs(avoid), None)[0])

    # -- geometry -----------------------------------------------------------------------------
    def _free_many(self, a: np.ndarray, b: np.ndarray, discs: np.ndarray, extra_walls) -> np.ndarray:
        """Vectorised :meth:`segment_free` over segments ``a[i] -> b[i]``."""
        ok = np.ones(len(a), dtype=bool)
        if len(discs):  # only discs reaching into the segments' bounding box can touch them
            lo, hi = np.minimum(a, b).min(axis=0), np.maximum(a, b).max(axis=0)
            reach = discs[:, 2:]
            discs = discs[np.all((discs[:, :2] >= lo - reach) & (discs[:, :2] <= hi + reach), axis=1)]
        if len(discs):
            dist = segment_point_distance(a[:, None, :], b[:, None, :], discs[None, :, :2])
            ok &= np.all(dist > discs[None, :, 2], axis=1)
        if not ok.any():
            return ok
        # prepared dwithin is wrong for zero-length lines (GEOS 3.14), so those are points
        degenerate = np.all(a == b, axis=1)
        geoms = np.where(degenerate, shapely.points(a),
                         shapely.linestrings(np.stack([a, b], axis=1)))
        limit = self.radius - _TOL
        for walls in (self.grid.obstacle_geometry, extra_walls):
            if walls is not None:
                idx = np.nonzero(ok)[0]
                ok[idx] = ~shapely.dwithin(walls, geoms[idx], limit)
        return ok

    def _pull_string(self, pts: np.ndarray, discs: np.ndarray, extra_walls) -> np.ndarray:
        """Greedy string pulling: from each kept vertex jump to the farthest vertex in free sight.

        Consecutive vertices are joined by grid moves (or checked connector pieces), so the
        fallback of keeping the next vertex never makes the path less valid than the grid path.
        """
        out = [0]
        i, n = 0, len(pts)
        while i < n - 1:
            later = np.arange(i + 2, n)
            nxt = i + 1
            if len(later):
                ok = self._free_many(np.broadcast_to(pts[i], (len(later), 2)), pts[later], discs, extra_walls)
                seen = np.nonzero(ok)[0]
                if len(seen):
                    nxt = int(later[seen[-1]])
            out.append(nxt)
            i = nxt
        return pts[out]

    # -- grid search --------------------------------------------------------------------------
    def _extra_cells(self, blocked_cells: Iterable[tuple[int, int]]) -> np.ndarray:
        cells = np.array(list(blocked_cells), dtype=float).reshape(-1, 2)
        if len(cells) and not np.all(cells == np.round(cells)):
            raise ValueError("blocked_cells: cells must be integer (col, row) pairs")
        cells = cells.astype(np.int64)
        inside = ((cells[:, 0] >= 0) & (cells[:, 0] < self.grid.width)
                  & (cells[:, 1] >= 0) & (cells[:, 1] < self.grid.height))
        return np.unique(cells[inside], axis=0)

    def _moves_with(self, discs: np.ndarray, cells: np.ndarray) -> tuple[list[int], frozenset[int]]:
        """The move table without the cells too close to the extra walls (returned as flat
        indices too) and without every move that passes through a disc."""
        h, w, wp = self.grid.height, self.grid.width, self._wp
        lost = np.zeros_like(self._moves)
        walled: frozenset[int] = frozenset()
        if len(cells):
            near = (cells[:, None, :] + self._kernel_offsets[None]).reshape(-1, 2)
            inside = (near[:, 0] >= 0) & (near[:, 0] < w) & (near[:, 1] >= 0) & (near[:, 1] < h)
            near = near[inside]
            near = near[self.free[near[:, 1], near[:, 0]]]
            flat = np.unique((near[:, 1] + 1) * wp + near[:, 0] + 1)
            walled = frozenset(flat.tolist())
            for rel, mask in self._lost:
                lost[flat + rel] |= np.uint8(mask)
        if len(discs):
            flat, bits = self._disc_cuts(discs)
            np.bitwise_or.at(lost, flat, bits)
        return (self._moves & ~lost).tolist(), walled

    def _disc_cuts(self, discs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat cell indices and move bits of every move passing within a disc (distance <= keep-out).

        The same discs (parked robots) come back in call after call, so each disc's cuts are
        computed once, in one vectorised batch for all new discs, and remembered.
        """
        keys = list(map(tuple, discs.tolist()))
        new = [k for k in dict.fromkeys(keys) if k not in self._cut_cache]
        if new:
            if len(self._cut_cache) + len(new) > _CUT_CACHE_SIZE:
                self._cut_cache.clear()
            self._cut_cache.update(self._compute_cuts(np.array(new), new))
        cuts = [self._cut_cache[k] for k in keys]
        return np.concatenate([c[0] for c in cuts]), np.concatenate([c[1] for c in cuts])

    def _compute_cuts(self, discs: np.ndarray, keys: list) -> dict:
        res, h, w, wp = self.grid.resolution, self.grid.height, self.grid.width, self._wp
        # a move (length <= sqrt(2) res) passing within k of P has both ends within k + sqrt(2) res
        reach = discs[:, 2] + _SQRT2 * res + _TOL
        span = int(math.ceil(float(reach.max()) / res)) + 1
        wc, wr = (a.ravel() for a in np.meshgrid(np.arange(-span, span + 1), np.arange(-span, span + 1)))
        base = np.floor(discs[:, :2] / res).astype(np.int64)
        col = (base[:, 0, None] + wc[None]).ravel()
        row = (base[:, 1, None] + wr[None]).ravel()
        which = np.repeat(np.arange(len(discs)), wc.size)
        tail = np.column_stack([(col + 0.5) * res, (row + 0.5) * res])
        near = ((col >= 0) & (col < w) & (row >= 0) & (row < h)
                & (np.hypot(*(tail - discs[which, :2]).T) <= reach[which]))
        col, row, which, tail = col[near], row[near], which[near], tail[near]
        flat = (row + 1) * wp + col + 1
        centre, keep_out = discs[which, :2], discs[which, 2]
        out_flat, out_bits, out_which = [], [], []
        for dcol, drow, bit_tail, bit_head in self._half_moves:
            hit = segment_point_distance(tail, tail + (dcol * res, drow * res), centre) <= keep_out
            t = flat[hit]
            out_flat += [t, t + dcol + drow * wp]
            out_bits += [np.full(len(t), bit_tail, np.uint8), np.full(len(t), bit_head, np.uint8)]
            out_which += [which[hit]] * 2
        all_flat, all_bits, all_which = (np.concatenate(x) for x in (out_flat, out_bits, out_which))
        order = np.argsort(all_which, kind="stable")
        bounds = np.searchsorted(all_which[order], np.arange(len(discs) + 1))
        all_flat, all_bits = all_flat[order], all_bits[order]
        return {k: (all_flat[bounds[n]:bounds[n + 1]], all_bits[bounds[n]:bounds[n + 1]])
                for n, k in enumerate(keys)}

    def _connect(self, p: np.ndarray, walled: frozenset[int], discs: np.ndarray,
                 extra_walls) -> dict[int, float]:
        """Cells a point joins the grid at, with the connector length in cells.

        The point's own cell if the straight piece to its centre is free, else those of the 8
        neighbours with a free straight piece (a point off-centre near a wall may need that).
        """
        res = self.grid.resolution
        col, row = (int(v) for v in np.floor(p / res))
        for ring in (((0, 0),), _DIRS):
            cand = [(col + dc, row + dr) for dc, dr in ring
                    if self.grid.in_bounds(col + dc, row + dr) and self.free[row + dr, col + dc]
                    and (row + dr + 1) * self._wp + col + dc + 1 not in walled]
            if not cand:
                continue
            centres = (np.array(cand, dtype=float) + 0.5) * res
            ok = self._free_many(np.broadcast_to(p, centres.shape), centres, discs, extra_walls)
            found = {(r + 1) * self._wp + c + 1: float(np.hypot(*(centre - p))) / res
                     for (c, r), centre, good in zip(cand, centres, ok) if good}
            if found:
                return found
        return {}

    def _astar(self, moves: list[int], sources: dict[int, float], targets: dict[int, float],
               goal_cell: tuple[int, int]) -> list[int] | None:
        """Flat indices of the cells from a source to a target (octile A*, ties to larger g).

        The heuristic of every cell is computed at once with numpy, and g and parent live in flat
        lists: the loop then does only list look-ups and heap operations."""
        wp = self._wp
        steps_of = self._steps_of
        g_col, g_row = goal_cell[0] + 1, goal_cell[1] + 1
        # targets other than the goal's own cell are its neighbours: shrink the heuristic by the
        # longest step so it stays admissible
        slack = 0.0 if list(targets) == [g_row * wp + g_col] else _SQRT2
        size = len(moves)
        dx = np.abs(np.arange(wp) - g_col)[None, :]
        dy = np.abs(np.arange(size // wp) - g_row)[:, None]
        h = np.maximum(dx + dy + (_SQRT2 - 2.0) * np.minimum(dx, dy) - slack, 0.0).ravel().tolist()
        inf = math.inf
        g = [inf] * size
        parent = [-1] * size
        heap: list[tuple[float, float, int]] = []
        for s, cost in sources.items():
            if cost < g[s]:
                g[s] = cost
                heapq.heappush(heap, (cost + h[s], -cost, s))
        push, pop = heapq.heappush, heapq.heappop
        while heap:
            _, neg, i = pop(heap)
            gi = -neg
            if gi > g[i]:
                continue
            if i in targets:
                path = [i]
                while parent[path[-1]] >= 0:
                    path.append(parent[path[-1]])
                return path[::-1]
            for off, cost in steps_of[moves[i]]:
                j = i + off
                nj = gi + cost
                if nj < g[j]:
                    g[j] = nj
                    parent[j] = i
                    push(heap, (nj + h[j], -nj, j))
        return None

    def _centre(self, i: int) -> tuple[float, float]:
        r, c = divmod(i, self._wp)
        return self.grid.centre(c - 1, r - 1)

    def _unpad(self, i: int) -> int:
        r, c = divmod(i, self._wp)
        return (r - 1) * self.grid.width + c - 1


def _corners(path: list[int]) -> list[int]:
    """The cells of a grid path where its direction changes (plus both ends)."""
    if len(path) <= 2:
        return list(path)
    out = [path[0]]
    for a, b, c in zip(path, path[1:], path[2:]):
        if b - a != c - b:
            out.append(b)
    out.append(path[-1])
    return out


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
