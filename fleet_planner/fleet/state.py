"""What the fleet manager knows: its robots (:class:`FleetRobot`, built from their statuses), its
jobs (:class:`Job`) and where a robot is bound (:class:`Target`); :func:`can_do` says which robot
kinds may take a job."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from msg_schemas.records import RobotStatus, Task

from ..model import Point, TimedPath
from ..robots import RobotKind
from ..warehouse import Station
from .legs import Leg

#: a robot in manual drive is planned around as a disc this much (m) larger than it is; the
#: operator's module re-plans the others around it whenever it has moved this far (.operator)
MANUAL_GROWTH_M = 0.5


def can_do(kind: RobotKind, task: Task) -> bool:
    """The kind has every capability the task needs and carries its payload."""
    return set(task.needs) <= kind.capabilities and task.payload_kg <= kind.payload_kg


@dataclass(frozen=True)
class Target:
    """Where a robot is bound and why: a station or parking spot and the purpose of the leg there."""

    purpose: str  # one of legs.PURPOSES
    name: str
    pose: Point


@dataclass
class Job:
    """An accepted task: its pick station (a chute), its storing site and how far it has got."""

    task: Task
    pick: Station
    place: Station
    seq: int                 # order of submission (ties between equal priorities)
    state: str = "queued"    # queued | active | done | failed | cancelled
    robot: str | None = None
    picked: bool = False


@dataclass
class FleetRobot:
    """What the fleet manager knows about one robot (its last status and what it was given)."""

    kind: RobotKind
    status: RobotStatus
    seen: float                       # when its last status arrived
    idle_since: float
    online: bool = True
    immobile: bool = False            # offline or out of battery: a fixed obstacle
    leg: Leg | None = None            # the trajectory it follows (None: it stands where it is)
    target: Target | None = None      # where it is going and why
    job: str | None = None
    replan: bool = False              # its leg to ``target`` must be (re)planned
    conflict: bool = False            # ... because its current leg runs into an obstacle
    arrived_at: float | None = None   # when it was first seen at the end of its leg
    saw_action: bool = False          # a status showed it picking / placing there
    last_path_id: int = -1
    trouble: str = ""                 # why its last leg could not be planned (noted once)
    stop: bool = False                # back online: stop it wherever it is heading
    paused: bool = False              # the operator paused it: it holds, others plan around it (.operator)
    manual: bool = False              # driven by the operator's cmd_vel: a moving obstacle (.operator)
    retry_at: float = -math.inf       # a spot it could not get a leg to is tried again from then on
    leg_retry_at: float = -math.inf   # a leg that could not be planned is tried again from then on
    evade_retry_at: float = -math.inf  # no refuge from a moving obstacle could be reached: tried again from then on
    leg_failures: int = 0             # legs refused in a row (the wait before the next try doubles)
    took_late: float = 0.0            # how late (s) its first status on its leg said it was (it took it late)
    #: when a heard record first showed it unheard (fleet/lease.py; None: heard)
    stale_since: float | None = None
    #: offline, it may still drive its leg until then (fleet/lease.py), and why it is offline
    unheard: tuple[float, str] | None = None
    #: immobile after it was unheard: every point it may stand at (n x 2; None: its status's position)
    reach: np.ndarray | None = None
    waits_on: tuple[str, ...] = ()    # the robots its last failed or refused leg named (.waits) ...
    waits_since: float = -math.inf    # ... and when
    broken_at: float = -math.inf      # when the wait-cycle breaker last held it (.waits)

    @property
    def id(self) -> str:
        return self.status.id

    @property
    def radius(self) -> float:
        return self.kind.radius

    @property
    def pos(self) -> Point:
        return self.status.x, self.status.y

    @property
    def free(self) -> bool:
        """Online, able to move, with nothing to do and not in the middle of a pick or place."""
        return (self.online and not self.immobile and self.target is None and self.job is None
                and not self.paused and not self.manual and self.status.mode not in ("picking", "placing", "error"))

    @property
    def on_leg(self) -> bool:
        """Its status shows it on its current leg, not yet at the end."""
        return (self.leg is not None and self.status.path_id == self.leg.path_id
                and self.status.progress < 1.0)

    def trajectory(self) -> TimedPath:
        """Where it will be: its leg, or standing where its status says for ever."""
        if self.leg is not None and not self.immobile and not self.manual:
            return self.leg.path
        # driven by hand: where it is, grown by what it may drive before the others re-plan around it
        radius = self.radius + (MANUAL_GROWTH_M if self.manual else 0.0)
        return TimedPath(self.id, radius, np.array([[self.status.x, self.status.y, 0.0]]))


class Occupancy:
    """Where the robots stand and where they are bound, indexed for one planning step: a k-d tree
    over every robot's position, the end of its leg and its target (:meth:`occupant`), so spot and
    station queries cost a logarithm of the fleet, not the fleet. Robots whose leg changes during
    the step are :meth:`touch` ed and checked directly (they are few)."""

    def __init__(self, robots: list[FleetRobot]):
        from scipy.spatial import cKDTree

        pts, owners = [], []
        for o in robots:
            for p in _ends(o):
                pts.append(p)
                owners.append(o)
        self._owners = owners
        self._tree = cKDTree(np.asarray(pts, dtype=float).reshape(-1, 2)) if pts else None
        self._largest = max((o.radius for o in robots), default=0.0)
        self._touched: dict[str, FleetRobot] = {}

    def touch(self, robot: FleetRobot) -> None:
        """``robot``'s leg changed after the index was made."""
        self._touched[robot.id] = robot
        self._largest = max(self._largest, robot.radius)

    def occupant(self, pose: Point, radius: float, exclude: FleetRobot | None = None) -> FleetRobot | None:
        """A robot standing on, or bound for, a disc of ``radius`` at ``pose`` (the first found)."""
        if self._tree is not None:
            for k in sorted(self._tree.query_ball_point(pose, radius + self._largest)):
                o = self._owners[k]
                if o is exclude or o.id in self._touched:
                    continue
                if _ends_near(o, pose, radius):
                    return o
        for o in self._touched.values():
            if o is not exclude and _ends_near(o, pose, radius):
                return o
        return None


def _ends(o: FleetRobot) -> list[Point]:
    """Where ``o`` stands, where its leg ends and where it is bound: its target too, which it keeps
    when it has no leg there (its leg was refused, it holds): ours, a charger whose robot refused its
    leg (late messages) went to a second robot, which parked on it; the first then could never get
    a leg there ("blocked by ..., which parks on its goal") and stood in the way of others for good."""
    ends = [o.pos]
    if o.immobile and o.reach is not None:  # anywhere on the stretch it could reach unheard (fleet/lease.py)
        ends += [(float(x), float(y)) for x, y in o.reach[::5]]
    if not o.immobile:
        if o.leg is not None:
            ends.append((float(o.leg.path.waypoints[-1, 0]), float(o.leg.path.waypoints[-1, 1])))
        if o.target is not None:
            ends.append(o.target.pose)
    return ends


def _ends_near(o: FleetRobot, pose: Point, radius: float) -> bool:
    near = o.radius + radius
    return any(math.dist(p, pose) < near for p in _ends(o))
