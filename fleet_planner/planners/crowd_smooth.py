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

import gc
import math
import time
from collections.abc import Sequence

import numpy as np

from .crowd_kernels import NIL
from .crowd_timing import Timing, time_move_list

#: the longest window of moves replaced by one octile path. Measured on one 400-robot plan of bench_dense
#: (warehouse-10-20-10-2-1, seed 0, load 10-15; sum of arrivals saved / CPU s): 2 rounds of windows <= 6
#: 687 s / 0.29, <= 8 736 / ~0.36, <= 14 791 / 0.69; 3 rounds <= 14 837 / 0.85; 4 rounds <= 10 824 / 0.78
WINDOW = 8
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
    """Every robot's cells and moves (start, end, sides), editable, and the holdings of the roomy cells
    (the only ones a rewrite can touch)."""

    def __init__(self, timing: Timing, starts: Sequence[int], roomy: np.ndarray):
        first = timing.first
        n = len(first) - 1
        m = len(timing.robot)
        start_cells = np.asarray(starts, dtype=np.int64)
        sides = timing.sides if timing.sides is not None else np.full((m, 2), NIL, dtype=np.int64)
        cut = first[1:-1].tolist()
        dst, t0, t1 = timing.dst.tolist(), timing.start.tolist(), timing.end.tolist()
        self.cells = [[int(s)] for s in start_cells.tolist()]
        for i, (a, b) in enumerate(zip([0] + cut, cut + [m])):
            self.cells[i] += dst[a:b]
        self.t0 = [t0[a:b] for a, b in zip([0] + cut, cut + [m])]
        self.t1 = [t1[a:b] for a, b in zip([0] + cut, cut + [m])]
        diag = (sides[:, 0] != NIL).tolist()
        pairs = sides.tolist()
        self.side: list[list[tuple[int, int] | None]] = [[(pairs[k][0], pairs[k][1]) if diag[k] else None
                                                          for k in range(a, b)] for a, b in zip([0] + cut, cut + [m])]
        # holdings (module docstring of crowd_timing): starts from 0, every move's destination from the move's
        # start to the end of the robot's next move (for ever after its last), sides during their move
        idx = np.arange(m)
        last = np.zeros(m, dtype=bool)
        last[first[1:][first[1:] > first[:-1]] - 1] = True
        nxt_end = np.where(last, np.inf, timing.end[np.minimum(idx + 1, max(m - 1, 0))] if m else 0.0)
        has = first[1:] > first[:-1]
        s_end = np.where(has, timing.end[np.minimum(first[:-1], max(m - 1, 0))] if m else 0.0, np.inf)
        sk, sj = np.nonzero(sides != NIL)
        cell = np.concatenate([start_cells, timing.dst, sides[sk, sj]])
        lo = np.concatenate([np.zeros(n), timing.start, timing.start[sk]])
        hi = np.concatenate([s_end, nxt_end, timing.end[sk]])
        who = np.concatenate([np.arange(n), timing.robot, timing.robot[sk]])
        keep = roomy[cell]
        cell, lo, hi, who = cell[keep], lo[keep], hi[keep], who[keep]
        order = np.argsort(cell, kind="stable")
        self.hold: dict[int, list[list]] = {}
        for c, a, b, w in zip(cell[order].tolist(), lo[order].tolist(), hi[order].tolist(), who[order].tolist()):
            self.hold.setdefault(c, []).append([a, b, w])
        self.roomy = roomy

    def _holdings(self, i: int, j0: int, j1: int):
        """(cell, from, to) of robot i's cells j0..j1 on its path and the sides of its moves j0..j1 - 1."""
        cells, t0, t1, side = self.cells[i], self.t0[i], self.t1[i], self.side[i]
        k = len(t0)
        for j in range(j0, j1 + 1):
            yield cells[j], (0.0 if j == 0 else t0[j - 1]), (t1[j] if j < k else math.inf)
        for j in range(j0, j1):
            swept = side[j]
            if swept is not None:
                yield swept[0], t0[j], t1[j]
                yield swept[1], t0[j], t1[j]

    def replace(self, i: int, j0: int, j1: int, cells: list[int], t0: list[float], t1: list[float],
                side: list[tuple[int, int] | None]) -> bool:
        """Replace robot i's moves j0..j1 - 1 by the moves along ``cells`` (after its cell j0, to its cell
        j1) timed ``t0``/``t1`` with swept ``side``s, if its new holdings fit; True when done. All
        cells involved are roomy."""
        hold, n_new = self.hold, len(t0)
        k_old = len(self.t0[i])
        new = [(self.cells[i][j0], 0.0 if j0 == 0 else self.t0[i][j0 - 1], t1[0])]
        new += [(cells[k], t0[k], t1[k + 1]) for k in range(n_new - 1)]
        new.append((cells[-1], t0[-1], self.t1[i][j1] if j1 < k_old else math.inf))
        for k in range(n_new):
            swept = side[k]
            if swept is not None:
                new += [(swept[0], t0[k], t1[k]), (swept[1], t0[k], t1[k])]
        for c, lo, hi in new:
            if c in hold and _overlaps(hold[c], i, lo, hi):
                return False
        for c, lo, _hi in list(self._holdings(i, j0, j1)):
            _drop(hold[c], i, lo)
        for c, lo, hi in new:
            hold.setdefault(c, []).append([lo, hi, i])
        self.cells[i][j0 + 1:j1 + 1] = cells
        self.t0[i][j0:j1] = t0
        self.t1[i][j0:j1] = t1
        self.side[i][j0:j1] = side
        return True


def _octile(grid_cells: list[list[int]], rows: list[int], cols: list[int], p: int, q: int,
            diagonal_first: bool) -> tuple[list[int], list[tuple[int, int] | None]] | None:
    """The cells of an octile path from cell p to cell q (after p) and the sides each move sweeps; None
    where a cell or a swept side is not roomy (``grid_cells[row][col]``: the roomy cell there, else NIL)."""
    r, c = rows[p], cols[p]
    dr, dc = rows[q] - r, cols[q] - c
    sr, sc = (dr > 0) - (dr < 0), (dc > 0) - (dc < 0)
    n_diag = min(abs(dr), abs(dc))
    n_straight = max(abs(dr), abs(dc)) - n_diag
    straight = (sr, 0) if abs(dr) > abs(dc) else (0, sc)
    steps = [(sr, sc)] * n_diag + [straight] * n_straight if diagonal_first else \
        [straight] * n_straight + [(sr, sc)] * n_diag
    cells: list[int] = []
    sides: list[tuple[int, int] | None] = []
    for a, b in steps:     # (all inside the map: p and q are, and so is their bounding box)
        nr, nc = r + a, c + b
        z = grid_cells[nr][nc]
        if z == NIL:
            return None
        if a and b:
            s1, s2 = grid_cells[r][nc], grid_cells[nr][c]
            if s1 == NIL or s2 == NIL:
                return None
            sides.append((s1, s2))
        else:
            sides.append(None)
        cells.append(z)
        r, c = nr, nc
    return cells, sides


def smooth(timing: Timing, starts: Sequence[int], graph, durations: Sequence[float] | np.ndarray,
           centres: np.ndarray, radii: Sequence[float], step_m: float, gap_m: float,
           rounds: int = ROUNDS, window: int = WINDOW, cpu_s: float | None = None) -> Timing:
    """``timing`` with diagonal steps where they fit (module docstring), re-timed by the precedence
    pass; ``timing`` itself where nothing changed. Robots without acceleration limits only, radii
    <= half the cell step (the caller checks). ``cpu_s``: no new window is tried after this much
    CPU time (the rewrites found by then are re-timed)."""
    collecting = gc.isenabled()
    gc.disable()   # 10^5 small lists, none cyclic: the collector would only re-scan them
    try:
        stop = math.inf if cpu_s is None else time.process_time() + cpu_s
        return _smooth(timing, starts, graph, durations, centres, radii, step_m, gap_m, rounds, window, stop)
    finally:
        if collecting:
            gc.enable()


def _smooth(timing: Timing, starts: Sequence[int], graph, durations, centres: np.ndarray, radii: Sequence[float],
            step_m: float, gap_m: float, rounds: int, window: int, stop: float) -> Timing:
    # roomy cells: in a free 2x2 block, where a diagonal step can start or end
    free = graph.index != NIL
    block = free[:-1, :-1] & free[1:, :-1] & free[:-1, 1:] & free[1:, 1:]
    near = np.zeros_like(free)
    for dr in (0, 1):
        for dc in (0, 1):
            near[dr:dr + block.shape[0], dc:dc + block.shape[1]] |= block
    roomy = near[graph.rows, graph.cols]
    rows, cols = graph.rows.tolist(), graph.cols.tolist()
    grid_cells = np.where(graph.index != NIL, graph.index, NIL)
    grid_cells[graph.rows[~roomy], graph.cols[~roomy]] = NIL
    grid_cells = grid_cells.tolist()
    dur = np.asarray(durations, dtype=float).tolist()
    ways: dict[tuple[int, int, bool], tuple[list[int], list[tuple[int, int] | None]] | None] = {}
    for _ in range(rounds):
        robot_c, j_c, w_c = _windows(timing, graph, roomy, window)
        if not len(robot_c):
            break
        changed = False
        paths = _Paths(timing, starts, roomy)
        # (windows robot-major, by start, longest first; an accepted rewrite shifts the robot's later windows)
        i_now, shift, skip_to = -1, 0, -1
        for count, (i, j_old, w) in enumerate(zip(robot_c.tolist(), j_c.tolist(), w_c.tolist())):
            if count % 256 == 0 and time.process_time() > stop:
                break
            if i != i_now:
                i_now, shift, skip_to = i, 0, -1
            if j_old < skip_to:
                continue
            j = j_old + shift
            p, q = paths.cells[i][j], paths.cells[i][j + w]
            for diagonal_first in (True, False):
                key = (p, q, diagonal_first)
                way = ways[key] if key in ways else \
                    ways.setdefault(key, _octile(grid_cells, rows, cols, p, q, diagonal_first))
                if way is None:
                    continue
                t, t0s, t1s = paths.t0[i][j], [], []
                for sd in way[1]:
                    t0s.append(t)
                    t += dur[i] * (1.0 if sd is None else SQRT2)
                    t1s.append(t)
                if paths.replace(i, j, j + w, way[0], t0s, t1s, way[1]):
                    changed = True
                    shift += len(t0s) - w
                    skip_to = j_old + w
                    break
        if not changed:
            break
        timing = _retime(paths, starts, durations, centres, radii, step_m, gap_m)
        if time.process_time() > stop:
            break
    return timing


def _windows(timing: Timing, graph, roomy: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every window of 2..``window`` consecutive moves of one robot on roomy cells whose octile path
    is shorter than it (and ends elsewhere than it starts): robot, index of its first move in the
    robot's moves, length; robot-major, by first move, longest first."""
    m = len(timing.robot)
    if m == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    robot, src, dst, first = timing.robot, timing.src, timing.dst, timing.first
    length = np.ones(m) if timing.sides is None else np.where(timing.sides[:, 0] != NIL, SQRT2, 1.0)
    cum_len = np.concatenate([[0.0], np.cumsum(length)])
    cum_bad = np.concatenate([[0], np.cumsum(~roomy[dst])])
    k = np.arange(m)
    out = []
    for w in range(2, window + 1):
        e = k + w - 1
        ok = e < m
        kk, ee = k[ok], e[ok]
        ok = (robot[ee] == robot[kk]) & roomy[src[kk]] & (cum_bad[ee + 1] == cum_bad[kk])
        kk, ee = kk[ok], ee[ok]
        p, q = src[kk], dst[ee]
        dr = np.abs(graph.rows[q] - graph.rows[p])
        dc = np.abs(graph.cols[q] - graph.cols[p])
        octile = np.maximum(dr, dc) + (SQRT2 - 1.0) * np.minimum(dr, dc)
        ok = (octile < cum_len[ee + 1] - cum_len[kk] - 1e-6) & (p != q)
        kk = kk[ok]
        out.append(np.column_stack([robot[kk], kk - first[robot[kk]], np.full(len(kk), w)]))
    rows = np.concatenate(out)
    rows = rows[np.lexsort((-rows[:, 2], rows[:, 1], rows[:, 0]))]
    return rows[:, 0], rows[:, 1], rows[:, 2]


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
