"""The compiled space-time side of the dense-crowd solver (numba, see :mod:`.crowd_kernels` for why):
one robot's earliest-arrival search against fixed others under the transition rules, and the
iterations of the large neighbourhood search of :mod:`.crowd_lns`.

Tables: ``occ`` (horizon + 1, cells) the robot on each cell at each step (NIL when free), ``paths``
(horizon + 1, robots) each robot's cell at each step (padded with its goal after its arrival).
"""
from __future__ import annotations

import numpy as np

from .crowd_kernels import NIL, _jit


@_jit
def occupy(occ, paths, a, value):
    """Write robot a's path into the occupancy table (value = a) or clear it (value = NIL)."""
    for t in range(occ.shape[0]):
        occ[t, paths[t, a]] = value


@_jit
def _move_ok(t, u, v, occ, paths, n):
    """May a robot (not on the table) go u -> v from step t to t + 1 against the table?"""
    if occ[t + 1, v] != NIL:
        return False
    if u == v:
        return True
    j = occ[t, v]
    if j == NIL:
        return True
    if paths[t + 1, j] == u:
        return False                     # swap
    k = j
    for _ in range(n):                   # no ring: walk the chain of robots ahead
        w = paths[t + 1, k]
        if w == u:
            return False
        k2 = occ[t, w]
        if k2 == NIL or k2 == k or paths[t + 1, k2] == w:
            return True
        k = k2
    return False


@_jit
def _key(g, h, weight10, state):
    """Heap key: the weighted estimate 10 g + weight10 h (20 bits), then h (11 bits: nearer the
    goal first), then the state (32 bits)."""
    f = np.int64(10 * g + weight10 * h)
    return (f << 43) | (np.int64(min(h, 2047)) << 32) | np.int64(state)


@_jit
def st_search(start, goal, d, occ, paths, nb, deg, limit, bound, weight10, stamp, gen, parent, out):
    """Earliest arrival of one robot from ``start`` (at step 0) at ``goal`` to stay there for ever,
    against the robots on ``occ`` ((horizon + 1, cells) robot per cell per step, NIL when free;
    ``paths`` (horizon + 1, robots) their cells), by A* over (step, cell) with the hop distance ``d``
    as heuristic, weighted by ``weight10`` / 10 (10: plain A*, optimal; more: faster, bounded
    suboptimal). Writes the path to ``out`` (padded with the goal) and returns the arrival step, or
    -1 when there is none within the horizon, ``limit`` expansions or ``bound`` steps (states whose
    arrival estimate exceeds it are not explored). ``stamp``/``parent`` are
    scratch arrays of (horizon + 1) * cells entries, ``gen`` this search's stamp."""
    horizon = occ.shape[0] - 1
    ncell = occ.shape[1]
    n = paths.shape[1]
    busy = -1                          # the last step anybody else is on the goal
    for t in range(horizon, -1, -1):
        if occ[t, goal] != NIL:
            busy = t
            break
    if busy >= horizon or occ[0, start] != NIL:
        return -1
    cap = 1 << 16
    hk = np.empty(cap, dtype=np.int64)     # heap keys: ((f << 16) | (horizon - g)) << 32 | state
    s0 = start
    stamp[s0] = gen
    parent[s0] = -1
    h0 = max(d[start], busy + 1)
    if h0 > bound:
        return -1
    mask = (np.int64(1) << 32) - 1
    hk[0] = _key(0, h0, weight10, s0)
    size = 1
    expanded = 0
    while size > 0:
        top = hk[0]
        size -= 1
        if size > 0:                       # pop: sift the last key down from the root
            x = hk[size]
            p = 0
            while True:
                c = 2 * p + 1
                if c >= size:
                    break
                if c + 1 < size and hk[c + 1] < hk[c]:
                    c += 1
                if hk[c] < x:
                    hk[p] = hk[c]
                    p = c
                else:
                    break
            hk[p] = x
        state = top & mask
        t = state // ncell
        v = state - t * ncell
        if v == goal and t > busy:
            for u in range(t + 1, horizon + 1):
                out[u] = goal
            s = state
            for u in range(t, -1, -1):
                out[u] = s - u * ncell
                s = parent[s]
            return t
        expanded += 1
        if expanded > limit or t >= horizon:
            if expanded > limit:
                return -1
            continue
        for e in range(deg[v] + 1):
            u = v if e == deg[v] else nb[v, e]
            s2 = (t + 1) * ncell + u
            if stamp[s2] == gen:
                continue
            if not _move_ok(t, v, u, occ, paths, n):
                continue
            stamp[s2] = gen
            parent[s2] = state
            g = t + 1
            h = d[u]
            if busy + 1 - g > h:
                h = busy + 1 - g
            if g + h > bound:
                continue
            # priority: f, then deeper first
            key = _key(g, h, weight10, s2)
            if size >= cap:
                grown = np.empty(2 * cap, dtype=np.int64)
                grown[:cap] = hk
                hk = grown
                cap *= 2
            p = size
            size += 1
            while p > 0:                   # push: sift up
                q = (p - 1) // 2
                if hk[q] > key:
                    hk[p] = hk[q]
                    p = q
                else:
                    break
            hk[p] = key
    return -1


@_jit
def arrival_steps(paths, goals):
    """Per robot: the first step from which it stays on its goal."""
    steps, n = paths.shape
    out = np.zeros(n, dtype=np.int64)
    for i in range(n):
        t = steps - 1
        while t > 0 and paths[t - 1, i] == goals[i]:
            t -= 1
        out[i] = t if paths[steps - 1, i] == goals[i] else steps
    return out


@_jit
def _roulette(weight, total):
    r = np.random.random() * total
    acc = 0.0
    for i in range(len(weight)):
        acc += weight[i]
        if acc > r and weight[i] > 0:
            return i
    for i in range(len(weight) - 1, -1, -1):
        if weight[i] > 0:
            return i
    return 0


# The large neighbourhood searches' shared steps (this module's over the discrete plan and
# :mod:`.crowd_sipp`'s over the timed plan): they differ only in how they find the robots in a delayed
# robot's way (their own tables), how they re-plan, and the cost of a robot (a weighted arrival step,
# an arrival time with weight 1).
@_jit
def pick_kind(strategy):
    """Which neighbourhood: 0 (a delayed robot and the robots in its way) or 1 (delayed robots at
    random), drawn by the two kinds' adaptive weights."""
    return 0 if np.random.random() * (strategy[0] + strategy[1]) < strategy[0] else 1


@_jit
def start_group(delay, total, group, mark):
    """A neighbourhood of kind 0 begins with a robot drawn by its delay: returns it."""
    a = _roulette(delay, total)
    group[0] = a
    mark[a] = True
    return a


@_jit
def add_member(j, g, group, mark):
    """Add robot j (NIL: nobody) to the neighbourhood of g robots unless it is in already or full;
    returns the new size."""
    if j != NIL and not mark[j] and g < group.shape[0]:
        group[g] = j
        mark[j] = True
        g += 1
    return g


@_jit
def downhill(v, d, nb, deg):
    """One step from cell v along a shortest path to the goal of the distance field d, a random one
    of the neighbours nearer the goal (v itself at the goal)."""
    ways = 0
    nxt = v
    for e in range(deg[v]):
        u = nb[v, e]
        if d[u] < d[v]:
            ways += 1
            if np.random.random() * ways < 1.0:
                nxt = u
    return nxt


@_jit
def delayed_at_random(delay, total, group, mark, scale, share):
    """A neighbourhood of kind 1: up to ``len(group)`` robots, each drawn by its delay when
    ``random() * scale < share`` and uniformly otherwise; returns their number."""
    n = delay.shape[0]
    size = group.shape[0]
    g = 0
    for _try in range(8 * size):
        if g >= size:
            break
        if np.random.random() * scale < share:
            a = _roulette(delay, total)
        else:
            a = np.random.randint(n)
        g = add_member(a, g, group, mark)
    return g


@_jit
def shuffle_group(group, g, mark):
    """Fewer than two robots: clear their marks and return False (no neighbourhood); otherwise put
    the g robots in random order (the order they are re-planned in) and return True."""
    if g < 2:
        for k in range(g):
            mark[group[k]] = False
        return False
    for k in range(g - 1, 0, -1):
        m = np.random.randint(k + 1)
        group[k], group[m] = group[m], group[k]
    return True


@_jit
def group_cost(group, g, weights, value):
    """Sum over the neighbourhood's robots of weight x value."""
    total = 0.0
    for k in range(g):
        total += weights[group[k]] * value[group[k]]
    return total


@_jit
def settle(kind, ok, before, after, strategy, stats):
    """Count the iteration, adapt the kind's weight; True when the neighbourhood's new paths are kept
    (all found and the weighted sum did not grow)."""
    stats[0] += 1
    if ok and after <= before + 1e-9:
        stats[1] += 1
        strategy[kind] = 0.9 * strategy[kind] + 0.1 * max(before - after, 0.01)
        return True
    strategy[kind] = max(0.9 * strategy[kind], 0.01)
    return False


@_jit
def lns_iterations(iters, paths, occ, cost, lb, weights, goals, fields, grow, nb, deg, stamp, gen, parent, out,
                   size, limit, weight10, horizon, strategy, stats):
    """``iters`` iterations of the large neighbourhood search (see :mod:`.crowd_lns`); updates
    ``paths``, ``occ`` and ``cost`` in place, ``strategy`` (the two neighbourhoods' weights) and
    ``stats`` ([iterations, accepted]); returns the last search stamp used."""
    n = paths.shape[1]
    h1 = paths.shape[0]
    group = np.empty(size, dtype=np.int32)
    old = np.empty((h1, size), dtype=np.int32)
    oldc = np.empty(size, dtype=np.int64)
    mark = np.zeros(n, dtype=np.bool_)
    delay = np.empty(n, dtype=np.float64)
    for _ in range(iters):
        total = 0.0
        for i in range(n):
            delay[i] = weights[i] * (cost[i] - lb[i])
            total += delay[i]
        if total <= 0:
            break
        kind = pick_kind(strategy)
        if kind == 0:       # a delayed robot and the robots in its way
            a = start_group(delay, total, group, mark)
            g = 1
            goal = goals[a]
            for t in range(h1 - 1, lb[a] - 1, -1):       # who is on its goal after it could be there
                g = add_member(occ[t, goal], g, group, mark)
            d = fields[grow[a]]
            v = paths[0, a]
            t = 0
            while d[v] > 0 and t < h1 - 1 and g < size:   # who is on a shortest path when it would pass
                v = downhill(v, d, nb, deg)
                t += 1
                for s in (t, t - 1):
                    g = add_member(occ[s, v], g, group, mark)
        else:               # delayed robots at random
            g = delayed_at_random(delay, total, group, mark, total + 0.1 * total, total)
        if not shuffle_group(group, g, mark):            # (re-planned in random order)
            continue
        before = group_cost(group, g, weights, cost)
        floor = group_cost(group, g, weights, lb)
        for k in range(g):
            a = group[k]
            old[:, k] = paths[:, a]
            oldc[k] = cost[a]
            occupy(occ, paths, a, NIL)
        room = before - floor
        ok = True
        done = 0
        for k in range(g):
            a = group[k]
            bound = int(lb[a] + room / weights[a] + 1e-9)
            if bound > horizon:
                bound = horizon
            gen += 1
            t = st_search(paths[0, a], goals[a], fields[grow[a]], occ, paths, nb, deg, limit, bound, weight10,
                          stamp, gen, parent, out)
            if t < 0:
                ok = False
                break
            paths[:, a] = out
            occupy(occ, paths, a, a)
            cost[a] = t
            room -= weights[a] * (t - lb[a])
            done += 1
        if not settle(kind, ok, before, group_cost(group, g, weights, cost), strategy, stats):
            for k in range(done):
                occupy(occ, paths, group[k], NIL)
            for k in range(g):
                a = group[k]
                paths[:, a] = old[:, k]
                cost[a] = oldc[k]
                occupy(occ, paths, a, a)
        for k in range(g):
            mark[group[k]] = False
    return gen


@_jit
def prioritized(order, hold, paths, occ, cost, goals, fields, grow, nb, deg, stamp, gen, parent, out, limit,
                weight10, failed, max_failed):
    """Prioritized planning on the discrete tables: the robots of ``order`` one after the other by
    :func:`st_search` against the ones before it and the start cells of the ones after it (held for
    the first ``hold`` steps). ``paths`` comes with every robot on its start at every step and
    ``occ`` empty. A robot without a path is left out of the tables and listed in ``failed``; more
    than ``max_failed`` of them stop the pass. Returns (the last search stamp, the number of failed
    robots)."""
    horizon = occ.shape[0] - 1
    n = len(order)
    top = min(hold, horizon)
    for q in range(n):
        a = order[q]
        for t in range(top + 1):
            occ[t, paths[0, a]] = a
    nf = 0
    for q in range(n):
        a = order[q]
        s0 = paths[0, a]
        for t in range(top + 1):
            if occ[t, s0] == a:
                occ[t, s0] = NIL
        gen += 1
        t = st_search(s0, goals[a], fields[grow[a]], occ, paths, nb, deg, limit, horizon, weight10, stamp, gen,
                      parent, out)
        if t < 0:
            failed[nf] = a
            nf += 1
            if nf > max_failed:
                break
            continue
        paths[:, a] = out
        occupy(occ, paths, a, a)
        cost[a] = t
    return gen, nf


@_jit
def seed_rng(seed):
    """Seed numba's own generator (the one the kernels draw from)."""
    np.random.seed(seed)


_WARM = False


def warm_up() -> None:
    """Compile (or load from numba's cache) the kernels of this module on a toy instance: two
    robots passing on a 3x2 grid, one of them re-planned by the LNS."""
    global _WARM
    if _WARM:
        return
    from .crowd_kernels import bfs_fields, toy_instance

    nb, deg, goals = toy_instance()
    fields = bfs_fields(nb, deg, goals)
    grow = np.array([0, 1], dtype=np.int32)
    paths = np.array([[0, 2], [1, 5], [2, 4], [2, 3], [2, 0], [2, 0]], dtype=np.int32)
    occ = np.full((paths.shape[0], 6), NIL, dtype=np.int32)
    occupy(occ, paths, 0, 0)
    occupy(occ, paths, 1, 1)
    cost = arrival_steps(paths, goals)
    lb = np.array([2, 2], dtype=np.int64)
    size = paths.shape[0] * 6
    seed_rng(0)
    lns_iterations(2, paths, occ, cost, lb, np.ones(2), goals, fields, grow, nb, deg, np.zeros(size, dtype=np.int32),
                   0, np.zeros(size, dtype=np.int32), np.empty(paths.shape[0], dtype=np.int32), 2, 100,
                   20, paths.shape[0] - 1, np.ones(2), np.zeros(2, dtype=np.int64))
    paths[:] = paths[0]
    occ[:] = NIL
    prioritized(np.array([1, 0], dtype=np.int64), 3, paths, occ, cost, goals, fields, grow, nb, deg,
                np.zeros(size, dtype=np.int32), 0, np.zeros(size, dtype=np.int32),
                np.empty(paths.shape[0], dtype=np.int32), 100, 15, np.empty(2, dtype=np.int64), 2)
    _WARM = True
