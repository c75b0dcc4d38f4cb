"""The tuning of the behaviour layer, :class:`BehaviorParams` (metres, seconds), and the length
tolerance :data:`EPS` its geometry shares.

"paper" in the comments is Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance"
(ICRA 2014): a default marked "paper: ..." is the paper's figure, the others are ours.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

EPS = 1e-9  # m: lengths below this are zero


@dataclass(frozen=True)
class BehaviorParams:
    """Tuning of the behaviour layer (metres, seconds). Defaults suit discs of radius 0.3-0.5 m at
    about 1 m/s on 1 m cells."""

    front_length: float = 2.0       # how far ahead of the robot the front area reaches
    front_width: float = 2.0        # full width of the front area
    critical_margin: float = 0.2    # critical area (drive channel) width = 2 * radius + this
    comm_range: float = 6.0         # robots sense / message only robots this close
    wait_msg_period: float = 2.0    # a waiting robot sends a WaitMessage this often (paper: 2 s)
    keep_gap: float = 0.3           # WaitKeepDistance / WaitForDocking keep this free gap to others
    avoid_margin: float = 0.15      # free gap left when driving round a partner
    safety_margin: float = 0.02     # the hard safety layer keeps discs this far apart
    dock_region: float = 1.5        # a robot this close to its station asks to dock
    dock_give_up: float = 3.0       # WaitForDocking ends when pushed this far from the station
    waypoint_reach: float = 0.05    # a robot refused its move this close to a waypoint (not the goal) has
                                    # reached it (ours; 0: never)
    go_through_timeout: float = 30.0  # a GoThrough lasting longer fails (paper IV.C.4)
    avoid_timeout: float = 15.0     # Avoid / Exchange / waiting for an obstacle this long without progress fails
    blocked_timeout: float = 5.0    # FollowWayPoint unable to move this long fails; also the re-plan cooldown
    retreat_timeout: float = 30.0   # a robot backing out of an aisle has right of way this long (ours; 0: none)
    escape_after: float = 30.0      # no progress this long (or a re-plan that finds no way): move into a
                                    # less crowded place nearby, then re-plan (ours; 0: never)
    escape_reach: float = 4.0       # how far such a place may be
    give_way_reach: float = 2.0     # a waiting robot this close to a Dock robot's channel gives way (ours; 0: never)
    stall_time: float = 60.0        # stats: a robot not closer to its goal for this long is stalled

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"BehaviorParams.{f.name}: must be a finite number, got {value!r}")
            may_be_zero = ("safety_margin", "avoid_margin", "critical_margin", "retreat_timeout", "escape_after",
                           "give_way_reach", "waypoint_reach")
            if value < 0 or (value == 0 and f.name not in may_be_zero):
                raise ValueError(f"BehaviorParams.{f.name}: must be > 0, got {value!r}")
        if self.dock_give_up < self.dock_region:
            raise ValueError(f"BehaviorParams.dock_give_up: must be >= dock_region ({self.dock_region}), "
                             f"got {self.dock_give_up}")


DEFAULT_PARAMS = BehaviorParams()
