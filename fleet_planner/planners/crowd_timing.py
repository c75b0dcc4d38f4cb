"""The continuous half of the crowd planner: from a discrete plan to timed paths by precedence.

A discrete plan (one cell per robot per step, from :mod:`.crowd_pibt`) says in which order robots
visit each cell. We keep that order and nothing else of its timing:

* each robot drives its own cell sequence at its own top speed, one *move* (centre to centre) after
  the other; a robot *holds* a cell from the start of the move into it to the end of the move out
  of it (parked robots hold their start from the beginning and their goal for ever);
* for every cell, each visit may begin (the next robot starts to move in) only when the previous
  visit by another robot has ended (that robot has *arrived* in its next cell). These are the links
  of the (M,D) network of You & Ji, "Design of a Multi-robot Bin Packing System in an Automatic
  Warehouse" (docs/ARCHITECTURE.md, "The (M,D) vocabulary") with the order chosen by the discrete
  plan: the earlier visitor is the higher robot, and with D <= 0 no link is dangerous;
* earliest times follow by a longest-path pass over those precedences (each move has at most two
  predecessors: the robot's own previous move and the previous visitor's move out of the cell),
  level by level with numpy.

Why this is safe for discs with r_i + r_j <= cell step: at any instant a robot is on the segment
between the (one or two) cells it holds, and no cell is held by two robots at once except at the
instant of hand-over, when the leaving robot is exactly on its next centre and the entering one
exactly on its previous centre. Two axis-aligned unit segments of the lattice of cell centres that
share no point are at least one step apart, so every pair keeps >= step >= r_i + r_j.

The one exception: a robot that follows another in the same direction may start to move into the
cell while the other is still leaving it (see :func:`time_moves`); the two are then on one line and
their gap is computed exactly, while every other robot keeps off that cell as before. Trains of
robots thus drive down an aisle one step apart instead of two.

Collinear moves driven without a stop in between are merged into one segment.

Diagonal steps (:mod:`.crowd_smooth`, ``sides`` of :func:`time_move_list`) hold their two side cells
while they drive: a robot is then inside the axis-aligned unit square of the four cells it holds, and
two such lattice boxes (points, unit edges, unit squares) that share no lattice point are still at
least one step apart.
"""
from __future__ import annotations

import gc
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..model import Link, Network, TimedPath
from . import crowd_kernels as kern

NIL = -1
#: what a follower keeps on top of r_i + r_j (metres): rounding, not a safety margin
GAP_M = 1e-6


@dataclass
class Timing:
    """Timed moves: move m of robot ``robot[m]`` at discrete ``step[m]`` from cell ``src[m]`` to
    ``dst[m]``, starting at ``start[m]`` and ending at ``end[m]``; ``after_cell[m]`` is the move
    (of another robot, or NIL) it waits for."""

    robot: np.ndarray
    step: np.ndarray
    src: np.ndarray
    dst: np.ndarray
    start: np.ndarray
    end: np.ndarray
    after_cell: np.ndarray
    first: np.ndarray      # (robots + 1,) robot i's moves are first[i]:first[i + 1]
    visits: list[tuple[int, int]]   # consecutive visits of a cell by two robots: (move out, move in)
    #: (moves, 2) the cells a diagonal move sweeps (its two side cells; NIL for straight moves), or None
    sides: np.ndarray | None = None
    #: per visit pair: whether the earlier / the later visit is a sweep (the move in is the move out), or None
    sweeps: list[tuple[bool, bool]] | None = None


def time_moves(configs: np.ndarray, durations: Sequence[float] | np.ndarray, centres: np.ndarray | None = None,
               radii: Sequence[float] | None = None, step_m: float = 1.0,
               accels: Sequence[float | None] | None = None, gap_m: float = GAP_M) -> Timing:
    """Earliest start and end of every move of the discrete plan ``configs`` ((steps + 1, robots)
    cell indices) under the precedences of the module docstring; ``durations[i]`` is how long
    robot i takes for one move of ``step_m`` metres at its top speed.

    With ``accels`` (per robot, None: instant speed changes) a robot drives each *run* (moves in
    one direction without a stop) as a trapezoid from standstill to standstill, each move at the
    ramp's average speed over that cell (the plan contract has constant speed between waypoints).
    Where a precedence makes a robot stop inside a run, the run is split there and the pass
    repeated, until every stop is at the end of a run (a fixed point: runs only split; at worst
    every move is a run of its own). A follower keeps ``gap_m`` on top of r_i + r_j.

    With ``centres`` ((cells, 2) metres) and ``radii``, a robot that follows another in the same
    direction (its move into the cell is collinear with the other's move out of it) may start
    before the other has arrived: both are on one line, the follower behind, and the gap between
    them, ``step + (t - S_j) v_j - (t - S_i) v_i``, is smallest when the leader arrives (or at the
    follower's start), so ``S_i >= max(S_j, E_j - (2 step - r_i - r_j) / v_i)`` keeps it >= r_i + r_j."""
    moving = configs[1:] != configs[:-1]                       # (steps, robots)
    robot, step = np.nonzero(moving.T)                         # robot-major, steps ascending
    src, dst = configs[step, robot], configs[step + 1, robot]
    return time_move_list(configs[0], robot, step, src, dst, durations, centres, radii, step_m, accels, gap_m,
                          consecutive=True)


def time_move_list(starts: np.ndarray, robot: np.ndarray, step: np.ndarray, src: np.ndarray, dst: np.ndarray,
                   durations: Sequence[float] | np.ndarray, centres: np.ndarray | None = None,
                   radii: Sequence[float] | None = None, step_m: float = 1.0,
                   accels: Sequence[float | None] | None = None, gap_m: float = GAP_M,
                   consecutive: bool = False, sides: np.ndarray | None = None) -> Timing:
    """:func:`time_moves` for a plan given as its moves: move k of robot ``robot[k]`` from cell
    ``src[k]`` to ``dst[k]``, robot-major, each robot's moves in its order; ``step[k]`` orders the
    moves in time (a discrete step, or a start time: only its order counts), so that each cell is
    visited in the order of the steps of the moves into it. ``consecutive``: steps are discrete
    steps (a robot's moves at consecutive steps can form one run of a trapezoid).

    ``sides`` ((moves, 2), with ``centres``; ours, :mod:`.crowd_smooth`): move k may be a diagonal
    step between two cells with a common corner, and ``sides[k]`` the two cells it sweeps (NIL for a
    straight move). The move takes sqrt 2 times as long; it holds its two side cells from its start
    to its end (a visit whose move in is its move out), and every precedence of a diagonal move or a
    sweep is a plain hand-over (no follower slack). The steps must order each cell's visits without
    overlap for those (the smoothing's schedule does): such a precedence then starts strictly later,
    so the level order stays topological. Without acceleration limits only."""
    n = len(starts)
    starts = np.asarray(starts)
    robot = np.asarray(robot, dtype=np.int64)
    if not consecutive:   # dense ranks: moves starting at one instant share a level
        step = np.unique(np.asarray(step), return_inverse=True)[1].reshape(-1).astype(np.int64)
    m = len(robot)
    first = np.searchsorted(robot, np.arange(n + 1))
    idx = np.arange(m)
    after_own = np.where((idx > 0) & (np.roll(robot, 1) == robot), idx - 1, NIL)
    next_own = np.where((idx < m - 1) & (np.roll(robot, -1) == robot), idx + 1, NIL)
    # visits: every start (entry step -1, no entry move) and every move's destination
    has_moves = first[1:] > first[:-1]
    v_cell = np.concatenate([starts, dst])
    v_entry_step = np.concatenate([np.full(n, -1), step])
    v_entry_move = np.concatenate([np.full(n, NIL), idx])
    v_exit_move = np.concatenate([np.where(has_moves, first[:-1], NIL), next_own])
    v_robot = np.concatenate([np.arange(n), robot])
    v_slot = np.zeros(len(v_cell), dtype=np.int64)     # 0: a cell the robot is on, 1 / 2: a side swept
    length = np.ones(m)
    if sides is not None:
        if centres is None or (accels is not None and any(a is not None for a in accels)):
            raise ValueError("time_move_list: sides need centres and no acceleration limits")
        sides = np.asarray(sides, dtype=np.int64).reshape(m, 2)
        length = np.hypot(*(centres[dst] - centres[src]).T) / step_m if m else length
        sk, sj = np.nonzero(sides != NIL)
        v_cell = np.concatenate([v_cell, sides[sk, sj]])
        v_entry_step = np.concatenate([v_entry_step, step[sk]])
        v_entry_move = np.concatenate([v_entry_move, sk])
        v_exit_move = np.concatenate([v_exit_move, sk])
        v_robot = np.concatenate([v_robot, robot[sk]])
        v_slot = np.concatenate([v_slot, 1 + sj])
    order = np.lexsort((v_entry_step, v_cell))
    same = v_cell[order[1:]] == v_cell[order[:-1]]
    a, b = order[:-1][same], order[1:][same]                   # a visited the cell just before b
    if np.any(v_exit_move[a] == NIL) or np.any(v_entry_move[b] == NIL):
        raise AssertionError("discrete plan: a cell is visited after a robot parked on it for good")
    after_cell = np.full(m, NIL)
    other = v_robot[a] != v_robot[b]
    plain = v_slot[b] == 0
    after_cell[v_entry_move[b[plain]]] = np.where(other[plain], v_exit_move[a[plain]], NIL)
    after_side = np.full((m, 2 if sides is not None else 0), NIL, dtype=np.int64)
    if sides is not None:
        swept = ~plain & other
        after_side[v_entry_move[b[swept]], v_slot[b[swept]] - 1] = v_exit_move[a[swept]]
    visits = list(zip(v_exit_move[a][other].tolist(), v_entry_move[b][other].tolist()))
    sweeps = list(zip((v_slot[a][other] > 0).tolist(), (v_slot[b][other] > 0).tolist())) if sides is not None \
        else None
    # levels: by step, then by depth in the chains of robots following each other within a step
    depth = np.zeros(m, dtype=np.int64)
    chained = (after_cell != NIL) & (step[np.maximum(after_cell, 0)] == step)
    src_c, dst_c = np.nonzero(chained)[0], after_cell[chained]
    for _ in range(n):
        new = depth[dst_c] + 1
        if np.all(depth[src_c] >= new):
            break
        depth[src_c] = np.maximum(depth[src_c], new)
    base = np.asarray(durations, dtype=float)[robot] * length
    straight = np.abs(length - 1.0) < 1e-9

    def schedule(dur: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # slack[m]: how long before the previous holder's arrival move m may start (it follows that robot)
        slack = np.zeros(m)
        if centres is not None and radii is not None:
            has = after_cell != NIL
            p = after_cell[has]
            mine = np.nonzero(has)[0]
            d_in = (centres[dst[mine]] - centres[src[mine]]) / step_m
            d_out = (centres[dst[p]] - centres[src[p]]) / step_m
            same_way = np.all(np.abs(d_in - d_out) < 1e-9, axis=1)
            turn = np.abs(np.sum(d_in * d_out, axis=1)) < 1e-9
            rad = np.asarray(radii, dtype=float)
            reach = (rad[robot[mine]] + rad[robot[p]] + max(gap_m, GAP_M)) / step_m
            ahead = np.where(same_way, np.maximum(2.0 - reach, 0.0) * dur[mine], 0.0)
            # a turn: the leader leaves the cell at right angles to the follower's way in. In cell units,
            # with the leader a = (t - S_j) / dur_j along its way out and the follower b = (t - S_i) / dur_i
            # along its way in, their gap is |(a, 1 - b)|; from the follower's start on it is the
            # distance of the origin to a line, smallest (a0 / dur_i + 1 / dur_j) / |(1 / dur_j, 1 / dur_i)|
            # for the leader's progress a0 at that start: a0 >= (reach |(..)| - 1 / dur_j) dur_i keeps it
            # >= r_i + r_j (the leader's arrival clips the line, which only widens the gap)
            v_out, v_in = 1.0 / dur[p], 1.0 / dur[mine]
            a0 = np.clip((reach * np.hypot(v_out, v_in) - v_out) / v_in, 0.0, 1.0)
            # the follower may start once the leader has done a0 of its move: (1 - a0) dur_j before its end
            corner = (1.0 - a0) * dur[p]
            slack[mine] = np.where(same_way, ahead, np.where(turn, corner, 0.0)) * (straight[mine] & straight[p])
        start = np.zeros(m)
        end = np.zeros(m)
        level = step * (int(depth.max(initial=0)) + 1) + depth
        by_level = np.argsort(level, kind="stable")
        # the longest-path pass, one move at a time in level order (compiled: 10^5 moves)
        kern.precedence_pass(by_level, after_own, after_cell, slack, dur, start, end, after_side)
        return start, end

    acc = np.array([np.inf if a is None else float(a) for a in accels], dtype=float) if accels is not None \
        else np.full(n, np.inf)
    if not np.any(np.isfinite(acc)) or m == 0:
        start, end = schedule(base)
        return Timing(robot, step, src, dst, start, end, after_cell, first, visits, sides, sweeps)
    # runs: a robot's moves at consecutive steps in one direction
    direction = (centres[dst] - centres[src]) if centres is not None else (dst - src)[:, None]
    breaks = np.ones(m, dtype=bool)
    if m > 1:
        turns = np.any(np.abs(direction[1:] - direction[:-1]) > 1e-9, axis=1)
        breaks[1:] = (robot[1:] != robot[:-1]) | turns
        if consecutive:   # (otherwise the stops are found in the times below)
            breaks[1:] |= step[1:] != step[:-1] + 1
    for _ in range(50):
        dur = _ramp_durations(breaks, base, acc[robot], step_m)
        start, end = schedule(dur)
        inner_stop = ~breaks & (start > np.concatenate([[0.0], end[:-1]]) + 1e-9)
        if not inner_stop.any():
            break
        breaks |= inner_stop
    else:   # pragma: no cover - every move its own run: no stop can be inside one
        breaks[:] = True
        start, end = schedule(_ramp_durations(breaks, base, acc[robot], step_m))
    return Timing(robot, step, src, dst, start, end, after_cell, first, visits)


def _ramp_durations(breaks: np.ndarray, base: np.ndarray, accel: np.ndarray, step_m: float) -> np.ndarray:
    """Per move: its time in its run driven as a trapezoid (a triangle on short runs) from standstill
    to standstill at top speed ``step_m / base`` and acceleration ``accel`` (inf: at top speed)."""
    m = len(base)
    run = np.cumsum(breaks) - 1
    run_first = np.flatnonzero(breaks)
    pos = np.arange(m) - run_first[run]
    length = np.bincount(run, minlength=len(run_first))[run] * step_m
    v = step_m / base
    with np.errstate(divide="ignore", invalid="ignore"):
        tri = length < v * v / accel
        peak = np.where(tri, np.sqrt(accel * length), v)
        t_ramp = np.where(np.isfinite(accel), peak / accel, 0.0)
        s_ramp = np.where(np.isfinite(accel), peak * peak / (2 * accel), 0.0)
        total = np.where(tri, 2 * t_ramp, length / v + t_ramp)

        def at(s: np.ndarray) -> np.ndarray:
            up = np.sqrt(np.maximum(2 * s / accel, 0.0))
            down = total - np.sqrt(np.maximum(2 * (length - s) / accel, 0.0))
            cruise = t_ramp + (s - s_ramp) / peak
            return np.where(s <= s_ramp, up, np.where(s <= length - s_ramp, cruise, down))

        dur = at((pos + 1) * step_m) - at(pos * step_m)
    return np.where(np.isfinite(accel), dur, base)


def timed_paths(timing: Timing, centres: np.ndarray, starts: Sequence[int], ids: Sequence[str],
                radii: Sequence[float]) -> list[TimedPath]:
    """One timed path per robot: holds where a precedence makes it wait, collinear moves driven
    without a stop merged into one segment. ``centres`` is (cells, 2).

    Built for all robots at once: move k adds a hold waypoint (its source, its start) when it starts
    later than the robot's previous waypoint, and its end waypoint unless the robot's next move goes
    on in the same direction without a stop (then that one's end replaces it)."""
    n = len(ids)
    robot, start, end = timing.robot, timing.start, timing.end
    m = len(robot)
    first = timing.first
    idx = np.arange(m)
    is_first = idx == first[robot] if m else np.zeros(0, dtype=bool)
    prev_end = np.where(is_first, 0.0, np.concatenate([[0.0], end[:-1]]))
    hold = start > prev_end
    direction = centres[timing.dst] - centres[timing.src]
    same_dir = np.zeros(m, dtype=bool)
    if m > 1:
        took = end - start
        same_dir[1:] = (np.all(np.abs(direction[1:] - direction[:-1]) < 1e-12, axis=1)
                        & (np.abs(took[1:] - took[:-1]) < 1e-9))   # and the same speed
    merge = ~is_first & ~hold & same_dir          # move k replaces the end waypoint of move k - 1
    emit_end = np.ones(m, dtype=bool)
    emit_end[:-1] = ~merge[1:]
    src_xy, dst_xy = centres[timing.src], centres[timing.dst]
    start_xy = centres[np.asarray(starts, dtype=np.int64)]
    # rows: (robot, move, sub) with sub 0 = the start (move -1), 1 = a hold, 2 = a move's end
    rob = np.concatenate([np.arange(n), robot[hold], robot[emit_end]])
    mov = np.concatenate([np.full(n, -1), idx[hold], idx[emit_end]])
    sub = np.concatenate([np.zeros(n, dtype=np.int64), np.ones(int(hold.sum()), dtype=np.int64),
                          np.full(int(emit_end.sum()), 2)])
    xy = np.concatenate([start_xy, src_xy[hold], dst_xy[emit_end]])
    t = np.concatenate([np.zeros(n), start[hold], end[emit_end]])
    order = np.lexsort((sub, mov, rob))
    rows = np.column_stack([xy[order], t[order]])
    counts = np.bincount(rob, minlength=n)
    pieces = np.split(rows, np.cumsum(counts)[:-1])
    return [TimedPath(rid, float(radii[i]), pieces[i]) for i, rid in enumerate(ids)]


def network(timing: Timing, ids: Sequence[str], step_m: float) -> Network:
    """The (M,D) network of the chosen order: per pair of consecutive visits of a cell by two
    robots, a link from the earlier visitor i (higher) to the later j (lower); region k is the
    k-th such cell along j's path. T1 = i starts to move into the cell (0 for its start cell),
    T4 = i has arrived in its next cell, T2 = j starts to move in, T3 = j has arrived in its next
    cell (inf when the cell is j's goal)."""
    first, robot = timing.first, timing.robot
    start, end = timing.start, timing.end
    # metres along a robot's path: a diagonal move (one with swept sides) is sqrt 2 steps long
    length = np.ones(len(robot)) if timing.sides is None else np.where(timing.sides[:, 0] != NIL, math.sqrt(2), 1.0)
    before = np.cumsum(length) - length                  # path length before each move, over all robots
    if timing.visits:
        pairs = np.asarray(timing.visits, dtype=np.int64).reshape(-1, 2)
        swept = np.asarray(timing.sweeps, dtype=bool).reshape(-1, 2) if timing.sweeps is not None \
            else np.zeros((len(pairs), 2), dtype=bool)
        by_in = np.argsort(pairs[:, 1], kind="stable")     # (compiled: sorting 10^5 tuples in Python took 0.07 s)
        pairs, swept = pairs[by_in], swept[by_in]
        out_move, in_move = pairs[:, 0], pairs[:, 1]
        hi, lo = robot[out_move], robot[in_move]
        # k: 1, 2, ... along each lower robot's path (pairs are sorted by its move, robot-major)
        new_lo = np.concatenate([[True], lo[1:] != lo[:-1]])
        run_start = np.maximum.accumulate(np.where(new_lo, np.arange(len(lo)), 0))
        k = np.arange(len(lo)) - run_start + 1
        # (a sweep's move in is its move out: the earlier visitor's T1 is that move's start, the later's T3 its end)
        entry_hi = np.where(swept[:, 0], out_move, out_move - 1)
        t1 = np.where(swept[:, 0] | (out_move > first[hi]), start[np.maximum(entry_hi, 0)], 0.0)
        t4 = end[out_move]
        t2 = start[in_move]
        has_next = (in_move + 1 < first[lo + 1]) & ~swept[:, 1]
        nxt = np.minimum(in_move + 1, len(end) - 1)
        t3 = np.where(swept[:, 1], end[in_move], np.where(has_next, end[nxt], math.inf))
        ls = (before[in_move] - before[first[lo]]) * step_m
        le = ls + (length[in_move] + np.where(has_next, length[nxt], 0.0)) * step_m
        collecting = gc.isenabled()
        gc.disable()   # 10^5 small objects, none cyclic: the collector would only re-scan them
        try:
            links = [Link(ids[a], ids[b], kk, m_, d_, k1, k4, l1, l2) for a, b, kk, m_, d_, k1, k4, l1, l2 in
                     zip(hi.tolist(), lo.tolist(), k.tolist(), (t3 - t1).tolist(), (t4 - t2).tolist(), t1.tolist(),
                         t4.tolist(), ls.tolist(), le.tolist())]
        finally:
            if collecting:
                gc.enable()
    else:
        links = []
    moves = first[1:] > first[:-1]
    d0 = np.where(moves, start[np.minimum(first[:-1], max(len(start) - 1, 0))] if len(start) else 0.0, 0.0)
    tr = np.where(moves, end[np.maximum(first[1:] - 1, 0)] - d0 if len(end) else 0.0, 0.0)
    delay = dict(zip(ids, d0.tolist()))
    travel = dict(zip(ids, tr.tolist()))
    return Network(list(ids), delay, travel, links, None)
