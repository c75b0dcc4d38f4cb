"""What the fleet manager hands out and the numbers that shape it: :class:`Leg` (a timed path for
one robot), :class:`Decisions` (the outcome of one planning step), :class:`DispatchParams` (what
the manager may tune) and how far a robot may lag a leg (:func:`lag_allowance`). Shared by both
ends of the fleet (:mod:`.manager`, :mod:`.agent`)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from msg_schemas.records import GateRecord, TaskEvent

from ..model import RAMP_PIECES, Point, TimedPath
from ..robots import RobotKind
from ..validation import check_ranges
from ..warehouse import Station, Warehouse

#: why a robot drives a leg
PURPOSES = ("pick", "place", "charge", "park", "hold")
#: the goal of a "hold" leg that steps a standing robot aside from a moving obstacle (FleetManager._evade)
EVADE = "evade"
#: the status mode of a robot doing what a leg of this purpose ends with
ACTING = {"pick": "picking", "place": "placing"}

#: a robot this close to a station's pose stands at it (robots stop exactly on the pose)
AT_STATION_M = 0.05
#: seconds between two steps of a robot's controller (the agent steps its model at its status rate)
CONTROL_PERIOD_S = 0.1
#: a status stamped further ahead of the receiver's clock than this is refused (a robot's clock
#: that runs ahead, or a forged stamp, must not make its later statuses look old for good)
MAX_CLOCK_SKEW_S = 2.0


@dataclass(frozen=True)
class DispatchParams:
    """What the fleet manager may tune (seconds, metres, battery fractions)."""

    speed_factor: float = 0.9         # legs are planned at this fraction of each robot's top speed
    safety_margin: float = 0.05       # added to the margin covering the robots' lag
    lead_s: float = 1.0               # a leg starts this long after it is planned (time to deliver it)
    offline_timeout_s: float = 3.0    # a robot silent this long is offline
    lateness_tolerance_s: float = 3.0  # a robot this far behind its schedule re-plans its leg
    low_battery: float = 0.25         # below this a free robot goes to a charger
    min_task_battery: float = 0.3     # a robot takes a job only with at least this much
    idle_s: float = 5.0               # a free robot idle this long goes to a charger
    lease_s: float = 0.0              # a robot not heard this long stops (fleet/lease.py); 0: offline_timeout_s / 2
    silence_s: float = 0.0            # ... and one that hears no planner this long; 0: 3 x offline_timeout_s

    RANGES = {"speed_factor": (0.05, 1.0), "safety_margin": (0.0, 5.0), "lead_s": (0.0, 60.0),
              "offline_timeout_s": (0.01, 3600.0), "lateness_tolerance_s": (0.01, 3600.0),
              "low_battery": (0.0, 1.0), "min_task_battery": (0.0, 1.0), "idle_s": (0.0, 3600.0),
              "lease_s": (0.0, 3600.0), "silence_s": (0.0, 3600.0)}

    def __post_init__(self) -> None:
        check_ranges(self, self.RANGES)

    @property
    def lease(self) -> float:
        """A robot not heard this long (s) stops: ``lease_s``, or half of ``offline_timeout_s`` if 0."""
        return self.lease_s if self.lease_s > 0.0 else self.offline_timeout_s / 2

    @property
    def silence(self) -> float:
        """A robot that hears no heard record this long (s) stops: ``silence_s``, or 3 x ``offline_timeout_s``
        if 0 (a planner that stalls for less does not stop the fleet)."""
        return self.silence_s if self.silence_s > 0.0 else 3.0 * self.offline_timeout_s


def lag_allowance(kind: RobotKind, speed_factor: float) -> float:
    """How far (m) a robot of this kind may fall behind a leg planned with its acceleration ramps at
    ``speed_factor`` of its top speed: the ramps' piecewise-constant approximation plus one control
    step of driving."""
    v = speed_factor * kind.max_speed
    ramp = 0.0 if math.isinf(kind.max_accel) else v * v / (8.0 * kind.max_accel * RAMP_PIECES ** 2)
    return ramp + v * CONTROL_PERIOD_S


@dataclass
class Leg:
    """A timed path for one robot. ``path`` has absolute times and starts at ``t0``; ``path_id`` is
    ``t0`` in nanoseconds: the stamp of the ``nav_msgs/Path`` header, reported back by the robot."""

    robot_id: str
    path: TimedPath
    path_id: int
    purpose: str  # one of PURPOSES
    goal: str     # the station or parking spot it ends at ("" for a hold)

    @property
    def t0(self) -> float:
        return self.path_id / 1e9

    def relative(self) -> TimedPath:
        """The path with times counted from ``t0`` (as it goes on the wire)."""
        wp = self.path.waypoints.copy()
        wp[:, 2] -= self.t0
        return TimedPath(self.robot_id, self.path.radius, wp)


@dataclass
class Decisions:
    """The outcome of one :meth:`FleetManager.step <.manager.FleetManager.step>`: legs to send,
    events to publish, log lines, and the gate records of robots whose links changed (central
    coordination, :mod:`.gate`; each goes to its robot, latched)."""

    legs: list[Leg] = field(default_factory=list)
    events: list[TaskEvent] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    gates: list[GateRecord] = field(default_factory=list)


def station_at(warehouse: Warehouse, pose: Point) -> Station | None:
    """The station a robot at ``pose`` stands at (within :data:`AT_STATION_M`), if any."""
    return next((s for s in warehouse.stations.values()
                 if math.hypot(s.x - pose[0], s.y - pose[1]) < AT_STATION_M), None)
