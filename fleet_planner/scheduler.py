"""The (M,D) network of You & Ji, "Design of a Multi-robot Bin Packing System in an Automatic
Warehouse", and its priority-ordered delay planner (Section 4, Eq. 3); the network itself
(:class:`~fleet_planner.model.Network`) is vocabulary: docs/ARCHITECTURE.md, "The (M,D) vocabulary".

Notation (paper Table 1), for a link from a higher-priority robot ``i`` to a lower one ``j`` in
collision region ``k``: T1 / T4 = when i enters / leaves the region (reaches / leaves the part
[ls, le] of j's path), T2 / T3 = when j enters / leaves it. M = T3 - T1, D = T4 - T2; the pair
collides there iff M > 0 and D > 0. Delaying j's departure by d gives M' = M + d, D' = D - d.

Parked robots are part of the trajectories: a robot sits on its start from t = 0 until it
departs and on its goal for ever after it arrives. So a region that touches i's goal has T4 = inf,
one that touches j's start has T2 = 0 whatever j's delay, and one that touches j's goal has T3 = inf.
A dangerous link of the first two kinds cannot be fixed by delaying j: the scheduler reports it
(:class:`Blocked`) and the planner re-orders the two robots (docs/ARCHITECTURE.md, measured fact 2).

The planner (Eq. 3): take robots in priority order; while any inlet link of robot j is dangerous,
delay j by the largest D over its dangerous inlet links.

Beyond the paper (``mode="exact"``, measured facts 4-5): a collision box makes a whole shared
stretch exclusive, so a robot can never follow another down an aisle. The exact mode uses the collision
region itself: for each convex piece of a region, the set of delays of j at which j's trajectory
meets it is an open interval (the range of t_i(a) - t_j(b) over the piece, shifted by i's delay),
and parked phases add half-lines. j gets the smallest delay outside the union of those intervals:
never larger than the box answer, and exact for constant-speed robots.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from . import collision as C
from .collision import CollisionModel
from .model import COLLISION_TESTS, EPS, Link, Network

INF = math.inf


@dataclass
class Blocked:
    """Robot ``j`` cannot be made safe by delaying it: ``blocker`` (higher) parks in or passes its way
    while ``j`` is parked (``why`` says which)."""

    j: int
    blocker: int
    why: str
    kind: str = "goal"   # "goal": blocker parks in j's way; "start": blocker passes j's start too early


class DelayScheduler:
    """Departure delays for robots on fixed paths, in a given priority order (Eq. 3).

    ``model`` holds the collision regions and how each robot drives its path (its times).
    ``schedule(order, start_at)`` keeps the delays of ``order[:start_at]`` (they do not depend on
    lower robots) and recomputes the rest, so a re-ordering recomputes only what changed.
    """

    def __init__(self, model: CollisionModel, mode: str = "box"):
        if mode not in COLLISION_TESTS:
            raise ValueError(f"mode: must be one of {', '.join(COLLISION_TESTS)} (got {mode!r})")
        self.model = model
        self.delays = np.zeros(len(model.paths))
        self.mode = mode
        self._done: set[int] = set()   # robots whose delay is up to date

    def travel(self, x: int) -> float:
        return float(self.model.travel[x])

    def _inlet(self, j: int, rank: dict[int, int]):
        """Arrays describing the inlet links of j: (i, T1, T4, b_lo, b_hi, pinned_start, to_goal)."""
        rows = []
        for i in self.model.neighbours(j):
            if rank.get(i, INF) >= rank[j]:
                continue
            di, Li = self.delays[i], self.model.lengths[i]
            Lj = self.model.lengths[j]
            for reg in self.model.regions(i, j):
                a_lo, a_hi, b_lo, b_hi = reg.oriented(i)
                t1 = 0.0 if a_lo <= EPS else di + float(self.model.tau(i, a_lo))
                t4 = INF if a_hi >= Li - EPS else di + float(self.model.tau(i, a_hi))
                rows.append((i, t1, t4, b_lo, b_hi, b_lo <= EPS, b_hi >= Lj - EPS))
        return rows

    def _times(self, j: int, b_lo, b_hi, pinned, to_goal, d: float):
        t2 = np.where(pinned, 0.0, d + self.model.tau(j, b_lo))
        t3 = np.where(to_goal, INF, d + self.model.tau(j, b_hi))
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
                    return Blocked(j, who[n], why, "goal" if np.isinf(t4[n]) else "start")
                d += float(D[danger].max())
        self.delays[j] = d
        return None

    def _schedule_exact(self, j: int, rank: dict[int, int]) -> Blocked | None:
        """Smallest delay of j outside every forbidden interval of its higher-priority neighbours."""
        higher = [i for i in self.model.neighbours(j) if rank.get(i, INF) < rank[j]]
        if not higher:
            self.delays[j] = 0.0
            return None
        tables = [self.model.pieces(i, j) for i in higher]
        P = np.vstack(tables)
        who = np.repeat(higher, [len(t) for t in tables])
        di, Li, Ti = self.delays[who], self.model.lengths[who], self.model.travel[who]
        Tj = self.model.travel[j]
        sw = who > j   # the piece table lists the smaller index first: is i the table's y?

        def col(x_col: int, y_col: int) -> np.ndarray:
            return np.where(sw, P[:, y_col], P[:, x_col])

        phi_lo = np.where(sw, di - P[:, C.P_PHI_HI], di + P[:, C.P_PHI_LO])
        phi_hi = np.where(sw, di - P[:, C.P_PHI_LO], di + P[:, C.P_PHI_HI])
        i_first, i_last = col(C.P_X_FIRST, C.P_Y_FIRST) > 0, col(C.P_X_LAST, C.P_Y_LAST) > 0
        j_first, j_last = col(C.P_Y_FIRST, C.P_X_FIRST) > 0, col(C.P_Y_LAST, C.P_X_LAST) > 0
        is_lo, is_hi = col(C.P_XS_LO, C.P_YS_LO), col(C.P_XS_HI, C.P_YS_HI)   # j's range, i at a segment start
        ie_lo, ie_hi = col(C.P_XE_LO, C.P_YE_LO), col(C.P_XE_HI, C.P_YE_HI)   # j's range, i at a segment end
        js_lo, js_hi = col(C.P_YS_LO, C.P_XS_LO), col(C.P_YS_HI, C.P_XS_HI)   # i's range, j at a segment start
        je_hi = col(C.P_YE_HI, C.P_XE_HI)                                     # i's range, j at a segment end
        je_lo = col(C.P_YE_LO, C.P_XE_LO)
        # undelayed time at a travelled length on the piece's segment of i, of j
        i_off, i_t0, i_v = col(C.P_X_OFF, C.P_Y_OFF), col(C.P_X_T0, C.P_Y_T0), col(C.P_X_V, C.P_Y_V)
        j_off, j_t0, j_v = col(C.P_Y_OFF, C.P_X_OFF), col(C.P_Y_T0, C.P_X_T0), col(C.P_Y_V, C.P_X_V)
        with np.errstate(invalid="ignore"):
            tau_i = lambda s: i_t0 + (s - i_off) / i_v  # noqa: E731
            tau_j = lambda s: j_t0 + (s - j_off) / j_v  # noqa: E731
            t_i_first = np.where(js_lo <= EPS, 0.0, di + tau_i(js_lo))        # i there from t = 0 if at its start
            t_i_last = np.where(je_hi >= Li - EPS, INF, di + tau_i(je_hi))    # ... for ever if at its goal
            cand = [  # (mask, lo, hi, kind): open intervals of forbidden delays of j
                (np.isfinite(phi_lo), phi_lo, phi_hi, "move"),                             # both moving
                (i_first & (is_lo <= is_hi), -tau_j(is_hi), di - tau_j(is_lo), "move"),      # i parked at start
                (i_last & (ie_lo <= ie_hi), di + Ti - tau_j(ie_hi), INF, "goal"),            # i parked at goal
                (j_first & (js_lo <= js_hi), t_i_first, INF, "start"),                       # j parked at start
                (j_last & (je_lo <= je_hi), -INF, t_i_last - Tj, "move"),                    # j parked at goal
            ]
        lo = np.concatenate([np.broadcast_to(c[1], len(P))[c[0]] for c in cand])
        hi = np.concatenate([np.broadcast_to(c[2], len(P))[c[0]] for c in cand])
        src = np.concatenate([np.nonzero(c[0])[0] for c in cand])
        kind = np.concatenate([np.full(int(c[0].sum()), k) for k, c in enumerate(cand)])
        if len(lo) == 0:
            self.delays[j] = 0.0
            return None
        order = np.argsort(lo, kind="stable")
        reach = np.maximum(np.maximum.accumulate(hi[order]), 0.0)
        before = np.concatenate([[0.0], reach[:-1]])
        gap = np.nonzero(lo[order] >= before)[0]   # first interval starting at or after the reach
        d = float(before[gap[0]]) if len(gap) else float(reach[-1])
        if math.isinf(d):
            # the culprit: of the unbounded intervals, the one the sweep reached first
            unbounded = np.nonzero(np.isinf(hi))[0]
            n = int(unbounded[np.argmin(lo[unbounded])])
            start = int(kind[n]) == 3
            why = "drives through its start disc before it can leave" if start else "parks on its goal in the way"
            self.delays[j] = 0.0
            return Blocked(j, int(who[src[n]]), why, "start" if start else "goal")
        self.delays[j] = d
        return None

    def schedule(self, order: Sequence[int], start_at: int = 0, dirty: set[int] | None = None) -> Blocked | None:
        """Schedule ``order[start_at:]``, highest first. With ``dirty`` (robots whose paths or rank
        changed since the last call, plus their neighbours), a robot is recomputed only if it is
        dirty, was not scheduled last time, or a higher neighbour's delay changed: a re-ordering
        then costs what it changes, not the whole fleet."""
        rank = {x: n for n, x in enumerate(order)}
        changed: set[int] = set()
        for n in range(start_at, len(order)):
            x = order[n]
            if (dirty is None or x in dirty or x not in self._done
                    or any(h in changed for h in self.model.neighbours(x) if rank[h] < n)):
                before = self.delays[x]
                blocked = self.schedule_robot(x, rank)
                if blocked:
                    self._done.discard(x)
                    self._done.difference_update(order[n + 1:])
                    return blocked
                self._done.add(x)
                if self.delays[x] != before:
                    changed.add(x)
        return None

    def network(self, order: Sequence[int], ids: Sequence[str]) -> Network:
        """The network under the current delays (links listed by lower robot, then k)."""
        rank = {x: n for n, x in enumerate(order)}
        net = Network([ids[x] for x in order], {ids[x]: float(self.delays[x]) for x in order},
                      {ids[x]: self.travel(x) for x in order}, mode=self.mode)
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
