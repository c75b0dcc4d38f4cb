"""The compiled inner loops of the md planner's hold search and region merging (numba).

Why numba: the safe-interval earliest-arrival search along a fixed path (:mod:`fleet_planner.scheduler`,
holds anywhere) is a dynamic programme over (vertex, safe interval) with branchy interval sweeps,
and the merging of a pair's collision pieces into regions is a union of touching boxes: both are
short loops over small, data-dependent lists that numpy cannot vectorise, run thousands of times
per plan (issue 8's profile: they were most of md's planning time). The functions are written in
plain Python over numpy arrays, so without numba they run as they are (correct, slower).

Results are the same numbers as the pure-Python loops they replace (same floating-point
operations in the same order, same tie-breaking); ``test/test_md_holds.py`` compares them on
random inputs against a plain transcription of the original code.
"""
from __future__ import annotations

from typing import Any

import numpy as np

_numba_njit: Any
try:
    from numba import njit as _numba_njit
except ImportError:   # pragma: no cover - the planner still works, only slowly
    _numba_njit = None

HAVE_NUMBA = _numba_njit is not None
INF = np.inf


def _jit(fn: Any) -> Any:
    """numba's nopython compilation with an on-disk cache, or the function itself without numba."""
    if _numba_njit is None:   # pragma: no cover
        return fn
    return _numba_njit(cache=True, nogil=True)(fn)


# ---------------------------------------------------------------------------------------------
# safe intervals and the earliest arrival along a chain of hold vertices
# ---------------------------------------------------------------------------------------------
@_jit
def safe_intervals(f_ptr, f_lo, f_hi, free_start):
    """The closed safe intervals in [0, inf) of each hold vertex k outside its open forbidden
    intervals ``f_lo/f_hi[f_ptr[k]:f_ptr[k + 1]]`` (sorted by lo); two forbidden intervals that
    only touch leave the instant between them free. ``free_start``: vertex 0 is safe for ever.
    Returns (s_ptr, s_lo, s_hi), vertex k's intervals at ``s_ptr[k]:s_ptr[k + 1]``."""
    nh = len(f_ptr) - 1
    s_ptr = np.empty(nh + 1, dtype=np.int64)
    s_lo = np.empty(len(f_lo) + nh)
    s_hi = np.empty(len(f_lo) + nh)
    pos = 0
    for k in range(nh):
        s_ptr[k] = pos
        if k == 0 and free_start:
            s_lo[pos], s_hi[pos] = 0.0, INF
            pos += 1
            continue
        cur = 0.0
        for q in range(f_ptr[k], f_ptr[k + 1]):
            a, b = f_lo[q], f_hi[q]
            if b <= cur:
                continue
            if a >= cur:
                s_lo[pos], s_hi[pos] = cur, a
                pos += 1
            cur = b
        if cur < INF:
            s_lo[pos], s_hi[pos] = cur, INF
            pos += 1
    s_ptr[nh] = pos
    return s_ptr, s_lo[:pos], s_hi[:pos]


@_jit
def _allowed(lo, hi, q0, q1, a, e, out_lo, out_hi):
    """The closed pieces of [a, e] outside the open intervals ``lo/hi[q0:q1]`` (sorted by lo), in
    order, written to ``out_lo/out_hi``; returns how many."""
    n = 0
    cur = a
    for q in range(q0, q1):
        x, y = lo[q], hi[q]
        if y <= cur:
            continue
        if x >= e:
            break
        if x >= cur:
            out_lo[n], out_hi[n] = cur, x
            n += 1
        cur = y
        if cur > e:
            return n
    if cur <= e and cur < INF:
        out_lo[n], out_hi[n] = cur, e
        n += 1
    return n


@_jit
def earliest(s_ptr, s_lo, s_hi, g_ptr, g_lo, g_hi, durations, early_holds):
    """Earliest arrival along a chain of hold vertices (safe-interval path planning on a fixed
    path): vertex k's safe intervals ``s_*[s_ptr[k]:s_ptr[k + 1]]``, the forbidden departure times
    from vertex k to k + 1 ``g_lo/g_hi[g_ptr[k]:g_ptr[k + 1]]`` (open, sorted by lo), a move that
    takes ``durations[k]``. The robot is on vertex 0 at t = 0 and must stay on the last one for
    ever. Per (vertex, safe interval) only the earliest arrival is kept (waiting there is free,
    so it dominates); of equal arrivals the first found. With ``early_holds`` the waits are then
    moved back along the path as far as the arrival allows (see :func:`_holds_early`).
    Returns (found, arrive, leave) per vertex."""
    nh = len(s_ptr) - 1
    arrive = np.zeros(nh)
    leave = np.full(nh, INF)
    total = s_ptr[nh]
    if s_ptr[1] == s_ptr[0] or s_lo[s_ptr[0]] > 0:
        return False, arrive, leave
    best_t = np.full(total, INF)
    best_par = np.full(total, -1, dtype=np.int64)
    best_dep = np.zeros(total)
    seq = np.zeros(total, dtype=np.int64)   # order of first arrival (the order of the original dict)
    best_t[s_ptr[0]] = 0.0
    m = max(1, len(g_lo) + 1)
    piece_lo, piece_hi = np.empty(m), np.empty(m)
    cand = np.empty(total, dtype=np.int64)
    for k in range(nh - 1):
        dur = durations[k]
        n0, n1 = s_ptr[k + 1], s_ptr[k + 2]
        # this vertex's reached intervals by (arrival, first found)
        nc = 0
        for si in range(s_ptr[k], s_ptr[k + 1]):
            if best_t[si] < INF:
                p = nc
                while p > 0 and (best_t[cand[p - 1]] > best_t[si]
                                 or (best_t[cand[p - 1]] == best_t[si] and seq[cand[p - 1]] > seq[si])):
                    cand[p] = cand[p - 1]
                    p -= 1
                cand[p] = si
                nc += 1
        count = 0
        last_start = s_lo[n1 - 1] if n1 > n0 else INF
        last_open = n1 > n0 and s_hi[n1 - 1] == INF
        for c in range(nc):
            si = cand[c]
            t, e = best_t[si], s_hi[si]
            npieces = _allowed(g_lo, g_hi, g_ptr[k], g_ptr[k + 1], t, e, piece_lo, piece_hi)
            for p in range(npieces):
                t_lo, t_hi = piece_lo[p] + dur, piece_hi[p] + dur
                # first next interval ending at or after t_lo (bisect_left on the ends)
                lo_i, hi_i = n0, n1
                while lo_i < hi_i:
                    mid = (lo_i + hi_i) // 2
                    if s_hi[mid] < t_lo:
                        lo_i = mid + 1
                    else:
                        hi_i = mid
                n = lo_i
                while n < n1 and s_lo[n] <= t_hi:
                    t_arr = max(t_lo, s_lo[n])
                    if best_t[n] == INF:
                        seq[n] = count
                        count += 1
                        best_t[n], best_par[n], best_dep[n] = t_arr, si, t_arr - dur
                    elif t_arr < best_t[n]:
                        best_t[n], best_par[n], best_dep[n] = t_arr, si, t_arr - dur
                    n += 1
                if n1 == n0 or (last_open and best_t[n1 - 1] < INF and t_lo >= last_start):
                    break
        if count == 0:
            return False, arrive, leave
    final = s_ptr[nh] - 1
    if s_ptr[nh] == s_ptr[nh - 1] or s_hi[final] != INF or best_t[final] == INF:
        return False, arrive, leave
    interval = np.zeros(nh, dtype=np.int64)
    interval[0] = s_ptr[0]
    si = final
    for k in range(nh - 1, 0, -1):
        arrive[k], leave[k - 1] = best_t[si], best_dep[si]
        interval[k] = si
        si = best_par[si]
    if early_holds:
        _holds_early(s_hi, g_ptr, g_lo, g_hi, durations, arrive, leave, interval, piece_lo, piece_hi)
    return True, arrive, leave


@_jit
def _holds_early(s_hi, g_ptr, g_lo, g_hi, durations, arrive, leave, interval, piece_lo, piece_hi):
    """Move waits back along the path, keeping the arrival at the goal: from the last vertex back,
    leave each vertex as late as it can and still reach the next one by the time it leaves that one
    (staying in the safe interval it arrived in, outside the forbidden departure times). An earliest
    arrival rushes ahead and waits in front of the conflict, in an aisle others use (docs/ARCHITECTURE.md,
    measured fact 5); this waits where it was already standing, at its start if it can."""
    last = len(arrive) - 1
    for k in range(last - 1, -1, -1):
        latest = arrive[last] if k + 1 == last else leave[k + 1]
        until = min(latest - durations[k], s_hi[interval[k]])
        if until <= leave[k]:
            continue
        npieces = _allowed(g_lo, g_hi, g_ptr[k], g_ptr[k + 1], leave[k], until, piece_lo, piece_hi)
        if npieces and piece_hi[npieces - 1] > leave[k]:
            best = piece_hi[npieces - 1]
            leave[k] = best
            arrive[k + 1] = best + durations[k]


# ---------------------------------------------------------------------------------------------
# collision pieces merged into regions
# ---------------------------------------------------------------------------------------------
@_jit
def _find(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@_jit
def merge_boxes(boxes, ptr, eps):
    """Per chunk ``boxes[ptr[c]:ptr[c + 1]]`` (rows a_lo, a_hi, b_lo, b_hi): the connected
    components of boxes that overlap or touch (within ``eps``), as bounding boxes, merged again
    until none touches another. Returns (out, out_ptr): each chunk's merged boxes sorted by
    (a_lo, b_lo), components numbered by their first box on ties (as SciPy's connected
    components number them)."""
    nc = len(ptr) - 1
    out = np.empty((len(boxes), 4))
    out_ptr = np.empty(nc + 1, dtype=np.int64)
    pos = 0
    for c in range(nc):
        out_ptr[c] = pos
        cur = boxes[ptr[c]:ptr[c + 1]].copy()
        while True:
            n = len(cur)
            parent = np.arange(n)
            for i in range(n):
                for j in range(i + 1, n):
                    if (cur[i, 0] <= cur[j, 1] + eps and cur[j, 0] <= cur[i, 1] + eps
                            and cur[i, 2] <= cur[j, 3] + eps and cur[j, 2] <= cur[i, 3] + eps):
                        ri, rj = _find(parent, i), _find(parent, j)
                        if ri != rj:
                            if ri < rj:
                                parent[rj] = ri
                            else:
                                parent[ri] = rj
            label = np.full(n, -1, dtype=np.int64)
            count = 0
            comp = np.empty(n, dtype=np.int64)
            for i in range(n):
                r = _find(parent, i)
                if label[r] < 0:
                    label[r] = count
                    count += 1
                comp[i] = label[r]
            if count == n:
                break
            merged = np.empty((count, 4))
            merged[:, 0] = INF
            merged[:, 2] = INF
            merged[:, 1] = -INF
            merged[:, 3] = -INF
            for i in range(n):
                k = comp[i]
                merged[k, 0] = min(merged[k, 0], cur[i, 0])
                merged[k, 1] = max(merged[k, 1], cur[i, 1])
                merged[k, 2] = min(merged[k, 2], cur[i, 2])
                merged[k, 3] = max(merged[k, 3], cur[i, 3])
            cur = merged
        # sort by (a_lo, b_lo), stable (insertion sort: components are few)
        n = len(cur)
        order = np.arange(n)
        for i in range(1, n):
            x = order[i]
            p = i
            while p > 0 and (cur[order[p - 1], 0] > cur[x, 0]
                             or (cur[order[p - 1], 0] == cur[x, 0] and cur[order[p - 1], 2] > cur[x, 2])):
                order[p] = order[p - 1]
                p -= 1
            order[p] = x
        for i in range(n):
            out[pos] = cur[order[i]]
            pos += 1
    out_ptr[nc] = pos
    return out[:pos], out_ptr


_WARM = False


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel on a toy instance, so that no planning
    budget is spent compiling: a path of three hold vertices with a forbidden interval on each."""
    global _WARM
    if _WARM:
        return
    f_ptr = np.array([0, 1, 2, 2], dtype=np.int64)
    s_ptr, s_lo, s_hi = safe_intervals(f_ptr, np.array([1.0, 0.5]), np.array([2.0, 1.5]), False)
    earliest(s_ptr, s_lo, s_hi, np.array([0, 1, 1], dtype=np.int64), np.array([0.2]), np.array([0.4]),
             np.array([1.0, 1.0]), True)
    merge_boxes(np.array([[0.0, 1.0, 0.0, 1.0], [1.0, 2.0, 1.0, 2.0], [5.0, 6.0, 5.0, 6.0]]),
                np.array([0, 3], dtype=np.int64), 1e-9)
    _WARM = True
