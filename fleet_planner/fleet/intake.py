"""What a node checks about a record before it hands it to the core (issue 9, hardened inputs):
stamps within a window of the receiver's clock (:func:`stamp_problem`). Pure; the nodes
(``fleet_planner/ros/planner_node.py``, ``robot_agent/agent_node.py``) call it and log the answer.

Why a window both ways: a status stamped far ahead would make every later status look old and its
robot offline for good; one stamped far behind says nothing about where the robot is now, and a
timed path whose stamp is hours off is not a leg the planner sent for this run.
"""
from __future__ import annotations

#: a status stamped more than this many seconds behind the receiver's clock is refused (it is stale:
#: a robot silent this long is offline anyway)
MAX_STATUS_AGE_S = 60.0
#: the most poses a timed path may have (a leg across a large warehouse has a few hundred)
MAX_PATH_POSES = 10_000
#: a timed path stamped further than this from the robot's clock (either way) is refused
MAX_PATH_OFFSET_S = 3600.0


def stamp_problem(what: str, stamp: float, now: float, ahead: float, behind: float) -> str | None:
    """Why ``stamp`` (s) is not acceptable on a clock reading ``now``: more than ``ahead`` s ahead or
    more than ``behind`` s behind it (a bounded, printable line naming ``what``), else None."""
    if stamp > now + ahead:
        return f"{what}: stamped {stamp - now:.3g} s ahead of the receiver's clock (at most {ahead:g} s)"
    if stamp < now - behind:
        return f"{what}: stamped {now - stamp:.3g} s behind the receiver's clock (at most {behind:g} s)"
    return None


__all__ = ["MAX_PATH_OFFSET_S", "MAX_PATH_POSES", "MAX_STATUS_AGE_S", "stamp_problem"]
