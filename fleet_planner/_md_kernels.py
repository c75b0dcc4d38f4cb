"""The compiled inner loops of the md planner (numba): the hold search, the collision pieces of
segment pairs and their merging into regions.

Why numba: the safe-interval earliest-arrival search along a fixed path (:mod:`fleet_planner.scheduler`,
holds anywhere) is a dynamic programme over (vertex, safe interval) with branchy interval sweeps,
and the merging of a pair's collision pieces into regions is a union of touching boxes: both are
short loops over small, data-dependent lists that numpy cannot vectorise, run thousands of times
per plan (issue 8's profile: they were most of md's planning time). The pieces of segment pairs
(:mod:`fleet_planner.collision`) vectorise, but as some 300 numpy operations on temporaries per
batch; one pass per row is several times faster. The functions are written in
plain Python over numpy arrays, so without numba they run as they are (correct, slower).

Results are the same numbers as the Python and numpy code they replace (same floating-point
operations in the same order, same tie-breaking, numpy's min / max on ties); ``test/test_md_holds.py``
and ``test/test_collision.py`` compare them on random inputs against transcriptions of that code.
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


def _jit_numpy_errors(fn: Any) -> Any:
    """:func:`_jit` with numpy's floating-point semantics (x / 0 is inf or nan, as in the numpy
    code a kernel replaces, not ZeroDivisionError)."""
    if _numba_njit is None:   # pragma: no cover
        return fn
    return _numba_njit(cache=True, nogil=True, error_model="numpy")(fn)


# ---------------------------------------------------------------------------------------------
# safe intervals and the earliest arrival along a chain of hold vertices
# ---------------------------------------------------------------------------------------------
@_jit
def grouped(key, lo, hi, n):
    """Open intervals (lo, hi) grouped by ``key`` in 0..n-1, each group sorted by ``lo``, ties in
    the given order (numpy's stable ``lexsort((lo, key))``): (ptr, lo, hi) with group k at
    ``ptr[k]:ptr[k + 1]``. A counting sort by key, then an insertion sort in each group (groups
    are a vertex's or a segment's few intervals)."""
    m = key.shape[0]
    ptr = np.zeros(n + 1, dtype=np.int64)
    for r in range(m):
        ptr[key[r] + 1] += 1
    for k in range(n):
        ptr[k + 1] += ptr[k]
    fill = ptr[:-1].copy()
    out_lo = np.empty(m)
    out_hi = np.empty(m)
    for r in range(m):
        q = fill[key[r]]
        fill[key[r]] += 1
        a, b = lo[r], hi[r]
        while q > ptr[key[r]] and out_lo[q - 1] > a:   # stable: equal lo keep their order
            out_lo[q], out_hi[q] = out_lo[q - 1], out_hi[q - 1]
            q -= 1
        out_lo[q], out_hi[q] = a, b
    return ptr, out_lo, out_hi


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


# ---------------------------------------------------------------------------------------------
# collision pieces of segment pairs (the geometry of fleet_planner.collision)
# ---------------------------------------------------------------------------------------------
@_jit
def _mn(a, b):
    return a if a <= b else b   # numpy's minimum (no NaN here): the first on ties


@_jit
def _mx(a, b):
    return a if a >= b else b


@_jit
def _circle(wx, wy, ux, uy, R):
    """Parameters s with |w + s*u| < R for unit u: roots of s^2 + 2 s (u.w) + |w|^2 - R^2
    (inf, -inf when there are none)."""
    b = ux * wx + uy * wy
    c = (wx * wx + wy * wy) - R * R
    disc = b * b - c
    if disc <= 0:
        return INF, -INF
    root = np.sqrt(_mx(disc, 0.0))
    return -b - root, -b + root


@_jit
def _capsule(px, py, ux, uy, length, qx, qy, vx, vy, qlen, R):
    """The interval [lo, hi] of s in [0, length] such that p + s*u lies within R of the segment
    q + t*v, t in [0, qlen] (u, v unit vectors); lo > hi when empty. The capsule is convex, so
    its intersection with a line is one interval: the union of the two end discs' intervals and
    the slab's."""
    wx, wy = px - qx, py - qy
    lo_a, hi_a = _circle(wx, wy, ux, uy, R)
    lo_b, hi_b = _circle(wx - vx * qlen, wy - vy * qlen, ux, uy, R)
    # slab: perpendicular distance to q's line < R and projection within [0, qlen]
    cross0 = vx * wy - vy * wx
    cross1 = vx * uy - vy * ux
    proj0 = vx * wx + vy * wy
    proj1 = vx * ux + vy * uy
    if cross1 != 0:   # |cross0 + s*cross1| < R
        s1 = (-R - cross0) / cross1
        s2 = (R - cross0) / cross1
        perp_lo, perp_hi = _mn(s1, s2), _mx(s1, s2)
    elif abs(cross0) < R:
        perp_lo, perp_hi = -INF, INF
    else:
        perp_lo, perp_hi = INF, -INF
    if proj1 != 0:    # 0 <= proj0 + s*proj1 <= qlen
        t1 = -proj0 / proj1
        t2 = (qlen - proj0) / proj1
        proj_lo, proj_hi = _mn(t1, t2), _mx(t1, t2)
    elif proj0 >= 0 and proj0 <= qlen:
        proj_lo, proj_hi = -INF, INF
    else:
        proj_lo, proj_hi = INF, -INF
    slab_lo = _mx(perp_lo, proj_lo)
    slab_hi = _mn(perp_hi, proj_hi)
    if slab_lo >= slab_hi:
        slab_lo, slab_hi = INF, -INF
    lo = _mn(_mn(lo_a, lo_b), slab_lo)
    hi = _mx(_mx(hi_a, hi_b), slab_hi)
    return _mx(lo, 0.0), _mn(hi, length)


@_jit
def _clip(lo, hi, length):
    lo, hi = _mx(lo, 0.0), _mn(hi, length)
    if lo <= hi:
        return lo, hi
    return INF, -INF


@_jit
def _phi(tp, a, vx, tq, b, vy):
    return (tp + a / vx) - (tq + b / vy)


@_jit
def segment_pieces(qi, ti, a_p0, a_u, a_len, a_own, a_off, a_t0, a_v, a_seg, a_first, a_last,
                   b_p0, b_u, b_len, b_own, b_off, b_t0, b_v, b_seg, b_first, b_last, radii, margin, ncols):
    """The piece table (columns ``P_*`` of :mod:`fleet_planner.collision`) of the candidate
    segment pairs (``a`` row ``qi[r]``, ``b`` row ``ti[r]``) whose discs come closer than
    R = r_x + r_y + margin, each oriented so that the smaller robot index is x.

    Per pair: the extents of the convex set S = {(a, b) in [0, lp] x [0, lq] : |p0 + a u - q0 - b v| < R}
    on both segments (capsule intervals), the range of phi(a, b) = (tp + a/vx) - (tq + b/vy) over
    S, and S's edge intervals. A linear function's extremes over a convex set lie on its
    boundary: on the square's edges (the ends of the four edge intervals) or where the ellipse
    boundary is tangent to phi's level lines."""
    n = len(qi)
    out = np.zeros((n, ncols))
    k = 0
    for r in range(n):
        ia, ib = qi[r], ti[r]
        if a_own[ia] <= b_own[ib]:
            sa, sb, swap = ia, ib, False
        else:
            sa, sb, swap = ib, ia, True
        if not swap:
            px, py, ux, uy, lp, x_own = a_p0[sa, 0], a_p0[sa, 1], a_u[sa, 0], a_u[sa, 1], a_len[sa], a_own[sa]
            offp, tp, vx, x_seg, x_first, x_last = a_off[sa], a_t0[sa], a_v[sa], a_seg[sa], a_first[sa], a_last[sa]
            qx, qy, wx_, wy_, lq, y_own = b_p0[sb, 0], b_p0[sb, 1], b_u[sb, 0], b_u[sb, 1], b_len[sb], b_own[sb]
            offq, tq, vy, y_seg, y_first, y_last = b_off[sb], b_t0[sb], b_v[sb], b_seg[sb], b_first[sb], b_last[sb]
        else:
            px, py, ux, uy, lp, x_own = b_p0[sa, 0], b_p0[sa, 1], b_u[sa, 0], b_u[sa, 1], b_len[sa], b_own[sa]
            offp, tp, vx, x_seg, x_first, x_last = b_off[sa], b_t0[sa], b_v[sa], b_seg[sa], b_first[sa], b_last[sa]
            qx, qy, wx_, wy_, lq, y_own = a_p0[sb, 0], a_p0[sb, 1], a_u[sb, 0], a_u[sb, 1], a_len[sb], a_own[sb]
            offq, tq, vy, y_seg, y_first, y_last = a_off[sb], a_t0[sb], a_v[sb], a_seg[sb], a_first[sb], a_last[sb]
        R = radii[x_own] + radii[y_own] + margin
        a_lo, a_hi = _capsule(px, py, ux, uy, lp, qx, qy, wx_, wy_, lq, R)
        b_lo, b_hi = _capsule(qx, qy, wx_, wy_, lq, px, py, ux, uy, lp, R)
        if not (a_lo <= a_hi and b_lo <= b_hi):
            continue
        row = out[k]
        k += 1
        p1x, p1y = px + ux * lp, py + uy * lp
        q1x, q1y = qx + wx_ * lq, qy + wy_ * lq
        c0, c1 = _circle(qx - px, qy - py, wx_, wy_, R)
        xs0, xs1 = _clip(c0, c1, lq)    # b-range with x at its segment start
        c0, c1 = _circle(qx - p1x, qy - p1y, wx_, wy_, R)
        xe0, xe1 = _clip(c0, c1, lq)    # ... at its segment end
        c0, c1 = _circle(px - qx, py - qy, ux, uy, R)
        ys0, ys1 = _clip(c0, c1, lp)    # a-range with y at its segment start
        c0, c1 = _circle(px - q1x, py - q1y, ux, uy, R)
        ye0, ye1 = _clip(c0, c1, lp)
        lo, hi = INF, -INF
        if np.isfinite(xs0):
            for c in (_phi(tp, 0.0, vx, tq, xs0, vy), _phi(tp, 0.0, vx, tq, xs1, vy)):
                lo, hi = _mn(lo, c), _mx(hi, c)
        if np.isfinite(xe0):
            for c in (_phi(tp, lp, vx, tq, xe0, vy), _phi(tp, lp, vx, tq, xe1, vy)):
                lo, hi = _mn(lo, c), _mx(hi, c)
        if np.isfinite(ys0):
            for c in (_phi(tp, ys0, vx, tq, 0.0, vy), _phi(tp, ys1, vx, tq, 0.0, vy)):
                lo, hi = _mn(lo, c), _mx(hi, c)
        if np.isfinite(ye0):
            for c in (_phi(tp, ye0, vx, tq, lq, vy), _phi(tp, ye1, vx, tq, lq, vy)):
                lo, hi = _mn(lo, c), _mx(hi, c)
        # tangent points: y = w + A z with A = [u, -v]; phi = c + g.z, g = (1/vx, -1/vy)
        det = ux * (-wy_) - (-wx_) * uy
        ok = abs(det) > 1e-12
        sdet = det if ok else 1.0
        # A^-1 = [[-v1, v0], [-u1, u0]] / det ; h = A^-T g
        i00, i01, i10, i11 = -wy_ / sdet, wx_ / sdet, -uy / sdet, ux / sdet
        g0, g1 = 1.0 / vx, -1.0 / vy
        h0 = i00 * g0 + i10 * g1
        h1 = i01 * g0 + i11 * g1
        hn = np.hypot(h0, h1)
        if not hn > 0:
            hn = 1.0
        w0, w1 = px - qx, py - qy
        for sign in (1.0, -1.0):
            y0 = sign * R * h0 / hn
            y1 = sign * R * h1 / hn
            z0 = i00 * (y0 - w0) + i01 * (y1 - w1)
            z1 = i10 * (y0 - w0) + i11 * (y1 - w1)
            if ok and z0 >= 0 and z0 <= lp and z1 >= 0 and z1 <= lq:
                c = _phi(tp, z0, vx, tq, z1, vy)
                lo, hi = _mn(lo, c), _mx(hi, c)
        row[0], row[1] = x_own, y_own
        row[2], row[3] = offp + a_lo, offp + a_hi
        row[4], row[5] = offq + b_lo, offq + b_hi
        row[6], row[7] = lo, hi
        row[8], row[9] = offq + xs0, offq + xs1
        row[10], row[11] = offq + xe0, offq + xe1
        row[12], row[13] = offp + ys0, offp + ys1
        row[14], row[15] = offp + ye0, offp + ye1
        row[16], row[17], row[18], row[19] = x_first, x_last, y_first, y_last
        row[20], row[21], row[22] = offp, tp, vx
        row[23], row[24], row[25] = offq, tq, vy
        row[26], row[27] = x_seg, y_seg
    return out[:k]


@_jit
def box_pairs(lo, hi, rlo, rhi):
    """Index pairs (q, t) of the boxes ``lo[q]..hi[q]`` and ``rlo[t]..rhi[t]`` (rows (x, y)) that
    overlap or touch, q ascending, then t (the order of ``np.nonzero`` on the overlap matrix)."""
    n, m = len(lo), len(rlo)
    count = 0
    for q in range(n):
        for t in range(m):
            if lo[q, 0] <= rhi[t, 0] and rlo[t, 0] <= hi[q, 0] and lo[q, 1] <= rhi[t, 1] and rlo[t, 1] <= hi[q, 1]:
                count += 1
    out_q = np.empty(count, dtype=np.int64)
    out_t = np.empty(count, dtype=np.int64)
    k = 0
    for q in range(n):
        for t in range(m):
            if lo[q, 0] <= rhi[t, 0] and rlo[t, 0] <= hi[q, 0] and lo[q, 1] <= rhi[t, 1] and rlo[t, 1] <= hi[q, 1]:
                out_q[k], out_t[k] = q, t
                k += 1
    return out_q, out_t


# ---------------------------------------------------------------------------------------------
# what higher robots' timed trajectories forbid a robot on its path (holds anywhere)
# ---------------------------------------------------------------------------------------------
#: the columns :func:`hold_constraints` reads, in this order, from a piece table seen from j (i in the
#: x columns): i's segment, j's segment, phi lo / hi, j's range with i at its segment start (lo, hi)
#: and end, i's range with j at its segment start and end, i's offset / t0 / speed, j's
HOLD_COLUMNS = ("X_SEG", "Y_SEG", "PHI_LO", "PHI_HI", "XS_LO", "XS_HI", "XE_LO", "XE_HI", "YS_LO", "YS_HI",
                "YE_LO", "YE_HI", "X_OFF", "X_T0", "X_V", "Y_OFF", "Y_T0", "Y_V")


@_jit_numpy_errors
def hold_constraints(P, cols, cols_sw, sw, who, first, last, arr_all, dep_all, cum_j):
    """The forbidden intervals of :meth:`fleet_planner.scheduler.DelayScheduler.hold_constraints`
    from its pieces ``P`` (columns ``cols`` in the order of HOLD_COLUMNS; rows with ``sw`` set list
    j in the x columns and i in the y columns, their columns are ``cols_sw`` and their phi range is
    negated: read as seen from j, with no swapped copy of the table), each
    row's higher robot ``who``, where that robot's vertex times start in ``arr_all`` / ``dep_all``
    (``first``) and its last vertex (``last``), and j's travelled length at its vertices ``cum_j``:
    (G key, lo, hi, owner, F key, lo, hi, owner), the candidates of each kind in row order, kinds in
    the scheduler's order, open intervals kept when lo < hi and hi > 0."""
    n = P.shape[0]
    nv = len(cum_j)
    g_key = np.empty(3 * n, dtype=np.int64)
    g_lo = np.empty(3 * n)
    g_hi = np.empty(3 * n)
    g_own = np.empty(3 * n, dtype=np.int64)
    f_key = np.empty(6 * n, dtype=np.int64)
    f_lo = np.empty(6 * n)
    f_hi = np.empty(6 * n)
    f_own = np.empty(6 * n, dtype=np.int64)
    ng = 0
    nf = 0
    for kind in range(9):
        for r in range(n):
            c = cols_sw if sw[r] else cols
            i_seg = np.int64(P[r, c[0]])
            j_seg = np.int64(P[r, c[1]])
            s0 = min(i_seg, last[r])
            s1 = first[r] + min(s0 + 1, last[r])
            s0 = first[r] + s0
            a0, d0, a1, d1 = arr_all[s0], dep_all[s0], arr_all[s1], dep_all[s1]
            is_lo, is_hi, ie_lo, ie_hi = P[r, c[4]], P[r, c[5]], P[r, c[6]], P[r, c[7]]
            i_off, i_v, j_off, j_v = P[r, c[12]], P[r, c[14]], P[r, c[15]], P[r, c[17]]
            ok = False
            lo = 0.0
            hi = 0.0
            key = j_seg
            if kind == 0:   # both moving: the piece's phi range shifted by i's entry time
                if sw[r]:
                    phi_lo, phi_hi = -P[r, cols[3]], -P[r, cols[2]]
                else:
                    phi_lo, phi_hi = P[r, cols[2]], P[r, cols[3]]
                sh_i = d0 - P[r, c[13]]
                j_t0 = P[r, c[16]]
                ok = np.isfinite(phi_lo) and np.isfinite(sh_i)
                lo, hi = sh_i + phi_lo + j_t0, sh_i + phi_hi + j_t0
            elif kind == 1:   # i holding at its segment start
                ok = d0 > a0 and is_lo <= is_hi
                lo, hi = a0 - (is_hi - j_off) / j_v, d0 - (is_lo - j_off) / j_v
            elif kind == 2:   # i holding at its segment end
                ok = d1 > a1 and ie_lo <= ie_hi
                lo, hi = a1 - (ie_hi - j_off) / j_v, d1 - (ie_lo - j_off) / j_v
            else:
                j_end = cum_j[min(j_seg + 1, nv - 1)]
                at = j_off if kind <= 5 else j_end   # j standing at its segment's start / end
                if kind == 3 or kind == 6:   # i's segment passes within reach
                    e_lo, e_hi = (P[r, c[8]], P[r, c[9]]) if kind == 3 else (P[r, c[10]], P[r, c[11]])
                    ok = np.isfinite(d0) and e_lo <= e_hi
                    lo, hi = d0 + (e_lo - i_off) / i_v, d0 + (e_hi - i_off) / i_v
                elif kind == 4 or kind == 7:   # i holding at its segment start within reach
                    ok = d0 > a0 and is_lo <= at and at <= is_hi
                    lo, hi = a0, d0
                else:   # i holding at its segment end within reach
                    ok = d1 > a1 and ie_lo <= at and at <= ie_hi
                    lo, hi = a1, d1
                key = min(j_seg if kind <= 5 else j_seg + 1, nv - 1)
            if not ok or not (lo < hi and hi > 0):
                continue
            if kind < 3:
                g_key[ng], g_lo[ng], g_hi[ng], g_own[ng] = key, lo, hi, who[r]
                ng += 1
            else:
                f_key[nf], f_lo[nf], f_hi[nf], f_own[nf] = key, lo, hi, who[r]
                nf += 1
    return g_key[:ng], g_lo[:ng], g_hi[:ng], g_own[:ng], f_key[:nf], f_lo[:nf], f_hi[:nf], f_own[:nf]


_WARM = False


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel on a toy instance, so that no planning
    budget is spent compiling: a path of three hold vertices with a forbidden interval on each."""
    global _WARM
    if _WARM:
        return
    grouped(np.array([1, 0], dtype=np.int64), np.array([1.0, 0.5]), np.array([2.0, 1.5]), 3)
    f_ptr = np.array([0, 1, 2, 2], dtype=np.int64)
    s_ptr, s_lo, s_hi = safe_intervals(f_ptr, np.array([1.0, 0.5]), np.array([2.0, 1.5]), False)
    earliest(s_ptr, s_lo, s_hi, np.array([0, 1, 1], dtype=np.int64), np.array([0.2]), np.array([0.4]),
             np.array([1.0, 1.0]), True)
    merge_boxes(np.array([[0.0, 1.0, 0.0, 1.0], [1.0, 2.0, 1.0, 2.0], [5.0, 6.0, 5.0, 6.0]]),
                np.array([0, 3], dtype=np.int64), 1e-9)
    p0, u = np.array([[0.0, 0.0], [0.5, -1.0]]), np.array([[1.0, 0.0], [0.0, 1.0]])
    one, two, idx = np.ones(2), np.full(2, 2.0), np.arange(2)
    box_pairs(p0 - 1.0, p0 + 1.0, p0 - 1.0, p0 + 1.0)
    segment_pieces(np.array([0]), np.array([1]), p0, u, two, idx, 0 * one, 0 * one, one, idx, idx == 0, idx == 1,
                   p0, u, two, idx, 0 * one, 0 * one, one, idx, idx == 0, idx == 1, np.full(2, 0.4), 0.0, 28)
    hold_constraints(np.ones((1, 28)), np.arange(18, dtype=np.int64), np.arange(18, dtype=np.int64),
                     np.zeros(1, dtype=np.bool_), np.zeros(1, dtype=np.int64),
                     np.zeros(1, dtype=np.int64), np.ones(1, dtype=np.int64), np.array([0.0, 1.0]),
                     np.array([0.5, np.inf]), np.array([0.0, 1.0]))
    _WARM = True
