"""The compiled inner loops of single-robot path finding (numba): the A* over the move graph of
:class:`~fleet_planner.paths.PathFinder` (with the moves cut by keep-out discs), the exact sight-line
test of string pulling and the shortest chain of vertices in sight, and connected components.

Why numba (issue 8): path finding was most of md's planning time at 100 robots - first a
pure-Python A*, then SciPy's Dijkstra on reduced weights, whose per-call set-up (weight arrays
over the whole graph, a CSR matrix, an octile field per start and goal) cost more than the search;
string pulling tested every sight line with GEOS through shapely.  Here one search touches only
the nodes A* expands, the moves through keep-out discs are found lazily (only those out of
expanded nodes are tested), and a sight line is tested against the wall cells it passes near, exactly.  The
functions are plain Python over numpy arrays, so without numba they run as they are (correct,
slowly).  Importing this module imports neither SciPy nor shapely.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

_numba_njit: Any
try:
    from numba import njit as _numba_njit
except ImportError:   # pragma: no cover - the path finder still works, only slowly
    _numba_njit = None

HAVE_NUMBA = _numba_njit is not None
_SQRT2 = math.sqrt(2.0)
_INF = np.inf


def _jit(fn: Any) -> Any:
    """numba's nopython compilation with an on-disk cache, or the function itself without numba."""
    if _numba_njit is None:   # pragma: no cover
        return fn
    return _numba_njit(cache=True, nogil=True)(fn)


# ---------------------------------------------------------------------------------------------
# geometry
# ---------------------------------------------------------------------------------------------
@_jit
def point_segment_distance(px, py, ax, ay, bx, by):
    """Distance from point p to the segment a-b (a point when a == b)."""
    dx, dy = bx - ax, by - ay
    den = dx * dx + dy * dy
    t = 0.0
    if den > 0.0:
        t = ((px - ax) * dx + (py - ay) * dy) / den
        t = min(max(t, 0.0), 1.0)
    return math.hypot(px - (ax + t * dx), py - (ay + t * dy))


@_jit
def _point_box_distance(px, py, x0, y0, x1, y1):
    ex = max(x0 - px, 0.0, px - x1)
    ey = max(y0 - py, 0.0, py - y1)
    return math.hypot(ex, ey)


@_jit
def _segment_hits_box(ax, ay, bx, by, x0, y0, x1, y1):
    """Whether the segment a-b meets the closed box (Liang-Barsky clipping)."""
    dx, dy = bx - ax, by - ay
    t0, t1 = 0.0, 1.0
    for k in range(4):
        if k == 0:
            p, q = -dx, ax - x0
        elif k == 1:
            p, q = dx, x1 - ax
        elif k == 2:
            p, q = -dy, ay - y0
        else:
            p, q = dy, y1 - ay
        if p == 0.0:
            if q < 0.0:
                return False
        else:
            r = q / p
            if p < 0.0:
                if r > t1:
                    return False
                if r > t0:
                    t0 = r
            else:
                if r < t0:
                    return False
                if r < t1:
                    t1 = r
    return True


@_jit
def segment_box_distance(ax, ay, bx, by, x0, y0, x1, y1):
    """Exact distance between the segment a-b and the closed box [x0, x1] x [y0, y1] (0 where they
    meet): for two disjoint convex sets it is attained at a vertex of one of them."""
    if _segment_hits_box(ax, ay, bx, by, x0, y0, x1, y1):
        return 0.0
    d = min(_point_box_distance(ax, ay, x0, y0, x1, y1), _point_box_distance(bx, by, x0, y0, x1, y1))
    d = min(d, point_segment_distance(x0, y0, ax, ay, bx, by))
    d = min(d, point_segment_distance(x1, y0, ax, ay, bx, by))
    d = min(d, point_segment_distance(x0, y1, ax, ay, bx, by))
    d = min(d, point_segment_distance(x1, y1, ax, ay, bx, by))
    return d


@_jit
def segment_free(ax, ay, bx, by, blocked, res, limit, discs):
    """True when every point of the segment a-b is more than ``limit`` from every blocked cell
    (``blocked[row, col]``) and from the outside of the map, and strictly more than its keep-out
    ``discs[k, 2]`` from every disc centre ``discs[k, :2]``.

    The walls: only cells whose box can come within ``limit`` of the segment are looked at - per
    column of cells the segment's y-range over the column's x-range grown by ``limit``, then the
    rows of that range grown by ``limit`` - and each by its exact distance."""
    h, w = blocked.shape
    # the map's edge: inside the (convex) map the distance to the edge is smallest at an end
    edge = min(min(ax, bx), min(ay, by), w * res - max(ax, bx), h * res - max(ay, by))
    if edge <= limit:
        return False
    for k in range(discs.shape[0]):
        cx, cy, keep = discs[k, 0], discs[k, 1], discs[k, 2]
        if (cx < min(ax, bx) - keep or cx > max(ax, bx) + keep
                or cy < min(ay, by) - keep or cy > max(ay, by) + keep):
            continue
        if point_segment_distance(cx, cy, ax, ay, bx, by) <= keep:
            return False
    xmin, xmax = min(ax, bx), max(ax, bx)
    c_lo = max(int(math.floor((xmin - limit) / res)), 0)
    c_hi = min(int(math.floor((xmax + limit) / res)), w - 1)
    dx, dy = bx - ax, by - ay
    for c in range(c_lo, c_hi + 1):
        # the part of the segment whose x is within limit of the column
        xa = max(c * res - limit, xmin)
        xb = min((c + 1) * res + limit, xmax)
        if dx == 0.0:
            ya, yb = min(ay, by), max(ay, by)
        else:
            y1 = ay + (xa - ax) / dx * dy
            y2 = ay + (xb - ax) / dx * dy
            ya, yb = min(y1, y2), max(y1, y2)
        r_lo = max(int(math.floor((ya - limit) / res)), 0)
        r_hi = min(int(math.floor((yb + limit) / res)), h - 1)
        for r in range(r_lo, r_hi + 1):
            if blocked[r, c]:
                if segment_box_distance(ax, ay, bx, by, c * res, r * res, (c + 1) * res, (r + 1) * res) <= limit:
                    return False
    return True


@_jit
def segments_free(a, b, blocked, res, limit, discs):
    """:func:`segment_free` for each segment ``a[i] -> b[i]``."""
    out = np.empty(a.shape[0], dtype=np.bool_)
    for i in range(a.shape[0]):
        out[i] = segment_free(a[i, 0], a[i, 1], b[i, 0], b[i, 1], blocked, res, limit, discs)
    return out


@_jit
def pull_string(pts, blocked, res, limit, discs):
    """String pulling: indices of the shortest chain of ``pts`` from the first to the last, each
    vertex in free sight of the next (consecutive vertices are taken as joined: they are grid
    moves or checked connector pieces).  A dynamic programme over the vertices in order, with a
    cost of 1e-12 per vertex (of equal chains, the one with fewer vertices); a sight line is tested
    only when it would shorten the best chain found so far to its end."""
    n = pts.shape[0]
    best = np.empty(n)
    prev = np.empty(n, dtype=np.int64)
    best[0] = 0.0
    prev[0] = -1
    for j in range(1, n):
        best[j] = best[j - 1] + math.hypot(pts[j, 0] - pts[j - 1, 0], pts[j, 1] - pts[j - 1, 1]) + 1e-12
        prev[j] = j - 1
        for i in range(j - 1):
            cand = best[i] + math.hypot(pts[j, 0] - pts[i, 0], pts[j, 1] - pts[i, 1]) + 1e-12
            if cand < best[j] and segment_free(pts[i, 0], pts[i, 1], pts[j, 0], pts[j, 1],
                                               blocked, res, limit, discs):
                best[j] = cand
                prev[j] = i
    count = 1
    k = n - 1
    while prev[k] >= 0:
        count += 1
        k = prev[k]
    out = np.empty(count, dtype=np.int64)
    k = n - 1
    for m in range(count - 1, -1, -1):
        out[m] = k
        k = prev[k]
    return out


# ---------------------------------------------------------------------------------------------
# the move graph
# ---------------------------------------------------------------------------------------------
@_jit
def _heap_push(hkey, hnode, size, key, node):
    """Push ``node`` with ``key`` onto the binary min-heap held in ``hkey[:size]`` / ``hnode[:size]``,
    doubling both arrays when full; the (possibly new) arrays and the new size."""
    if size == hkey.shape[0]:
        hkey = np.concatenate((hkey, np.empty(size)))
        hnode = np.concatenate((hnode, np.empty(size, dtype=np.int64)))
    i = size
    while i > 0:
        p = (i - 1) >> 1
        if hkey[p] <= key:
            break
        hkey[i], hnode[i] = hkey[p], hnode[p]
        i = p
    hkey[i], hnode[i] = key, node
    return hkey, hnode, size + 1


@_jit
def _alt_bound(col, row, v, goal_c, goal_r, slack, lm, lm_lo, lm_hi):
    """A lower bound on node v's distance to the targets: the octile distance to the goal cell less
    ``slack``, or a landmark's triangle bound where larger (:func:`astar`); infinite when a
    landmark reaches the targets but not v (another component)."""
    ex, ey = abs(col[v] - goal_c), abs(row[v] - goal_r)
    h = max(ex + ey + (_SQRT2 - 2.0) * min(ex, ey) - slack, 0.0)
    for m in range(lm.shape[1]):
        dl = lm[v, m]
        h = max(h, dl - lm_hi[m], lm_lo[m] - dl)
    return h


@_jit
def distances(heads, weights, source):
    """Length of the shortest path (cells) from node ``source`` to every node over the allowed
    moves (infinite where unreachable). Dijkstra with a bucket queue of unit-wide buckets (Dial):
    no move is shorter than one cell, so nothing found from bucket k lands in bucket k and every
    node in bucket k is final when the bucket is taken; a move is at most sqrt 2 long, so three
    buckets in a ring hold everything pending. Linear in the graph's size."""
    v_count = heads.shape[0]
    dist = np.full(v_count, _INF)
    cap = 8 * v_count + 1
    ent_node = np.empty(cap, dtype=np.int64)
    ent_next = np.empty(cap, dtype=np.int64)
    bucket = np.full(3, -1, dtype=np.int64)
    n_ent = 0
    dist[source] = 0.0
    ent_node[0], ent_next[0] = source, -1
    bucket[0] = 0
    n_ent = 1
    pending = 1
    k = 0
    while pending > 0:
        b = k % 3
        e = bucket[b]
        bucket[b] = -1
        while e >= 0:
            u = ent_node[e]
            e = ent_next[e]
            pending -= 1
            du = dist[u]
            if int(du) != k:   # a stale entry: u was reached sooner since
                continue
            for d in range(8):
                w = weights[u, d]
                if w == _INF:
                    continue
                v = heads[u, d]
                dv = du + w
                if dv < dist[v]:
                    dist[v] = dv
                    q = int(dv) % 3
                    if n_ent == cap:   # cannot happen: each node is entered at most once per in-move
                        return dist
                    ent_node[n_ent], ent_next[n_ent] = v, bucket[q]
                    bucket[q] = n_ent
                    n_ent += 1
                    pending += 1
        k += 1
    return dist


@_jit
def astar(heads, weights, col, row, cut, stamp, discs, res, dcol, drow, src, src_cost, tgt, tgt_cost,
          start_c, start_r, goal_c, goal_r, slack, tie, lm, lm_lo, lm_hi):
    """Nodes of a shortest path from a source node (entered at ``src_cost``) to a target node (left
    at ``tgt_cost``) over the allowed moves not cut (``cut[9 * v + d] == stamp``; ``cut`` may be empty
    when no move is cut) that pass no
    nearer than their keep-out ``discs[k, 2]`` to any disc centre ``discs[k, :2]`` (metres; ``col``
    and ``row`` are padded cell indices, cells ``res`` wide); empty if none.

    The discs are tested lazily, when a node is expanded: they are bucketed on a coarse grid of
    squares at least as wide as the farthest a disc can reach (keep-out + a move's length), so the
    discs that can cut a move out of a node are in the 3 x 3 squares around it.

    A* with the octile distance to the goal cell less ``slack`` (consistent for these moves, 0 at
    every target, which is within ``slack`` of the goal cell), raised where landmarks know better
    (ALT: Goldberg & Harrelson, "Computing the shortest path: A* search meets graph theory", SODA
    2005): ``lm[v, m]`` is node v's distance from landmark m over the uncut graph (symmetric moves)
    and ``lm_lo[m]`` / ``lm_hi[m]`` the least / greatest of the targets' distances from it, so by the
    triangle inequality v is at least ``lm[v, m] - lm_hi[m]`` and ``lm_lo[m] - lm[v, m]`` from every
    target; cuts only lengthen paths, so the bound holds for every search, and each term is
    consistent (a move changes ``lm[v, m]`` by at most its weight). On warehouse maps the octile
    distance misses the detours round the racks (half the nodes expanded with 4 landmarks).

    Ties: every move into a cell also
    costs ``tie`` times the cell's distance (in cells) from the line through start and goal, so of
    equal-length paths the one nearest that line is found (it pulls straighter); the heuristic
    stays consistent since those costs are >= 0."""
    v_count = heads.shape[0]
    any_cut = cut.shape[0] > 0   # (an empty ``cut``: no move is cut, none is looked up)
    # the discs by coarse square (CSR): square (bc, br) holds the discs whose centre is in it
    n_discs = discs.shape[0]
    reach_max = _SQRT2 * res
    for k in range(n_discs):
        reach_max = max(reach_max, discs[k, 2] + _SQRT2 * res + 1e-9)
    side = reach_max
    nbc = int(col.max() * res / side) + 2 if v_count else 1
    nbr = int(row.max() * res / side) + 2 if v_count else 1
    d_ptr = np.zeros(nbc * nbr + 1, dtype=np.int64)
    d_sq = np.empty(n_discs, dtype=np.int64)
    for k in range(n_discs):
        bc = min(max(int(discs[k, 0] / side), 0), nbc - 1)
        br = min(max(int(discs[k, 1] / side), 0), nbr - 1)
        d_sq[k] = br * nbc + bc
        d_ptr[d_sq[k] + 1] += 1
    for q in range(nbc * nbr):
        d_ptr[q + 1] += d_ptr[q]
    d_fill = d_ptr[:-1].copy()
    d_idx = np.empty(n_discs, dtype=np.int64)
    for k in range(n_discs):
        d_idx[d_fill[d_sq[k]]] = k
        d_fill[d_sq[k]] += 1
    near = np.empty(max(n_discs, 1), dtype=np.int64)
    g = np.full(v_count, _INF)
    parent = np.full(v_count, -1, dtype=np.int64)
    closed = np.zeros(v_count, dtype=np.bool_)
    tcost = np.full(v_count, _INF)
    for k in range(len(tgt)):
        tcost[tgt[k]] = min(tcost[tgt[k]], tgt_cost[k])
    ax, ay = goal_c - start_c, goal_r - start_r
    norm = math.hypot(ax, ay)
    if norm == 0.0:
        norm = 1.0
    hkey = np.empty(1024)
    hnode = np.empty(1024, dtype=np.int64)
    size = 0
    target = v_count   # the virtual target node in the heap
    best_t, best_par = _INF, -1
    u = -1
    for k in range(len(src)):
        s = src[k]
        if src_cost[k] < g[s]:
            g[s] = src_cost[k]
    for k in range(len(src)):
        s = src[k]
        if g[s] != src_cost[k]:
            continue
        f = g[s] + _alt_bound(col, row, s, goal_c, goal_r, slack, lm, lm_lo, lm_hi)
        hkey, hnode, size = _heap_push(hkey, hnode, size, f, s)
    while size > 0:
        # pop the smallest
        u = hnode[0]
        size -= 1
        if size > 0:
            key, node = hkey[size], hnode[size]
            i = 0
            while True:
                c = 2 * i + 1
                if c >= size:
                    break
                if c + 1 < size and hkey[c + 1] < hkey[c]:
                    c += 1
                if hkey[c] >= key:
                    break
                hkey[i], hnode[i] = hkey[c], hnode[c]
                i = c
            hkey[i], hnode[i] = key, node
        if u == target:
            break
        if closed[u]:
            continue
        closed[u] = True
        gu = g[u]
        # the discs within reach of this cell's centre
        n_near = 0
        tx, ty = (col[u] - 0.5) * res, (row[u] - 0.5) * res
        if n_discs:
            bc0, br0 = int(tx / side), int(ty / side)
            for br in range(max(br0 - 1, 0), min(br0 + 2, nbr)):
                for bc in range(max(bc0 - 1, 0), min(bc0 + 2, nbc)):
                    q = br * nbc + bc
                    for m in range(d_ptr[q], d_ptr[q + 1]):
                        k = d_idx[m]
                        if math.hypot(discs[k, 0] - tx, discs[k, 1] - ty) <= discs[k, 2] + _SQRT2 * res + 1e-9:
                            near[n_near] = k
                            n_near += 1
        for d in range(9):
            if d == 8:
                if tcost[u] == _INF:
                    continue
                nv = gu + tcost[u]
                if nv >= best_t:
                    continue
                best_t, best_par = nv, u
                v = target
                f = nv
            else:
                wgt = weights[u, d]
                if wgt == _INF or (any_cut and cut[9 * u + d] == stamp):
                    continue
                v = heads[u, d]
                if closed[v]:
                    continue
                hit = False
                for m in range(n_near):
                    k = near[m]
                    if point_segment_distance(discs[k, 0], discs[k, 1], tx, ty,
                                              tx + dcol[d] * res, ty + drow[d] * res) <= discs[k, 2]:
                        hit = True
                        break
                if hit:
                    continue
                nv = gu + wgt + tie * abs((col[v] - start_c) * ay - (row[v] - start_r) * ax) / norm
                if nv >= g[v]:
                    continue
                g[v] = nv
                parent[v] = u
                f = nv + _alt_bound(col, row, v, goal_c, goal_r, slack, lm, lm_lo, lm_hi)
            hkey, hnode, size = _heap_push(hkey, hnode, size, f, v)
    if best_par < 0 or not closed[best_par] or u != target:
        return np.zeros(0, dtype=np.int64)
    count = 0
    k = best_par
    while k >= 0:
        count += 1
        k = parent[k]
    out = np.empty(count, dtype=np.int64)
    k = best_par
    for m in range(count - 1, -1, -1):
        out[m] = k
        k = parent[k]
    return out


@_jit
def components(heads, weights):
    """Weakly connected component of each node over the allowed moves (a move joins its two ends
    whichever way it runs), numbered in the order of each component's first node. Where every move
    has its reverse (the map's own moves) these are the connected components; on a road map of
    one-way lanes that is not strongly connected, two nodes in different components have no path
    either way, while one in the same component may still have none (the search finds that out):
    the labels only prune. Union-find with path halving over the moves, then one numbering pass."""
    v_count = heads.shape[0]
    parent = np.arange(v_count)
    for u in range(v_count):
        a = u        # u's root
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        for d in range(8):
            if weights[u, d] == _INF:
                continue
            b = heads[u, d]
            while parent[b] != b:
                parent[b] = parent[parent[b]]
                b = parent[b]
            # the larger root under the smaller: a root is its component's first node
            if b < a:
                parent[a] = b
                a = b
            elif a < b:
                parent[b] = a
    label = np.full(v_count, -1, dtype=np.int64)
    n = 0
    for s in range(v_count):
        root = s
        while parent[root] != root:
            root = parent[root]
        if root == s:   # the first node of its component: a new number
            label[s] = n
            n += 1
        else:           # the root comes before s, so it is numbered already
            label[s] = label[root]
    return label


@_jit
def count_components4(mask):
    """Number of 4-connected groups of True cells of a 2-D mask."""
    h, w = mask.shape
    seen = np.zeros((h, w), dtype=np.bool_)
    stack = np.empty(h * w, dtype=np.int64)
    n = 0
    for r0 in range(h):
        for c0 in range(w):
            if not mask[r0, c0] or seen[r0, c0]:
                continue
            n += 1
            seen[r0, c0] = True
            stack[0] = r0 * w + c0
            top = 1
            while top > 0:
                top -= 1
                r, c = divmod(stack[top], w)
                for k in range(4):
                    rr, cc = r, c
                    if k == 0:
                        rr = r - 1
                    elif k == 1:
                        rr = r + 1
                    elif k == 2:
                        cc = c - 1
                    else:
                        cc = c + 1
                    if 0 <= rr < h and 0 <= cc < w and mask[rr, cc] and not seen[rr, cc]:
                        seen[rr, cc] = True
                        stack[top] = rr * w + cc
                        top += 1
    return n
