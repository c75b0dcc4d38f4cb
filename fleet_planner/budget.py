"""A planning budget in CPU seconds, :class:`Budget`, shared by the planners (md, PRIOR) and the
road map's LP rounding (ARMO): what they do within it does not depend on how loaded the machine is."""
from __future__ import annotations

import math
import time
from typing import ClassVar

#: a :class:`Budget` also runs out after this many times its CPU seconds of wall-clock time (so that a
#: starved process still stops)
WALL_BACKSTOP = 10.0


class Budget:
    """A planning budget in CPU seconds of the thread that plans (``time.thread_time``: a ROS node's
    other threads do not spend it), not wall-clock seconds: what a planner does with it does not
    depend on how loaded the machine is (the same md run and seed of the delivery benchmark ended
    at CTime 1170 and 1304 s under different loads with wall-clock budgets). As a backstop it also
    runs out once :data:`WALL_BACKSTOP` times as many wall-clock seconds have passed. ``None``: no
    bound.
    ``wall``: wall-clock seconds instead (PRIOR's own ``time_limit_s``, as published).

    :attr:`backstops` counts the CPU budgets that ran out on the backstop before their CPU seconds (a
    starved process: then what the planner did depends on the load; the delivery benchmark reports it)."""

    #: CPU budgets (of any instance, in this process) that ran out on the wall-clock backstop first
    backstops: ClassVar[int] = 0
    #: budgets (in this process) that ran out at all, on either clock (checked and found spent)
    spent: ClassVar[int] = 0

    def __init__(self, cpu_s: float | None, wall: bool = False):
        self.cpu_s = cpu_s
        self._cpu_end = math.inf if cpu_s is None or wall else time.thread_time() + cpu_s
        self._wall_end = math.inf if cpu_s is None else time.perf_counter() + (1.0 if wall else WALL_BACKSTOP) * cpu_s
        self._counted = False

    def passed(self) -> bool:
        """True once the budget is spent."""
        if time.thread_time() > self._cpu_end:
            self._count(backstop=False)
            return True
        if time.perf_counter() <= self._wall_end:
            return False
        self._count(backstop=self._cpu_end != math.inf)
        return True

    def _count(self, backstop: bool) -> None:
        if not self._counted:
            self._counted = True
            Budget.spent += 1
            Budget.backstops += backstop

    def left(self) -> float:
        """Seconds left (CPU, or wall-clock with ``wall``; 0 once spent, at the backstop too; infinite
        without a bound)."""
        if self.passed():
            return 0.0
        if self._cpu_end == math.inf:
            return max(self._wall_end - time.perf_counter(), 0.0)
        return max(self._cpu_end - time.thread_time(), 0.0)
