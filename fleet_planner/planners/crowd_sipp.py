"""Speed-aware refinement of the dense-crowd solver: large neighbourhood search over the *timed* plan,
each robot re-planned by safe-interval path planning (SIPP, Phillips & Likhachev, ICRA 2011) at its
own top speed against the timed cell holdings of all the others (numba, as :mod:`.crowd_st`).

Why: the discrete plan moves every robot one cell per step. Timed at their own speeds (0.7-1.0 m/s
in the benchmarks), fast robots queue behind slow ones wherever the discrete plan made them follow:
on warehouse-10-20-10-2-1 with 400 robots the timing adds ~0.10 to SoC/free over the discrete plan's
own (speed-weighted) sum, while with equal speeds it adds 0.006. Here the neighbourhood's robots are
taken out of the timed plan and put back, one after the other, where their own speed gets them
earliest; a neighbourhood is kept when the sum of arrival times did not grow.

The safety rule is the timing's (:mod:`.crowd_timing`): a robot *holds* a cell from the start of
its move into it (time 0 for its start cell) to the end of its move out of it (for ever on its
goal); a re-planned robot holds no cell while anybody else holds it (hand-over at an instant is
allowed: the one leaving is then exactly on its next centre, the one entering on its previous one).
Two robots on distinct cells of the lattice keep one cell step >= r_i + r_j, so every accepted plan
passes the checker. The holdings of the others may overlap among themselves (the followers of the
first timing): those are left as they were.

Tables (all numpy): per cell ``h_lo``, ``h_hi``, ``h_who`` (cells, K) holding intervals and their
robot, ``h_n`` (cells,) how many; per robot ``p_cell`` (robots, L) its cells, ``p_dep`` (robots, L)
the start of its move out of each (so its move into cell k starts at ``p_dep[k - 1]``), ``p_len``.
The result goes back through the precedence pass (:func:`.crowd_timing.time_move_list`), which
keeps each cell's order and can only make robots earlier.
"""
from __future__ import annotations

import time

import numpy as np

from .crowd_kernels import NIL, _jit
from .crowd_lns import LNSStats
from .crowd_st import add_member, delayed_at_random, downhill, group_cost, pick_kind, settle, shuffle_group, start_group

INF = np.inf
SQRT2 = np.sqrt(2.0)
#: how long after the start of its move out of a cell a robot lets it go, in its time per cell, where
#: the precedence pass re-times the result (measured on bench_dense's 400 robots on
#: warehouse-10-20-10-2-1, 3 seeds, discrete pipeline with 0.8 s of discrete and 0.5 s of timed LNS:
#: SoC/free 1.246 at 1 (on arrival in the next cell) -> 1.231 at 0.3; the timed first plan plans
#: with it too): a follower may start into a cell well before its leader has arrived in the
#: next one (the timing's closed forms: at once behind a leader of the same speed in the same
#: direction, after 0-0.42 of the leader's move at a corner for radius sums <= 0.92 cell), so planning
#: with release 1 keeps trains of robots two cells apart where the timing lets them drive one apart.
#: It must stay > 0: moves into a cell then start strictly after the move out of it, which keeps the
#: precedences acyclic.
RELEASE = 0.3
#: the first plan repairs a robot cut off by at most this many parked robots on the spot
#: (:func:`prioritized`)
REPAIR = 4
#: the extra cost of a move against a 1-cell corridor's lane (:func:`one_way`), in the robot's time per
#: cell: in the first plan and in the timed LNS
LANE = 0.5
LANE_LNS = 0.0
TRAPPED = True
#: the heuristic's weight with diagonal steps (the hop distance is no lower bound then): in the timed LNS
#: plain 1 (0.9 measured no better, 400 robots on warehouse-10-20-10-2-1, 5 seeds), in the first plan 0.85
#: (less greedy, more expansions: 5 seeds SoC/free 1.150/1.141/1.152/1.152/1.144 at 1 -> 1.141/1.144/1.152/1.138/
#: 1.145 at 0.85 with the 1.5 s budget; 0.8 failed the first plan on one seed: 1.231 by the discrete pipeline)
DIAG_WEIGHT = 1.0
FIRST_WEIGHT = 0.85
#: timed LNS iterations per compiled call between budget checks (16: ~0.15-0.3 s per call with diagonal steps
#: at 400 robots, which overshot the budget by that much)
BATCH = 16
DIAG_BATCH = 4


@_jit
def _diag(v, w, dnb, ddeg):
    """Which of cell v's diagonal neighbours w is (its slot in ``dnb``), or -1: a straight move."""
    for e in range(ddeg[v]):
        if dnb[v, e] == w:
            return e
    return -1


@_jit
def _hold(p_cell, p_dep, i, k, length, rel, d, dnb, ddeg):
    """Robot i's holding interval of its k-th cell (``rel``: how long after the start of its move out
    it lets the cell go; out of a diagonal step, at its end: the timing gives a diagonal step no
    follower slack)."""
    lo = 0.0 if k == 0 else p_dep[i, k - 1]
    if k == length - 1:
        return lo, np.inf
    if _diag(p_cell[i, k], p_cell[i, k + 1], dnb, ddeg) >= 0:
        return lo, p_dep[i, k] + SQRT2 * d
    return lo, p_dep[i, k] + rel


@_jit
def _remove_at(a, c, h_who, h_lo, h_hi, h_n):
    w = 0
    for m in range(h_n[c]):
        if h_who[c, m] != a:
            h_who[c, w] = h_who[c, m]
            h_lo[c, w] = h_lo[c, m]
            h_hi[c, w] = h_hi[c, m]
            w += 1
    h_n[c] = w


@_jit
def _remove(a, p_cell, p_len, h_who, h_lo, h_hi, h_n, dnb, dside, ddeg):
    """Take robot a's holdings out of the tables (each cell's list stays sorted by start), the side
    cells its diagonal steps sweep too."""
    for k in range(p_len[a]):
        c = p_cell[a, k]
        _remove_at(a, c, h_who, h_lo, h_hi, h_n)
        if k + 1 < p_len[a]:
            e = _diag(c, p_cell[a, k + 1], dnb, ddeg)
            if e >= 0:
                _remove_at(a, dside[c, e, 0], h_who, h_lo, h_hi, h_n)
                _remove_at(a, dside[c, e, 1], h_who, h_lo, h_hi, h_n)


@_jit
def _put(c, who, lo, hi, h_who, h_lo, h_hi, h_n):
    """Insert one holding into cell c's list, kept sorted by start; False when it is full."""
    m = h_n[c]
    if m >= h_who.shape[1]:
        return False
    b = m - 1
    while b >= 0 and h_lo[c, b] > lo:
        h_who[c, b + 1] = h_who[c, b]
        h_lo[c, b + 1] = h_lo[c, b]
        h_hi[c, b + 1] = h_hi[c, b]
        b -= 1
    h_who[c, b + 1] = who
    h_lo[c, b + 1] = lo
    h_hi[c, b + 1] = hi
    h_n[c] = m + 1
    return True


@_jit
def _insert(a, p_cell, p_dep, p_len, rel, h_who, h_lo, h_hi, h_n, dur, dnb, dside, ddeg):
    """Write robot a's holdings (``rel[a]``: see :func:`_hold`; a diagonal step holds its two side
    cells from its start to its end); False (nothing left written) when a cell's table is full."""
    for k in range(p_len[a]):
        lo, hi = _hold(p_cell, p_dep, a, k, p_len[a], rel[a], dur[a], dnb, ddeg)
        ok = _put(p_cell[a, k], a, lo, hi, h_who, h_lo, h_hi, h_n)
        if ok and k + 1 < p_len[a]:
            c = p_cell[a, k]
            e = _diag(c, p_cell[a, k + 1], dnb, ddeg)
            if e >= 0:
                t0 = p_dep[a, k]
                ok = _put(dside[c, e, 0], a, t0, t0 + SQRT2 * dur[a], h_who, h_lo, h_hi, h_n) and \
                    _put(dside[c, e, 1], a, t0, t0 + SQRT2 * dur[a], h_who, h_lo, h_hi, h_n)
        if not ok:
            _remove(a, p_cell, p_len, h_who, h_lo, h_hi, h_n, dnb, dside, ddeg)
            return False
    return True


@_jit
def _intervals(c, h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen):
    """The safe intervals of cell c (complement of the union of its holdings), cached per search."""
    if si_gen[c] == gen:
        return
    si_gen[c] = gen
    count = 0
    free_from = 0.0
    for k in range(h_n[c]):
        if h_lo[c, k] > free_from:
            si_lo[c, count] = free_from
            si_hi[c, count] = h_lo[c, k]
            count += 1
        if h_hi[c, k] > free_from:
            free_from = h_hi[c, k]
    if free_from < np.inf:
        si_lo[c, count] = free_from
        si_hi[c, count] = np.inf
        count += 1
    si_n[c] = count


@_jit
def _side_free(s1, s2, tau, dd, si_lo, si_hi, si_n):
    """The earliest time from ``tau`` on at which both side cells s1, s2 stay free for ``dd`` (their
    safe intervals cached), or inf."""
    for _ in range(64):
        moved = False
        for c in (s1, s2):
            m = 0
            while m < si_n[c] and si_hi[c, m] < tau + dd:
                m += 1
            if m == si_n[c]:
                return np.inf
            if si_lo[c, m] > tau:
                tau = si_lo[c, m]
                moved = True
        if not moved:
            return tau
    return np.inf


@_jit
def _push(hf, hn, size, key, node):
    """Push ``node`` with ``key`` on the binary heap (hf, hn) of ``size`` entries; returns the heap
    (grown when full) and its new size."""
    cap = hf.shape[0]
    if size >= cap:
        gf = np.empty(2 * cap, dtype=np.float64)
        gn = np.empty(2 * cap, dtype=np.int64)
        gf[:cap] = hf
        gn[:cap] = hn
        hf, hn = gf, gn
    p = size
    size += 1
    while p > 0:
        q = (p - 1) // 2
        if hf[q] > key:
            hf[p] = hf[q]
            hn[p] = hn[q]
            p = q
        else:
            break
    hf[p] = key
    hn[p] = node
    return hf, hn, size


@_jit
def _relax(s, s2, arr, p2, h2, bound, busy, weight, gen, node_gen, node_t, node_p, node_par):
    """A step of :func:`sipp` from node ``s`` into node ``s2`` (cell, safe interval), arriving at
    ``arr`` with the extra cost ``p2`` paid by then and ``h2`` seconds of hops still to go: recorded
    unless it cannot arrive within ``bound`` or ``s2`` was reached at no higher cost in this search
    (stamp ``gen``). Returns the key to push ``s2`` with, or infinity (not recorded). The same for
    straight and diagonal steps; they differ only in how they find ``arr``. (The caller pushes: a
    helper that returned the heap arrays measured a few % slower.)"""
    if arr + h2 > bound:
        return np.inf
    if node_gen[s2] == gen and node_t[s2] + node_p[s2] <= arr + p2:
        return np.inf
    node_gen[s2] = gen
    node_t[s2] = arr
    node_p[s2] = p2
    node_par[s2] = s
    return arr + p2 + weight * max(h2, busy - arr)


@_jit
def sipp(a, start, goal, d, hd, h_lo, h_hi, h_n, nb, deg, si_lo, si_hi, si_n, si_gen, gen, node_gen, node_t,
         node_par, node_closed, bound, weight, limit, out_cell, out_dep, stats, rel, node_p, wrong, lane,
         dnb, dside, ddeg):
    """Earliest arrival of robot a (``d`` seconds per cell, ``hd`` hop distances to its goal) from
    ``start`` at time 0 at ``goal`` to stay there for ever, against the holdings in the tables (its
    own removed). Weighted A* (``weight`` on the heuristic) over (cell, safe interval) with the
    earliest arrival per interval. Writes its cells and departure times to ``out_cell`` / ``out_dep``
    and returns the number of cells, or -1 (none within ``bound`` seconds, ``limit`` expansions or
    the length of ``out_cell``). ``rel``: how long after the start of its move out of a cell the
    robot lets it go (see :func:`_hold`). The heuristic also knows when the goal is free for good
    (ours, as the discrete search's: a robot that must wait for others to pass its goal finds its
    waiting place without exploring everything it could reach before).

    ``wrong`` (shaped as ``nb``) and ``lane`` (ours): a move from cell v to its e-th neighbour with
    ``wrong[v, e]`` costs ``lane`` x ``d`` on top of its time in the search's order (a soft one-way
    rule, :func:`one_way`; ``node_p``: the extra cost paid so far per node); with ``lane`` 0 the
    search is plain SIPP.

    ``dnb`` / ``dside`` / ``ddeg`` (ours): per cell its diagonal neighbours, the two side cells each
    diagonal step sweeps and how many (all 0: 4-connected). A diagonal step takes sqrt 2 x ``d``, holds
    its source to its end and its two side cells from its start to its end (:mod:`.crowd_smooth`'s
    rule, which the precedence pass times exactly). The heuristic stays the 4-connected hop distance:
    no longer a lower bound, it makes the search greedy towards diagonal steps where they fit."""
    ks = si_lo.shape[1]
    _intervals(start, h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen)
    if si_n[start] == 0 or si_lo[start, 0] > 0.0:
        return -1
    _intervals(goal, h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen)
    if si_n[goal] == 0 or si_hi[goal, si_n[goal] - 1] < np.inf:
        return -1
    busy = si_lo[goal, si_n[goal] - 1]      # the goal is free for good from then on
    if busy > bound or hd[start] * d > bound:
        return -1
    s0 = start * ks
    node_gen[s0] = gen
    node_t[s0] = 0.0
    node_p[s0] = 0.0
    node_par[s0] = -1
    hf = np.empty(1 << 14, dtype=np.float64)
    hn = np.empty(1 << 14, dtype=np.int64)
    hf[0] = weight * max(hd[start] * d, busy)
    hn[0] = s0
    size = 1
    expanded = 0
    while size > 0:
        s = hn[0]
        size -= 1
        if size > 0:
            xf = hf[size]
            xn = hn[size]
            p = 0
            while True:
                c = 2 * p + 1
                if c >= size:
                    break
                if c + 1 < size and hf[c + 1] < hf[c]:
                    c += 1
                if hf[c] < xf:
                    hf[p] = hf[c]
                    hn[p] = hn[c]
                    p = c
                else:
                    break
            hf[p] = xf
            hn[p] = xn
        if node_closed[s] == gen:
            continue
        node_closed[s] = gen
        v = s // ks
        k = s - v * ks
        t = node_t[s]
        hi_v = si_hi[v, k]
        if v == goal and hi_v == np.inf:
            length = 0
            x = s
            while x != -1:
                length += 1
                x = node_par[x]
            if length > out_cell.shape[0]:
                return -1
            x = s
            prev = s
            for q in range(length - 1, -1, -1):
                out_cell[q] = x // ks
                if q < length - 1:
                    diag = _diag(x // ks, prev // ks, dnb, ddeg) >= 0
                    out_dep[q] = node_t[prev] - (SQRT2 * d if diag else d)
                prev = x
                x = node_par[x]
            out_dep[length - 1] = np.inf
            return length
        expanded += 1
        stats[2] += 1
        if expanded > limit:
            stats[3] += 1
            return -1
        for e in range(deg[v]):
            w = nb[v, e]
            _intervals(w, h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen)
            for j in range(si_n[w]):
                lo_w = si_lo[w, j]
                hi_w = si_hi[w, j]
                if lo_w + rel > hi_v:
                    break                 # this one and every later one opens too late
                if hi_w < t + d + rel:
                    continue              # over before the robot could get in and out
                tau = t if t > lo_w else lo_w
                arr = tau + d
                if tau + rel > hi_v or (arr + rel > hi_w and hi_w < np.inf):
                    continue
                s2 = w * ks + j
                key = _relax(s, s2, arr, node_p[s] + lane * d * wrong[v, e], hd[w] * d, bound, busy, weight, gen,
                             node_gen, node_t, node_p, node_par)
                if key < np.inf:
                    hf, hn, size = _push(hf, hn, size, key, s2)
        dd = SQRT2 * d
        for e in range(ddeg[v]):
            w = dnb[v, e]
            c1 = dside[v, e, 0]
            c2 = dside[v, e, 1]
            _intervals(w, h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen)
            _intervals(c1, h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen)
            _intervals(c2, h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen)
            for j in range(si_n[w]):
                lo_w = si_lo[w, j]
                hi_w = si_hi[w, j]
                if lo_w + dd > hi_v:
                    break                 # the source is held to the step's end
                if hi_w < t + dd + rel:
                    continue
                tau = _side_free(c1, c2, t if t > lo_w else lo_w, dd, si_lo, si_hi, si_n)
                if tau == np.inf or tau + dd > hi_v:
                    break                 # (a later interval of w only starts later)
                arr = tau + dd
                if arr + rel > hi_w and hi_w < np.inf:
                    continue
                s2 = w * ks + j
                key = _relax(s, s2, arr, node_p[s], hd[w] * d, bound, busy, weight, gen, node_gen, node_t, node_p,
                             node_par)
                if key < np.inf:
                    hf, hn, size = _push(hf, hn, size, key, s2)
    return -1


@_jit
def _arrival(p_cell, p_dep, p_len, i, d, dnb, ddeg):
    n = p_len[i]
    if n <= 1:
        return 0.0
    diag = _diag(p_cell[i, n - 2], p_cell[i, n - 1], dnb, ddeg) >= 0
    return p_dep[i, n - 2] + (SQRT2 * d if diag else d)


@_jit
def _holder(c, t0, t1, h_who, h_lo, h_hi, h_n, mark):
    """An unmarked robot holding cell c at some time in [t0, t1], or NIL."""
    for m in range(h_n[c]):
        j = h_who[c, m]
        if not mark[j] and h_lo[c, m] <= t1 and h_hi[c, m] >= t0:
            return j
    return NIL


@_jit
def lns(iters, p_cell, p_dep, p_len, arrival, lb, dur, rel, goals, fields, grow, nb, deg, h_who, h_lo, h_hi, h_n,
        si_lo, si_hi, si_n, si_gen, gen, node_gen, node_t, node_par, node_closed, size, weight, limit,
        strategy, stats, node_p, wrong, lane, dnb, dside, ddeg):
    """``iters`` iterations of the timed large neighbourhood search (module docstring); updates the
    tables and ``arrival`` in place, ``strategy`` (the neighbourhoods' weights) and ``stats``
    ([iterations, accepted]); returns the last search stamp."""
    n = p_cell.shape[0]
    L = p_cell.shape[1]
    group = np.empty(size, dtype=np.int32)
    old_cell = np.empty((size, L), dtype=np.int32)
    old_dep = np.empty((size, L), dtype=np.float64)
    old_len = np.empty(size, dtype=np.int64)
    old_arr = np.empty(size, dtype=np.float64)
    out_cell = np.empty(L, dtype=np.int32)
    out_dep = np.empty(L, dtype=np.float64)
    mark = np.zeros(n, dtype=np.bool_)
    delay = np.empty(n, dtype=np.float64)
    ones = np.ones(n)           # (a robot's cost is its arrival time)
    for _ in range(iters):
        total = 0.0
        for i in range(n):
            delay[i] = max(arrival[i] - lb[i], 0.0)
            total += delay[i]
        if total <= 1e-9:
            break
        kind = pick_kind(strategy)
        if kind == 0:       # a delayed robot and the robots in its way along a shortest path
            a = start_group(delay, total, group, mark)
            g = 1
            goal = goals[a]
            j = _holder(goal, lb[a], np.inf, h_who, h_lo, h_hi, h_n, mark)
            while j != NIL and g < size:
                g = add_member(j, g, group, mark)
                j = _holder(goal, lb[a], np.inf, h_who, h_lo, h_hi, h_n, mark)
            d = fields[grow[a]]
            v = p_cell[a, 0]
            t = 0.0
            da = dur[a]
            while d[v] > 0 and g < size:
                v = downhill(v, d, nb, deg)
                t += da
                g = add_member(_holder(v, t - da, t + da, h_who, h_lo, h_hi, h_n, mark), g, group, mark)
        else:               # delayed robots at random
            g = delayed_at_random(delay, total, group, mark, 1.0, 0.9)
        if not shuffle_group(group, g, mark):            # (re-planned in random order)
            continue
        before = group_cost(group, g, ones, arrival)
        floor = group_cost(group, g, ones, lb)
        for k in range(g):
            a = group[k]
            ln = p_len[a]
            old_len[k] = ln
            old_arr[k] = arrival[a]
            old_cell[k, :ln] = p_cell[a, :ln]
            old_dep[k, :ln] = p_dep[a, :ln]
            _remove(a, p_cell, p_len, h_who, h_lo, h_hi, h_n, dnb, dside, ddeg)
        for k in range(g):       # who is not re-planned yet still stands on its start at time 0
            a = group[k]
            _put(p_cell[a, 0], a, 0.0, dur[a], h_who, h_lo, h_hi, h_n)
        room = before - floor
        ok = True
        done = 0
        for k in range(g):
            a = group[k]
            _remove(a, p_cell, p_len, h_who, h_lo, h_hi, h_n, dnb, dside, ddeg)
            gen += 1
            ln = sipp(a, p_cell[a, 0], goals[a], dur[a], fields[grow[a]], h_lo, h_hi, h_n, nb, deg, si_lo, si_hi,
                      si_n, si_gen, gen, node_gen, node_t, node_par, node_closed,
                      lb[a] + room + 1e-9, weight, limit, out_cell, out_dep, stats, rel[a], node_p,
                      wrong, lane, dnb, dside, ddeg)
            if ln < 0:
                stats[4] += 1
                ok = False
                break
            p_cell[a, :ln] = out_cell[:ln]
            p_dep[a, :ln] = out_dep[:ln]
            p_len[a] = ln
            if not _insert(a, p_cell, p_dep, p_len, rel, h_who, h_lo, h_hi, h_n, dur, dnb, dside, ddeg):
                ok = False
                break
            arrival[a] = _arrival(p_cell, p_dep, p_len, a, dur[a], dnb, ddeg)
            room -= arrival[a] - lb[a]
            done += 1
        if not settle(kind, ok, before, group_cost(group, g, ones, arrival), strategy, stats):
            for k in range(g):
                _remove(group[k], p_cell, p_len, h_who, h_lo, h_hi, h_n, dnb, dside, ddeg)
            for k in range(g):
                a = group[k]
                ln = old_len[k]
                p_len[a] = ln
                p_cell[a, :ln] = old_cell[k, :ln]
                p_dep[a, :ln] = old_dep[k, :ln]
                arrival[a] = old_arr[k]
                _insert(a, p_cell, p_dep, p_len, rel, h_who, h_lo, h_hi, h_n, dur, dnb, dside, ddeg)
        for k in range(g):
            mark[group[k]] = False
    return gen


class TimedRefiner(LNSStats):
    """The timed LNS over a :class:`.crowd_timing.Timing` of robots driving at constant top speeds
    (``durations``: seconds per cell); ``fields`` / ``grow`` / ``goals`` / ``nb`` / ``deg`` as in the
    configuration search; :meth:`run` improves, :meth:`moves` gives the result as a move list for
    :func:`.crowd_timing.time_move_list`. ``release``: a robot lets a cell go ``release`` x its time
    per cell after the start of its move out (1: on its arrival in the next cell, the timing's rule
    without followers; less: the planned order only, re-timed by the precedence pass, which lets a
    follower in as early as the geometry allows - see :data:`RELEASE`). :meth:`from_scratch` plans
    the first timed plan itself (prioritized)."""

    def __init__(self, timing, starts, goals, durations, fields, grow, nb, deg, ncell: int, seed: int = 0,
                 size: int = 4, release: float = 1.0, wrong: np.ndarray | None = None, lane: float = 0.0,
                 diagonals: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None):
        n = len(starts)
        self._setup(starts, goals, durations, fields, grow, nb, deg, seed, size, release, diagonals)
        if wrong is not None:
            self.wrong, self.lane_lns = wrong, float(lane)
        first = timing.first
        counts = np.diff(first) + 1
        self.L = int(max(2 * counts.max(initial=1), counts.max(initial=1) + 64))
        self.p_cell = np.zeros((n, self.L), dtype=np.int32)
        self.p_dep = np.full((n, self.L), np.inf)
        self.p_len = counts.astype(np.int64)
        self.p_cell[:, 0] = np.asarray(starts, dtype=np.int32)
        rob = timing.robot
        pos = np.arange(len(rob)) - first[rob]
        self.p_cell[rob, pos + 1] = timing.dst
        self.p_dep[rob, pos] = timing.start
        # each move holds its source until its end (release 1): record the move's *start* and the
        # robot's own duration; where the first timing sped a move up or slowed it (ramps: not here)
        # the hold interval below still covers [start of move in, end of move out]
        end_of = np.full((n, self.L), np.inf)
        end_of[rob, pos] = timing.end
        self.arrival = np.where(counts > 1, end_of[np.arange(n), np.maximum(counts - 2, 0)], 0.0)
        if release < 1.0:
            end_of = self.p_dep + self.rel[:, None]
        sides = timing.sides if timing.sides is not None else np.full((len(rob), 2), NIL, dtype=np.int64)
        diag = sides[:, 0] != NIL
        end_of[rob[diag], pos[diag]] = np.maximum(end_of[rob[diag], pos[diag]],
                                                  timing.start[diag] + SQRT2 * self.dur[rob[diag]])
        # holdings exactly as the first timing has them
        cells_n = np.zeros(ncell, dtype=np.int64)
        np.add.at(cells_n, self.p_cell[np.arange(self.L)[None, :] < counts[:, None]], 1)
        self._tables(ncell, int(max(16, 2 * cells_n.max(initial=1) + 8)))
        _fill(self.p_cell, self.p_dep, self.p_len, end_of, self.h_who, self.h_lo, self.h_hi, self.h_n)
        for c, who, lo, hi in zip(sides[diag].reshape(-1).tolist(), np.repeat(rob[diag], 2).tolist(),
                                  np.repeat(timing.start[diag], 2).tolist(),
                                  np.repeat(np.maximum(timing.end[diag], timing.start[diag] + SQRT2 *
                                                       self.dur[rob[diag]]), 2).tolist()):
            _put(c, who, lo, hi, self.h_who, self.h_lo, self.h_hi, self.h_n)

    def _setup(self, starts, goals, durations, fields, grow, nb, deg, seed, size, release, diagonals=None) -> None:
        n = len(starts)
        if diagonals is None:
            diagonals = no_diagonals(len(nb))
        self.dnb, self.dside, self.ddeg = diagonals
        self.n = n
        self.dur = np.asarray(durations, dtype=np.float64)
        if not 0.0 < release <= 1.0:
            raise ValueError(f"release: must be in (0, 1] (got {release!r})")
        self.rel = release * self.dur
        self.goals = np.asarray(goals, dtype=np.int32)
        self.fields, self.grow, self.nb, self.deg = fields, grow, nb, deg
        self.lb = fields[grow, np.asarray(starts, dtype=np.int32)].astype(np.float64) * self.dur
        self.gen = 0
        self.size = max(2, min(int(size), n))
        self.wrong = np.zeros(np.shape(nb), dtype=np.uint8)
        self.lane_first = self.lane_lns = 0.0
        self.weight = 1.0     # (plain A*: measured 3 seeds at 400 robots, ~0.004 lower SoC/free than 1.2)
        if self.ddeg.any():
            self.weight = DIAG_WEIGHT
        self.limit = 20 * len(nb)
        self.strategy = np.ones(2)
        self.stats = np.zeros(5, dtype=np.int64)   # iterations, accepted, expansions, over limit, failed
        from . import crowd_st

        crowd_st.seed_rng(int(seed))

    def _tables(self, ncell: int, K: int) -> None:
        """Empty holding tables of K entries per cell and the search's scratch arrays."""
        self.h_who = np.full((ncell, K), NIL, dtype=np.int32)
        self.h_lo = np.zeros((ncell, K))
        self.h_hi = np.zeros((ncell, K))
        self.h_n = np.zeros(ncell, dtype=np.int32)
        ks = K + 1
        self.si_lo = np.zeros((ncell, ks))
        self.si_hi = np.zeros((ncell, ks))
        self.si_n = np.zeros(ncell, dtype=np.int32)
        self.si_gen = np.zeros(ncell, dtype=np.int64)
        self.node_gen = np.zeros(ncell * ks, dtype=np.int64)
        self.node_t = np.zeros(ncell * ks)
        self.node_par = np.zeros(ncell * ks, dtype=np.int64)
        self.node_closed = np.zeros(ncell * ks, dtype=np.int64)
        self.node_p = np.zeros(ncell * ks)

    @classmethod
    def from_scratch(cls, starts, goals, durations, fields, grow, nb, deg, ncell: int, seed: int = 0,
                     size: int = 4, release: float = 1.0, tries: int = 3, hold: float = 3.0,
                     cpu_s: float = float("inf"), give_up: int = 20,
                     repair: int = REPAIR, wrong: np.ndarray | None = None,
                     lane: float = 0.0, diagonals: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                     ) -> tuple[TimedRefiner | None, bool]:
        """The first timed plan by prioritized safe-interval planning (:func:`prioritized`): robots
        with the shortest time alone first, each at its own speed against the ones before it and the
        start cells of the ones after it (held ``hold`` x its time per cell). As in the discrete
        first plan (:func:`.crowd_lns.prioritized_first`) the failed robots go first in the next of
        at most ``tries`` passes. Returns (the refiner holding the plan, ready for :meth:`run`, or
        None when no pass succeeded within ``cpu_s`` CPU seconds, and whether a pass stopped because
        more than one robot in ``give_up`` failed: prioritized planning of the crowd is hopeless)."""
        self = cls.__new__(cls)
        self._setup(starts, goals, durations, fields, grow, nb, deg, seed, size, release, diagonals)
        if wrong is not None:
            self.wrong, self.lane_first = wrong, float(lane)
        n = self.n
        if n == 0:
            return None, False
        starts = np.asarray(starts, dtype=np.int32)
        hops = fields[grow, starts].astype(np.int64)
        self.L = int(4 * hops.max(initial=0) + 64)
        cpu_end = time.process_time() + cpu_s
        order = np.argsort(self.lb, kind="stable").astype(np.int64)
        failed = np.empty(n, dtype=np.int64)
        max_failed = max(2, n // give_up)
        K = 64
        self._tables(ncell, K)
        attempt = 0
        while attempt < tries:
            self.p_cell = np.zeros((n, self.L), dtype=np.int32)
            self.p_cell[:, 0] = starts
            self.p_dep = np.full((n, self.L), np.inf)
            self.p_len = np.ones(n, dtype=np.int64)
            self.arrival = np.zeros(n)
            self.h_n[:] = 0
            self.gen, nf = prioritized(order, hold, self.p_cell, self.p_dep, self.p_len, self.arrival, self.dur,
                                       self.rel, self.goals, fields, grow, nb, deg, self.h_who, self.h_lo, self.h_hi,
                                       self.h_n, self.si_lo, self.si_hi, self.si_n, self.si_gen, self.gen,
                                       self.node_gen, self.node_t, self.node_par, self.node_closed,
                                       FIRST_WEIGHT if self.ddeg.any() else 1.0,
                                       4 * ncell, failed, max_failed, self.stats, self.node_p, repair, self.wrong,
                                       self.lane_first, self.dnb, self.dside, self.ddeg)
            if nf < 0:              # a cell's holding table overflowed: twice the room, same order
                K *= 2
                self._tables(ncell, K)
                self.gen = 0
                continue
            if nf == 0:
                self.stats[:] = 0
                return self, False
            attempt += 1
            if nf > max_failed or time.process_time() > cpu_end:
                return None, nf > max_failed
            first = failed[:nf]
            order = np.concatenate([first, order[~np.isin(order, first)]])
        return None, False

    def total(self) -> float:
        return float(self.arrival.sum())

    def run(self, deadline: float, cpu_s: float, batch: int | None = None, patience: int = 0) -> None:
        """Improve the plan until ``deadline`` (perf_counter), ``cpu_s`` seconds of this process's CPU
        time, until no robot is delayed, or until ``patience`` iterations in a row did not lower the
        sum of arrivals (default: 50 + the number of robots, as the discrete LNS)."""
        cpu_end = time.process_time() + cpu_s
        batch = batch or (DIAG_BATCH if self.ddeg.any() else BATCH)
        patience = patience or 50 + self.n
        best, best_at = self.total(), self.iterations
        while time.perf_counter() < deadline and time.process_time() < cpu_end:
            if self.iterations - best_at >= patience:
                return
            now = self.total()
            if now < best - 1e-9:
                best, best_at = now, self.iterations
            before = self.iterations
            self.gen = int(lns(batch, self.p_cell, self.p_dep, self.p_len, self.arrival, self.lb, self.dur, self.rel,
                               self.goals, self.fields, self.grow, self.nb, self.deg, self.h_who, self.h_lo,
                               self.h_hi, self.h_n, self.si_lo, self.si_hi, self.si_n, self.si_gen, self.gen,
                               self.node_gen, self.node_t, self.node_par, self.node_closed, self.size,
                               self.weight, self.limit, self.strategy, self.stats, self.node_p,
                               self.wrong, self.lane_lns, self.dnb, self.dside, self.ddeg))
            if self.iterations == before:
                return

    def moves(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(robot, order key, src, dst) of every move, robot-major in time order; the key is the
        move's start time."""
        L = self.L
        idx = np.arange(L - 1)[None, :]
        has = idx < (self.p_len - 1)[:, None]
        robot = np.nonzero(has)[0]
        pos = np.nonzero(has)[1]
        return robot, self.p_dep[robot, pos], self.p_cell[robot, pos], self.p_cell[robot, pos + 1]

    def sides(self, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
        """(moves, 2): the side cells each move from ``src`` to ``dst`` sweeps (NIL, NIL for straight
        moves), as :func:`.crowd_timing.time_move_list` takes them."""
        out = np.full((len(src), 2), NIL, dtype=np.int64)
        for e in range(self.dnb.shape[1]):
            hit = (self.dnb[src, e] == dst) & (e < self.ddeg[src])
            out[hit] = self.dside[src[hit], e]
        return out


def no_diagonals(ncell: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The diagonal tables of a 4-connected search (no diagonal steps)."""
    return np.full((ncell, 4), NIL, dtype=np.int32), np.full((ncell, 4, 2), NIL, dtype=np.int32), \
        np.zeros(ncell, dtype=np.int32)


def diagonal_table(index: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Diagonal steps between cells (ours): per cell its diagonal neighbours whose 2x2 block is four
    cells (``index``: (rows, cols) cell index, NIL where there is none), the two side cells of each,
    and how many. A disc of radius <= half the cell step on the centre line of such a step keeps
    clear of every obstacle (obstacles are whole cells); the caller checks the radii."""
    h, w = index.shape
    n = len(rows)
    dnb, dside, ddeg = no_diagonals(n)

    def at(r, c):
        ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        out = np.full(r.shape, NIL, dtype=np.int64)
        out[ok] = index[r[ok], c[ok]]
        return out

    for dr, dc in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
        z, s1, s2 = at(rows + dr, cols + dc), at(rows, cols + dc), at(rows + dr, cols)
        ok = np.nonzero((z != NIL) & (s1 != NIL) & (s2 != NIL))[0]
        slot = ddeg[ok]
        dnb[ok, slot] = z[ok]
        dside[ok, slot, 0] = s1[ok]
        dside[ok, slot, 1] = s2[ok]
        ddeg[ok] += 1
    return dnb, dside, ddeg


@_jit
def _fill(p_cell, p_dep, p_len, end_of, h_who, h_lo, h_hi, h_n):
    """The first timing's holdings: cell k from the start of the move into it to ``end_of`` the move
    out of it (for ever on the goal)."""
    n = p_cell.shape[0]
    for i in range(n):
        ln = p_len[i]
        for k in range(ln):
            lo = 0.0 if k == 0 else p_dep[i, k - 1]
            hi = np.inf if k == ln - 1 else end_of[i, k]
            _put(p_cell[i, k], i, lo, hi, h_who, h_lo, h_hi, h_n)


@_jit
def _sealed_by(a, start, goal, goal_of, planned, nb, deg, seen, queue, out):
    """The planned robots parked on their goals around robot a's goal that cut it off from its start
    (ours): a breadth-first search from the goal that does not cross their goal cells, each found one
    listed in ``out``; returns how many (0 when the start is reached: not sealed, or more than
    ``len(out)``: too many to re-plan)."""
    seen[:] = False
    seen[goal] = True
    queue[0] = goal
    head, tail, k = 0, 1, 0
    while head < tail:
        v = queue[head]
        head += 1
        for e in range(deg[v]):
            w = nb[v, e]
            if seen[w]:
                continue
            seen[w] = True
            if w == start:
                return 0
            b = goal_of[w]
            if b != NIL and b != a and planned[b]:
                if k >= len(out):
                    return len(out) + 1
                out[k] = b
                k += 1
                continue
            queue[tail] = w
            tail += 1
    return k


@_jit
def _through_start(a, start, planned, h_who, h_n, out):
    """The first planned robots that drive through robot a's start cell (ours: a robot not sealed off
    from its goal that still finds no path is trapped on its start: they come before it can get out),
    at most ``len(out)``, listed in ``out`` (each cell's holdings are sorted by start); how many."""
    k = 0
    for m in range(h_n[start]):
        b = h_who[start, m]
        if b == a or not planned[b]:
            continue
        dup = False
        for q in range(k):
            if out[q] == b:
                dup = True
        if dup:
            continue
        out[k] = b
        k += 1
        if k == len(out):
            break
    return k


@_jit
def _plan_one(a, p_cell, p_dep, p_len, arrival, dur, rel, goals, fields, grow, nb, deg, h_who, h_lo, h_hi, h_n,
              si_lo, si_hi, si_n, si_gen, gen, node_gen, node_t, node_par, node_closed, weight, limit, stats, node_p,
              out_cell, out_dep, wrong, lane, dnb, dside, ddeg):
    """Robot a (its holdings already out of the tables) by :func:`sipp`, written to the tables; returns
    (the search stamp, 1 planned, 0 no path, -1 a cell's holding table is full)."""
    gen += 1
    ln = sipp(a, p_cell[a, 0], goals[a], dur[a], fields[grow[a]], h_lo, h_hi, h_n, nb, deg, si_lo, si_hi, si_n,
              si_gen, gen, node_gen, node_t, node_par, node_closed, np.inf, weight, limit, out_cell, out_dep,
              stats, rel[a], node_p, wrong, lane, dnb, dside, ddeg)
    if ln < 0:
        return gen, 0
    p_cell[a, :ln] = out_cell[:ln]
    p_dep[a, :ln] = out_dep[:ln]
    p_len[a] = ln
    if not _insert(a, p_cell, p_dep, p_len, rel, h_who, h_lo, h_hi, h_n, dur, dnb, dside, ddeg):
        return gen, -1
    arrival[a] = _arrival(p_cell, p_dep, p_len, a, dur[a], dnb, ddeg)
    return gen, 1


@_jit
def prioritized(order, hold, p_cell, p_dep, p_len, arrival, dur, rel, goals, fields, grow, nb, deg, h_who, h_lo,
                h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen, node_gen, node_t, node_par, node_closed, weight, limit,
                failed, max_failed, stats, node_p, repair, wrong, lane, dnb, dside, ddeg):
    """Prioritized safe-interval planning on empty tables: the robots of ``order`` one after the
    other by :func:`sipp` at their own speeds against the ones before it and the start cells of the
    ones after it (each held ``hold`` x its time per cell). ``p_cell[:, 0]`` holds the starts,
    ``p_len`` ones. A robot without a path is left out of the tables and listed in ``failed``; more
    than ``max_failed`` of them stop the pass. Returns (the last search stamp, the number of failed
    robots), -1 failed when a cell's holding table is full.

    ``repair`` (ours): a robot whose goal is cut off by at most ``repair`` robots parked on their
    goals (a 1-cell aisle shut on both sides) is planned before them on the spot: they are taken out
    (back on their starts), it is planned, and they are planned again after it, waiting for it to pass.
    Without it the robot fails and goes first in the next pass, ahead of everybody, which makes
    robots wait by their goals for a robot from far away that needed only to pass those few. Repairs
    count as failures towards ``max_failed`` (then the number returned is ``max_failed + 1``)."""
    n = len(order)
    ncell = nb.shape[0]
    L = p_cell.shape[1]
    out_cell = np.empty(L, dtype=np.int32)
    out_dep = np.empty(L, dtype=np.float64)
    goal_of = np.full(ncell, NIL, dtype=np.int32)
    planned = np.zeros(n, dtype=np.bool_)
    seen = np.zeros(ncell, dtype=np.bool_)
    queue = np.empty(ncell, dtype=np.int32)
    blockers = np.empty(max(repair, 1), dtype=np.int32)
    for q in range(n):
        a = order[q]
        if not _put(p_cell[a, 0], a, 0.0, hold * dur[a], h_who, h_lo, h_hi, h_n):
            return gen, -1
        goal_of[goals[a]] = a
    nf = 0
    fixes = 0
    for q in range(n):
        a = order[q]
        _remove(a, p_cell, p_len, h_who, h_lo, h_hi, h_n, dnb, dside, ddeg)
        gen, ok = _plan_one(a, p_cell, p_dep, p_len, arrival, dur, rel, goals, fields, grow, nb, deg, h_who, h_lo,
                            h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen, node_gen, node_t, node_par, node_closed,
                            weight, limit, stats, node_p, out_cell, out_dep, wrong, lane, dnb, dside, ddeg)
        if ok < 0:
            return gen, -1
        k = 0
        if ok == 0 and repair > 0:
            k = _sealed_by(a, p_cell[a, 0], goals[a], goal_of, planned, nb, deg, seen, queue, blockers)
            if k > repair:
                k = 0
            if k == 0 and TRAPPED:
                k = _through_start(a, p_cell[a, 0], planned, h_who, h_n, blockers)
        if k > 0:
            fixes += 1
            if nf + fixes > max_failed:      # (hopeless as when they fail: at 1000 robots on warehouse-10-20-10-2-1
                return gen, max_failed + 1    # the repairs overflowed the holding tables after 1 s)
            for m in range(k):
                b = blockers[m]
                _remove(b, p_cell, p_len, h_who, h_lo, h_hi, h_n, dnb, dside, ddeg)
                p_len[b] = 1
                planned[b] = False
                if not _put(p_cell[b, 0], b, 0.0, hold * dur[b], h_who, h_lo, h_hi, h_n):
                    return gen, -1
            gen, ok = _plan_one(a, p_cell, p_dep, p_len, arrival, dur, rel, goals, fields, grow, nb, deg, h_who,
                                h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen, node_gen, node_t, node_par,
                                node_closed, weight, limit, stats, node_p, out_cell, out_dep, wrong, lane, dnb, dside,
                                ddeg)
            if ok < 0:
                return gen, -1
            for m in range(k):
                b = blockers[m]
                _remove(b, p_cell, p_len, h_who, h_lo, h_hi, h_n, dnb, dside, ddeg)
                gen, okb = _plan_one(b, p_cell, p_dep, p_len, arrival, dur, rel, goals, fields, grow, nb, deg, h_who,
                                     h_lo, h_hi, h_n, si_lo, si_hi, si_n, si_gen, gen, node_gen, node_t, node_par,
                                     node_closed, weight, limit, stats, node_p, out_cell, out_dep, wrong, lane, dnb,
                                     dside, ddeg)
                if okb < 0:
                    return gen, -1
                if okb == 0:
                    failed[nf] = b
                    nf += 1
                else:
                    planned[b] = True
        if ok == 0:
            failed[nf] = a
            nf += 1
            if nf > max_failed:
                break
            continue
        planned[a] = True
    return gen, nf


def one_way(index: np.ndarray, rows: np.ndarray, cols: np.ndarray, nb: np.ndarray, deg: np.ndarray) -> np.ndarray:
    """Lanes of 1-cell corridors (ours, after the "highways" of Cohen et al., "Improved Solvers for
    Bounded-Suboptimal Multi-Agent Path Finding", IJCAI 2016, there a cost factor on moves against a
    chosen direction): a cell whose two sides across a row (column) are blocked lies in a horizontal
    (vertical) corridor, driven east on even rows and west on odd ones (south on even columns, north on
    odd ones), so that parallel corridors one shelf apart run opposite ways. Returns ``wrong`` shaped as
    ``nb``: 1 where the move from a cell to its e-th neighbour goes against the lane of its source or
    its destination cell. ``index``: (rows, cols) cell index, NIL where there is no cell."""
    h, w = index.shape

    def cell_at(r, c):
        ok = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        out = np.full(r.shape, NIL, dtype=np.int64)
        out[ok] = index[r[ok], c[ok]]
        return out

    horizontal = (cell_at(rows - 1, cols) == NIL) & (cell_at(rows + 1, cols) == NIL)
    vertical = (cell_at(rows, cols - 1) == NIL) & (cell_at(rows, cols + 1) == NIL)
    east = rows % 2 == 0          # on horizontal corridors: +1 column is the lane's way
    south = cols % 2 == 0         # on vertical ones: +1 row
    n = len(rows)
    src = np.repeat(np.arange(n), nb.shape[1])
    dst = nb.reshape(-1).astype(np.int64)
    has = dst != NIL
    dst_ok = np.where(has, dst, 0)
    dr, dc = rows[dst_ok] - rows[src], cols[dst_ok] - cols[src]
    wrong = np.zeros(len(src), dtype=bool)
    for c in (src, dst_ok):
        wrong |= horizontal[c] & (dr == 0) & (dc == np.where(east[c], -1, 1))
        wrong |= vertical[c] & (dc == 0) & (dr == np.where(south[c], -1, 1))
    return (wrong & has).reshape(nb.shape).astype(np.uint8)


_WARM = False


def warm_up() -> None:
    """Compile (or load from numba's cache) this module's kernels on the kernels' toy instance: two
    robots passing on a 3x2 grid, both re-planned by the timed LNS."""
    global _WARM
    if _WARM:
        return
    from .crowd_kernels import bfs_fields, toy_instance
    from .crowd_timing import time_move_list, time_moves

    nb, deg, goals = toy_instance()
    fields = bfs_fields(nb, deg, goals)
    grow = np.array([0, 1], dtype=np.int32)
    plan = np.array([[0, 2], [1, 5], [2, 4], [2, 3], [2, 0]], dtype=np.int64)
    dur = np.array([1.0, 1.25])
    timing = time_moves(plan, dur)
    refiner = TimedRefiner(timing, plan[0], goals, dur, fields, grow, nb, deg, 6, 0, size=2)
    refiner.lb[:] = 0.0            # every robot "delayed": the iterations run
    refiner.run(float("inf"), cpu_s=0.0, batch=2)
    lns(2, refiner.p_cell, refiner.p_dep, refiner.p_len, refiner.arrival, refiner.lb, refiner.dur, refiner.rel,
        refiner.goals, fields, grow, nb, deg, refiner.h_who, refiner.h_lo, refiner.h_hi, refiner.h_n, refiner.si_lo,
        refiner.si_hi, refiner.si_n, refiner.si_gen, 0, refiner.node_gen, refiner.node_t, refiner.node_par,
        refiner.node_closed, 2, 1.2, 1000, refiner.strategy, refiner.stats, refiner.node_p,
        refiner.wrong, 0.0, *no_diagonals(6))
    robot, key, src, dst = refiner.moves()
    time_move_list(plan[0], robot, key, src, dst, dur)
    TimedRefiner.from_scratch(plan[0], goals, dur, fields, grow, nb, deg, 6, 0, size=2, release=RELEASE)
    # a diagonal move's side cells are held from Python (TimedRefiner.__init__): the same call here
    _put(0, 0, 0.0, 1.0, refiner.h_who, refiner.h_lo, refiner.h_hi, refiner.h_n)
    _WARM = True
