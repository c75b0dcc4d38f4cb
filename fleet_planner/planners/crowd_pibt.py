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

from ..grid import GridMap
from . import crowd_kernels as kern
from .crowd_kernels import UNREACHABLE, bfs_fields

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
        # the same, padded, for the compiled kernels
        self.deg = np.diff(ptr).astype(np.int32)
        self.nb = np.full((self.n, 4), NIL, dtype=np.int32)
        slot = np.arange(len(ind)) - np.repeat(ptr[:-1], self.deg)
        self.nb[np.repeat(np.arange(self.n), self.deg), slot] = ind

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

    def distance_fields(self, goals: Sequence[int] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(fields, row of each goal): BFS hop counts (int32, compiled) from every distinct goal,
        ``UNREACHABLE`` where a cell cannot reach it."""
        distinct, row = np.unique(np.asarray(goals, dtype=np.int32), return_inverse=True)
        return bfs_fields(self.nb, self.deg, distinct.astype(np.int32)), row.astype(np.int32)


@dataclass
class _Constraint:
    """A node of LaCAM's low-level tree: robots ``who`` go to cells ``where``."""

    who: tuple[int, ...] = ()
    where: tuple[int, ...] = ()


@dataclass
class _Node:
    """A high-level node of LaCAM: a configuration, its parent, robot order and constraint tree."""

    config: np.ndarray
    parent: _Node | None
    order: np.ndarray
    priority: np.ndarray
    tree: deque[_Constraint] = field(default_factory=lambda: deque([_Constraint()]))


class ConfigSearch:
    """LaCAM over configurations with PIBT as the successor generator (see the module docstring);
    the PIBT step is compiled (:func:`.crowd_kernels.successor`)."""

    def __init__(self, graph: CellGraph, starts: Sequence[int], goals: Sequence[int], seed: int = 0):
        self.graph = graph
        self.starts = np.asarray(starts, dtype=np.int32)
        self.goals = np.asarray(goals, dtype=np.int32)
        self.n = len(self.starts)
        self.fields, self.grow = graph.distance_fields(self.goals)
        self.rng = random.Random(seed)
        self.np_rng = np.random.default_rng(seed)
        self.occ_now = np.full(graph.n, NIL, dtype=np.int32)
        self.occ_next = np.full(graph.n, NIL, dtype=np.int32)
        self.q_to = np.empty(self.n, dtype=np.int32)
        self.expanded = 0

    def lower_bounds(self) -> np.ndarray:
        """Each robot's hop distance from its start to its goal."""
        return self.fields[self.grow, self.starts].astype(np.int64)

    def unreachable(self) -> list[int]:
        """Robots whose goal cannot be reached from their start."""
        return np.flatnonzero(self.lower_bounds() >= UNREACHABLE).tolist()

    # -- LaCAM ---------------------------------------------------------------------------------
    def solve(self, deadline: float) -> list[Config]:
        """Configurations from the starts to the goals, one per step."""
        return [tuple(c) for c in self.solve_array(deadline).tolist()]

    def solve_array(self, deadline: float) -> np.ndarray:
        """The plan as an array (steps + 1, robots) of cells."""
        goals = self.goals
        goal_key = goals.tobytes()
        prio0 = self.lower_bounds() / max(1, self.graph.n)
        root = _Node(self.starts.copy(), None, np.argsort(-prio0, kind="stable").astype(np.int32), prio0)
        open_: list[_Node] = [root]
        explored: dict[bytes, _Node] = {root.config.tobytes(): root}
        neighbours = self.graph.neighbours
        while open_:
            if time.perf_counter() > deadline:
                raise SearchFailed(f"search budget exhausted after {self.expanded} configurations")
            node = open_[-1]
            if node.config.tobytes() == goal_key:
                out = []
                cur: _Node | None = node
                while cur is not None:
                    out.append(cur.config)
                    cur = cur.parent
                return np.asarray(out[::-1], dtype=np.int32).reshape(len(out), self.n)
            if not node.tree:
                open_.pop()
                continue
            c = node.tree.popleft()
            depth = len(c.who)
            if depth < self.n:   # grow the constraint tree by the next robot in the node's order
                i = int(node.order[depth])
                v0 = int(node.config[i])
                cands = neighbours[v0] + [v0]
                self.rng.shuffle(cands)
                for v in cands:
                    node.tree.append(_Constraint(c.who + (i,), c.where + (v,)))
            new = self._successor(node, c)
            if new is None:
                continue
            self.expanded += 1
            key = new.tobytes()
            known = explored.get(key)
            if known is not None:
                open_.append(known)
                continue
            prio = np.where(new != goals, node.priority + 1.0, node.priority - np.floor(node.priority))
            child = _Node(new, node, np.argsort(-prio, kind="stable").astype(np.int32), prio)
            explored[key] = child
            open_.append(child)
        raise SearchFailed("no plan exists under the disc transition rules (every configuration reachable "
                           "from the starts was explored)")

    def _successor(self, node: _Node, c: _Constraint) -> np.ndarray | None:
        g = self.graph
        tie = self.np_rng.random(g.n)   # fresh tie-breaking per step
        ok = kern.successor(node.config, node.order, np.asarray(c.who, dtype=np.int32),
                            np.asarray(c.where, dtype=np.int32), self.fields, self.grow, self.goals, g.nb, g.deg,
                            tie, self.occ_now, self.occ_next, self.q_to)
        return self.q_to.copy() if ok else None


def _valid_step(q_from: Sequence[int], q_to: Sequence[int], occ_now: Sequence[int]) -> bool:
    """The transition rules of the module docstring, checked on a whole step."""
    return bool(kern.valid_step(np.asarray(q_from, dtype=np.int32), np.asarray(q_to, dtype=np.int32),
                                np.asarray(occ_now, dtype=np.int32)))


def moves_of(configs: Sequence[Config]) -> np.ndarray:
    """The configurations as an array (steps + 1, robots)."""
    return np.asarray(configs, dtype=np.int64).reshape(len(configs), -1)


def remove_loops(configs: np.ndarray) -> np.ndarray:
    """The plan with detours cut: where a robot leaves a cell and comes back to it later while no
    other robot enters that cell in between, it waits there instead (PIBT wanders when it gives
    way). Cutting a detour only removes moves and occupancies of that robot, and the cell it waits
    on is nobody else's meanwhile, so every step stays valid under the transition rules."""
    out = np.ascontiguousarray(configs, dtype=np.int64).copy()
    if out.size == 0:
        return out
    return kern.remove_loops_inplace(out, int(out.max()) + 1)
