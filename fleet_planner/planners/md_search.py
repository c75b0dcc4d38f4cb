"""Priority search for the md planner (issue 8, deliverable 3): what to try when greedy re-ordering
gives up, within a time budget.

The md planner's repair is greedy: where a delay cannot help, the blocked robot moves just ahead
of its blocker (docs/ARCHITECTURE.md, measured fact 2), at most a few times per pair. In dense
1-cell aisles that can cycle (a ahead of b, later b ahead of a) and give up although other orders
work. The search keeps what each failed attempt learnt as pairwise priorities, as priority-based
search does (Ma, Harabor, Stuckey, Li and Koenig, "Searching with Consistent Prioritization for
Multi-Agent Path Finding", AAAI 2019): the robot that could not be served goes above the robot in
its way, for good. The next attempt starts from the failed attempt's final order (its re-orderings
kept) re-sorted to respect every learnt priority (a stable topological order). A new priority that
closes a cycle with older ones means those priorities cannot all hold for these paths: the oldest
ones on the cycle are forgotten (the search restarts from the most recent evidence); an order
already tried is perturbed at random around the failing robot (a large-neighbourhood move), seeded,
so the search is reproducible. The search never undoes a success: the first attempt is exactly
the greedy planner, later ones only run when it failed.
"""
from __future__ import annotations

import heapq
import random
from collections.abc import Sequence


class PrioritySearch:
    """Learnt pairwise priorities and the next order to try (see the module docstring)."""

    def __init__(self, seed: int = 0):
        #: (above, below) pairs, oldest first
        self.constraints: list[tuple[int, int]] = []
        self.tried: set[tuple[int, ...]] = set()
        self.rng = random.Random(seed)
        self.forgotten = 0
        self.perturbed = 0

    def next_order(self, failed: Sequence[int], j: int, blocker: int) -> list[int]:
        """The order to try after an attempt that ended in ``failed`` order with robot ``j``
        blocked by ``blocker``: ``j`` above ``blocker`` from now on."""
        self.tried.add(tuple(failed))
        if (j, blocker) not in self.constraints:
            self.constraints.append((j, blocker))
        self.constraints = [c for c in self.constraints if c != (blocker, j)]
        base = list(failed)
        order = self._topological(base)
        while order is None:   # a cycle: forget the oldest priority until none is left
            self.constraints.pop(0)
            self.forgotten += 1
            order = self._topological(base)
        tries = 0
        while tuple(order) in self.tried and tries < 20:
            tries += 1
            self.perturbed += 1
            order = self._topological(self._perturb(order, j)) or order
        return order

    def _perturb(self, order: list[int], j: int) -> list[int]:
        """The order with the robots around ``j`` shuffled (j itself moved to the front of them)."""
        out = list(order)
        k = out.index(j)
        width = self.rng.randint(2, max(2, min(len(out), 8)))
        lo = max(0, k - self.rng.randint(0, width))
        window = out[lo:lo + width]
        self.rng.shuffle(window)
        if j in window:
            window.remove(j)
            window.insert(0, j)
        out[lo:lo + width] = window
        return out

    def _topological(self, base: Sequence[int]) -> list[int] | None:
        """``base`` re-sorted so that every learnt priority holds, otherwise as in ``base``
        (Kahn's algorithm taking the earliest robot of ``base`` that is free); None on a cycle."""
        rank = {x: k for k, x in enumerate(base)}
        below: dict[int, list[int]] = {}
        indeg = dict.fromkeys(base, 0)
        for a, b in self.constraints:
            if a in rank and b in rank:
                below.setdefault(a, []).append(b)
                indeg[b] += 1
        heap = [rank[x] for x in base if indeg[x] == 0]
        heapq.heapify(heap)
        out = []
        while heap:
            x = base[heapq.heappop(heap)]
            out.append(x)
            for y in below.get(x, ()):
                indeg[y] -= 1
                if indeg[y] == 0:
                    heapq.heappush(heap, rank[y])
        return out if len(out) == len(base) else None
