"""Compiled shortest-path search over the move graph of :class:`~fleet_planner.paths.PathFinder`.

The move graph (cells whose centre keeps the disc clear of walls, joined by the 8 grid moves that
do not cut a corner) is stored once per path finder as a CSR matrix.  One search is an A* done by
SciPy's compiled Dijkstra: edge weights are reduced by a consistent heuristic ``h`` (``w'(u, v) =
w(u, v) - h(u) + h(v) >= 0``), so the distance of a node from the source in the reduced graph is
``g(v) + h(v) - h(source)``, and Dijkstra with a ``limit`` on it settles exactly the nodes A* would
expand with ``f <= f(source) + limit``.  Raising the limit until the target is settled therefore
gives an exact shortest path (every node a search did not reach is farther than the limit, and
reduced distances only grow along a path), in compiled code, and a failed search stops as soon as
the reached set can grow no further.

Per-call changes (moves removed by keep-out discs or extra walls, the start and goal connectors)
only touch the weight array: the structure (``indptr``, ``indices``) is built once.  The first
search imports ``scipy.sparse.csgraph``; nothing here imports ``scipy.ndimage``.
"""
from __future__ import annotations

import math

import numpy as np

_SQRT2 = math.sqrt(2.0)
#: the 8 moves as (dcol, drow); bit d of a cell's move mask says move d is allowed
DIRS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))
_COST = np.array([_SQRT2 if dc and dr else 1.0 for dc, dr in DIRS])
_FIRST_LIMIT = 4.0     # cells of detour over the heuristic the first search allows
_LIMIT_GROWTH = 4.0


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

    Nodes ``0 .. n-1`` are the padded cells themselves (flat index = node; cells that are not
    traversable simply have no finite edge), node ``n`` is the source (joined to the start cells
    by the start connectors) and ``n + 1`` the target (joined from the goal cells).  Every cell
    has 9 slots: its 8 moves in ``DIRS`` order, then one to the target, finite only for the goal
    cells of the current search.  Edge ``9 * flat + d`` is move d out of cell ``flat``, and the
    heuristic's change along every move is a shifted copy of one array (no gathers).
    """

    def __init__(self, free_padded: np.ndarray, moves: np.ndarray, wp: int):
        n = moves.size
        self.n, self.wp = n, wp
        self.source, self.target = n, n + 1
        self.free = free_padded.ravel().copy()
        self.col = np.tile(np.arange(wp, dtype=float), n // wp)
        self.row = np.repeat(np.arange(n // wp, dtype=float), wp)
        self.offsets = [dc + dr * wp for dc, dr in DIRS]
        allowed = ((moves[:, None] >> np.arange(8)[None, :]) & 1).astype(bool)
        self.weights = np.full((n, 9), np.inf)
        self.weights[:, :8] = np.where(allowed, _COST[None, :], np.inf)
        heads = np.empty((n, 9), dtype=np.int32)
        for d, off in enumerate(self.offsets):
            heads[:, d] = np.clip(np.arange(n) + off, 0, n - 1)
        heads[:, 8] = self.target
        self.indices = np.concatenate([heads.ravel(), np.full(9, self.target, dtype=np.int32)])
        self.indptr = np.concatenate([np.arange(0, 9 * (n + 2), 9), [9 * (n + 1)]]).astype(np.int32)
        self._labels: np.ndarray | None = None
        #: disc centre -> (keep-out it was computed for, edge ids of the moves near it, their
        #: distances to the centre); filled by the path finders that share this graph
        self.cuts: dict[tuple[float, float], tuple[float, np.ndarray, np.ndarray]] = {}

    def has_move(self, flat: np.ndarray, d: int) -> np.ndarray:
        return np.isfinite(self.weights[flat, d])

    @staticmethod
    def edges(flat: np.ndarray, bits: np.ndarray) -> np.ndarray:
        """Edge ids of the moves ``bits`` (move masks) out of padded cells ``flat``."""
        if not len(flat):
            return np.zeros(0, dtype=np.int64)
        want = ((bits[:, None].astype(np.int64) >> np.arange(8)[None, :]) & 1).astype(bool)
        return (9 * flat.astype(np.int64)[:, None] + np.arange(8)[None, :])[want]

    def labels(self) -> np.ndarray:
        """Connected component of each cell (moves are symmetric)."""
        if self._labels is None:
            from scipy.sparse import csr_matrix
            from scipy.sparse.csgraph import connected_components

            n = self.n
            tails, dirs = np.nonzero(np.isfinite(self.weights[:, :8]))
            heads = self.indices[:9 * n].reshape(n, 9)[tails, dirs]
            graph = csr_matrix((np.ones(len(tails)), (tails, heads)), shape=(n, n))
            self._labels = connected_components(graph, directed=False)[1]
        return self._labels

    def search(self, sources: dict[int, float], targets: dict[int, float], start: tuple[int, int],
               goal: tuple[int, int], slack: float, removed: np.ndarray) -> list[int] | None:
        """Padded flat indices of the cells of a shortest path from a source to a target.

        ``sources`` / ``targets``: padded flat cell -> connector cost (cells), all within one
        cell of ``start`` / ``goal`` (padded (col, row) of the start's and the goal's cell); the
        octile heuristic is measured from the goal cell (minus ``slack``, for targets that are
        neighbours of that cell); ``removed``: edge ids that are cut.

        Only the edges out of cells that a search with the current limit can reach need reduced
        weights, and those cells lie in an octile "ellipse" around start and goal (below), so
        the weights are reduced there only, and the ellipse grows with the limit.
        """
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import dijkstra

        n = self.n
        src = np.fromiter(sources, dtype=np.int64, count=len(sources))
        src_cost = np.fromiter(sources.values(), dtype=float, count=len(sources))
        tgt = np.fromiter(targets, dtype=np.int64, count=len(targets))
        tgt_cost = np.fromiter(targets.values(), dtype=float, count=len(targets))
        # octile distance to the goal cell: consistent for these moves, and 0 at every target
        to_goal = _octile(self.col, self.row, goal)
        h = np.maximum(to_goal - slack, 0.0)
        h_source = float(np.min(src_cost + h[src]))
        # g(v) >= oct(start, v) - sqrt 2 (a source is within one cell of the start cell) and
        # h(v) >= oct(v, goal) - slack, so a cell whose reduced distance g + h - h_source is
        # <= limit has oct(start, v) + oct(v, goal) <= limit + h_source + slack + sqrt 2
        ellipse = _octile(self.col, self.row, start) + to_goal
        w = np.empty(9 * (n + 1))
        w[:9 * n] = self.weights.ravel()   # non-negative; replaced wherever a search can scan
        w[9 * tgt + 8] = tgt_cost - h[tgt]
        indices = self.indices.copy()
        indices[9 * n:9 * n + len(src)] = src
        w[9 * n:] = np.inf
        w[9 * n:9 * n + len(src)] = src_cost + h[src] - h_source
        graph = csr_matrix((w, indices, self.indptr), shape=(n + 2, n + 2))
        reduced = np.zeros(n, dtype=bool)
        # a bound on the reduced weight of any edge (a move: w + h(head) - h(tail) <= 2 sqrt 2; a
        # connector: its cost plus the heuristic's spread over the 3x3 block, <= 2): a reachable
        # node beyond the limit is one such edge from a reached node within it
        step = 2.0 * _SQRT2 + 2.0 + float(src_cost.max()) + float(tgt_cost.max())
        limit = _FIRST_LIMIT
        while True:
            cells = np.nonzero(~reduced & (ellipse <= limit + h_source + slack + _SQRT2 + 1e-6))[0]
            if len(cells):
                ids = (9 * cells[:, None] + np.arange(8)[None, :]).ravel()
                w_ids = self.weights[cells, :8].ravel() + h[self.indices[ids]] - np.repeat(h[cells], 8)
                w[ids] = np.maximum(w_ids, 0.0)   # rounding of the reduced weights of tight moves
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
            path.append(node)
            node = int(pred[node])
        return path[::-1]


def _octile(col: np.ndarray, row: np.ndarray, cell: tuple[int, int]) -> np.ndarray:
    dx, dy = np.abs(col - cell[0]), np.abs(row - cell[1])
    return dx + dy + (_SQRT2 - 2.0) * np.minimum(dx, dy)
