"""The compiled inner loops of the dense-crowd solver (numba): BFS distance fields, the PIBT step,
the step rules, the single-robot space-time search of the refinement and loop cutting.

Why numba: profiling (the issue 11 note) shows the time of the configuration search in PIBT's
recursion and the swap look-ahead, branchy per-robot code that numpy cannot vectorise; and the
refinement (:mod:`.crowd_lns`) needs thousands of space-time searches per second. The same functions
run as plain Python when numba is not installed (correct, much slower).

Data layout (all numpy, int32 where it is a cell or a robot):

* ``nb`` (cells, 4) neighbours padded with NIL, ``deg`` (cells,) their number;
* ``dist`` (fields, cells) BFS hop counts to a goal, ``grow[i]`` the row of robot i's goal;
* ``goals`` (robots,) goal cells; configurations are (robots,) cell arrays.

The transition rules are those of :mod:`.crowd_pibt` (vertex, swap, no rings of followers).
"""
from __future__ import annotations

from typing import Any

import numpy as np

_numba_njit: Any
try:
    from numba import njit as _numba_njit
except ImportError:   # pragma: no cover - the planner still works, only slowly
    _numba_njit = None

NIL = -1
UNREACHABLE = np.int32(2**30)


def _jit(fn: Any) -> Any:
    """numba's nopython compilation with an on-disk cache, or the function itself without numba."""
    if _numba_njit is None:   # pragma: no cover
        return fn
    return _numba_njit(cache=True, nogil=True)(fn)


HAVE_NUMBA = _numba_njit is not None


# ---------------------------------------------------------------------------------------------
# distance fields
# ---------------------------------------------------------------------------------------------
@_jit
def bfs_fields(nb, deg, sources):
    """(len(sources), cells) int32 BFS hop counts from each source (UNREACHABLE where none)."""
    n = nb.shape[0]
    out = np.full((len(sources), n), UNREACHABLE, dtype=np.int32)
    queue = np.empty(n, dtype=np.int32)
    for k in range(len(sources)):
        d = out[k]
        s = sources[k]
        d[s] = 0
        queue[0] = s
        head, tail = 0, 1
        while head < tail:
            v = queue[head]
            head += 1
            dv = d[v] + 1
            for e in range(deg[v]):
                u = nb[v, e]
                if d[u] == UNREACHABLE:
                    d[u] = dv
                    queue[tail] = u
                    tail += 1
    return out


# ---------------------------------------------------------------------------------------------
# PIBT with the swap operation (Okumura, "Engineering LaCAM*", AAMAS 2024)
# ---------------------------------------------------------------------------------------------
@_jit
def _closes_ring(i, v, q_from, q_to, occ_now):
    """Would robot i moving into v close a ring of robots each following the next?"""
    home = q_from[i]
    j = occ_now[v]
    for _ in range(len(q_from)):
        if j == NIL or q_to[j] == NIL or q_to[j] == q_from[j]:
            return False
        nxt = q_to[j]
        if nxt == home:
            return True
        j = occ_now[nxt]
    return True


@_jit
def _passable(v, came_from, occ_now, goals, nb, deg):
    """(number of ways on from v other than back to ``came_from`` or into a dead end where a robot
    sits on its goal, one such way)."""
    count = 0
    way = NIL
    for e in range(deg[v]):
        u = nb[v, e]
        a = occ_now[u]
        if u == came_from or (deg[u] == 1 and a != NIL and goals[a] == u):
            continue
        count += 1
        way = u
    return count, way


@_jit
def _swap_required(pusher, puller, v_pusher, v_puller, dist, grow, occ_now, goals, nb, deg):
    d_push = dist[grow[pusher]]
    d_pull = dist[grow[puller]]
    for _ in range(nb.shape[0]):
        if not d_push[v_puller] < d_push[v_pusher]:
            break
        count, way = _passable(v_puller, v_pusher, occ_now, goals, nb, deg)
        if count >= 2:
            return False   # there is room to pass here
        if count <= 0:
            break
        v_pusher, v_puller = v_puller, way
    return d_pull[v_pusher] < d_pull[v_puller] and (d_push[v_pusher] == 0 or d_push[v_puller] < d_push[v_pusher])


@_jit
def _swap_possible(v_pusher, v_puller, occ_now, goals, nb, deg):
    origin = v_pusher
    for _ in range(nb.shape[0]):
        if v_puller == origin:
            return False
        count, way = _passable(v_puller, v_pusher, occ_now, goals, nb, deg)
        if count >= 2:
            return True
        if count <= 0:
            return False
        v_pusher, v_puller = v_puller, way
    return False


@_jit
def _swap_partner(i, best, q_from, q_to, dist, grow, occ_now, goals, nb, deg):
    """The robot i should pull after it instead of pushing (NIL: none)."""
    here = q_from[i]
    j = occ_now[best]
    if (j != NIL and j != i and q_to[j] == NIL
            and _swap_required(i, j, here, best, dist, grow, occ_now, goals, nb, deg)
            and _swap_possible(best, here, occ_now, goals, nb, deg)):
        return j
    for e in range(deg[here]):
        u = nb[here, e]
        k = occ_now[u]
        if k == NIL or best == u:
            continue
        if (_swap_required(k, i, here, best, dist, grow, occ_now, goals, nb, deg)
                and _swap_possible(best, here, occ_now, goals, nb, deg)):
            return k
    return NIL


@_jit
def _blocking(u, occ_now, goals, q_to):
    """0: cell u is free now, 1: its robot leaves it this step, 2: a robot on its way is on it, 3: a
    robot parked on its goal is."""
    j = occ_now[u]
    if j == NIL:
        return 0
    if q_to[j] != NIL and q_to[j] != u:
        return 1
    return 3 if goals[j] == u else 2


@_jit
def _after(u, v, d, occ_now, goals, q_to, tie):
    """Does candidate u sort after v: (distance to goal, how it is held now (:func:`_blocking`), random tie)?"""
    if d[u] != d[v]:
        return d[u] > d[v]
    ou, ov = _blocking(u, occ_now, goals, q_to), _blocking(v, occ_now, goals, q_to)
    if ou != ov:
        return ou > ov
    return tie[u] > tie[v]


@_jit
def _open_frame(i, sp, q_from, occ_now, occ_next, q_to, dist, grow, goals, nb, deg, tie, st_agent, st_k, st_nc,
                st_cands, st_pull):
    """Start PIBT for robot i: returns True when it is settled at once (on its goal, nobody
    pushing), else pushes its frame (sorted candidates, swap partner) at ``sp``."""
    here = q_from[i]
    d = dist[grow[i]]
    if d[here] == 0 and occ_next[here] == NIL:
        q_to[i] = here
        occ_next[here] = i
        return True
    cands = st_cands[sp]
    nc = deg[here]
    for e in range(nc):
        cands[e] = nb[here, e]
    cands[nc] = here
    nc += 1
    for a in range(1, nc):   # insertion sort by (distance to goal, occupied now, random tie)
        v = cands[a]
        b = a - 1
        while b >= 0 and _after(cands[b], v, d, occ_now, goals, q_to, tie):
            cands[b + 1] = cands[b]
            b -= 1
        cands[b + 1] = v
    puller = _swap_partner(i, cands[0], q_from, q_to, dist, grow, occ_now, goals, nb, deg)
    if puller != NIL:
        for a in range(nc // 2):
            cands[a], cands[nc - 1 - a] = cands[nc - 1 - a], cands[a]
    st_agent[sp] = i
    st_k[sp] = 0
    st_nc[sp] = nc
    st_pull[sp] = puller
    return False


@_jit
def _pull(i, k, v, puller, q_from, q_to, occ_now, occ_next):
    """After robot i took its first choice v: its swap partner follows into the cell it left."""
    here = q_from[i]
    if (k == 0 and puller != NIL and v != here and q_to[puller] == NIL and occ_next[here] == NIL
            and v != q_from[puller] and not _closes_ring(puller, here, q_from, q_to, occ_now)):
        q_to[puller] = here
        occ_next[here] = puller


@_jit
def _pibt(root, q_from, q_to, occ_now, occ_next, dist, grow, goals, nb, deg, tie, st_agent, st_k, st_nc,
          st_cands, st_pull):
    """PIBT for robot ``root`` (Okumura et al., AIJ 2022): each robot takes its best free neighbour,
    pushing its occupant (priority inheritance, here with an explicit stack instead of recursion);
    where a robot and the one in its way must pass each other in a corridor, it backs off and pulls
    that robot after it (the swap operation). Returns whether ``root`` got a cell it wanted."""
    if _open_frame(root, 0, q_from, occ_now, occ_next, q_to, dist, grow, goals, nb, deg, tie, st_agent, st_k,
                   st_nc, st_cands, st_pull):
        return True
    sp = 1
    result = -1        # -1: none pending; 0/1: the child frame just returned False/True
    while True:
        f = sp - 1
        i = st_agent[f]
        here = q_from[i]
        if result == 1:                 # the pushed robot found a cell: i keeps its choice
            k = st_k[f] - 1
            _pull(i, k, st_cands[f, k], st_pull[f], q_from, q_to, occ_now, occ_next)
            sp -= 1
            if sp == 0:
                return True
            continue                    # result stays 1 for the parent
        result = -1
        pushed = False
        while st_k[f] < st_nc[f]:
            k = st_k[f]
            st_k[f] = k + 1
            v = st_cands[f, k]
            if occ_next[v] != NIL:
                continue
            j = occ_now[v]
            if j != NIL and j != i:
                if q_to[j] == here:      # swap
                    continue
                if q_to[j] != NIL and _closes_ring(i, v, q_from, q_to, occ_now):
                    continue
            q_to[i] = v
            occ_next[v] = i
            if j != NIL and j != i and q_to[j] == NIL:
                if _open_frame(j, sp, q_from, occ_now, occ_next, q_to, dist, grow, goals, nb, deg, tie, st_agent,
                               st_k, st_nc, st_cands, st_pull):
                    result = 1
                else:
                    sp += 1
                pushed = True
                break
            _pull(i, k, v, st_pull[f], q_from, q_to, occ_now, occ_next)
            result = 1
            break
        if pushed:
            continue
        if result == 1:
            sp -= 1
            if sp == 0:
                return True
            continue
        q_to[i] = here                  # no candidate: i stays (and tells its pusher)
        occ_next[here] = i
        sp -= 1
        if sp == 0:
            return False
        result = 0


@_jit
def valid_step(q_from, q_to, occ_now):
    """The transition rules checked on a whole step (``occ_now``: robot per cell of q_from)."""
    n = len(q_from)
    seen = np.zeros(occ_now.shape[0], dtype=np.bool_)
    for i in range(n):
        if seen[q_to[i]]:
            return False
        seen[q_to[i]] = True
    for i in range(n):
        v = q_to[i]
        if v == q_from[i]:
            continue
        j = occ_now[v]
        if j != NIL and j != i and q_to[j] == q_from[i]:
            return False
    state = np.zeros(n, dtype=np.int8)   # 0 unseen, 1 on the current walk, 2 done
    walk = np.empty(n, dtype=np.int32)
    for s in range(n):
        w = 0
        i = s
        while i != NIL and state[i] == 0:
            state[i] = 1
            walk[w] = i
            w += 1
            v = q_to[i]
            i = occ_now[v] if v != q_from[i] else NIL
            if i != NIL and state[i] == 1:
                return False
        for k in range(w):
            state[walk[k]] = 2
    return True


@_jit
def successor(q_from, order, who, where, dist, grow, goals, nb, deg, tie, occ_now, occ_next, q_to):
    """One PIBT step from ``q_from`` under the constraints "robot who[k] goes to where[k]", robots
    planned in ``order``; writes ``q_to`` and says whether it is a valid step. ``occ_now`` and
    ``occ_next`` are NIL-filled scratch arrays of one entry per cell (left NIL-filled)."""
    n = len(q_from)
    for i in range(n):
        q_to[i] = NIL
        occ_now[q_from[i]] = i
    ok = True
    for c in range(len(who)):
        i = who[c]
        v = where[c]
        if occ_next[v] != NIL:
            ok = False
            break
        j = occ_now[v]
        if j != NIL and j != i and q_to[j] == q_from[i]:
            ok = False
            break
        q_to[i] = v
        occ_next[v] = i
    if ok:
        st_agent = np.empty(n + 1, dtype=np.int32)
        st_k = np.empty(n + 1, dtype=np.int32)
        st_nc = np.empty(n + 1, dtype=np.int32)
        st_pull = np.empty(n + 1, dtype=np.int32)
        st_cands = np.empty((n + 1, 5), dtype=np.int32)
        for k in range(n):
            i = order[k]
            if q_to[i] == NIL and not _pibt(i, q_from, q_to, occ_now, occ_next, dist, grow, goals, nb, deg, tie,
                                            st_agent, st_k, st_nc, st_cands, st_pull):
                ok = False
                break
    if ok:
        ok = valid_step(q_from, q_to, occ_now)
    for i in range(n):
        occ_now[q_from[i]] = NIL
        if q_to[i] != NIL:
            occ_next[q_to[i]] = NIL
    return ok


# ---------------------------------------------------------------------------------------------
# loop cutting
# ---------------------------------------------------------------------------------------------
@_jit
def remove_loops_inplace(out, ncells):
    """Where a robot leaves a cell and comes back to it later while no other robot enters that cell
    in between, it waits there instead (see :func:`.crowd_pibt.remove_loops`)."""
    steps, n = out.shape
    occ = np.full((steps, ncells), NIL, dtype=np.int32)
    for t in range(steps):
        for i in range(n):
            occ[t, out[t, i]] = i
    last_seen = np.full(ncells, -1, dtype=np.int64)
    for i in range(n):
        path = out[:, i]
        for t in range(steps):
            last_seen[path[t]] = t
        t = 0
        while t < steps:
            c = path[t]
            back = last_seen[c]
            e = t
            while e + 1 < steps and path[e + 1] == c:
                e += 1
            if back > e:
                free = True
                for u in range(e + 1, back):
                    if occ[u, c] != NIL:
                        free = False
                        break
                if free:
                    for u in range(e + 1, back):
                        occ[u, path[u]] = NIL
                        occ[u, c] = i
                        path[u] = c
                    t = back
                    continue
            t = e + 1
        for t in range(steps):
            last_seen[path[t]] = -1
    return out


# ---------------------------------------------------------------------------------------------
# the timing's longest-path pass
# ---------------------------------------------------------------------------------------------
@_jit
def precedence_pass(order, after_own, after_cell, slack, dur, start, end, after_side):
    """Earliest start and end of every move, taken in ``order`` (a topological order of the
    precedences): after its robot's previous move ``after_own`` ended, after the move
    ``after_cell`` out of its cell started and ended at most ``slack`` before (NIL: none), and
    after the moves ``after_side[k, :]`` (NIL: none; (moves, 0) when no move sweeps a cell) out of
    the cells a diagonal move sweeps ended."""
    for q in range(len(order)):
        k = order[q]
        t = 0.0
        o = after_own[k]
        if o != NIL and end[o] > t:
            t = end[o]
        c = after_cell[k]
        if c != NIL:
            if start[c] > t:
                t = start[c]
            if end[c] - slack[k] > t:
                t = end[c] - slack[k]
        for j in range(after_side.shape[1]):
            c = after_side[k, j]
            if c != NIL and end[c] > t:
                t = end[c]
        start[k] = t
        end[k] = t + dur[k]


_WARM = False


def toy_instance() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The warm-ups' toy instance: the neighbour table and degrees of a 3x2 grid (cells 0-2 on top,
    3-5 below) and the goals of two robots passing each other (2 and 0)."""
    nb = np.array([[1, 3, NIL, NIL], [0, 2, 4, NIL], [1, 5, NIL, NIL],
                   [0, 4, NIL, NIL], [1, 3, 5, NIL], [2, 4, NIL, NIL]], dtype=np.int32)
    return nb, np.array([2, 3, 2, 2, 3, 2], dtype=np.int32), np.array([2, 0], dtype=np.int32)


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel on a toy instance, so that no planning
    budget is spent compiling: two robots passing on a 3x2 grid."""
    global _WARM
    if _WARM:
        return
    nb, deg, goals = toy_instance()
    dist = bfs_fields(nb, deg, goals)
    grow = np.array([0, 1], dtype=np.int32)
    occ_now = np.full(6, NIL, dtype=np.int32)
    occ_next = np.full(6, NIL, dtype=np.int32)
    q_to = np.empty(2, dtype=np.int32)
    q = np.array([0, 2], dtype=np.int32)
    successor(q, np.array([0, 1], dtype=np.int32), np.empty(0, dtype=np.int32), np.empty(0, dtype=np.int32),
              dist, grow, goals, nb, deg, np.linspace(0, 1, 6), occ_now, occ_next, q_to)
    plan = np.array([[0, 2], [1, 5], [2, 4], [2, 3], [2, 0]], dtype=np.int32)
    remove_loops_inplace(plan.astype(np.int64), 6)
    z = np.zeros(2)
    side = np.full((2, 2), NIL, dtype=np.int64)
    precedence_pass(np.arange(2), np.array([NIL, 0]), np.array([NIL, NIL]), z, np.ones(2), z.copy(), z.copy(), side)
    precedence_pass(np.arange(2), np.array([NIL, 0]), np.array([NIL, NIL]), z, np.ones(2), z.copy(), z.copy(),
                    np.full((2, 0), NIL, dtype=np.int64))
    _WARM = True
