"""Compiled shortest-path search over the move graph of :class:`~fleet_planner.paths.PathFinder`.

The move graph (cells whose centre keeps the disc clear of walls, joined by the 8 grid moves that
do not cut a corner) is stored once per move table: per node its 8 heads and move weights.  One
search is an A* in compiled code (:func:`fleet_planner._path_kernels.astar`) with the octile
heuristic raised by the triangle bounds of a few landmarks (ALT; their distances are computed once
per move graph), exact (optimal for this move set); it touches only the nodes it expands.

Ties: every move into a cell also costs 1e-12 times the cell's distance (in cells) from the line
through start and goal, so of equal-length paths the one nearest that line is found (it pulls
straighter).  That adds at most 1e-12 * cells * distance, under 1e-6 cells on any path of 1000
cells, while two grid paths of different length differ by at least about 1e-4 cells (lengths are
a + b sqrt 2 with integers a, b): the length found is the shortest for the move set.

Per-call changes: moves removed by extra walls are marked in a stamp array over the edges (one
integer per edge, the search's stamp where the move is cut); moves through keep-out discs are
tested by the search when it expands their tail (the discs bucketed by place), so nothing of the
size of the graph is built per call.  Nothing here imports SciPy.
"""
from __future__ import annotations

import math
import threading

import numpy as np

_SQRT2 = math.sqrt(2.0)
#: the 8 moves as (dcol, drow); bit d of a cell's move mask says move d is allowed
DIRS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))
_COST = np.array([_SQRT2 if dc and dr else 1.0 for dc, dr in DIRS])
_DCOL = np.array([dc for dc, _ in DIRS], dtype=float)
_DROW = np.array([dr for _, dr in DIRS], dtype=float)
_TIE = 1e-12          # per cell of distance from the start-goal line, added to a move (ties)
#: landmarks of the search's lower bounds (ALT) per move graph, from maps of this many traversable
#: cells (measured on warehouse-20-40-10-2-2, 38756 cells, 118 searches of md at 100 robots: nodes
#: expanded per search 3839 with the octile distance alone, 1823 with 4 landmarks, 1523 with 8)
LANDMARKS = 4
#: the cut stamps of a search that cuts no move (none is looked up: an array of the graph's edges less to
#: read per expanded node)
_NO_CUT = np.zeros(0, dtype=np.int64)
LANDMARKS_FROM = 2000


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

    Nodes ``0 .. V-1`` are the traversable cells (``cells[v]`` is the padded flat index); each has
    its 8 moves in ``DIRS`` order (``heads[v, d]``, ``weights[v, d]``: infinite where the move is
    not allowed).  Edge ``9 * v + d`` is move d out of node v (slot 8 is unused: the ids are those
    of earlier versions, where it joined the goal cells to a target node).
    """

    def __init__(self, free_padded: np.ndarray, moves: np.ndarray, wp: int, symmetric: bool | None = None):
        flat_free = free_padded.ravel()
        self.cells = np.nonzero(flat_free)[0]
        v = len(self.cells)
        self.n_cells, self.wp = v, wp
        #: the unpadded map's (height, width)
        self.shape = (free_padded.shape[0] - 2, free_padded.shape[1] - 2)
        self.node_of = np.full(flat_free.size, -1, dtype=np.int64)
        self.node_of[self.cells] = np.arange(v)
        self.col = (self.cells % wp).astype(float)
        self.row = (self.cells // wp).astype(float)
        allowed = ((moves[self.cells, None] >> np.arange(8)[None, :]) & 1).astype(bool)
        self.weights = np.ascontiguousarray(np.where(allowed, _COST[None, :], np.inf))
        heads = np.empty((v, 8), dtype=np.int64)
        for d, (dc, dr) in enumerate(DIRS):
            head = self.node_of[np.clip(self.cells + dc + dr * wp, 0, flat_free.size - 1)]
            heads[:, d] = np.where(allowed[:, d], head, np.arange(v))
        self.heads = heads
        self._lock = threading.Lock()
        #: per edge ``9 * v + d``, the stamp of the last search that cut it
        self._cut: np.ndarray | None = None
        self._stamp = 0
        self._labels: np.ndarray | None = None
        #: per node its distance from each landmark (V, LANDMARKS), made at the first search
        self._landmarks: np.ndarray | None = None
        #: whether every move has its reverse (None: tested when the landmarks are made)
        self.symmetric = symmetric

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
        """Weakly connected component of each padded cell (-1 where not traversable): cells with
        different labels have no path either way (on one-way lanes, one with the same label may
        still have none: the labels only prune, :func:`fleet_planner._path_kernels.components`)."""
        if self._labels is None:
            from . import _path_kernels as K

            labels = np.full(self.node_of.size, -1, dtype=np.int64)
            labels[self.cells] = K.components(self.heads, self.weights)
            self._labels = labels
        return self._labels

    def landmarks(self) -> np.ndarray:
        """Per node its distance (cells) from each of :data:`LANDMARKS` landmarks over the allowed
        moves, as rows ``(V, LANDMARKS)`` (infinite where unreachable): the lower bounds of the
        search (ALT, :func:`fleet_planner._path_kernels.astar`). Landmarks are picked farthest
        first (each the node farthest from those before, within the largest component: the map's
        corners on a warehouse). No landmarks (zero columns) when a move has no reverse move of the
        same weight (lanes: the bounds need distances both ways) or the map is tiny."""
        if self._landmarks is None:
            from . import _path_kernels as K

            v = self.n_cells
            lm = np.zeros((v, 0))
            if self.symmetric is None:
                self.symmetric = self._symmetric()
            if v >= LANDMARKS_FROM and self.symmetric:
                labels = self.labels()[self.cells]
                biggest = int(np.argmax(np.bincount(labels)))
                seed = int(np.nonzero(labels == biggest)[0][0])
                far = K.distances(self.heads, self.weights, seed)
                nearest = np.where(np.isfinite(far), far, -1.0)
                cols = []
                for _ in range(LANDMARKS):
                    dist = K.distances(self.heads, self.weights, int(np.argmax(nearest)))
                    cols.append(dist)
                    nearest = np.minimum(nearest, np.where(np.isfinite(dist), dist, -1.0))
                lm = np.ascontiguousarray(np.column_stack(cols))
            self._landmarks = lm
        return self._landmarks

    def _symmetric(self) -> bool:
        """Whether every allowed move has its reverse move, of the same weight."""
        opposite = np.array([DIRS.index((-dc, -dr)) for dc, dr in DIRS])
        ok = np.isfinite(self.weights)
        back = self.weights[self.heads, opposite[None, :]]
        return bool(np.all(back[ok] == self.weights[ok]))

    def search(self, sources: dict[int, float], targets: dict[int, float], start: tuple[int, int],
               goal: tuple[int, int], slack: float, removed: np.ndarray, discs: np.ndarray,
               res: float) -> list[int] | None:
        """Padded flat indices of the cells of a shortest path from a source to a target.

        ``sources`` / ``targets``: padded flat cell -> connector cost (cells), all within one
        cell of ``start`` / ``goal`` (padded (col, row) of the start's and the goal's cell); the
        octile heuristic is measured from the goal cell (minus ``slack``, for targets that are
        neighbours of that cell); ``removed``: edge ids that are cut; ``discs``: (x, y, keep-out)
        rows in metres (grid resolution ``res``), every move passing within one is cut too.
        """
        from . import _path_kernels as K

        src = self.node_of[np.fromiter(sources, dtype=np.int64, count=len(sources))]
        src_cost = np.fromiter(sources.values(), dtype=float, count=len(sources))
        tgt = self.node_of[np.fromiter(targets, dtype=np.int64, count=len(targets))]
        tgt_cost = np.fromiter(targets.values(), dtype=float, count=len(targets))
        lm = self.landmarks()
        at = lm[tgt]   # the targets' distances from each landmark; landmarks that miss one are left out
        use = np.all(np.isfinite(at), axis=0)
        if not use.all():
            lm, at = np.ascontiguousarray(lm[:, use]), at[:, use]
        lm_lo, lm_hi = at.min(axis=0, initial=np.inf), at.max(axis=0, initial=-np.inf)
        with self._lock:
            if self._cut is None:
                self._cut = np.zeros(9 * self.n_cells, dtype=np.int64)
            self._stamp += 1
            stamp = self._stamp
            cut = self._cut
            if len(removed):
                cut[removed] = stamp
            nodes = K.astar(self.heads, self.weights, self.col, self.row, cut if len(removed) else _NO_CUT, stamp,
                            np.ascontiguousarray(discs, dtype=float).reshape(-1, 3), float(res), _DCOL, _DROW,
                            src, src_cost, tgt, tgt_cost, float(start[0]), float(start[1]), float(goal[0]),
                            float(goal[1]), float(slack), _TIE, lm, lm_lo, lm_hi)
        if not len(nodes):
            return None
        return self.cells[nodes].tolist()


