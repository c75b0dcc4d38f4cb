"""What a node checks about a record before it hands it to the core (issue 9, hardened inputs):
stamps within a window of the receiver's clock (:func:`stamp_problem`), robot ids on a roster
with one warning per stranger (:class:`Roster`). Pure; the nodes
(``fleet_planner/ros/planner_node.py``, ``robot_agent/agent_node.py``) call it and log the answer.

Why a window both ways: a status stamped far ahead would make every later status look old and its
robot offline for good; one stamped far behind says nothing about where the robot is now, and a
timed path whose stamp is hours off is not a leg the planner sent for this run.
"""
from __future__ import annotations

from collections.abc import Iterable

#: a status stamped more than this many seconds behind the receiver's clock is refused (it is stale:
#: a robot silent this long is offline anyway)
MAX_STATUS_AGE_S = 60.0
#: the most poses a timed path may have (a leg across a large warehouse has a few hundred)
MAX_PATH_POSES = 10_000
#: a timed path stamped further than this from the robot's clock (either way) is refused
MAX_PATH_OFFSET_S = 3600.0


#: robots whose statuses an agent keeps at most (its safety net looks at each of them every step)
MAX_HEARD = 5000
#: unknown robot ids warned about one by one; beyond that, silently ignored
MAX_STRANGERS = 1000


class Roster:
    """The robot ids a node listens to (``ids``; None: any) and the strangers it has warned about,
    at most :data:`MAX_STRANGERS` of them."""

    def __init__(self, ids: Iterable[str] | None = None):
        self.ids = None if ids is None else frozenset(ids)
        self.strangers: set[str] = set()

    def admit(self, robot_id: str) -> tuple[bool, str | None]:
        """(whether ``robot_id`` is on the roster, a warning to log the first time it is not)."""
        if self.ids is None or robot_id in self.ids:
            return True, None
        if robot_id in self.strangers or len(self.strangers) > MAX_STRANGERS:
            return False, None
        self.strangers.add(robot_id)
        if len(self.strangers) > MAX_STRANGERS:
            return False, f"more than {MAX_STRANGERS} robot ids not on the roster; further ones are ignored silently"
        return False, f"robot {robot_id!r}: not on the fleet's roster; its statuses are ignored"


def stamp_problem(what: str, stamp: float, now: float, ahead: float, behind: float) -> str | None:
    """Why ``stamp`` (s) is not acceptable on a clock reading ``now``: more than ``ahead`` s ahead or
    more than ``behind`` s behind it (a bounded, printable line naming ``what``), else None."""
    if stamp > now + ahead:
        return f"{what}: stamped {stamp - now:.3g} s ahead of the receiver's clock (at most {ahead:g} s)"
    if stamp < now - behind:
        return f"{what}: stamped {now - stamp:.3g} s behind the receiver's clock (at most {behind:g} s)"
    return None


__all__ = ["MAX_HEARD", "MAX_PATH_OFFSET_S", "MAX_PATH_POSES", "MAX_STATUS_AGE_S", "MAX_STRANGERS", "Roster",
           "stamp_problem"]
