"""Diagonal steps for the dense-crowd solver's timed plan (ours, issue 11): a post-pass that shortens
each robot's path where the grid has room, inside the precedence timing of :mod:`.crowd_timing`.

The solver plans on the 4-connected graph of cell centres, while SoC/free measures against each
robot's any-angle path driven alone: in open floor a staircase of unit steps is up to sqrt 2 times as
long as the straight line (on warehouse-10-20-10-2-1 the 4-connected floor is 1.064 of free, the
8-connected one 1.008). Here, robot after robot, a window of up to :data:`WINDOW` consecutive moves
from cell P to cell Q is replaced by an octile path from P to Q (its diagonal steps first, or its
straight steps first) when that is shorter and fits, driven from the window's start at top speed
(the robot then waits on Q for the window's old end).

**A diagonal step** from X to Z sweeps the two other cells Y, W of their 2x2 block: it is allowed
only where all four cells are free (the centre line then keeps step / 2 >= r from every wall: obstacles
are whole cells) and it *holds* all four cells from its start to its end. With that rule the
timing's safety argument carries over unchanged: whatever a robot does at an instant lies in the
axis-aligned lattice box of the cells it holds (a point, a unit edge or a unit square), and two
such boxes that share no lattice point are at least one step apart >= r_i + r_j.

**Fits** means: none of the robot's new holdings (P held to the end of its first new move, each new
cell and swept side from the start of the move in to the end of the move out, Q from the start of
the last new move) overlaps another robot's holding of that cell in the current schedule (hand-over
at an instant is allowed). The schedule with the rewrite is then feasible under the precedences the
timing draws from it, so the precedence pass that re-times the result (cells visited in the order of
that schedule, :func:`.crowd_timing.time_move_list` with ``sides``) can only make every robot earlier:
the sum of arrivals never grows. Rewrites are checked against the holdings as updated by the earlier
ones; :data:`ROUNDS` rounds, each from the last one's re-timed plan.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .crowd_kernels import NIL
from .crowd_timing import Timing, time_move_list

#: the longest window of moves replaced by one octile path (measured on bench_dense, see crowd.py)
WINDOW = 6
#: smoothing rounds, each from the precedence pass's timing of the last
ROUNDS = 2
SQRT2 = math.sqrt(2.0)
_EPS = 1e-9


def _overlaps(hold: list[list], who: int, lo: float, hi: float) -> bool:
    """Whether [lo, hi] overlaps (more than at an instant) a holding in ``hold`` of a robot other than ``who``."""
    for h_lo, h_hi, h_who in hold:
        if h_who != who and lo < h_hi - _EPS and h_lo < hi - _EPS:
            return True
    return False


def _drop(hold: list[list], who: int, lo: float) -> None:
    """Remove robot ``who``'s holding that starts at ``lo`` from one cell's list."""
    for q, h in enumerate(hold):
        if h[2] == who and abs(h[0] - lo) <= _EPS:
            del hold[q]
            return
    raise AssertionError("crowd_smooth: a holding to replace was not found")


class _Paths:
    """Every robot's cells, moves (start, end, sides) and the cells' holdings, editable."""

    def __init__(self, timing: Timing, starts: Sequence[int]):
        self.cells: list[list[int]] = []
        self.t0: list[list[float]] = []
        self.t1: list[list[float]] = []
        self.side: list[list[tuple[int, int] | None]] = []
        self.hold: dict[int, list[list]] = {}
        first, dst = timing.first, timing.dst.tolist()
        start, end = timing.start.tolist(), timing.end.tolist()
        sides = timing.sides.tolist() if timing.sides is not None else None
        for i, s in enumerate(starts):
            a, b = int(first[i]), int(first[i + 1])
            self.cells.append([int(s)] + dst[a:b])
            self.t0.append(start[a:b])
            self.t1.append(end[a:b])
            self.side.append([None if sides is None or sides[k][0] == NIL else (sides[k][0], sides[k][1])
                              for k in range(a, b)])
            for c, lo, hi in self._holdings(i, 0, b - a):
                self.hold.setdefault(c, []).append([lo, hi, i])

    def _holdings(self, i: int, j0: int, j1: int):
        """(cell, from, to) of robot i's cells j0..j1 on its path and the sides of its moves j0..j1 - 1."""
        cells, t0, t1, side = self.cells[i], self.t0[i], self.t1[i], self.side[i]
        k = len(t0)
        for j in range(j0, j1 + 1):
            yield cells[j], (0.0 if j == 0 else t0[j - 1]), (t1[j] if j < k else math.inf)
        for j in range(j0, j1):
            if side[j] is not None:
                yield side[j][0], t0[j], t1[j]
                yield side[j][1], t0[j], t1[j]

    def replace(self, i: int, j0: int, j1: int, cells: list[int], t0: list[float], t1: list[float],
                side: list[tuple[int, int] | None]) -> bool:
        """Replace robot i's moves j0..j1 - 1 by the moves along ``cells`` (from its cell j0 to its cell
        j1) timed ``t0``/``t1`` with swept ``side``s, if its new holdings fit; True when done."""
        old = list(self._holdings(i, j0, j1))
        keep = (self.cells[i], self.t0[i], self.t1[i], self.side[i])
        self.cells[i] = keep[0][:j0 + 1] + cells + keep[0][j1 + 1:]
        self.t0[i] = keep[1][:j0] + t0 + keep[1][j1:]
        self.t1[i] = keep[2][:j0] + t1 + keep[2][j1:]
        self.side[i] = keep[3][:j0] + side + keep[3][j1:]
        new = list(self._holdings(i, j0, j0 + len(t0)))
        for c, lo, hi in new:
            if _overlaps(self.hold.get(c, ()), i, lo, hi):
                self.cells[i], self.t0[i], self.t1[i], self.side[i] = keep
                return False
        for c, lo, _hi in old:
            _drop(self.hold[c], i, lo)
        for c, lo, hi in new:
            self.hold.setdefault(c, []).append([lo, hi, i])
        return True


def _octile(graph, p: int, q: int, diagonal_first: bool) -> tuple[list[int], list[tuple[int, int] | None]] | None:
    """The cells of an octile path from cell p to cell q (after p) and the sides each move sweeps; None
    where a cell or a swept side is not free."""
    r, c = int(graph.rows[p]), int(graph.cols[p])
    dr, dc = int(graph.rows[q]) - r, int(graph.cols[q]) - c
    sr, sc = (dr > 0) - (dr < 0), (dc > 0) - (dc < 0)
    n_diag = min(abs(dr), abs(dc))
    straight = (sr, 0) if abs(dr) > abs(dc) else (0, sc)
    steps = [(sr, sc)] * n_diag
    steps = steps + [straight] * (max(abs(dr), abs(dc)) - n_diag) if diagonal_first else \
        [straight] * (max(abs(dr), abs(dc)) - n_diag) + steps
    index = graph.index
    h, w = index.shape
    cells, sides = [], []
    for a, b in steps:
        nr, nc = r + a, c + b
        if not (0 <= nr < h and 0 <= nc < w) or index[nr, nc] == NIL:
            return None
        if a and b:
            s1, s2 = index[r, nc], index[nr, c]
            if s1 == NIL or s2 == NIL:
                return None
            sides.append((int(s1), int(s2)))
        else:
            sides.append(None)
        cells.append(int(index[nr, nc]))
        r, c = nr, nc
    return cells, sides


def smooth(timing: Timing, starts: Sequence[int], graph, durations: Sequence[float] | np.ndarray,
           centres: np.ndarray, radii: Sequence[float], step_m: float, gap_m: float,
           rounds: int = ROUNDS, window: int = WINDOW) -> Timing:
    """``timing`` with diagonal steps where they fit (module docstring), re-timed by the precedence
    pass; ``timing`` itself where nothing changed. Robots without acceleration limits only, radii
    <= half the cell step (the caller checks)."""
    # cells with a free 2x2 block round them: where a diagonal step can start or end
    free = graph.index != NIL
    block = free[:-1, :-1] & free[1:, :-1] & free[:-1, 1:] & free[1:, 1:]
    near = np.zeros_like(free)
    for dr in (0, 1):
        for dc in (0, 1):
            near[dr:dr + block.shape[0], dc:dc + block.shape[1]] |= block
    roomy = near[graph.rows, graph.cols]
    rows, cols = graph.rows.tolist(), graph.cols.tolist()
    dur = np.asarray(durations, dtype=float).tolist()
    for _ in range(rounds):
        paths = _Paths(timing, starts)
        changed = False
        for i in range(len(starts)):
            j = 0
            while j < len(paths.t0[i]):
                cells = paths.cells[i]
                if not roomy[cells[j]]:
                    j += 1
                    continue
                done = False
                for w in range(min(window, len(paths.t0[i]) - j), 1, -1):
                    p, q = cells[j], cells[j + w]
                    if not roomy[q]:
                        continue
                    dr, dc = abs(rows[q] - rows[p]), abs(cols[q] - cols[p])
                    new_len = max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc)
                    side = paths.side[i]
                    old_len = sum(1.0 if side[k] is None else SQRT2 for k in range(j, j + w))
                    if new_len > old_len - 1e-6:
                        continue
                    for diagonal_first in (True, False):
                        way = _octile(graph, p, q, diagonal_first)
                        if way is None:
                            continue
                        t, t0s, t1s = paths.t0[i][j], [], []
                        for s in way[1]:
                            t0s.append(t)
                            t += dur[i] * (1.0 if s is None else SQRT2)
                            t1s.append(t)
                        if paths.replace(i, j, j + w, way[0], t0s, t1s, way[1]):
                            done = changed = True
                            j += len(t0s)
                            break
                    if done:
                        break
                if not done:
                    j += 1
        if not changed:
            break
        timing = _retime(paths, starts, durations, centres, radii, step_m, gap_m)
    return timing


def _retime(paths: _Paths, starts: Sequence[int], durations, centres, radii, step_m: float, gap_m: float) -> Timing:
    """The precedence pass over the edited paths, each cell's visits in the order of their schedule."""
    robot, key, src, dst, sides = [], [], [], [], []
    for i, cells in enumerate(paths.cells):
        k = len(paths.t0[i])
        robot += [i] * k
        key += paths.t0[i]
        src += cells[:-1]
        dst += cells[1:]
        sides += [(NIL, NIL) if s is None else s for s in paths.side[i]]
    return time_move_list(np.asarray(starts), np.asarray(robot, dtype=np.int64), np.asarray(key),
                          np.asarray(src, dtype=np.int64), np.asarray(dst, dtype=np.int64), durations, centres,
                          radii, step_m, None, gap_m, sides=np.asarray(sides, dtype=np.int64).reshape(-1, 2))
