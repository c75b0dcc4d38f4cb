"""New legs for the dense-crowd solver around trajectories being driven (``plan_incremental``).

When every driven trajectory lies on the lattice of cell centres (the dense solver's own plans, or
robots standing on cell centres: waypoints on centres, axis-aligned or diagonal moves), each of them
is turned into *exactly* the cell holdings of the timing rule (:mod:`.crowd_timing`: a robot holds a
cell from the start of its move into it to its arrival in the next one, for ever on its last
waypoint; a diagonal step of :mod:`.crowd_smooth` holds its two side cells while it drives). The
new robots are then planned one after another by safe-interval path planning at their own top speeds
(:func:`.crowd_sipp.sipp`, compiled) against those holdings and the ones already planned; a robot not
planned yet keeps its start cell for its first move. The safety argument is the timing's: no cell
held by two robots at once, so two robots are at least one cell step >= r_i + r_j apart - the checker
is the judge in the tests.

What is not on the lattice (md's and PRIOR's any-angle legs, robots between cell centres) has no
exact cell holdings: :func:`lattice_holdings` says so (None) and the planner hands those legs to
PRIOR's space-time search, which checks the continuous geometry itself.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..model import PlanningError, RobotSpec, TimedPath
from . import crowd_sipp as sipp_k
from .crowd_kernels import NIL

TOL = 1e-6


def lattice_holdings(fixed: Sequence[TimedPath], graph, t0: float) -> list[tuple[int, float, float]] | None:
    """(cell, from, to) holdings of the trajectories ``fixed``, in seconds after ``t0`` (clipped at
    0; cells the new robots cannot use are left out), or None when one of them leaves the lattice."""
    res = graph.grid.resolution
    h, w = graph.index.shape
    out: list[tuple[int, float, float]] = []
    for path in fixed:
        wp = np.asarray(path.waypoints, dtype=float)
        col = np.floor(wp[:, 0] / res)
        row = np.floor(wp[:, 1] / res)
        if (np.any(np.abs((col + 0.5) * res - wp[:, 0]) > TOL) or np.any(np.abs((row + 0.5) * res - wp[:, 1]) > TOL)
                or np.any(col < 0) or np.any(row < 0) or np.any(col >= w) or np.any(row >= h)):
            return None
        col, row = col.astype(np.int64), row.astype(np.int64)
        # cells with the time the robot is on each centre: (col, row, arrive, leave)
        seq: list[list[float]] = [[col[0], row[0], -np.inf, wp[0, 2]]]
        swept: list[tuple[int, int, float, float]] = []   # (col, row, from, to): sides of diagonal steps
        for k in range(1, len(wp)):
            dc, dr = col[k] - col[k - 1], row[k] - row[k - 1]
            if dc == 0 and dr == 0:
                seq[-1][3] = wp[k, 2]
                continue
            if dc != 0 and dr != 0 and abs(dc) != abs(dr):
                return None                       # neither axis-aligned nor diagonal
            steps = int(max(abs(dc), abs(dr)))
            ta, tb = wp[k - 1, 2], wp[k, 2]
            for m in range(1, steps + 1):
                t = ta + (tb - ta) * m / steps
                c_to, r_to = col[k - 1] + np.sign(dc) * m, row[k - 1] + np.sign(dr) * m
                if dc != 0 and dr != 0:           # a diagonal step (crowd_smooth) holds its two side cells
                    t_from = ta + (tb - ta) * (m - 1) / steps
                    swept += [(c_to, r_to - np.sign(dr), t_from, t), (c_to - np.sign(dc), r_to, t_from, t)]
                seq.append([c_to, r_to, t, t])
        for m, (c, r, _arrive, _leave) in enumerate(seq):
            lo = -np.inf if m == 0 else seq[m - 1][3]            # start of the move into it
            hi = np.inf if m == len(seq) - 1 else seq[m + 1][2]  # arrival in the next cell
            cell = int(graph.index[int(r), int(c)])
            if cell == NIL or hi - t0 < 0:
                continue
            out.append((cell, max(lo - t0, 0.0), hi - t0))
        for c, r, lo, hi in swept:
            cell = int(graph.index[int(r), int(c)])
            if cell != NIL and hi - t0 >= 0:
                out.append((cell, max(lo - t0, 0.0), hi - t0))
    return out


def plan_legs(graph, robots: Sequence[RobotSpec], starts: Sequence[int], goals: Sequence[int],
              holdings: list[tuple[int, float, float]], t0: float, seed: int = 0) -> list[TimedPath]:
    """One timed path per robot (in absolute time from ``t0``) around ``holdings`` (see the module
    docstring); tries up to three orders (shortest legs first, then each failed robot first); raises
    PlanningError naming the robots it could not serve."""
    n = len(robots)
    dur = np.array([graph.grid.resolution / r.max_speed for r in robots])
    goals_a = np.asarray(goals, dtype=np.int32)
    fields, grow = graph.distance_fields(goals_a)
    hops = fields[grow, np.asarray(starts, dtype=np.int32)]
    L = int(4 * max(int(hops.max(initial=0)), 1) + 64 + 2 * len(holdings) // max(graph.n, 1))
    counts = np.bincount(np.array([c for c, _, _ in holdings] + [0], dtype=np.int64), minlength=graph.n)
    K = int(counts.max(initial=0) + 4 * n + 16)
    # shortest legs first (measured on bench_dense_legs: sum of leg times 1.106 x free at 100 robots,
    # against 1.178 in the given order and 1.244 longest first)
    order = np.argsort(hops * dur, kind="stable").tolist()
    failed: list[int] = []
    for _attempt in range(3):
        result, failed = _sequential(graph, order, starts, goals_a, dur, fields, grow, holdings, L, K)
        if result is not None:
            return [_timed_path(graph, robots[i], result[i], dur[i], t0) for i in range(n)]
        order = failed + [i for i in order if i not in failed]
    raise PlanningError({robots[i].id: "dense solver: no leg around the driven trajectories (safe-interval "
                         "search on the cell graph)" for i in failed})


def _sequential(graph, order, starts, goals, dur, fields, grow, holdings, L, K):
    n = len(starts)
    ncell = graph.n
    h_who = np.full((ncell, K), NIL, dtype=np.int32)
    h_lo = np.zeros((ncell, K))
    h_hi = np.zeros((ncell, K))
    h_n = np.zeros(ncell, dtype=np.int32)
    for c, lo, hi in holdings:
        sipp_k._put(c, n, lo, hi, h_who, h_lo, h_hi, h_n)       # robot id n: the driven ones
    p_cell = np.zeros((n, L), dtype=np.int32)
    p_dep = np.full((n, L), np.inf)
    p_len = np.ones(n, dtype=np.int64)
    p_cell[:, 0] = np.asarray(starts, dtype=np.int32)
    for i in range(n):        # not planned yet: on its start for at least its first move
        sipp_k._put(int(starts[i]), i, 0.0, float(dur[i]), h_who, h_lo, h_hi, h_n)
    ks = K + 1
    si_lo, si_hi = np.zeros((ncell, ks)), np.zeros((ncell, ks))
    si_n, si_gen = np.zeros(ncell, dtype=np.int32), np.zeros(ncell, dtype=np.int64)
    node_gen = np.zeros(ncell * ks, dtype=np.int64)
    node_t = np.zeros(ncell * ks)
    node_par = np.zeros(ncell * ks, dtype=np.int64)
    node_closed = np.zeros(ncell * ks, dtype=np.int64)
    node_p = np.zeros(ncell * ks)
    no_lanes = np.zeros(graph.nb.shape, dtype=np.uint8)
    straight = sipp_k.no_diagonals(ncell)      # (legs keep to the cell graph's edges)
    out_cell = np.empty(L, dtype=np.int32)
    out_dep = np.empty(L)
    stats = np.zeros(5, dtype=np.int64)
    failed = []
    gen = 0
    for i in order:
        sipp_k._remove(i, p_cell, p_len, h_who, h_lo, h_hi, h_n, *straight)
        gen += 1
        ln = sipp_k.sipp(i, int(starts[i]), int(goals[i]), float(dur[i]), fields[grow[i]], h_lo, h_hi, h_n, graph.nb,
                         graph.deg, si_lo, si_hi, si_n, si_gen, gen, node_gen, node_t, node_par, node_closed, np.inf,
                         1.0, 50 * ncell, out_cell, out_dep, stats, float(dur[i]), node_p,
                         no_lanes, 0.0, *straight)
        if ln < 0:
            failed.append(i)
            sipp_k._put(int(starts[i]), i, 0.0, np.inf, h_who, h_lo, h_hi, h_n)   # it stays where it is
            continue
        p_cell[i, :ln] = out_cell[:ln]
        p_dep[i, :ln] = out_dep[:ln]
        p_len[i] = ln
        if not sipp_k._insert(i, p_cell, p_dep, p_len, dur, h_who, h_lo, h_hi, h_n, dur, *straight):
            failed.append(i)
    if failed:
        return None, failed
    return [(p_cell[i, :p_len[i]].copy(), p_dep[i, :p_len[i]].copy()) for i in range(n)], []


def _timed_path(graph, robot: RobotSpec, path, d: float, t0: float) -> TimedPath:
    cells, dep = path
    xy = np.column_stack([(graph.cols[cells] + 0.5), (graph.rows[cells] + 0.5)]) * graph.grid.resolution
    rows = [(xy[0, 0], xy[0, 1], t0)]
    last_dir = None
    for k in range(len(cells) - 1):
        t_dep = t0 + dep[k]
        here = rows[-1]
        direction = (xy[k + 1] - xy[k]).round(9).tolist()
        if t_dep > here[2] + 1e-12:          # it waits on its cell
            rows.append((xy[k, 0], xy[k, 1], t_dep))
            last_dir = None
        elif last_dir == direction and len(rows) > 1:
            rows.pop()                        # collinear without a stop: one segment
        rows.append((xy[k + 1, 0], xy[k + 1, 1], t_dep + d))
        last_dir = direction
    return TimedPath(robot.id, robot.radius, np.array(rows, dtype=float))
