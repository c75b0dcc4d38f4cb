"""The discrete half of the crowd planner: a configuration-space search on the grid graph.

* :class:`CellGraph` - the 4-connected graph of the cell centres a disc of the largest radius fits
  on, with distance-to-goal fields computed in C by ``scipy.sparse.csgraph`` (one BFS per distinct
  goal).
* :class:`ConfigSearch` - LaCAM (Okumura, "LaCAM: Search-Based Algorithm for Quick Multi-Agent
  Pathfinding", AAAI 2023): a depth-first search over configurations (one cell per robot) whose
  successors are generated lazily by PIBT (Okumura et al., "Priority Inheritance with Backtracking
  for Iterative Multi-agent Path Finding", AIJ 2022) under a growing tree of constraints ("robot i
  goes to cell v"). Every successor of a configuration is eventually generated, so the search is
  complete for the transition rules below: it finds a plan when one exists and says so when none
  does (within its budget).

Transition rules (a step from configuration Q to Q'), made for discs whose radius sums do not
exceed the cell step (the planner checks that; docs/ARCHITECTURE.md, measured fact 7):

1. vertex: no two robots in one cell of Q' (cells closer than r_i + r_j are then only equal cells);
2. swap: no two robots exchange cells;
3. following is allowed (a robot moves into the cell another leaves in the same step, whatever the
   two directions), but never in a closed ring (a rotation): the timing pass
   (:mod:`.crowd_timing`) lets the follower start only once the leader has *arrived* in its next
   cell, which needs the leaders of each step to form chains, not cycles. This is what makes the
   corner case of measured fact 7 (a robot turning into the cell another leaves, centres 0.707 m
   apart when driven in lock-step) safe: nobody drives in lock-step.

The inner loop (:meth:`ConfigSearch._pibt`) is plain Python on lists of ints, small on purpose.
"""
from __future__ import annotations

import random
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

from ..grid import GridMap

NIL = -1
Config = tuple[int, ...]


class SearchFailed(Exception):
    """The configuration search found no plan: ``reason`` in words."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class CellGraph:
    """Free cells whose centre keeps ``radius`` from every obstacle, 4-connected (an axis-aligned
    move between two such centres keeps the disc in free space, since obstacles are whole cells)."""

    def __init__(self, grid: GridMap, radius: float):
        self.grid = grid
        h, w = grid.blocked.shape
        free = ~grid.blocked
        if radius > grid.resolution / 2 + 1e-12:
            import shapely
            rows, cols = np.nonzero(free)
            pts = shapely.points(np.column_stack([(cols + 0.5) * grid.resolution, (rows + 0.5) * grid.resolution]))
            ok = shapely.distance(grid.obstacle_geometry, pts) >= radius - 1e-9
            free = np.zeros_like(free)
            free[rows[ok], cols[ok]] = True
        self.index = np.full((h, w), NIL, dtype=np.int64)
        rows, cols = np.nonzero(free)
        self.index[rows, cols] = np.arange(len(rows))
        self.rows, self.cols = rows, cols
        self.n = len(rows)
        src, dst = [], []
        for dr, dc in ((0, 1), (1, 0)):
            a = self.index[: h - dr, : w - dc]
            b = self.index[dr:, dc:]
            both = (a != NIL) & (b != NIL)
            src.append(a[both])
            dst.append(b[both])
        s, d = np.concatenate(src), np.concatenate(dst)
        self.adjacency = csr_matrix((np.ones(2 * len(s)), (np.concatenate([s, d]), np.concatenate([d, s]))),
                                    shape=(self.n, self.n))
        ptr, ind = self.adjacency.indptr, self.adjacency.indices
        self.neighbours: list[list[int]] = [ind[ptr[v]:ptr[v + 1]].tolist() for v in range(self.n)]

    def cell(self, x: float, y: float) -> int:
        """Index of the cell whose centre is (x, y) within 1e-6 m, else NIL."""
        res = self.grid.resolution
        col, row = int(np.floor(x / res)), int(np.floor(y / res))
        if not self.grid.in_bounds(col, row):
            return NIL
        cx, cy = self.grid.centre(col, row)
        if abs(cx - x) > 1e-6 or abs(cy - y) > 1e-6:
            return NIL
        return int(self.index[row, col])

    def centre(self, v: int) -> tuple[float, float]:
        return self.grid.centre(int(self.cols[v]), int(self.rows[v]))

    def distance_fields(self, goals: Sequence[int]) -> tuple[np.ndarray, list[int]]:
        """(fields, row of each goal): BFS hop counts from every distinct goal (large where unreachable)."""
        distinct = sorted(set(goals))
        d = shortest_path(self.adjacency, directed=False, unweighted=True, indices=distinct)
        d = np.where(np.isfinite(d), d, 10 * self.n + 1).astype(np.int64)
        where = {g: k for k, g in enumerate(distinct)}
        return d, [where[g] for g in goals]


@dataclass
class _Constraint:
    """A node of LaCAM's low-level tree: robots ``who`` go to cells ``where``."""

    who: tuple[int, ...] = ()
    where: tuple[int, ...] = ()


@dataclass
class _Node:
    """A high-level node of LaCAM: a configuration, its parent, robot order and constraint tree."""

    config: Config
    parent: _Node | None
    order: list[int]
    priority: list[float]
    tree: deque[_Constraint] = field(default_factory=lambda: deque([_Constraint()]))


class ConfigSearch:
    """LaCAM over configurations with PIBT as the successor generator (see the module docstring)."""

    def __init__(self, graph: CellGraph, starts: Sequence[int], goals: Sequence[int], seed: int = 0):
        self.graph = graph
        self.starts = tuple(starts)
        self.goals = tuple(goals)
        self.n = len(starts)
        fields, row = graph.distance_fields(goals)
        self.fields = fields
        # plain lists: the PIBT loop reads single entries, which lists serve fastest
        rows = [r.tolist() for r in fields]
        self.dist: list[list[int]] = [rows[row[i]] for i in range(self.n)]
        self.rng = random.Random(seed)
        self.np_rng = np.random.default_rng(seed)
        self.occ_now = [NIL] * graph.n
        self.occ_next = [NIL] * graph.n
        self.expanded = 0
        self.starts_now: Sequence[int] = self.starts
        self.tie: list[float] = [0.0] * graph.n

    def unreachable(self) -> list[int]:
        """Robots whose goal cannot be reached from their start."""
        big = 10 * self.graph.n
        return [i for i in range(self.n) if self.dist[i][self.starts[i]] > big]

    # -- LaCAM ---------------------------------------------------------------------------------
    def solve(self, deadline: float) -> list[Config]:
        """Configurations from the starts to the goals, one per step."""
        n, goals = self.n, self.goals
        prio0 = [float(self.dist[i][self.starts[i]]) / max(1, self.graph.n) for i in range(n)]
        root = _Node(self.starts, None, sorted(range(n), key=lambda i: -prio0[i]), prio0)
        open_: list[_Node] = [root]
        explored: dict[Config, _Node] = {root.config: root}
        while open_:
            if time.perf_counter() > deadline:
                raise SearchFailed(f"search budget exhausted after {self.expanded} configurations")
            node = open_[-1]
            if node.config == goals:
                out = []
                cur: _Node | None = node
                while cur is not None:
                    out.append(cur.config)
                    cur = cur.parent
                return out[::-1]
            if not node.tree:
                open_.pop()
                continue
            c = node.tree.popleft()
            depth = len(c.who)
            if depth < n:   # grow the constraint tree by the next robot in the node's order
                i = node.order[depth]
                v0 = node.config[i]
                cands = self.graph.neighbours[v0] + [v0]
                self.rng.shuffle(cands)
                for v in cands:
                    node.tree.append(_Constraint(c.who + (i,), c.where + (v,)))
            new = self._successor(node, c)
            if new is None:
                continue
            self.expanded += 1
            known = explored.get(new)
            if known is not None:
                open_.append(known)
                continue
            prio = [node.priority[i] + 1.0 if new[i] != goals[i] else node.priority[i] - int(node.priority[i])
                    for i in range(n)]
            child = _Node(new, node, sorted(range(n), key=lambda i: -prio[i]), prio)
            explored[new] = child
            open_.append(child)
        raise SearchFailed("no plan exists under the disc transition rules (every configuration reachable "
                           "from the starts was explored)")

    # -- PIBT with constraints -----------------------------------------------------------------
    def _successor(self, node: _Node, c: _Constraint) -> Config | None:
        q_from = node.config
        q_to = [NIL] * self.n
        occ_now, occ_next = self.occ_now, self.occ_next
        for i, v in enumerate(q_from):
            occ_now[v] = i
        self.starts_now = q_from
        self.tie = self.np_rng.random(self.graph.n).tolist()   # fresh tie-breaking per step
        try:
            for i, v in zip(c.who, c.where):
                if occ_next[v] != NIL:
                    return None
                j = occ_now[v]
                if j != NIL and j != i and q_to[j] == q_from[i]:
                    return None
                q_to[i] = v
                occ_next[v] = i
            for i in node.order:
                if q_to[i] == NIL and not self._pibt(i, q_from, q_to):
                    return None
            return tuple(q_to) if _valid_step(q_from, q_to, occ_now) else None
        finally:
            for v in q_from:
                occ_now[v] = NIL
            for v in q_to:
                if v != NIL:
                    occ_next[v] = NIL

    def _pibt(self, i: int, q_from: Sequence[int], q_to: list[int]) -> bool:
        """PIBT for robot i: take the best free neighbour, pushing its occupant (priority
        inheritance). Where i and the robot in its way must pass each other in a corridor, i
        first backs off and pulls that robot after it (the swap operation of Okumura, "Engineering
        LaCAM*: Towards Real-Time, Large-Scale, and Near-Optimal Multi-Agent Pathfinding", AAMAS 2024)."""
        occ_now, occ_next = self.occ_now, self.occ_next
        here = q_from[i]
        d = self.dist[i]
        if d[here] == 0 and occ_next[here] == NIL:
            # on its goal with nobody pushing: it stays (the sort below would say so, and no swap applies)
            q_to[i] = here
            occ_next[here] = i
            return True
        tie = self.tie
        cands = self.graph.neighbours[here] + [here]
        cands.sort(key=lambda v: (d[v], occ_now[v] != NIL, tie[v]))
        puller = self._swap_partner(i, cands[0], q_to)
        if puller != NIL:
            cands.reverse()
        for k, v in enumerate(cands):
            if occ_next[v] != NIL:
                continue
            j = occ_now[v]
            if j != NIL and j != i:
                if q_to[j] == here:          # swap
                    continue
                if q_to[j] != NIL and _closes_ring(i, v, q_from, q_to, occ_now):
                    continue
            q_to[i] = v
            occ_next[v] = i
            if j != NIL and j != i and q_to[j] == NIL and not self._pibt(j, q_from, q_to):
                continue
            if (k == 0 and puller != NIL and v != here and q_to[puller] == NIL and occ_next[here] == NIL
                    and v != q_from[puller] and not _closes_ring(puller, here, q_from, q_to, occ_now)):
                q_to[puller] = here          # pulled after i
                occ_next[here] = puller
            return True
        q_to[i] = here
        occ_next[here] = i
        return False

    # -- the swap operation ---------------------------------------------------------------------
    def _swap_partner(self, i: int, best: int, q_to: Sequence[int]) -> int:
        """The robot i should pull after it instead of pushing (NIL: none)."""
        occ_now = self.occ_now
        here = self.starts_now[i]
        j = occ_now[best]
        if (j != NIL and j != i and q_to[j] == NIL and self._swap_required(i, j, here, best)
                and self._swap_possible(best, here)):
            return j
        for u in self.graph.neighbours[here]:
            k = occ_now[u]
            if k == NIL or best == u:
                continue
            if self._swap_required(k, i, here, best) and self._swap_possible(best, here):
                return k
        return NIL

    def _passable(self, v: int, came_from: int) -> tuple[int, int]:
        """(number of ways on from v other than back to ``came_from`` or into a dead end where a
        robot sits on its goal, one such way)."""
        occ_now, goals, nb = self.occ_now, self.goals, self.graph.neighbours
        count, way = 0, NIL
        for u in nb[v]:
            a = occ_now[u]
            if u == came_from or (len(nb[u]) == 1 and a != NIL and goals[a] == u):
                continue
            count += 1
            way = u
        return count, way

    def _swap_required(self, pusher: int, puller: int, v_pusher: int, v_puller: int) -> bool:
        d_push, d_pull = self.dist[pusher], self.dist[puller]
        for _ in range(self.graph.n):
            if not d_push[v_puller] < d_push[v_pusher]:
                break
            count, way = self._passable(v_puller, v_pusher)
            if count >= 2:
                return False   # there is room to pass here
            if count <= 0:
                break
            v_pusher, v_puller = v_puller, way
        return bool(d_pull[v_pusher] < d_pull[v_puller]
                    and (d_push[v_pusher] == 0 or d_push[v_puller] < d_push[v_pusher]))

    def _swap_possible(self, v_pusher: int, v_puller: int) -> bool:
        origin = v_pusher
        for _ in range(self.graph.n):
            if v_puller == origin:
                return False
            count, way = self._passable(v_puller, v_pusher)
            if count >= 2:
                return True
            if count <= 0:
                return False
            v_pusher, v_puller = v_puller, way
        return False


def _closes_ring(i: int, v: int, q_from: Sequence[int], q_to: Sequence[int], occ_now: Sequence[int]) -> bool:
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


def _valid_step(q_from: Sequence[int], q_to: Sequence[int], occ_now: Sequence[int]) -> bool:
    """The transition rules of the module docstring, checked on a whole step."""
    n = len(q_from)
    if len(set(q_to)) != n:
        return False
    for i in range(n):
        v = q_to[i]
        if v == q_from[i]:
            continue
        j = occ_now[v]
        if j != NIL and j != i and q_to[j] == q_from[i]:
            return False
    # rings: walk each chain of followers once
    state = [0] * n   # 0 unseen, 1 on the current walk, 2 done
    for s in range(n):
        walk = []
        i = s
        while i != NIL and state[i] == 0:
            state[i] = 1
            walk.append(i)
            v = q_to[i]
            i = occ_now[v] if v != q_from[i] else NIL
            if i != NIL and state[i] == 1:
                return False
        for k in walk:
            state[k] = 2
    return True


def moves_of(configs: Sequence[Config]) -> np.ndarray:
    """The configurations as an array (steps + 1, robots)."""
    return np.asarray(configs, dtype=np.int64).reshape(len(configs), -1)


def remove_loops(configs: np.ndarray) -> np.ndarray:
    """The plan with detours cut: where a robot leaves a cell and comes back to it later while no
    other robot enters that cell in between, it waits there instead (PIBT wanders when it gives
    way). Cutting a detour only removes moves and occupancies of that robot, and the cell it waits
    on is nobody else's meanwhile, so every step stays valid under the transition rules."""
    out = configs.copy()
    n = out.shape[1]
    for i in range(n):
        path = out[:, i]
        starts = np.flatnonzero(np.concatenate([[True], path[1:] != path[:-1]]))   # runs of one cell
        cells = path[starts].tolist()
        ends = np.concatenate([starts[1:] - 1, [len(path) - 1]]).tolist()
        last: dict[int, int] = {}
        for k, c in enumerate(cells):
            last[c] = k
        k = 0
        while k < len(cells):
            back = last[cells[k]]
            if back > k:
                t, u = ends[k], starts[back]   # it leaves after t and is back at u
                window = out[t:u + 1] == cells[k]
                window[:, i] = False
                if not window.any():
                    path[t:u + 1] = cells[k]
                    k = back
                    continue
            k += 1
    return out
