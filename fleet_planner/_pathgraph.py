"""Compiled shortest-path search over the move graph of :class:`~fleet_planner.paths.PathFinder`.

The move graph (cells whose centre keeps the disc clear of walls, joined by the 8 grid moves that
do not cut a corner) is stored once per move table as a CSR matrix.  One search is an A* done by
SciPy's compiled Dijkstra: edge weights are reduced by a consistent heuristic ``h`` (``w'(u, v) =
w(u, v) - h(u) + h(v) >= 0``), so the distance of a node from the source in the reduced graph is
``g(v) + h(v) - h(source)``, and Dijkstra with a ``limit`` on it settles exactly the nodes A* would
expand with ``f <= f(source) + limit``.  Raising the limit until the target is settled therefore
gives an exact shortest path (every node a search did not reach is farther than the limit, and
reduced distances only grow along a path), in compiled code, and a failed search stops as soon as
the reached set can grow no further.

Ties: every move into a cell also costs 1e-12 times the cell's distance (in cells) from the line
through start and goal, so of equal-length paths the one nearest that line is found (it pulls
straighter).  That adds at most 1e-12 * cells * distance, under 1e-6 cells on any path of 1000
cells, while two grid paths of different length differ by at least about 1e-4 cells (lengths are
a + b sqrt 2 with integers a, b): the length found is the shortest for the move set.

Per-call changes (moves removed by keep-out discs or extra walls, the start and goal connectors)
only touch the weight array: the structure (``indptr``, ``indices``) is built once, and weights
are reduced only where a search with the current limit can scan (see :meth:`MoveGraph.search`).
The first search imports ``scipy.sparse.csgraph``; nothing here imports ``scipy.ndimage``.
"""
from __future__ import annotations

import math
import threading
from collections import OrderedDict
from typing import Any

import numpy as np

_SQRT2 = math.sqrt(2.0)
#: the 8 moves as (dcol, drow); bit d of a cell's move mask says move d is allowed
DIRS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))
_COST = np.array([_SQRT2 if dc and dr else 1.0 for dc, dr in DIRS])
_FIRST_LIMIT = 12.0    # cells of detour over the heuristic the first search allows
_LIMIT_GROWTH = 4.0
_TIE = 1e-12          # per cell of distance from the start-goal line, added to a move (ties)
_OCTILE_CACHE_SIZE = 16   # octile fields (one per start or goal cell) kept per graph


def dilate(mask: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Binary dilation of ``mask`` by a symmetric ``kernel`` (odd square, True = in the kernel),
    with False outside ``mask``: ``out[r, c]`` is True iff some ``mask[r + dr, c + dc]`` is True
    for a kernel offset ``(dr, dc)``.  Exact (a boolean OR), computed per kernel row as a running
    window over the columns, so no SciPy import is needed."""
    h, w = mask.shape
    k = kernel.shape[0] // 2
    padded = np.zeros((h + 2 * k, w + 2 * k), dtype=bool)
    padded[k:k + h, k:k + w] = mask
    # counts[r, c] = number of True in padded[r, :c]
    counts = np.zeros((h + 2 * k, w + 2 * k + 1), dtype=np.int32)
    np.cumsum(padded, axis=1, out=counts[:, 1:])
    out = np.zeros((h, w), dtype=bool)
    for i in range(kernel.shape[0]):
        cols = np.nonzero(kernel[i])[0]
        if not len(cols):
            continue
        lo, hi = int(cols[0]), int(cols[-1])
        if hi - lo + 1 != len(cols):   # not one run: fall back to one shift per offset
            for j in cols:
                out |= padded[i:i + h, j:j + w]
            continue
        # a run of kernel columns lo..hi: any True in padded[row, c + lo .. c + hi]
        rows = counts[i:i + h]
        out |= rows[:, hi + 1:hi + 1 + w] > rows[:, lo:lo + w]
    return out


class MoveGraph:
    """The move graph of a padded move table (``moves[flat]``: bit d = move ``DIRS[d]`` allowed).

    Nodes ``0 .. V-1`` are the traversable cells (``cells[v]`` is the padded flat index), node
    ``V`` is the source (joined to the start cells by the start connectors) and ``V + 1`` the
    target (joined from the goal cells).  Every cell has 9 slots: its 8 moves in ``DIRS`` order
    (infinite weight where the move is not allowed), then one to the target, finite only for the
    goal cells of the current search.  Edge ``9 * v + d`` is move d out of node v.
    """

    def __init__(self, free_padded: np.ndarray, moves: np.ndarray, wp: int):
        flat_free = free_padded.ravel()
        self.cells = np.nonzero(flat_free)[0]
        v = len(self.cells)
        self.n_cells, self.wp = v, wp
        self.source, self.target = v, v + 1
        self.node_of = np.full(flat_free.size, -1, dtype=np.int64)
        self.node_of[self.cells] = np.arange(v)
        self.col = (self.cells % wp).astype(float)
        self.row = (self.cells // wp).astype(float)
        allowed = ((moves[self.cells, None] >> np.arange(8)[None, :]) & 1).astype(bool)
        self.weights = np.full((v, 9), np.inf)
        self.weights[:, :8] = np.where(allowed, _COST[None, :], np.inf)
        heads = np.empty((v, 9), dtype=np.int32)
        for d, (dc, dr) in enumerate(DIRS):
            head = self.node_of[np.clip(self.cells + dc + dr * wp, 0, flat_free.size - 1)]
            heads[:, d] = np.where(allowed[:, d], head, np.arange(v))
        heads[:, 8] = self.target
        self.heads = heads
        # the source's 9 slots at the end are rewritten by each search (under the lock)
        self._indices = np.concatenate([heads.ravel(), np.full(9, self.target, dtype=np.int32)])
        self._indptr = np.concatenate([np.arange(0, 9 * (v + 2), 9), [9 * (v + 1)]]).astype(np.int32)
        self._lock = threading.Lock()
        self._csr: Any = None   # one CSR matrix over these arrays; each search swaps in its weights
        self._octile: OrderedDict[tuple[int, int], np.ndarray] = OrderedDict()
        self._labels: np.ndarray | None = None
        #: disc centre -> (keep-out it was computed for, edge ids of the moves near it, their
        #: distances to the centre); filled by the path finders that share this graph
        self.cuts: dict[tuple[float, float], tuple[float, np.ndarray, np.ndarray]] = {}

    def has_move(self, flat: np.ndarray, d: int) -> np.ndarray:
        """Whether move d is allowed out of each padded cell ``flat``."""
        node = self.node_of[flat]
        return (node >= 0) & np.isfinite(self.weights[node, d])

    def edge_ids(self, flat: np.ndarray, d: int | np.ndarray) -> np.ndarray:
        """Edge ids of move(s) d out of padded cells ``flat`` (cells must be traversable)."""
        return 9 * self.node_of[flat] + d

    def edges(self, flat: np.ndarray, bits: np.ndarray) -> np.ndarray:
        """Edge ids of the moves ``bits`` (move masks) out of traversable padded cells ``flat``."""
        if not len(flat):
            return np.zeros(0, dtype=np.int64)
        want = ((bits[:, None].astype(np.int64) >> np.arange(8)[None, :]) & 1).astype(bool)
        return (9 * self.node_of[flat][:, None] + np.arange(8)[None, :])[want]

    def labels(self) -> np.ndarray:
        """Connected component of each padded cell (-1 where not traversable; moves are symmetric)."""
        if self._labels is None:
            from scipy.sparse import csr_matrix
            from scipy.sparse.csgraph import connected_components

            v = self.n_cells
            tails, dirs = np.nonzero(np.isfinite(self.weights[:, :8]))
            graph = csr_matrix((np.ones(len(tails)), (tails, self.heads[tails, dirs])), shape=(v, v))
            labels = np.full(self.node_of.size, -1, dtype=np.int64)
            labels[self.cells] = connected_components(graph, directed=False)[1]
            self._labels = labels
        return self._labels

    def _octile_from(self, cell: tuple[int, int]) -> np.ndarray:
        """Octile distance of every node from a padded (col, row) cell (a few kept: goals and
        starts come back call after call)."""
        field = self._octile.get(cell)
        if field is None:
            field = self._octile[cell] = _octile(self.col, self.row, cell)
            if len(self._octile) > _OCTILE_CACHE_SIZE:
                self._octile.popitem(last=False)
        else:
            self._octile.move_to_end(cell)
        return field

    def search(self, sources: dict[int, float], targets: dict[int, float], start: tuple[int, int],
               goal: tuple[int, int], slack: float, removed: np.ndarray) -> list[int] | None:
        """Padded flat indices of the cells of a shortest path from a source to a target.

        ``sources`` / ``targets``: padded flat cell -> connector cost (cells), all within one
        cell of ``start`` / ``goal`` (padded (col, row) of the start's and the goal's cell); the
        octile heuristic is measured from the goal cell (minus ``slack``, for targets that are
        neighbours of that cell); ``removed``: edge ids that are cut.

        Only the edges out of cells that a search with the current limit can reach need reduced
        weights: such a cell has g + h - h_source <= limit, and g(v) >= oct(start, v) - sqrt 2 (a
        source is within one cell of the start cell), h(v) >= oct(v, goal) - slack, so it lies
        in the octile "ellipse" oct(start, v) + oct(v, goal) <= limit + h_source + slack + sqrt 2.
        The weights are reduced there only (elsewhere they stay the non-negative base weights,
        never scanned), and the ellipse grows with the limit.
        """
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import dijkstra

        v = self.n_cells
        src = self.node_of[np.fromiter(sources, dtype=np.int64, count=len(sources))]
        src_cost = np.fromiter(sources.values(), dtype=float, count=len(sources))
        tgt = self.node_of[np.fromiter(targets, dtype=np.int64, count=len(targets))]
        tgt_cost = np.fromiter(targets.values(), dtype=float, count=len(targets))
        with self._lock:
            to_goal = self._octile_from(goal)
            ellipse = self._octile_from(start) + to_goal
        # octile distance to the goal cell: consistent for these moves, and 0 at every target
        h = np.maximum(to_goal - slack, 0.0)
        h_source = float(np.min(src_cost + h[src]))
        # ties: of equal-length paths, prefer cells near the line from start to goal
        ax, ay = goal[0] - start[0], goal[1] - start[1]
        norm = math.hypot(ax, ay) or 1.0
        cross = _TIE * np.abs((self.col - start[0]) * ay - (self.row - start[1]) * ax) / norm
        w = np.empty(9 * (v + 1))
        w[:9 * v] = self.weights.ravel()
        w[9 * tgt + 8] = tgt_cost - h[tgt]
        w[9 * v:] = np.inf
        w[9 * v:9 * v + len(src)] = src_cost + h[src] - h_source
        reduced = np.zeros(v, dtype=bool)
        # a bound on the reduced weight of any edge (a move: w + h(head) - h(tail) <= 2 sqrt 2; a
        # connector: its cost plus the heuristic's spread over the 3x3 block, <= 2): a reachable
        # node beyond the limit is one such edge from a reached node within it
        step = 2.0 * _SQRT2 + 2.0 + float(src_cost.max()) + float(tgt_cost.max())
        limit = _FIRST_LIMIT
        with self._lock:
            self._indices[9 * v:] = self.target
            self._indices[9 * v:9 * v + len(src)] = src
            if self._csr is None:
                self._csr = csr_matrix((w, self._indices, self._indptr), shape=(v + 2, v + 2))
            graph = self._csr
            graph.data = w
            while True:
                cells = np.nonzero(~reduced & (ellipse <= limit + h_source + slack + _SQRT2 + 1e-6))[0]
                if len(cells):
                    ids = (9 * cells[:, None] + np.arange(8)[None, :]).ravel()
                    heads = self.heads[cells, :8]
                    w_ids = self.weights[cells, :8] + h[heads] - h[cells][:, None] + cross[heads]
                    w[ids] = np.maximum(w_ids.ravel(), 0.0)   # rounding of the reduced weights of tight moves
                    reduced[cells] = True
                    if len(removed):
                        w[removed] = np.inf
                dist, pred = dijkstra(graph, directed=True, indices=self.source, return_predecessors=True,
                                      limit=limit)
                if math.isfinite(dist[self.target]):
                    break
                if float(dist[np.isfinite(dist)].max()) < limit - step:   # nothing more can be reached
                    return None
                limit *= _LIMIT_GROWTH
        path = []
        node = int(pred[self.target])
        while node != self.source:
            path.append(int(self.cells[node]))
            node = int(pred[node])
        return path[::-1]


def _octile(col: np.ndarray, row: np.ndarray, cell: tuple[int, int]) -> np.ndarray:
    dx, dy = np.abs(col - cell[0]), np.abs(row - cell[1])
    return dx + dy + (_SQRT2 - 2.0) * np.minimum(dx, dy)
