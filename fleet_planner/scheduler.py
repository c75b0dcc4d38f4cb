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

Holds anywhere (``holds="anywhere"``, exact regions only; issue 8): instead of one delay at the
start, j may wait at any vertex of its path (robots in ``start_only``, those with acceleration
ramps, only at the start). Each trajectory is moves along segments at the drive profile's speed
and holds at vertices (parked on the start until departure, on the goal for ever after). From the
same exact pieces, the higher robots' trajectories *as timed, holds included* give per segment of
j an open interval of forbidden entry times for every part within reach (moving: the piece's phi
range shifted by i's entry time; i holding: the zero-speed piece, j's range near i's point) and
per vertex of j open intervals in which j must not stand there (i's segment passing within reach,
or i holding within reach). j's timing is then the earliest arrival over (vertex, safe interval)
pairs, as in safe-interval path planning (Phillips & Likhachev, "SIPP: Safe Interval Path Planning
for Dynamic Environments"), along the fixed path; the earliest arrival per safe interval dominates
because waiting inside it is free. Every pair of parts is covered and each test is exact, so the
timing is safe against every higher robot; lower robots see j's holds. The network is computed
from the final times (T1, T2 when a robot first reaches a region, T3, T4 when it last leaves it).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from . import _md_kernels as K
from . import collision as C
from .collision import CollisionModel
from .model import COLLISION_TESTS, EPS, Link, Network

INF = math.inf
#: where a robot may wait on its fixed path: only before it departs (the paper's departure delays)
#: or at any vertex of its path (docs/ARCHITECTURE.md, "The (M,D) vocabulary of paper 001")
HOLDS = ("none", "anywhere")


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

    def __init__(self, model: CollisionModel, mode: str = "box", holds: str = "none",
                 start_only: Iterable[int] = (), early_holds: bool = False):
        if mode not in COLLISION_TESTS:
            raise ValueError(f"mode: must be one of {', '.join(COLLISION_TESTS)} (got {mode!r})")
        if holds not in HOLDS:
            raise ValueError(f"holds: must be one of {', '.join(HOLDS)} (got {holds!r})")
        if holds == "anywhere" and mode != "exact":
            raise ValueError(f"holds: 'anywhere' needs the exact collision regions (mode='exact', got {mode!r})")
        if holds == "anywhere":
            K.warm_up()   # the compiled hold search (numba's cache): not part of any planning budget
        self.model = model
        self.delays = np.zeros(len(model.paths))
        self.mode = mode
        self.holds = holds
        #: robots that may hold only before they depart (their drive profile has speed ramps: a
        #: stop en route would need a braking and an accelerating ramp the profile does not have)
        self.start_only = set(start_only)
        #: with holds: move each robot's waits back along its path as far as its arrival allows
        #: (to where it already stands, its start if it can; :func:`_holds_early`)
        self.early_holds = bool(early_holds)
        #: with holds: per robot, when it reaches (``arr``) and leaves (``dep``) each vertex of its
        #: driven path; arr[0] = 0 (it is there from the start), dep[-1] = inf (it parks on its goal)
        self.arr: list[np.ndarray] = []
        self.dep: list[np.ndarray] = []
        for x in range(len(model.paths)):
            self.set_timing(x, 0.0)
        self._done: set[int] = set()   # robots whose delay is up to date
        #: called after robot x is scheduled (holds); True if it changed x's path (route choice)
        self.after: Callable[[int], bool] | None = None

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
        if self.holds == "anywhere":
            return self._schedule_holds(j, rank)
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
                    or (changed and any(h in changed for h in self.model.neighbours(x) if rank[h] < n))):
                before = self.delays[x]
                before_dep = self.dep[x].copy() if self.holds == "anywhere" else None
                blocked = self.schedule_robot(x, rank)
                if blocked:
                    self._done.discard(x)
                    self._done.difference_update(order[n + 1:])
                    return blocked
                self._done.add(x)
                if self.after is not None and self.after(x):
                    changed.add(x)
                elif self.delays[x] != before or (before_dep is not None and (
                        len(before_dep) != len(self.dep[x]) or not np.array_equal(before_dep, self.dep[x]))):
                    changed.add(x)
        return None

    def checkpoint(self) -> tuple:
        """The scheduler's state (delays, vertex times, who is up to date), for :meth:`rollback`."""
        return self.delays.copy(), list(self.arr), list(self.dep), set(self._done)

    def rollback(self, state: tuple) -> None:
        delays, arr, dep, done = state
        self.delays, self.arr, self.dep, self._done = delays.copy(), list(arr), list(dep), set(done)

    def network(self, order: Sequence[int], ids: Sequence[str]) -> Network:
        """The network under the current delays (links listed by lower robot, then k)."""
        if self.holds == "anywhere":
            return self._network_holds(order, ids)
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

    # -- holds anywhere along the path ----------------------------------------------------------
    def set_timing(self, x: int, departure: float, arr: np.ndarray | None = None,
                   dep: np.ndarray | None = None) -> None:
        """Robot x's vertex times: given (``arr``, ``dep``, from t = 0), or no hold but the
        departure delay ``departure``."""
        if arr is None or dep is None:
            times = np.asarray(self.model.times[x], dtype=float)
            arr, dep = departure + times, departure + times
            arr[0] = 0.0
            dep[-1] = INF
        arr, dep = np.asarray(arr, dtype=float), np.asarray(dep, dtype=float)
        if x < len(self.arr):
            self.arr[x], self.dep[x] = arr, dep
        else:
            self.arr.append(arr)
            self.dep.append(dep)
        self.delays[x] = float(self.dep[x][0]) if len(self.dep[x]) > 1 else 0.0

    def hold_constraints(self, j: int, higher: list[int]):
        """What the higher robots' timed trajectories forbid robot j on its path, from the exact
        pieces of the collision regions (one per pair of segments): ``G`` rows (segment of j, lo,
        hi, owner): j must not enter that segment at a time in the open interval (lo, hi); ``F``
        rows (vertex of j, lo, hi, owner): j must not stand on that vertex during (lo, hi).

        Every trajectory is a sequence of moves along segments at the drive profile's speed and
        holds at vertices (parked at the start before departure, on the goal for ever after). For
        each pair of parts within reach: j moving / i moving is the piece's range of
        t_i(a) - t_j(b) shifted by i's entry time (what the departure-only test uses); j moving /
        i holding at a segment end is j's range near that point (a zero-speed piece); j standing /
        i moving is the window in which i's segment passes within reach of j's vertex; j standing
        / i holding is i's hold interval when the two points are within reach."""
        tables = self.model.pieces_with(j, higher)   # the smaller robot index in the x columns
        sizes = np.fromiter(map(len, tables), dtype=np.int64, count=len(tables))
        P = np.concatenate(tables, axis=0)   # (all (n, 28): no atleast_2d per table, as vstack does)
        higher_a = np.asarray(higher, dtype=np.int64)
        who = np.repeat(higher_a, sizes)
        swapped = np.repeat(higher_a > j, sizes)   # rows with j in the x columns: read swapped
        # each row's segment ends as timed: i's vertex times of all higher robots in one array
        arrs = [self.arr[i] for i in higher]
        lens = np.fromiter(map(len, arrs), dtype=np.int64, count=len(arrs))
        first = np.repeat(np.cumsum(lens) - lens, sizes)
        last = np.repeat(lens - 1, sizes)
        arr_all = np.concatenate(arrs)
        dep_all = np.concatenate([self.dep[i] for i in higher])
        # the candidates of each kind for every row, compiled (fleet_planner._md_kernels): j moving
        # / i moving (the piece's range of t_i(a) - t_j(b) shifted by i's entry time), j moving / i
        # holding at its segment's start or end, then j standing at its segment's start or end / i
        # moving, holding at its segment's start, or at its end
        g_key, g_lo, g_hi, g_own, f_key, f_lo, f_hi, f_own = K.hold_constraints(
            P, _HOLD_COLUMNS, _HOLD_COLUMNS_SWAPPED, swapped, who, first, last, arr_all, dep_all, self.model.cumlen[j])
        G = g_key, g_lo, g_hi, g_own
        F = f_key, f_lo, f_hi, f_own
        return G, F

    def _schedule_holds(self, j: int, rank: dict[int, int]) -> Blocked | None:
        """Earliest arrival of j along its fixed path with waits at its vertices (safe-interval
        search over (vertex, safe interval), as in SIPP, against the higher robots' trajectories as
        timed, holds included); robots in ``start_only`` wait only before they depart."""
        m = self.model
        mine = rank[j]
        higher = [i for i in m.neighbours(j) if rank.get(i, INF) < mine]
        if not higher:
            self.set_timing(j, 0.0)
            return None
        (g_key, g_lo, g_hi, g_own), (f_key, f_lo, f_hi, f_own) = self.hold_constraints(j, higher)
        nv = len(m.paths[j])
        if nv == 1:   # j never moves: nobody may come near it, ever
            self.set_timing(j, 0.0)
            if len(f_lo) == 0:
                return None
            n = int(np.argmax(np.isinf(f_hi))) if np.isinf(f_hi).any() else int(np.argmin(f_lo))
            return self._blocked(j, int(f_own[n]), goal=bool(np.isinf(f_hi[n])))
        T0 = np.asarray(m.times[j], dtype=float)
        hold_at = np.array([0, nv - 1]) if j in self.start_only else np.arange(nv)
        nh = len(hold_at)
        h_key, h_lo, h_hi = f_key, f_lo, f_hi   # the hold vertices' rows (macro vertex numbers)
        if nh == nv:
            g_edge = g_key
        else:
            g_edge = np.searchsorted(hold_at, g_key, side="right") - 1   # macro edge of each segment
            g_lo = g_lo - (T0[g_key] - T0[hold_at[g_edge]])              # as times of leaving its hold vertex
            g_hi = g_hi - (T0[g_key] - T0[hold_at[g_edge]])
            is_hold = np.zeros(nv, dtype=bool)
            is_hold[hold_at] = True
            keep = is_hold[f_key]
            vert_of = np.full(nv, -1)
            vert_of[hold_at] = np.arange(nh)
            h_key, h_lo, h_hi = vert_of[f_key[keep]], f_lo[keep], f_hi[keep]
        # the compiled search (fleet_planner._md_kernels) on each vertex's and edge's intervals by lo
        f_ptr, f_slo, f_shi = _grouped(h_key, h_lo, h_hi, nh)
        g_ptr, g_slo, g_shi = _grouped(g_edge, g_lo, g_hi, nh - 1)
        durations = np.diff(T0[hold_at])
        s_ptr, s_lo, s_hi = K.safe_intervals(f_ptr, f_slo, f_shi, False)
        ok, arrive, leave = K.earliest(s_ptr, s_lo, s_hi, g_ptr, g_slo, g_shi, durations, self.early_holds)
        if not ok:
            r_ptr, r_lo, r_hi = K.safe_intervals(f_ptr, f_slo, f_shi, True)
            relaxed = K.earliest(r_ptr, r_lo, r_hi, g_ptr, g_slo, g_shi, durations, False)[0]
            self.set_timing(j, 0.0)
            if relaxed:   # waiting at its start would do, but a higher robot comes by first
                first = s_hi[0] if s_ptr[1] > 0 and s_lo[0] <= 0 else 0.0
                at0 = f_key == 0
                cand = np.nonzero(at0 & (f_hi > first))[0]
                n = int(cand[np.argmin(f_lo[cand])]) if len(cand) else int(np.argmin(np.where(at0, f_lo, INF)))
                return self._blocked(j, int(f_own[n]), goal=False)
            lo_all = np.concatenate([g_lo, f_lo])
            hi_all = np.concatenate([g_hi, f_hi])
            own_all = np.concatenate([g_own, f_own])
            unbounded = np.nonzero(np.isinf(hi_all))[0]
            n = int(unbounded[np.argmin(lo_all[unbounded])]) if len(unbounded) else int(np.argmax(hi_all))
            return self._blocked(j, int(own_all[n]), goal=True)
        if nh == nv:
            arr, dep = arrive, leave
        else:   # between hold vertices it drives on at the profile's times
            macro = np.searchsorted(hold_at, np.arange(nv), side="right") - 1
            arr = leave[macro] + T0 - T0[hold_at[macro]]
            dep = arr.copy()
            arr[hold_at], dep[hold_at] = arrive, leave
        arr[0], arr[-1], dep[-1] = 0.0, arrive[-1], INF
        self.set_timing(j, 0.0, arr, dep)
        return None

    def _blocked(self, j: int, blocker: int, goal: bool) -> Blocked:
        if goal:
            return Blocked(j, blocker, "parks on its goal in the way", "goal")
        return Blocked(j, blocker, "drives through its start disc before it can leave", "start")

    def _times_at(self, x: int, s: np.ndarray, last) -> np.ndarray:
        """When robot x (as timed) first reaches / last leaves (``last``: one flag, or one per
        length) each travelled length in ``s``."""
        cum = self.model.cumlen[x]
        k = np.searchsorted(cum, s, side="left")
        kc = np.minimum(k, len(cum) - 1)
        at_vertex = (k < len(cum)) & (np.abs(cum[kc] - s) <= EPS)
        seg = np.maximum(k - 1, 0)
        with np.errstate(invalid="ignore"):
            t = self.dep[x][seg] + self.model.tau(x, s) - self.model.times[x][seg]
        last = np.broadcast_to(np.asarray(last, dtype=bool), s.shape)
        t = np.where(at_vertex, np.where(last, self.dep[x][kc], self.arr[x][kc]), t)
        return np.where(last, np.where(s >= cum[-1] - EPS, INF, t), np.where(s <= EPS, 0.0, t))

    def _network_holds(self, order: Sequence[int], ids: Sequence[str]) -> Network:
        """The network under the final timing with holds: a robot's node has its departure and its
        time from departure to arrival (holds included); a link's T1 / T2 are when the robot first
        reaches the region, T4 / T3 when it last leaves it."""

        def arrival(x: int) -> float:
            return float(self.arr[x][-1]) if len(self.arr[x]) > 1 else 0.0

        net = Network([ids[x] for x in order], {ids[x]: float(self.delays[x]) for x in order},
                      {ids[x]: arrival(x) - float(self.delays[x]) for x in order}, mode=self.mode)
        # every inlet region of every robot as rows (j's rank, i, j, i's range, j's range): the
        # model's regions (x < y) oriented from the higher robot i to the lower j, of robots in
        # ``order``; their times computed per robot in one batch
        table = self.model.region_table()
        n = len(self.model.paths)
        rank_of = np.full(n, -1, dtype=np.int64)
        rank_of[np.asarray(order, dtype=np.int64)] = np.arange(len(order))   # -1: not in ``order``
        x, y = table[:, 0].astype(np.int64), table[:, 1].astype(np.int64)
        table = table[(rank_of[x] >= 0) & (rank_of[y] >= 0)]
        if not len(table):
            return net
        x, y = table[:, 0].astype(np.int64), table[:, 1].astype(np.int64)
        x_first = rank_of[x] < rank_of[y]   # x is the higher robot i
        i_of, j_of = np.where(x_first, x, y), np.where(x_first, y, x)
        xf = x_first[:, None]
        R = np.column_stack([rank_of[j_of], i_of, j_of, np.where(xf, table[:, 2:4], table[:, 4:6]),
                             np.where(xf, table[:, 4:6], table[:, 2:4])]).astype(float)
        seq = np.arange(len(R))
        # per j (in order): by (b_lo, i), ties in the pair's region order
        R = R[np.lexsort((seq, R[:, 1], R[:, 5], R[:, 0]))]
        who_i, who_j = R[:, 1].astype(np.int64), R[:, 2].astype(np.int64)
        # T1 / T4 (when i first reaches / last leaves its range), T2 / T3 (the same for j), per robot at once
        nr = len(R)
        who = np.concatenate([who_i, who_i, who_j, who_j])
        s_all = np.concatenate([R[:, 3], R[:, 4], R[:, 5], R[:, 6]])
        last_all = np.repeat(np.array([False, True, False, True]), nr)
        t_all = np.empty(4 * nr)
        by = np.argsort(who, kind="stable")
        cuts = np.searchsorted(who[by], np.arange(n + 1))
        for r in np.nonzero(np.diff(cuts))[0].tolist():
            rows_r = by[cuts[r]:cuts[r + 1]]
            t_all[rows_r] = self._times_at(r, s_all[rows_r], last_all[rows_r])
        t1, t4, t2, t3 = t_all[:nr], t_all[nr:2 * nr], t_all[2 * nr:3 * nr], t_all[3 * nr:]
        with np.errstate(invalid="ignore"):
            M, D = t3 - t1, t4 - t2
        # k: the link's number among the pair's links, in that order
        pair = who_j * len(self.model.paths) + who_i
        first = np.ones(len(R), dtype=bool)
        by_pair = np.argsort(pair, kind="stable")
        first[1:] = pair[by_pair][1:] != pair[by_pair][:-1]
        start = np.maximum.accumulate(np.where(first, np.arange(len(R)), 0))
        k = np.empty(len(R), dtype=np.int64)
        k[by_pair] = np.arange(len(R)) - start + 1
        for i, j, kk, m, d, a, b, lo, hi in zip(who_i.tolist(), who_j.tolist(), k.tolist(), M.tolist(), D.tolist(),
                                                t1.tolist(), t4.tolist(), R[:, 5].tolist(), R[:, 6].tolist()):
            net.links.append(Link(ids[i], ids[j], kk, m, d, a, b, lo, hi))
        return net


#: the piece columns the compiled hold constraints read (fleet_planner._md_kernels.HOLD_COLUMNS)
_HOLD_COLUMNS = np.array([getattr(C, "P_" + name) for name in K.HOLD_COLUMNS], dtype=np.int64)
#: column order of a piece table with its two robots swapped (x columns <-> y columns)
_SWAP = np.arange(C.P_Y_SEG + 1)
for _a, _b in ((C.P_X, C.P_Y), (C.P_A_LO, C.P_B_LO), (C.P_A_HI, C.P_B_HI), (C.P_XS_LO, C.P_YS_LO),
               (C.P_XS_HI, C.P_YS_HI), (C.P_XE_LO, C.P_YE_LO), (C.P_XE_HI, C.P_YE_HI), (C.P_X_FIRST, C.P_Y_FIRST),
               (C.P_X_LAST, C.P_Y_LAST), (C.P_X_OFF, C.P_Y_OFF), (C.P_X_T0, C.P_Y_T0), (C.P_X_V, C.P_Y_V),
               (C.P_X_SEG, C.P_Y_SEG)):
    _SWAP[_a], _SWAP[_b] = _b, _a
#: the columns of :data:`_HOLD_COLUMNS` in a piece table whose robots are the other way round
_HOLD_COLUMNS_SWAPPED = _SWAP[_HOLD_COLUMNS]


def _grouped(key: np.ndarray, lo: np.ndarray, hi: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Open intervals (lo, hi) grouped by ``key`` in 0..n-1, each group sorted by ``lo``: (ptr, lo,
    hi) with group k at ``ptr[k]:ptr[k + 1]`` (compiled: :func:`fleet_planner._md_kernels.grouped`;
    numpy's lexsort and its calls were 4% of md's planning time at 100 robots)."""
    return K.grouped(np.ascontiguousarray(key, dtype=np.int64), np.ascontiguousarray(lo, dtype=float),
                     np.ascontiguousarray(hi, dtype=float), int(n))
