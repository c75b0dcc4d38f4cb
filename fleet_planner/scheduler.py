"""The (M,D) network of paper 001 and its priority-ordered delay planner (Section 4, Eq. 3).

Notation (paper Table 1), for a link from a higher-priority robot ``i`` to a lower one ``j`` in
collision region ``k``: T1 / T4 = when i enters / leaves the region (reaches / leaves the part
[ls, le] of j's path), T2 / T3 = when j enters / leaves it. M = T3 - T1, D = T4 - T2; the pair
collides there iff M > 0 and D > 0. Delaying j's departure by d gives M' = M + d, D' = D - d.

Parked robots are part of the trajectories: a robot sits on its start from t = 0 until it
departs and on its goal for ever after it arrives. So a region that touches i's goal has T4 = inf,
one that touches j's start has T2 = 0 whatever j's delay, and one that touches j's goal has T3 = inf.
A dangerous link of the first two kinds cannot be fixed by delaying j: the scheduler reports it
(:class:`Blocked`) and the planner re-orders the two robots (FINDINGS 2).

The planner (Eq. 3): take robots in priority order; while any inlet link of robot j is dangerous,
delay j by the largest D over its dangerous inlet links.

Beyond the paper (``mode="exact"``, FINDINGS 4-5): a collision box makes a whole shared stretch
exclusive, so a robot can never follow another down an aisle. The exact mode uses the collision
region itself: for each convex piece of a region, the set of delays of j at which j's trajectory
meets it is an open interval (the range of t_i(a) - t_j(b) over the piece, shifted by i's delay),
and parked phases add half-lines. j gets the smallest delay outside the union of those intervals:
never larger than the box answer, and exact for constant-speed robots.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from . import collision as C
from .collision import EPS, CollisionModel

INF = math.inf
MODES = ("box", "exact")


@dataclass
class Link:
    """A link (i -> j, k) of the network with its collision box and (M, D) under the final delays.

    ``paper_tuple`` is the paper's (lower, higher, k) notation, e.g. (3, 1, 2)."""

    i: str          # higher priority
    j: str          # lower priority
    k: int          # 1-based index of the region along j's path
    M: float
    D: float
    ks: float       # T1: i enters the region (absolute time)
    ke: float       # T4: i leaves it (inf if i parks in it)
    ls: float       # smallest travelled length of j inside the region
    le: float       # largest

    @property
    def paper_tuple(self) -> tuple[str, str, int]:
        return (self.j, self.i, self.k)

    @property
    def dangerous(self) -> bool:
        return self.M > EPS and self.D > EPS

    def to_dict(self) -> dict[str, Any]:
        return {"i": self.i, "j": self.j, "k": self.k, "M": _num(self.M), "D": _num(self.D),
                "ks": _num(self.ks), "ke": _num(self.ke), "ls": self.ls, "le": self.le}


@dataclass
class Network:
    """The paper's (V, E, C, T, P) as plain data: nodes with (T_delayed, T_traveled), links with
    (M, D) and boxes, and the priority order."""

    priority: list[str]
    delay: dict[str, float]
    travel: dict[str, float]
    links: list[Link] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"priority": list(self.priority),
                "nodes": {r: {"delay": self.delay[r], "travel": self.travel[r]} for r in self.priority},
                "links": [link.to_dict() for link in self.links]}


@dataclass
class Blocked:
    """Robot ``j`` cannot be made safe by delaying it: ``blocker`` (higher) parks in or passes its way
    while ``j`` is parked (``why`` says which)."""

    j: int
    blocker: int
    why: str


def _num(x: float) -> float | None:
    """JSON has no infinity: an unbounded time is written as null."""
    return None if math.isinf(x) else float(x)


class DelayScheduler:
    """Departure delays for robots on fixed paths, in a given priority order (Eq. 3).

    ``speeds`` are constant speeds along the paths; ``model`` holds the collision regions.
    ``schedule(order, start_at)`` keeps the delays of ``order[:start_at]`` (they do not depend on
    lower robots) and recomputes the rest, so a re-ordering recomputes only what changed.
    """

    def __init__(self, model: CollisionModel, speeds: Sequence[float], mode: str = "box"):
        if mode not in MODES:
            raise ValueError(f"mode: must be one of {', '.join(MODES)} (got {mode!r})")
        self.model = model
        self.speeds = np.asarray(speeds, dtype=float)
        self.delays = np.zeros(len(speeds))
        self.mode = mode

    def travel(self, x: int) -> float:
        return float(self.model.lengths[x] / self.speeds[x])

    def _inlet(self, j: int, rank: dict[int, int]):
        """Arrays describing the inlet links of j: (i, T1, T4, b_lo, b_hi, pinned_start, to_goal)."""
        rows = []
        for i in self.model.neighbours(j):
            if rank.get(i, INF) >= rank[j]:
                continue
            vi, di, Li = self.speeds[i], self.delays[i], self.model.lengths[i]
            Lj = self.model.lengths[j]
            for reg in self.model.regions(i, j):
                a_lo, a_hi, b_lo, b_hi = reg.oriented(i)
                t1 = 0.0 if a_lo <= EPS else di + a_lo / vi
                t4 = INF if a_hi >= Li - EPS else di + a_hi / vi
                rows.append((i, t1, t4, b_lo, b_hi, b_lo <= EPS, b_hi >= Lj - EPS))
        return rows

    def _times(self, j: int, b_lo, b_hi, pinned, to_goal, d: float):
        v = self.speeds[j]
        t2 = np.where(pinned, 0.0, d + b_lo / v)
        t3 = np.where(to_goal, INF, d + b_hi / v)
        return t2, t3

    def schedule_robot(self, j: int, rank: dict[int, int]) -> Blocked | None:
        """Eq. 3 for one robot: delay it until no inlet link is dangerous."""
        if self.mode == "exact":
            return self._schedule_exact(j, rank)
        rows = self._inlet(j, rank)
        d = 0.0
        if rows:
            arr = np.array([r[1:5] for r in rows], dtype=float)
            who = [r[0] for r in rows]
            t1, t4, b_lo, b_hi = arr.T
            pinned = np.array([r[5] for r in rows])
            to_goal = np.array([r[6] for r in rows])
            while True:
                t2, t3 = self._times(j, b_lo, b_hi, pinned, to_goal, d)
                with np.errstate(invalid="ignore"):
                    M, D = t3 - t1, t4 - t2
                danger = (M > EPS) & (D > EPS)
                if not danger.any():
                    break
                stuck = danger & (pinned | np.isinf(t4))
                if stuck.any():
                    n = int(np.argmax(stuck))
                    why = ("parks on its goal in the way" if np.isinf(t4[n])
                           else "drives through its start disc before it can leave")
                    self.delays[j] = d
                    return Blocked(j, who[n], why)
                d += float(D[danger].max())
        self.delays[j] = d
        return None

    def _schedule_exact(self, j: int, rank: dict[int, int]) -> Blocked | None:
        """Smallest delay of j outside every forbidden interval of its higher-priority neighbours."""
        lo_parts, hi_parts, who_parts, kind_parts = [], [], [], []
        vj, Lj = self.speeds[j], self.model.lengths[j]
        for i in self.model.neighbours(j):
            if rank.get(i, INF) >= rank[j]:
                continue
            P = self.model.pieces(i, j)
            di, vi, Li = self.delays[i], self.speeds[i], self.model.lengths[i]
            if i < j:   # i is the table's x
                phi_lo, phi_hi = di + P[:, C.P_PHI_LO], di + P[:, C.P_PHI_HI]
                i_first, i_start = P[:, C.P_X_FIRST] > 0, P[:, [C.P_XS_LO, C.P_XS_HI]]
                i_last, i_end = P[:, C.P_X_LAST] > 0, P[:, [C.P_XE_LO, C.P_XE_HI]]
                j_first, j_start = P[:, C.P_Y_FIRST] > 0, P[:, [C.P_YS_LO, C.P_YS_HI]]
                j_last, j_end = P[:, C.P_Y_LAST] > 0, P[:, [C.P_YE_LO, C.P_YE_HI]]
            else:
                phi_lo, phi_hi = di - P[:, C.P_PHI_HI], di - P[:, C.P_PHI_LO]
                i_first, i_start = P[:, C.P_Y_FIRST] > 0, P[:, [C.P_YS_LO, C.P_YS_HI]]
                i_last, i_end = P[:, C.P_Y_LAST] > 0, P[:, [C.P_YE_LO, C.P_YE_HI]]
                j_first, j_start = P[:, C.P_X_FIRST] > 0, P[:, [C.P_XS_LO, C.P_XS_HI]]
                j_last, j_end = P[:, C.P_X_LAST] > 0, P[:, [C.P_XE_LO, C.P_XE_HI]]
            t_i_first = np.where(j_start[:, 0] <= EPS, 0.0, di + j_start[:, 0] / vi)
            t_i_last = np.where(j_end[:, 1] >= Li - EPS, INF, di + j_end[:, 1] / vi)
            with np.errstate(invalid="ignore"):
                cand = [  # (mask, lo, hi, kind) - kind names the reason if it ends up blocking j
                    (np.isfinite(phi_lo), phi_lo, phi_hi, "move"),
                    (i_first & (i_start[:, 0] <= i_start[:, 1]), -i_start[:, 1] / vj, di - i_start[:, 0] / vj, "move"),
                    (i_last & (i_end[:, 0] <= i_end[:, 1]), di + Li / vi - i_end[:, 1] / vj, np.full(len(P), INF), "goal"),
                    (j_first & (j_start[:, 0] <= j_start[:, 1]), t_i_first, np.full(len(P), INF), "start"),
                    (j_last & (j_end[:, 0] <= j_end[:, 1]), np.full(len(P), -INF), t_i_last - Lj / vj, "move"),
                ]
            for mask, lo, hi, kind in cand:
                if mask.any():
                    lo_parts.append(lo[mask])
                    hi_parts.append(hi[mask])
                    who_parts.append(np.full(int(mask.sum()), i))
                    kind_parts.append(np.full(int(mask.sum()), kind))
        if not lo_parts:
            self.delays[j] = 0.0
            return None
        lo, hi = np.concatenate(lo_parts), np.concatenate(hi_parts)
        order = np.argsort(lo, kind="stable")
        lo, hi = lo[order], hi[order]
        reach = np.maximum(np.maximum.accumulate(hi), 0.0)
        before = np.concatenate([[0.0], reach[:-1]])
        gap = np.nonzero(lo >= before)[0]      # first interval that starts at or after the reach
        d = float(before[gap[0]]) if len(gap) else float(reach[-1])
        if math.isinf(d):
            # the culprit: of the unbounded intervals, the one the sweep reached first
            lo_all, hi_all = np.concatenate(lo_parts), np.concatenate(hi_parts)
            unbounded = np.nonzero(np.isinf(hi_all))[0]
            n = int(unbounded[np.argmin(lo_all[unbounded])])
            kind = np.concatenate(kind_parts)[n]
            why = {"goal": "parks on its goal in the way",
                   "start": "drives through its start disc before it can leave"}.get(kind, "is in the way")
            self.delays[j] = 0.0
            return Blocked(j, int(np.concatenate(who_parts)[n]), why)
        self.delays[j] = d
        return None

    def schedule(self, order: Sequence[int], start_at: int = 0) -> Blocked | None:
        rank = {x: n for n, x in enumerate(order)}
        for n in range(start_at, len(order)):
            blocked = self.schedule_robot(order[n], rank)
            if blocked:
                return blocked
        return None

    def network(self, order: Sequence[int], ids: Sequence[str]) -> Network:
        """The network under the current delays (links listed by lower robot, then k)."""
        rank = {x: n for n, x in enumerate(order)}
        net = Network([ids[x] for x in order], {ids[x]: float(self.delays[x]) for x in order},
                      {ids[x]: self.travel(x) for x in order})
        for j in order:
            rows = self._inlet(j, rank)
            rows.sort(key=lambda r: (r[3], r[0]))
            per_pair: dict[int, int] = {}
            for i, t1, t4, b_lo, b_hi, pinned, to_goal in rows:
                t2, t3 = self._times(j, np.array([b_lo]), np.array([b_hi]), np.array([pinned]),
                                     np.array([to_goal]), self.delays[j])
                per_pair[i] = per_pair.get(i, 0) + 1
                with np.errstate(invalid="ignore"):
                    M, D = float(t3[0] - t1), float(t4 - t2[0])
                net.links.append(Link(ids[i], ids[j], per_pair[i], M, D, t1, t4, b_lo, b_hi))
        return net
