"""BBMRCA: behaviour-based multi-robot collision avoidance (paper 002, section IV), no rclpy.

Every robot plans its own A* path without looking at the others and drives it; when another robot
shows up in its *front area* it picks one of eight behaviours by the paper's traffic rules. This
module keeps the rules pure and separately testable, and wraps them in one steppable simulation:

* geometry   - :func:`front_area_check`, :func:`in_front_area`, :func:`in_critical_area`,
  :func:`collision_type` (rear-end / head-on / side, by the angle between travel directions);
* rules      - :func:`select_behavior` (Algorithms 1-4, SolveActiveAndWaitCollision, the Dock and
  WaitForDocking rules) with the helpers :func:`low_order`, :func:`no_other_active`,
  :func:`same_goal_station`;
* docking    - :class:`DockingArbiter`: one robot docks at a station at a time (first come first
  served, ties by priority);
* deadlocks  - :class:`WaitMessage` and :func:`on_wait_message`: the wait-chain messages of IV.C;
* re-planning - :func:`virtual_wall_cells`: the cells between a robot and its next waypoint;
* :class:`BehaviorController` - one robot, from what it knows: its own state and path, the views
  of the robots in communication range and the WaitMessages addressed to it. A robot on its own
  (the agent node, ``coordination:=behavior``) calls ``step``, which adds a local safety layer
  against the others' reported discs and keeps the docking agreement from what it hears
  (:class:`HeardDocking`);
* :class:`BehaviorFleet` - the decentralised fleet as one object (one controller per robot, a
  shared :class:`DockingArbiter`, an exact safety layer): ``assign`` goals, ``step(dt)``;
* :func:`safety_stop` - the same critical area as the safety net of a robot that follows a
  central plan: the robot it must wait for rather than drive into.

Frames: a robot's *front frame* has its origin at the robot, axis ``u`` from the robot to its next
waypoint (its heading is ignored, as in the paper) and ``n`` = ``u`` turned +90 degrees. ``s`` is the
distance ahead along ``u``, ``l`` the lateral offset along ``n``.

Where the paper leaves a choice open, the choice and its reason are written where it is made
(search for "Interpretation").
"""
from __future__ import annotations

import enum
import math
import re
from dataclasses import dataclass, fields, replace
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np
from scipy.spatial import cKDTree

from .grid import GridMap
from .model import ACTIVE_BEHAVIORS, WAIT_BEHAVIORS, Behavior, Point, PlanningError
from .paths import PathFinder


B = Behavior
ACTIVE = ACTIVE_BEHAVIORS
WAITS = WAIT_BEHAVIORS

#: Collision classes by the angle between the two robots' travel directions (documented thresholds):
#: below 45 degrees the robots go the same way (rear-end), above 135 degrees opposite ways (head-on),
#: in between their paths cross (side).
REAR_END_MAX_ANGLE_DEG = 45.0
HEAD_ON_MIN_ANGLE_DEG = 135.0
_COS_REAR = math.cos(math.radians(REAR_END_MAX_ANGLE_DEG))
_COS_HEAD = math.cos(math.radians(HEAD_ON_MIN_ANGLE_DEG))
_EPS = 1e-9
_COS_STRAIGHT = math.cos(math.radians(10.0))  # a path bending less than this at a waypoint goes on straight
_PROGRESS = 0.05  # m: coming this much closer to the goal (straight line) is progress (stats)


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
    go_through_timeout: float = 30.0  # a GoThrough lasting longer fails (paper IV.C.4)
    avoid_timeout: float = 15.0     # Avoid / Exchange / waiting for an obstacle this long without progress fails
    blocked_timeout: float = 5.0    # FollowWayPoint unable to move this long fails; also the re-plan cooldown
    stall_time: float = 60.0        # stats: a robot not closer to its goal for this long is stalled

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"BehaviorParams.{f.name}: must be a finite number, got {value!r}")
            if value < 0 or (value == 0 and f.name not in ("safety_margin", "avoid_margin", "critical_margin")):
                raise ValueError(f"BehaviorParams.{f.name}: must be > 0, got {value!r}")
        if self.dock_give_up < self.dock_region:
            raise ValueError(f"BehaviorParams.dock_give_up: must be >= dock_region ({self.dock_region}), "
                             f"got {self.dock_give_up}")


DEFAULT_PARAMS = BehaviorParams()


@dataclass(frozen=True)
class RobotView:
    """What a robot knows of itself or hears from a neighbour: position, path, status.

    ``next_waypoint`` is None for a robot without a path (idle, or arrived): it stands still.
    ``remaining`` is the length of the rest of its path (for :func:`low_order`), ``straight`` the
    length of the straight run of it ahead (up to the next turn or the goal).
    ``partner`` is the id of the robot its current behaviour is about (the one it waits for,
    avoids, exchanges with...); ``no_space`` says its Avoid / Exchange finds no free space.
    ``docked_at`` is the station it docks at (it may be leaving it for its next goal already),
    ``dock_since`` when it first asked to dock at its station (for :class:`HeardDocking`).
    """

    id: str
    position: Point
    radius: float
    behavior: Behavior = B.FOLLOW_WAYPOINT
    next_waypoint: Point | None = None
    remaining: float = math.inf
    straight: float = math.inf
    station: str | None = None
    partner: str | None = None
    no_space: bool = False
    docked_at: str | None = None
    dock_since: float | None = None

    @property
    def direction(self) -> tuple[float, float] | None:
        """Unit vector from the position to the next waypoint (the travel direction), or None."""
        if self.next_waypoint is None:
            return None
        dx = self.next_waypoint[0] - self.position[0]
        dy = self.next_waypoint[1] - self.position[1]
        d = math.hypot(dx, dy)
        if d < _EPS:
            return None
        return dx / d, dy / d

    @property
    def travelling(self) -> bool:
        """Has somewhere to go (a robot without a path is a standing obstacle to the others)."""
        return self.direction is not None


# -- geometry ---------------------------------------------------------------------------------
def front_coords(me: RobotView, other: RobotView) -> tuple[float, float] | None:
    """``(s, l)`` of the other robot's centre in my front frame, or None if I have no direction."""
    d = me.direction
    if d is None:
        return None
    rx, ry = other.position[0] - me.position[0], other.position[1] - me.position[1]
    return rx * d[0] + ry * d[1], -rx * d[1] + ry * d[0]


def in_front_area(me: RobotView, other: RobotView, params: BehaviorParams = DEFAULT_PARAMS) -> bool:
    """The other disc overlaps my front area: a ``front_length`` x ``front_width`` rectangle
    starting at my position, pointing at my next waypoint (the other's centre must be ahead).

    Interpretation: the area is cut short (to my radius beyond it) where my path turns or ends.
    The paper's A* paths have a waypoint per cell, ours are straightened polylines; a robot
    beyond my next turn is not in my way, and waiting for it blocked narrow crossings.
    """
    c = front_coords(me, other)
    if c is None or other.id == me.id:
        return False
    s, l = c
    length = min(params.front_length, me.straight + me.radius)
    return 0.0 <= s <= length + other.radius and abs(l) <= params.front_width / 2 + other.radius


def in_critical_area(me: RobotView, other: RobotView, params: BehaviorParams = DEFAULT_PARAMS) -> bool:
    """The other disc overlaps my drive channel (width ``2 * radius + critical_margin``) inside
    my front area: driving straight on, I would touch it (when the margin is 0)."""
    if not in_front_area(me, other, params):
        return False
    _, l = front_coords(me, other)  # type: ignore[misc]
    return abs(l) < me.radius + params.critical_margin / 2 + other.radius


def robots_in_front(me: RobotView, others: Iterable[RobotView],
                    params: BehaviorParams = DEFAULT_PARAMS) -> list[RobotView]:
    """The robots in my front area, closest first."""
    found = [o for o in others if in_front_area(me, o, params)]
    found.sort(key=lambda o: math.dist(o.position, me.position))
    return found


def front_area_check(me: RobotView, others: Iterable[RobotView],
                     params: BehaviorParams = DEFAULT_PARAMS) -> RobotView | None:
    """The paper's FrontAreaCheck: the robot in my front area closest to me, where robots in the
    critical area come first (if any robot is in it, those outside it are ignored)."""
    in_front = robots_in_front(me, others, params)
    critical = [o for o in in_front if in_critical_area(me, o, params)]
    pool = critical or in_front
    return pool[0] if pool else None


class Collision(enum.Enum):
    NONE = "none"
    REAR_END = "rearEndCollision"
    HEAD_ON = "headOnCollision"
    SIDE = "sideCollision"


def _enters_channel(me: RobotView, other: RobotView, params: BehaviorParams) -> bool:
    """The other robot's travel ray crosses my drive channel ahead of me within a front length."""
    c = front_coords(me, other)
    d_me, d_o = me.direction, other.direction
    if c is None or d_o is None:
        return False
    s, l = c
    ds = d_o[0] * d_me[0] + d_o[1] * d_me[1]   # its direction in my frame
    dl = -d_o[0] * d_me[1] + d_o[1] * d_me[0]
    half = me.radius + params.critical_margin / 2 + other.radius
    if abs(l) < half:
        t = 0.0
    elif l * dl < 0:
        t = (abs(l) - half) / abs(dl)
    else:
        return False
    return t <= params.front_length and -half <= s + ds * t <= params.front_length + other.radius


def collision_type(me: RobotView, other: RobotView, params: BehaviorParams = DEFAULT_PARAMS) -> Collision:
    """How my path collides with the other robot's, if it does.

    There is a path collision when the other is in my critical area or its travel direction takes
    it into my drive channel within a front length; its class is then given by the angle between
    the two travel directions (see :data:`REAR_END_MAX_ANGLE_DEG`, :data:`HEAD_ON_MIN_ANGLE_DEG`).
    Interpretation: a standing robot (no path) in my channel is a rear-end collision (I would run
    into it from behind), elsewhere no collision.
    """
    d_me, d_o = me.direction, other.direction
    if d_me is None:
        return Collision.NONE
    if not (in_critical_area(me, other, params) or _enters_channel(me, other, params)):
        return Collision.NONE
    if d_o is None:
        return Collision.REAR_END
    cos = d_me[0] * d_o[0] + d_me[1] * d_o[1]
    if cos >= _COS_REAR:
        return Collision.REAR_END
    if cos <= _COS_HEAD:
        return Collision.HEAD_ON
    return Collision.SIDE


# -- helpers of the traffic rules -----------------------------------------------------------------
_ID_PART = re.compile(r"(\d+)")


def id_key(robot_id: str) -> tuple:
    """Natural order of ids ("r2" before "r10"); a smaller key is a higher priority."""
    return tuple((0, int(p), "") if p.isdigit() else (1, 0, p) for p in _ID_PART.split(robot_id) if p)


def low_order(me: RobotView, other: RobotView) -> bool:
    """The paper's lowOrder: True when I have the lower priority of the two.

    The robot with the shorter remaining distance to its goal station has the higher priority (the
    robot closest to a crowded station should leave it first); on equal distances the smaller id.
    """
    if abs(me.remaining - other.remaining) > 1e-6:
        return me.remaining > other.remaining
    return id_key(me.id) > id_key(other.id)


def no_other_active(me: RobotView, others_in_front: Sequence[RobotView], partner: RobotView | None = None) -> bool:
    """The paper's noOtherActive: no robot in my front area besides the partner is moving with an
    active behaviour (then driving round the partner adds no new conflict)."""
    skip = {me.id, partner.id if partner else None}
    return not any(o.behavior.is_active and o.travelling for o in others_in_front if o.id not in skip)


def same_goal_station(me: RobotView, other: RobotView) -> bool:
    """Both robots are headed to the same station."""
    return me.station is not None and me.station == other.station


def proper_active(me: RobotView, other: RobotView, params: BehaviorParams = DEFAULT_PARAMS) -> Behavior:
    """Interpretation of "drive around the robot with a proper active behavior" (Algorithm 4):
    Exchange for a head-on collision (both pass on their right), Avoid when the other stands in
    my drive channel (drive round it), otherwise GoThrough (pass while it keeps waiting)."""
    if collision_type(me, other, params) is Collision.HEAD_ON:
        return B.EXCHANGE
    if in_critical_area(me, other, params):
        return B.AVOID
    return B.GO_THROUGH


def cooperate(other: RobotView) -> Behavior | None:
    """Interpretation of "cooperate with the robot with a proper active behavior" (Algorithm 4),
    when the other robot's active behaviour is about me: Exchange with an exchanging robot,
    WaitForGoThrough for a robot going through, and hold still (keep the wait) for one that
    avoids me, since Avoid drives round a standing partner."""
    if other.behavior is B.EXCHANGE:
        return B.EXCHANGE
    if other.behavior is B.GO_THROUGH:
        return B.WAIT_FOR_GO_THROUGH
    return None


def _engaged(me: RobotView, other: RobotView) -> bool:
    """We already resolve this collision together: I drive round / through / past the other while
    it waits for me, or we exchange with each other.

    Interpretation: the paper applies the rules "once a new possible collision is found"; we apply
    them at every step, so a pair that is already cooperating must keep its behaviours, or e.g.
    Algorithm 2 (Exchange vs a waiting robot in my channel) would stop a running exchange.
    """
    if me.partner != other.id or other.partner != me.id:
        return False
    if me.behavior is B.EXCHANGE and other.behavior is B.EXCHANGE:
        return True
    return me.behavior in (B.AVOID, B.EXCHANGE, B.GO_THROUGH) and other.behavior.is_wait


# -- the traffic rules --------------------------------------------------------------------------
# In every algorithm the switch is on the behaviour of the OTHER robot (the one in my front area);
# the result is MY new behaviour, None = keep the current one.

def solve_active_and_wait_collision(me: RobotView, other: RobotView, others_in_front: Sequence[RobotView],
                                    params: BehaviorParams = DEFAULT_PARAMS) -> Behavior:
    """SolveActiveAndWaitCollision: I am active, the other waits. Circumnavigation is delayed
    (WaitKeepDistance) when it has my goal station or stands in my critical area; otherwise it
    proceeds if no other robot in the front area is active."""
    if (not same_goal_station(me, other) and not in_critical_area(me, other, params)
            and no_other_active(me, others_in_front, other)):
        return proper_active(me, other, params)
    return B.WAIT_KEEP_DISTANCE


def solve_follow_waypoint_collision(me: RobotView, other: RobotView, others_in_front: Sequence[RobotView],
                                    params: BehaviorParams = DEFAULT_PARAMS) -> Behavior | None:
    """Algorithm 1 (I follow my waypoints)."""
    ob = other.behavior
    if ob in (B.FOLLOW_WAYPOINT, B.AVOID, B.EXCHANGE, B.GO_THROUGH):      # case 1: active, not docking
        return B.WAIT_KEEP_DISTANCE
    if ob is B.DOCK:                                                       # case 2: it docks
        return B.AVOID if collision_type(me, other, params) is not Collision.NONE else B.WAIT_KEEP_DISTANCE
    return solve_active_and_wait_collision(me, other, others_in_front, params)  # case 3: it waits


def solve_avoid_collision(me: RobotView, other: RobotView, others_in_front: Sequence[RobotView],
                          params: BehaviorParams = DEFAULT_PARAMS) -> Behavior | None:
    """Algorithm 2 (I avoid or exchange)."""
    ob, col = other.behavior, collision_type(me, other, params)
    if ob in (B.FOLLOW_WAYPOINT, B.AVOID, B.EXCHANGE):                     # case 1
        if col is Collision.REAR_END:
            return B.WAIT_KEEP_DISTANCE
        if col in (Collision.HEAD_ON, Collision.SIDE) and low_order(me, other):
            return B.WAIT_KEEP_DISTANCE
        return None
    if ob is B.GO_THROUGH:                                                 # case 2
        return B.WAIT_KEEP_DISTANCE if col is not Collision.NONE else None
    if ob is B.DOCK:                                                       # case 3
        return B.AVOID if col is not Collision.NONE else B.WAIT_KEEP_DISTANCE
    return solve_active_and_wait_collision(me, other, others_in_front, params)  # case 4


def solve_go_through_collision(me: RobotView, other: RobotView, others_in_front: Sequence[RobotView],
                               params: BehaviorParams = DEFAULT_PARAMS) -> Behavior | None:
    """Algorithm 3 (I go through an intersection)."""
    ob, col = other.behavior, collision_type(me, other, params)
    if ob in (B.FOLLOW_WAYPOINT, B.AVOID, B.EXCHANGE):                     # case 1
        return B.WAIT_KEEP_DISTANCE if col is Collision.REAR_END else None
    if ob is B.GO_THROUGH:                                                 # case 2
        if col is Collision.REAR_END:
            return B.WAIT_KEEP_DISTANCE
        if col in (Collision.HEAD_ON, Collision.SIDE) and low_order(me, other):
            return B.WAIT_KEEP_DISTANCE
        return None
    if ob is B.DOCK:                                                       # case 3
        return B.AVOID if col is not Collision.NONE else B.WAIT_KEEP_DISTANCE
    return solve_active_and_wait_collision(me, other, others_in_front, params)  # case 4


def solve_wait_keep_distance_collision(me: RobotView, other: RobotView, others_in_front: Sequence[RobotView],
                                       params: BehaviorParams = DEFAULT_PARAMS) -> Behavior | None:
    """Algorithm 4 (I wait: WaitKeepDistance or WaitForGoThrough)."""
    ob = other.behavior
    if ob in (B.AVOID, B.EXCHANGE, B.GO_THROUGH):                          # case 1
        return cooperate(other) if other.partner == me.id else None        # "Avoid me"
    if ob is B.DOCK:                                                       # case 2
        return B.AVOID if collision_type(me, other, params) is not Collision.NONE else None
    if ob.is_wait:                                                         # case 3
        if other.partner == me.id:                                         # "Wait for me": 2-robot deadlock
            return proper_active(me, other, params) if low_order(me, other) else None
        if (not same_goal_station(me, other) and not in_critical_area(me, other, params)
                and no_other_active(me, others_in_front, other)):
            return proper_active(me, other, params)
        return None
    return None                                                            # it follows its waypoints


def select_behavior(me: RobotView, other: RobotView, others_in_front: Sequence[RobotView] = (),
                    params: BehaviorParams = DEFAULT_PARAMS) -> Behavior | None:
    """My new behaviour given the robot ``other`` found by :func:`front_area_check` (None = keep).

    ``others_in_front``: every robot in my front area (the partner among them is ignored where
    the rules say "other robots"). Dispatch on MY behaviour (IV.B list), then the algorithm's
    switch on the OTHER's behaviour:

    * FollowWayPoint -> Algorithm 1; Avoid, Exchange -> Algorithm 2; GoThrough -> Algorithm 3;
      WaitKeepDistance, WaitForGoThrough -> Algorithm 4;
    * Dock -> keep moving, the others give way (IV.B.5);
    * WaitForDocking -> keep; it only backs off and gives up by distance (IV.B.8, done by the fleet).

    Interpretation, for robots standing without a path (idle, or parked on their goal): the paper
    treats an unknown obstacle as an Avoid partner, so a standing robot in my channel is avoided
    and one beside it is no reason to wait.
    """
    mine = me.behavior
    if mine in (B.DOCK, B.WAIT_FOR_DOCKING) or other.id == me.id:
        return None
    if not other.travelling:
        if in_critical_area(me, other, params):
            return None if mine is B.AVOID else B.AVOID
        return B.FOLLOW_WAYPOINT if mine.is_wait else None
    if _engaged(me, other):
        return None
    if mine is B.FOLLOW_WAYPOINT:
        return solve_follow_waypoint_collision(me, other, others_in_front, params)
    if mine in (B.AVOID, B.EXCHANGE):
        return solve_avoid_collision(me, other, others_in_front, params)
    if mine is B.GO_THROUGH:
        return solve_go_through_collision(me, other, others_in_front, params)
    return solve_wait_keep_distance_collision(me, other, others_in_front, params)


# -- docking --------------------------------------------------------------------------------
class DockingArbiter:
    """One robot docks at a station at a time (IV.A): the first to reach the docking region is
    served first; robots arriving at the same time go by priority (smaller id first).

    The robots near a station agree on this among themselves in the paper; the arbiter is that
    agreement written down (it only ever compares robots that reached the same docking region).
    """

    def __init__(self) -> None:
        self._holder: dict[str, str] = {}
        self._queue: dict[str, dict[str, tuple[float, tuple]]] = {}

    def holder(self, station: str) -> str | None:
        """The robot docking at the station now."""
        return self._holder.get(station)

    def first_waiting(self, station: str) -> str | None:
        """The robot next in line at the station."""
        queue = self._queue.get(station)
        return min(queue, key=queue.__getitem__) if queue else None

    def request(self, station: str, robot_id: str, time: float) -> bool:
        """The robot is in the docking region at ``time``; True when it may dock (now or already).

        The first request records the robot's arrival time; later ones only ask again.
        """
        if self._holder.get(station) == robot_id:
            return True
        queue = self._queue.setdefault(station, {})
        queue.setdefault(robot_id, (float(time), id_key(robot_id)))
        if station not in self._holder and self.first_waiting(station) == robot_id:
            del queue[robot_id]
            self._holder[station] = robot_id
            return True
        return False

    def withdraw(self, station: str, robot_id: str) -> None:
        """The robot gave up waiting (it will queue again, as a new arrival, when it comes back)."""
        self._queue.get(station, {}).pop(robot_id, None)

    def release(self, station: str, robot_id: str) -> None:
        """The docked robot left the docking region."""
        if self._holder.get(station) == robot_id:
            del self._holder[station]

    def keeps(self, station: str, robot_id: str) -> bool:
        """The robot still docks at the station (the arbiter never takes a station back)."""
        return self._holder.get(station) == robot_id


# -- deadlock detection (IV.C) -------------------------------------------------------------
@dataclass(frozen=True)
class WaitMessage:
    """Sent every ``wait_msg_period`` by a waiting robot to its partner: the ids of the waiting
    robots the message has passed through, the sender first."""

    waiting: tuple[str, ...]


def on_wait_message(me: RobotView, msg: WaitMessage) -> tuple[bool, WaitMessage | None]:
    """What a robot does with a WaitMessage: ``(deadlock, message to forward to my partner)``.

    A robot that does not wait ignores it; a waiting robot whose id is already in the list has
    found a wait cycle (a deadlock: it must re-plan); otherwise it appends its id and forwards
    the message to the robot it waits for.
    """
    if not me.behavior.is_wait:
        return False, None
    if me.id in msg.waiting:
        return True, None
    if me.partner is None:
        return False, None
    return False, WaitMessage(msg.waiting + (me.id,))


# -- re-planning (IV.C) ---------------------------------------------------------------------
def virtual_wall_cells(grid: GridMap, ahead: Sequence[Point], goal: Point, radius: float) -> list[tuple[int, int]]:
    """The virtual wall A* must not cross when re-planning: the cells the polyline ``ahead`` (the
    robot's position, then its next waypoint and possibly more of its path) passes through.

    Cells closer than ``radius`` to the robot or to its goal are left open (the search must start
    and end somewhere); diagonal steps also block both side cells, so the wall has no diagonal gap.
    """
    res = grid.resolution
    cells: list[tuple[int, int]] = []
    prev = None
    for (x0, y0), (x1, y1) in zip(ahead, ahead[1:]):
        n = max(1, int(math.ceil(math.hypot(x1 - x0, y1 - y0) / (res / 8))))
        for k in range(n + 1):
            c = grid.cell_of(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n)
            if c == prev:
                continue
            if prev is not None and c[0] != prev[0] and c[1] != prev[1]:
                cells += [(c[0], prev[1]), (prev[0], c[1])]
            cells.append(c)
            prev = c

    def near(c: tuple[int, int], p: Point) -> bool:
        dx = max(c[0] * res - p[0], 0.0, p[0] - (c[0] + 1) * res)
        dy = max(c[1] * res - p[1], 0.0, p[1] - (c[1] + 1) * res)
        return math.hypot(dx, dy) < radius + _EPS

    return [c for c in dict.fromkeys(cells)
            if grid.in_bounds(*c) and not near(c, ahead[0]) and not near(c, goal)]


# -- one robot ----------------------------------------------------------------------------
def _xy(p: np.ndarray) -> tuple[float, float]:
    return float(p[0]), float(p[1])


class HeardDocking:
    """The docking agreement of IV.A kept by one robot from what it hears, for robots running on
    their own (:meth:`BehaviorController.step`): every robot broadcasts the station it docks at
    (``RobotView.docked_at``) and since when it asked to (``RobotView.dock_since``).

    A robot may dock when nobody it hears docks at the station and no robot it hears waiting for
    it asked earlier (same time: the smaller id). Two robots that granted themselves the station
    before hearing of each other find out at the next step: the later one (by the same order)
    gives it up and waits (:meth:`keeps`). Same interface as :class:`DockingArbiter`.
    """

    def __init__(self, robot_id: str) -> None:
        self.id = robot_id
        self._heard: list[RobotView] = []
        self._since: dict[str, float] = {}

    def hear(self, views: Iterable[RobotView]) -> None:
        """The robots heard this step (the views they broadcast)."""
        self._heard = [v for v in views if v.id != self.id]

    def _key(self, station: str) -> tuple:
        return self._since.get(station, math.inf), id_key(self.id)

    @staticmethod
    def _order(v: RobotView) -> tuple:
        return -math.inf if v.dock_since is None else v.dock_since, id_key(v.id)

    def holder(self, station: str) -> str | None:
        held = [v for v in self._heard if v.docked_at == station]
        return min(held, key=self._order).id if held else None

    def first_waiting(self, station: str) -> str | None:
        queue = [v for v in self._heard if v.behavior is B.WAIT_FOR_DOCKING and v.station == station]
        first = min(queue, key=self._order, default=None)
        if first is None or (station in self._since and self._key(station) < self._order(first)):
            return self.id if station in self._since else None
        return first.id

    def request(self, station: str, robot_id: str, time: float) -> bool:
        self._since.setdefault(station, float(time))
        return self.holder(station) is None and self.first_waiting(station) == self.id

    def keeps(self, station: str, robot_id: str) -> bool:
        """False when a robot that asked earlier docks at the station too (a race lost)."""
        mine = self._key(station)
        return not any(v.docked_at == station and self._order(v) < mine for v in self._heard)

    def withdraw(self, station: str, robot_id: str) -> None:
        self._since.pop(station, None)

    def release(self, station: str, robot_id: str) -> None:
        self._since.pop(station, None)


class BehaviorController:
    """One BBMRCA robot: its own A* path, the traffic rules against the robots it senses, docking,
    WaitMessages and re-planning, and the motion its behaviour wants.

    It knows only what one robot can know: its own state and path, the :class:`RobotView` of the
    robots within ``comm_range`` (what they broadcast) and the :class:`WaitMessage` s addressed to
    it. :class:`BehaviorFleet` steps many of them in one simulation, with a shared
    :class:`DockingArbiter` and an exact safety layer; a robot on its own (the agent node) calls
    :meth:`step`, which adds the local safety layer (:meth:`keeps_clear`) and keeps the docking
    agreement from what it hears (:class:`HeardDocking`).

    ``docking``: a :class:`DockingArbiter` shared by simulated robots, or None for a robot on its
    own (a :class:`HeardDocking` of its own). ``finders`` may be shared between controllers on the
    same map (one :class:`PathFinder` per radius); ``first_message`` is when the robot first checks
    whether to send a WaitMessage (robots' clocks are not synchronised: spread phases make waiting
    robots seldom send at once).
    """

    def __init__(self, grid: GridMap, robot_id: str, radius: float, max_speed: float, position: Point,
                 params: BehaviorParams = DEFAULT_PARAMS, *, docking: DockingArbiter | HeardDocking | None = None,
                 finders: dict[float, PathFinder] | None = None, first_message: float = 0.0) -> None:
        for name, value in (("radius", radius), ("max_speed", max_speed)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"robot {robot_id!r}: {name} must be a finite number > 0, got {value!r}")
        start = np.asarray(position, dtype=float)
        if start.shape != (2,) or not np.all(np.isfinite(start)):
            raise ValueError(f"robot {robot_id!r}: start must be a finite (x, y), got {position!r}")
        if not grid.disc_is_free(*start, radius):
            raise ValueError(f"robot {robot_id!r}: start {_xy(start)} is not free for radius {radius}")
        self.grid, self.params = grid, params
        self.id, self.radius, self.max_speed = robot_id, float(radius), float(max_speed)
        finders = {} if finders is None else finders
        if self.radius not in finders:
            finders[self.radius] = PathFinder(grid, self.radius)
        self.finder = finders[self.radius]
        self._heard_docking = HeardDocking(robot_id) if docking is None else None
        self.docking = docking if docking is not None else self._heard_docking
        self.time = 0.0                       # the robot's clock: the time of the last call
        self.pos = start
        self.msg_tick = float(first_message)  # next time to check whether to send a WaitMessage
        self.path: np.ndarray | None = None   # waypoints still ahead, path[wp] is the next one
        self.tail: np.ndarray | None = None   # tail[k] = length of path[k:]
        self.run: np.ndarray | None = None    # run[k] = length of the straight run of the path after path[k]
        self.wp = 0
        self.goal: Point | None = None
        self.station: str | None = None
        self.holds: tuple[str, np.ndarray] | None = None  # (station, its point) while docking there
        self.dock_since: float | None = None  # when it first asked to dock at its station
        self.arrived = False
        self.behavior = B.FOLLOW_WAYPOINT
        self.partner: str | None = None
        self.since = 0.0                      # when the current behaviour began
        self.replan_after = -math.inf         # no re-plan before this time
        self.best_distance = math.inf         # closest it came to its goal since assigned
        self.progress_at = 0.0                # when it last came closer by _PROGRESS (or was assigned)
        self.side = 0                         # Avoid/Exchange: +1 pass the partner on the left, -1 right
        self.no_space = False                 # Avoid/Exchange found no free space to pass the partner
        self.blocked_since: float | None = None  # since when the wanted motion is refused
        self.off_path = False                 # pushed off its path: the way to the next waypoint hits a wall
        self.clear_at = (0.0, 0.0, -math.inf)  # (x, y, clearance there), a cache
        self.deadlocks = self.replans = self.replan_failures = 0

    # -- public ---------------------------------------------------------------------------
    @property
    def position(self) -> Point:
        return float(self.pos[0]), float(self.pos[1])

    def assign(self, goal: Point, station: str | None = None, now: float | None = None) -> None:
        """Go to ``goal`` (at ``station``, if given, which it docks at one robot at a time).

        The robot plans its own path from where it is, ignoring the other robots (paper 002, II).
        Raises ValueError for a bad goal and PlanningError when no path exists.
        """
        if now is not None:
            self.time = float(now)
        g = np.asarray(goal, dtype=float)
        if g.shape != (2,) or not np.all(np.isfinite(g)):
            raise ValueError(f"robot {self.id!r}: goal must be a finite (x, y), got {goal!r}")
        if not self.grid.disc_is_free(*g, self.radius):
            raise ValueError(f"robot {self.id!r}: goal {_xy(g)} is not free for radius {self.radius}")
        path = self.finder.find(self.position, (float(g[0]), float(g[1])))
        if path is None:
            raise PlanningError({self.id: f"no path from {self.position} to {_xy(g)}"})
        if self.station is not None and self.holds is None:
            self.docking.withdraw(self.station, self.id)
            self.dock_since = None
        self.goal, self.station, self.arrived = (float(g[0]), float(g[1])), station, False
        self._set_path(path)
        self.best_distance, self.progress_at = math.dist(self.pos, g), self.time
        self._set(B.DOCK if self.holds else B.FOLLOW_WAYPOINT, None)

    def view(self) -> RobotView:
        """What the robot broadcasts about itself."""
        nxt, remaining, straight = None, 0.0, 0.0
        if self.path is not None:
            nxt = (float(self.path[self.wp, 0]), float(self.path[self.wp, 1]))
            ahead = math.dist(self.pos, nxt)
            remaining, straight = ahead + float(self.tail[self.wp]), ahead + float(self.run[self.wp])
        return RobotView(self.id, self.position, self.radius, self.behavior, nxt, remaining, straight,
                         self.station, self.partner, self.no_space,
                         self.holds[0] if self.holds else None, self.dock_since)

    def step(self, now: float, dt: float, heard: Sequence[RobotView], inbox: Sequence[WaitMessage] = (), *,
             reach: Mapping[str, float] | None = None, speed: float | None = None,
             move: bool = True) -> list[tuple[str, WaitMessage]]:
        """One control step of a robot on its own, from ``now`` to ``now + dt``; returns the
        WaitMessages to send, as ``(receiver, message)``.

        ``heard``: the last views of the other robots (those beyond ``comm_range`` are ignored);
        ``inbox``: WaitMessages addressed to this robot since the last step (one whose sender,
        the last id in it, is out of range is dropped). ``reach``: how far each heard robot may
        have moved from the position it reported by the end of this step (for the local safety
        layer, :meth:`keeps_clear`). ``speed``: the speed it may drive at in this step (default:
        its top speed), e.g. under an acceleration limit. ``move=False`` decides and talks but
        does not move (the robot is busy, e.g. picking).
        """
        sensed = [v for v in heard if v.id != self.id and math.dist(v.position, self.pos) <= self.params.comm_range]
        if self._heard_docking is not None:
            self._heard_docking.hear(sensed)
        out = []
        in_range = {v.id for v in sensed}
        for msg in inbox:
            if msg.waiting and msg.waiting[-1] in in_range:
                forward = self.receive(now, msg, sensed)
                if forward is not None:
                    out.append(forward)
        self.decide(now, sensed)
        own = self.wait_message(now)
        if own is not None:
            out.append(own)
        if move:
            self.move(now, dt, sensed, self.keeps_clear(sensed, reach or {}), speed)
        self.track_progress(now + dt)
        return out

    def receive(self, now: float, msg: WaitMessage, sensed: Sequence[RobotView]) -> tuple[str, WaitMessage] | None:
        """A WaitMessage addressed to me: the message to forward to the robot I wait for, or None.
        A wait cycle through me (a deadlock) makes me re-plan (IV.C)."""
        self.time = float(now)
        deadlock, forward = on_wait_message(self.view(), msg)
        if deadlock:
            self.deadlocks += 1
            self._replan(sensed)
        return (self.partner, forward) if forward is not None else None

    def decide(self, now: float, sensed: Sequence[RobotView]) -> None:
        """Sensing and behaviour selection from the views of the robots in range.

        A behaviour left and taken up again within the step on the same path (e.g. Avoid completed
        for one partner and started for the next) keeps its start time, so the timeouts see one
        behaviour.
        """
        self.time = float(now)
        sensed = list(sensed)
        before, path, since, blocked_since = self.behavior, self.path, self.since, self.blocked_since
        self._select(self.view(), sensed)
        if self.behavior is before and self.path is path:
            self.since, self.blocked_since = since, blocked_since

    def wait_message(self, now: float) -> tuple[str, WaitMessage] | None:
        """The WaitMessage a waiting robot sends its partner every ``wait_msg_period``, when due."""
        period = self.params.wait_msg_period
        if now + _EPS >= self.msg_tick:
            self.msg_tick += period * (1 + math.floor((now - self.msg_tick) / period))
            if self.behavior.is_wait and self.partner is not None:
                return self.partner, WaitMessage((self.id,))
        return None

    def move(self, now: float, dt: float, sensed: Sequence[RobotView],
             robot_ok: Callable[[np.ndarray], bool] | None = None, speed: float | None = None) -> bool | None:
        """Move by the behaviour: the first motion it wants that keeps the disc in free space and
        that ``robot_ok`` (the safety layer) accepts. True when it moved, False when every wanted
        motion was refused, None when it wanted none."""
        self.time = float(now)
        candidates = self._candidates(dt, sensed, self.max_speed if speed is None else speed)
        for n_tried, (q, wp) in enumerate(candidates):
            if not self._map_clear(q):
                if n_tried == 0 and self.behavior in (B.FOLLOW_WAYPOINT, B.GO_THROUGH, B.DOCK):
                    self.off_path = True     # the straight way to the next waypoint hits a wall
                continue
            if robot_ok is not None and not robot_ok(q):
                continue
            self.pos = q
            self._advance(wp)
            self.blocked_since = None
            if self.holds is not None and math.dist(self.pos, self.holds[1]) > self.params.dock_region:
                self.docking.release(self.holds[0], self.id)   # left the docking region
                self.holds, self.dock_since = None, None
                self._set(B.FOLLOW_WAYPOINT, None)
            return True
        if not candidates:
            return None
        if self.blocked_since is None:
            self.blocked_since = self.time
        return False

    def keeps_clear(self, sensed: Sequence[RobotView], reach: Mapping[str, float]) -> Callable[[np.ndarray], bool]:
        """The local safety layer of a robot on its own: may the disc move to ``q``?

        Each other disc is grown by ``reach[id]`` (how far it may have moved since it reported)
        plus ``safety_margin``: a move into a grown disc is refused unless it increases the
        distance, a move closer than the sum of radii plus ``reach`` always. So whatever the
        other robot did since its report, this robot's own move never brings the discs together.
        """
        margin = self.params.safety_margin
        others = [(np.asarray(o.position), self.radius + o.radius + reach.get(o.id, 0.0)) for o in sensed]

        def ok(q: np.ndarray) -> bool:
            for p, hard in others:
                d_new = math.dist(q, p)
                if d_new < hard or (d_new < hard + margin and d_new < math.dist(self.pos, p)):
                    return False
            return True
        return ok

    def track_progress(self, now: float) -> None:
        """Note when the robot last came closer to its goal (for the timeouts and the stall stats)."""
        self.time = float(now)
        distance = math.dist(self.pos, self.goal) if self.path is not None else 0.0
        if distance < self.best_distance - _PROGRESS or self.path is None:
            self.best_distance, self.progress_at = distance, self.time

    # -- state --------------------------------------------------------------------------------
    def _set_path(self, path: np.ndarray) -> None:
        path = np.asarray(path, dtype=float)
        if len(path) and np.allclose(path[0], self.pos, atol=1e-9):
            path = path[1:]
        if not len(path):
            self.path = self.tail = self.run = None
            self.arrived = True
            return
        seg = np.hypot(*np.diff(path, axis=0).T)
        self.path, self.wp = path, 0
        self.tail = np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]])
        # run[k]: how far the path goes on straight after waypoint k (0 where it turns)
        self.run = np.zeros(len(path))
        d = np.diff(np.vstack([self.pos, path]), axis=0)
        for k in range(len(path) - 2, -1, -1):
            a, b = d[k], d[k + 1]
            cos = float(np.dot(a, b)) / max(math.hypot(*a) * math.hypot(*b), _EPS)
            self.run[k] = seg[k] + self.run[k + 1] if cos > _COS_STRAIGHT else 0.0
        self.blocked_since = None

    def _set(self, behavior: Behavior, partner: str | None) -> None:
        if behavior is not self.behavior or partner != self.partner:
            self.side, self.no_space = 0, False
        if behavior is not self.behavior:
            self.since = self.time
            self.blocked_since = None
        self.behavior, self.partner = behavior, partner

    # -- decisions ------------------------------------------------------------------------------
    def _select(self, me: RobotView, sensed: list[RobotView]) -> None:
        if self.holds is not None and not self.docking.keeps(self.holds[0], self.id):
            self.holds = None                   # another robot asked to dock earlier: queue again
        if self.path is None:                   # idle, or parked on its goal (docked if it holds)
            self._set(B.DOCK if self.holds else B.FOLLOW_WAYPOINT, None)
            return
        if self.holds is not None:              # IV.B.5: Dock keeps moving, the others give way
            rival = self._dock_rival(me, sensed)
            self._set(B.DOCK if rival is None else B.WAIT_KEEP_DISTANCE, None if rival is None else rival.id)
            if rival is None and self._leaving() and self._stalled() and any(
                    not o.travelling and in_critical_area(me, o, self.params) for o in sensed):
                self._replan(sensed)            # a standing robot in the way does not give way (IV.C.1)
            return
        if self.station is not None and self._docking():
            return
        path = self.path
        if self.off_path:
            self._repair()
            if self.path is None:
                return
        if self._skip_covered_waypoints(sensed) or self.path is not path:
            me = self.view()
        in_front = robots_in_front(me, sensed, self.params)
        self._complete(me, sensed, in_front)
        # traffic rules (IV.B) against the robot the front area check selects
        other = front_area_check(me, in_front, self.params)
        if other is not None:
            me = replace(me, behavior=self.behavior, partner=self.partner)
            new = select_behavior(me, other, in_front, self.params)
            if new is not None:
                self._set(new, other.id)
            elif self.behavior is B.WAIT_KEEP_DISTANCE:
                self.partner = other.id   # I wait for whoever blocks my front area now (WaitMessages go there)
        if self._failed(me, sensed, in_front):
            self._replan(sensed)

    def _leaving(self) -> bool:
        """Driving away from the station it still holds (until it is out of the docking region)."""
        return self.holds is not None and self.holds[0] != self.station and self.path is not None

    def _stalled(self) -> bool:
        """The safety layer has refused the wanted motion for longer than ``blocked_timeout``."""
        return self.blocked_since is not None and self.time - self.blocked_since > self.params.blocked_timeout

    def _dock_rival(self, me: RobotView, sensed: list[RobotView]) -> RobotView | None:
        """The Dock robot a robot leaving the station it still holds gives way to (or None).

        Interpretation: the paper's Dock drives on while the others give way, so two robots
        docking at once (here: leaving neighbouring stations towards each other) would block
        each other for good. A robot leaving its station gives way (WaitKeepDistance, backing off)
        to a moving Dock robot in its critical area that drives into its own station, or that is
        leaving too and has the higher priority (:func:`low_order`). A leaving robot stopped for
        ``blocked_timeout`` with a standing robot in its critical area (one that does not give way)
        re-plans like a FollowWayPoint robot waiting for an obstacle (IV.C.1)."""
        if not self._leaving():
            return None
        for o in robots_in_front(me, sensed, self.params):
            if (o.behavior is B.DOCK and o.travelling and in_critical_area(me, o, self.params)
                    and (o.docked_at == o.station or low_order(me, o))):
                return o
        return None

    def _complete(self, me: RobotView, sensed: list[RobotView], in_front: list[RobotView]) -> None:
        """End the running behaviour when its partner left the front area (IV.A), back to
        FollowWayPoint; WaitForGoThrough also ends when the partner stops going through."""
        b = self.behavior
        if b not in (B.AVOID, B.EXCHANGE, B.GO_THROUGH, B.WAIT_KEEP_DISTANCE, B.WAIT_FOR_GO_THROUGH):
            return
        partner = next((o for o in sensed if o.id == self.partner), None)
        done = partner is None or all(o.id != partner.id for o in in_front)
        if b is B.AVOID and partner is not None and not partner.travelling:
            done = not in_critical_area(me, partner, self.params)  # a standing obstacle: once my channel is clear
        if b is B.WAIT_FOR_GO_THROUGH and partner is not None and partner.behavior is not B.GO_THROUGH:
            done = True
        if done:
            self._set(B.FOLLOW_WAYPOINT, None)

    def _failed(self, me: RobotView, sensed: list[RobotView], in_front: list[RobotView]) -> bool:
        """The failures of IV.C, after which the robot re-plans with a virtual wall."""
        p = self.params
        stalled = self._stalled()
        no_progress = self.time - self.progress_at > p.avoid_timeout
        if self.behavior in (B.AVOID, B.EXCHANGE):                           # IV.C.2-3
            stalled = stalled or (no_progress and self.time - self.since > p.blocked_timeout)
            if self._pass_or_fail(me, sensed, in_front, stalled):
                return True
        elif self.behavior is B.GO_THROUGH:                                  # IV.C.4
            return self.time - self.since > p.go_through_timeout
        elif self.behavior is B.FOLLOW_WAYPOINT:                             # IV.C.1
            return stalled and not in_front
        # Interpretation: waiting for a standing robot in my channel that I could not drive round
        # is waiting for an obstacle (IV.C.1)
        return (self.behavior is B.WAIT_KEEP_DISTANCE and no_progress
                and any(o.id == self.partner and not o.travelling and in_critical_area(me, o, p) for o in in_front))

    def _repair(self) -> None:
        """A robot pushed off its path (by avoiding or backing off) whose straight way to the next
        waypoint is walled off plans its path again from where it is (no virtual wall: the map,
        not a robot, is in the way)."""
        self.off_path = False
        path = self.finder.find(self.position, self.goal)
        if path is not None:
            self._set_path(path)

    def _skip_covered_waypoints(self, sensed: list[RobotView]) -> bool:
        """Interpretation: a waypoint (not the goal) on which a robot stands cannot be reached; the
        robot heads for the next one instead if the straight way there is free of walls (it will
        avoid the standing robot on the way); otherwise the behaviours fail and it re-plans."""
        skipped = False
        while self.wp < len(self.path) - 1 and any(
                not o.travelling and math.dist(o.position, self.path[self.wp]) < self.radius + o.radius
                for o in sensed):
            if not self.finder.segment_free(self.position, tuple(self.path[self.wp + 1])):
                break
            self.wp += 1
            skipped = True
        return skipped

    def _docking(self) -> bool:
        """Station rules (IV.A, IV.B.8); True when they decided the robot's behaviour."""
        p = self.params
        dist = math.dist(self.pos, self.goal)
        if dist <= p.dock_region or (self.behavior is B.WAIT_FOR_DOCKING and dist <= p.dock_give_up):
            if self.dock_since is None:
                self.dock_since = self.time
            if self.docking.request(self.station, self.id, self.time):
                self.holds = (self.station, np.array(self.goal))
                self._set(B.DOCK, None)
            else:
                waiting_for = self.docking.holder(self.station) or self.docking.first_waiting(self.station)
                self._set(B.WAIT_FOR_DOCKING, waiting_for)
            return True
        if self.behavior is B.WAIT_FOR_DOCKING:  # pushed too far from the station: give up waiting
            self.docking.withdraw(self.station, self.id)
            self.dock_since = None
            self._set(B.FOLLOW_WAYPOINT, None)
        return False

    def _frame(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(u, n) of the robot's front frame."""
        if self.path is None:
            return None
        d = self.path[self.wp] - self.pos
        length = math.hypot(*d)
        if length < _EPS:
            return None
        u = d / length
        return u, np.array([-u[1], u[0]])

    def _sidestep(self, partner: RobotView, side: int) -> float:
        """Lateral offset (in my frame) that passes the partner on ``side`` with the margin."""
        u, n = self._frame()
        l_p = float(np.dot(np.asarray(partner.position) - self.pos, n))
        clear = self.radius + partner.radius + self.params.avoid_margin
        return min(0.0, l_p - clear) if side < 0 else max(0.0, l_p + clear)

    def _side_is_free(self, partner: RobotView, side: int, sensed: list[RobotView]) -> bool:
        """Free space for the sidestep: my disc fits beside me and beside the partner, clear of
        the walls and of the other robots I sense."""
        u, n = self._frame()
        lat = self._sidestep(partner, side)
        s_p = max(0.0, float(np.dot(np.asarray(partner.position) - self.pos, u)))
        for s in (0.0, s_p):
            q = self.pos + u * s + n * lat
            if not self.grid.disc_is_free(float(q[0]), float(q[1]), self.radius):
                return False
            if any(math.dist(q, o.position) < self.radius + o.radius + self.params.safety_margin
                   for o in sensed if o.id != partner.id):
                return False
        return True

    def _pass_or_fail(self, me: RobotView, sensed: list[RobotView], in_front: list[RobotView], stalled: bool) -> bool:
        """Avoid / Exchange: pick the side to pass the partner on; True when the behaviour failed
        and the robot must re-plan (IV.C.2-3). A sidestep refused by the safety layer for
        ``blocked_timeout``, or a behaviour running for that long while the robot came no closer
        to its goal for ``avoid_timeout``, counts as no free space. Robots standing without a path
        are obstacles like the partner, not "other robots"."""
        partner = next((o for o in sensed if o.id == self.partner), None)
        if partner is None or self._frame() is None:
            return False
        if self.behavior is B.EXCHANGE:
            sides = [-1]                       # both pass on their right
        else:
            c = front_coords(me, partner)
            away = -1 if c is None or c[1] >= 0 else 1
            sides = [self.side] if self.side else []
            sides += [s for s in (away, -away) if s not in sides]
        if not stalled:
            for side in sides:
                if self._side_is_free(partner, side, sensed):
                    self.side, self.no_space = side, False
                    return False
        self.side, self.no_space = 0, True
        if self.behavior is B.AVOID:
            if not any(o.id != partner.id and o.travelling for o in in_front):
                return True                    # IV.C.2: no free space, no robot but the partner in front
            self._set(B.WAIT_KEEP_DISTANCE, partner.id)
            return False
        # IV.C.3: when both exchanging robots find no free space, the lower id re-plans and the
        # higher id waits (still saying it found no space, so that the lower id learns it). A
        # partner that has not tried yet gets its turn (it cooperates with my Exchange), one with
        # room passes me while I hold still, and one that is not about me is waited for.
        about_me = partner.partner == self.id
        if (about_me and partner.no_space) or stalled:
            if id_key(self.id) < id_key(partner.id):
                return True
            self._set(B.WAIT_KEEP_DISTANCE, partner.id)
            self.no_space = True
        elif not about_me:
            self._set(B.WAIT_KEEP_DISTANCE, partner.id)
        return False

    def _replan(self, sensed: Sequence[RobotView]) -> None:
        """IV.C: a new path to the goal with a virtual wall between the robot and its next waypoint.

        Interpretation: the new path also keeps out of the robots standing in range (parked robots
        do not give way) and, where possible, of those waiting close by (what the behaviour failed
        on), by enough to keep them out of its critical area.

        A robot re-plans at most once per ``blocked_timeout``; when it cannot (or finds no path)
        it keeps its path and waits for its partner if it has one: a wait cycle is then found by
        WaitMessages and another robot in it re-plans. (Otherwise the robot the rules pick, e.g.
        the lower id of an Exchange, may re-plan back and forth between two blocked ways.)
        """
        if self.path is None or self.goal is None:
            return
        path = None
        if self.time >= self.replan_after:
            path = self._find_detour(sensed)
            self.replan_after = self.time + self.params.blocked_timeout
        if path is None:
            if self.partner is not None and self.behavior.is_active:
                self._set(B.WAIT_KEEP_DISTANCE, self.partner)
            return
        self.replans += 1
        self._set_path(path)
        self._set(B.FOLLOW_WAYPOINT, None)

    def _ahead(self) -> list[Point]:
        """Where the virtual wall goes: from the robot to its next waypoint and, when that is
        closer than a front length, on along the path for a front length (interpretation: our
        straightened paths have few waypoints, and a wall shorter than the robot's front area
        leaves the blocked way open)."""
        points, left = [self.position], self.params.front_length
        for q in self.path[self.wp:]:
            step = math.dist(points[-1], q)
            if step >= left and len(points) > 1:
                (x, y), t = points[-1], left / step
                points.append((x + (q[0] - x) * t, y + (q[1] - y) * t))
                break
            points.append((float(q[0]), float(q[1])))
            left -= step
            if left <= 0:
                break
        return points

    def _find_detour(self, sensed: Sequence[RobotView]) -> np.ndarray | None:
        """The re-planned path, or None (counted as a failed re-plan)."""
        wall = virtual_wall_cells(self.grid, self._ahead(), self.goal, self.radius)
        reach = self.params.front_length + 2 * self.radius

        def keep_out(with_waiting: bool) -> list[tuple[Point, float]]:
            return [(o.position, self.radius + o.radius + self.params.critical_margin) for o in sensed
                    if not o.travelling or (with_waiting and o.behavior.is_wait
                                            and math.dist(o.position, self.pos) <= reach + o.radius)]

        path = self.finder.find(self.position, self.goal, avoid=keep_out(True), blocked_cells=wall)
        if path is None:
            path = self.finder.find(self.position, self.goal, avoid=keep_out(False), blocked_cells=wall)
        if path is None:
            self.replan_failures += 1
        return path

    # -- motion ---------------------------------------------------------------------------------
    def _map_clear(self, q: np.ndarray) -> bool:
        """The disc at ``q`` is in free space (the clearance measured last is reused while it settles it)."""
        if self.clear_at[2] - math.dist(q, self.clear_at[:2]) < self.radius:   # not sure from the last measurement
            self.clear_at = (float(q[0]), float(q[1]), self.grid.clearance(float(q[0]), float(q[1])))
            if self.clear_at[2] < self.radius - _EPS:
                return False
        return True

    def _advance(self, wp: int) -> None:
        """Commit the waypoint index after a move; arriving at the goal ends the path."""
        if self.path is None or wp < 0:
            return
        self.wp = wp
        if wp >= len(self.path):
            self.path = self.tail = self.run = None
            self.arrived = True
            self._set(B.DOCK if self.holds else B.FOLLOW_WAYPOINT, None)

    def _along_path(self, distance: float) -> tuple[np.ndarray, int]:
        """The point ``distance`` further along the path and the index of the next waypoint there."""
        p, wp = self.pos.copy(), self.wp
        while distance > _EPS and wp < len(self.path):
            seg = self.path[wp] - p
            length = math.hypot(*seg)
            if length <= distance:
                p, distance, wp = self.path[wp].copy(), distance - length, wp + 1
            else:
                p = p + seg * (distance / length)
                distance = 0.0
        return p, wp

    def _candidates(self, dt: float, sensed: Sequence[RobotView], speed: float) -> list[tuple[np.ndarray, int]]:
        """Motions the behaviour wants this step, preferred first: ``(new position, next waypoint
        index after it)``, index -1 when the move leaves the path index unchanged."""
        if self.path is None:
            return []
        step = speed * dt
        b = self.behavior
        partner = next((o for o in sensed if o.id == self.partner), None) if self.partner is not None else None
        if b in (B.FOLLOW_WAYPOINT, B.GO_THROUGH, B.DOCK) or (b in (B.AVOID, B.EXCHANGE) and partner is None):
            return [self._along_path(step), self._along_path(step / 2)]
        if b in (B.AVOID, B.EXCHANGE):
            if not self.side:
                return []
            u, n = self._frame()
            lat = max(-step, min(step, self._sidestep(partner, self.side)))
            fwd = math.sqrt(max(step * step - lat * lat, 0.0))
            out = []
            for q in (self.pos + u * fwd + n * lat, self.pos + n * lat, self.pos + u * fwd / 2 + n * lat / 2):
                # a waypoint passed close by while stepping aside counts as reached (not the goal)
                passed = self.wp < len(self.path) - 1 and math.dist(q, self.path[self.wp]) <= step
                out.append((q, self.wp + 1 if passed else -1))
            return out
        if b is B.WAIT_FOR_GO_THROUGH and partner is not None and partner.direction is not None:
            # make the intersection free: leave the going-through robot's drive channel sideways
            du = np.asarray(partner.direction)
            rel = self.pos - np.asarray(partner.position)
            lateral = float(rel[0] * -du[1] + rel[1] * du[0])
            half = partner.radius + self.params.critical_margin / 2 + self.radius
            if float(np.dot(rel, du)) > 0 and abs(lateral) < half:
                away = np.array([-du[1], du[0]]) * (1.0 if lateral >= 0 else -1.0)
                return [(self.pos + away * min(step, half - abs(lateral) + _EPS), -1)]
        # waits: hold, backing off from a robot closer than the kept gap
        others = [partner] if b is not B.WAIT_FOR_DOCKING and partner is not None else list(sensed)
        return self._back_off(others, step / 2)

    def _back_off(self, others: Sequence[RobotView], step: float) -> list[tuple[np.ndarray, int]]:
        """Move away from the nearest of ``others`` if it is closer than ``keep_gap`` (or hold)."""
        nearest, gap = None, math.inf
        for o in others:
            g = math.dist(self.pos, o.position) - self.radius - o.radius
            if g < gap:
                nearest, gap = o, g
        if nearest is None or gap >= self.params.keep_gap:
            return []
        away = self.pos - np.asarray(nearest.position)
        length = math.hypot(*away)
        if length < _EPS:
            return []
        away /= length
        dist = min(step, self.params.keep_gap - gap)
        out = []
        for angle in (0.0, math.pi / 4, -math.pi / 4):
            c, s = math.cos(angle), math.sin(angle)
            out.append((self.pos + dist * np.array([c * away[0] - s * away[1], s * away[0] + c * away[1]]), -1))
        return out


# -- the fleet ----------------------------------------------------------------------------
@dataclass(frozen=True)
class FleetStats:
    """Counters of a :class:`BehaviorFleet` run."""

    time: float
    deadlocks: int            # wait cycles found by WaitMessages
    replans: int              # successful re-plans (deadlocks and behaviour failures)
    replan_failures: int      # re-plans that found no path (the robot kept its old one)
    refused_moves: int        # motions the safety layer refused
    stalled: tuple[str, ...]  # robots not closer to their goal for more than ``stall_time`` s, now
    longest_stall: float      # longest time any robot went without getting closer to its goal (s)


class BehaviorFleet:
    """The whole decentralised BBMRCA fleet, stepped in simulated time: one
    :class:`BehaviorController` per robot.

    Each robot plans its own path (A*, no schedule, other robots ignored), senses only robots
    within ``comm_range``, runs the front-area check and the traffic rules, and moves by its
    behaviour; WaitMessages reach robots within ``comm_range`` at the next step, and one shared
    :class:`DockingArbiter` keeps the docking agreement. Beneath the behaviours a hard safety layer
    refuses any motion that would bring two discs closer than the sum of their radii (plus
    ``safety_margin`` unless moving apart) or a disc into a wall, so a simulated run never overlaps,
    whatever the rules decide.

    ``robots``: objects with ``id``, ``radius``, ``max_speed`` and ``start`` (e.g.
    :class:`~fleet_planner.model.RobotSpec`); they stand on their start until assigned a goal.
    """

    def __init__(self, grid: GridMap, robots: Sequence, params: BehaviorParams = DEFAULT_PARAMS):
        self.grid = grid
        self.params = params
        self.time = 0.0
        self._arbiter = DockingArbiter()
        self._robots: list[BehaviorController] = []
        self._index: dict[str, int] = {}
        finders: dict[float, PathFinder] = {}
        golden = (math.sqrt(5) - 1) / 2
        for k, spec in enumerate(robots):
            rid = str(spec.id)
            if rid in self._index:
                raise ValueError(f"robots[{k}].id: duplicate id {rid!r}")
            # robots' clocks are not synchronised: each sends WaitMessages at its own phase, the
            # first one within a period (a spread phase, so that waiting robots seldom send at once)
            tick = params.wait_msg_period * (1.0 - (k * golden) % 1.0)
            self._index[rid] = k
            self._robots.append(BehaviorController(grid, rid, spec.radius, spec.max_speed, spec.start, params,
                                                   docking=self._arbiter, finders=finders, first_message=tick))
        if self._robots:
            reach = 2 * max(r.radius for r in self._robots)
            for i, j in sorted(cKDTree(self.positions()).query_pairs(reach)):
                a, b = self._robots[i], self._robots[j]
                if math.dist(a.pos, b.pos) < a.radius + b.radius:
                    raise ValueError(f"robots {a.id!r} and {b.id!r}: start discs overlap")
        self._inbox: list[tuple[str, str, WaitMessage]] = []   # (sender, receiver, message)
        self._refused = 0
        self._longest_stall = 0.0

    # -- public ---------------------------------------------------------------------------
    @property
    def ids(self) -> list[str]:
        return [r.id for r in self._robots]

    def controller(self, robot_id: str) -> BehaviorController:
        """The robot's controller (ValueError for an unknown id)."""
        try:
            return self._robots[self._index[robot_id]]
        except KeyError:
            raise ValueError(f"robot_id: unknown robot {robot_id!r}") from None

    def assign(self, robot_id: str, goal: Point, station: str | None = None) -> None:
        """Send a robot to ``goal`` (see :meth:`BehaviorController.assign`)."""
        self.controller(robot_id).assign(goal, station, self.time)

    def step(self, dt: float) -> None:
        """Advance every robot by ``dt`` seconds: messages, sensing and rules, then safe motion."""
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"step: dt must be a finite number > 0, got {dt!r}")
        near = self._neighbours()
        self._deliver(near)
        views = [r.view() for r in self._robots]
        sensed = [[views[j] for j in near[k]] for k in range(len(self._robots))]
        for k, r in enumerate(self._robots):
            r.decide(self.time, sensed[k])
        for r in self._robots:
            msg = r.wait_message(self.time)
            if msg is not None:
                self._inbox.append((r.id, *msg))
        self._move(dt, sensed, near)
        self.time += dt
        for r in self._robots:
            r.track_progress(self.time)
            self._longest_stall = max(self._longest_stall, self.time - r.progress_at)

    def positions(self) -> np.ndarray:
        """``(n, 2)`` robot positions, in the order of :attr:`ids`."""
        return np.array([r.pos for r in self._robots]).reshape(len(self._robots), 2)

    def behaviors(self) -> dict[str, Behavior]:
        return {r.id: r.behavior for r in self._robots}

    def arrived(self, robot_id: str) -> bool:
        """The robot reached the goal of its last assignment."""
        return self.controller(robot_id).arrived

    def view(self, robot_id: str) -> RobotView:
        """What the robot broadcasts about itself."""
        return self.controller(robot_id).view()

    def stats(self) -> FleetStats:
        p = self.params
        stalled = tuple(r.id for r in self._robots if self.time - r.progress_at > p.stall_time)
        return FleetStats(self.time, sum(r.deadlocks for r in self._robots), sum(r.replans for r in self._robots),
                          sum(r.replan_failures for r in self._robots), self._refused, stalled, self._longest_stall)

    # -- steps ----------------------------------------------------------------------------------
    def _neighbours(self) -> list[list[int]]:
        """For each robot, the robots within communication range (a k-d tree, so the cost grows
        with the number of neighbours, not with the fleet squared)."""
        if not self._robots:
            return []
        tree = cKDTree(self.positions())
        return [[j for j in found if j != k]
                for k, found in enumerate(tree.query_ball_point(tree.data, self.params.comm_range))]

    def _deliver(self, near: list[list[int]]) -> None:
        """Hand over last step's WaitMessages (only within communication range)."""
        inbox, self._inbox = self._inbox, []
        for sender, receiver, msg in inbox:
            k = self._index.get(receiver)
            if k is None or math.dist(self.controller(sender).pos, self._robots[k].pos) > self.params.comm_range:
                continue
            r = self._robots[k]
            forward = r.receive(self.time, msg, [self._robots[j].view() for j in near[k]])
            if forward is not None:
                self._inbox.append((r.id, *forward))

    def _move(self, dt: float, sensed: list[list[RobotView]], near: list[list[int]]) -> None:
        """Move every robot by its behaviour through the safety layer (in index order)."""
        n = len(self._robots)
        old = self.positions()
        new = old.copy()
        radii = np.array([r.radius for r in self._robots])
        cell = 2 * float(radii.max(initial=0)) + 2 * max((r.max_speed for r in self._robots), default=0) * dt \
            + self.params.safety_margin + _EPS
        grid_of: dict[tuple[int, int], list[int]] = {}
        for k in range(n):
            grid_of.setdefault((int(old[k, 0] // cell), int(old[k, 1] // cell)), []).append(k)

        def clear_of_robots(k: int, q: np.ndarray) -> bool:
            """The disc stays at least the sum of radii (plus the safety margin, unless the move
            increases the distance) from every other robot's position at the start of the step
            and, for robots moved already, its new one."""
            cx, cy = int(q[0] // cell), int(q[1] // cell)
            margin = self.params.safety_margin
            for j in (j for dx in (-1, 0, 1) for dy in (-1, 0, 1) for j in grid_of.get((cx + dx, cy + dy), ())):
                if j == k:
                    continue
                touch = radii[k] + radii[j]
                for pj in (old[j], new[j]):
                    d_new = math.dist(q, pj)
                    if d_new < touch or (d_new < touch + margin and d_new < math.dist(old[k], pj)):
                        return False
            return True

        for k, r in enumerate(self._robots):
            moved = r.move(self.time, dt, sensed[k], lambda q, k=k: clear_of_robots(k, q))
            if moved:
                new[k] = r.pos
            elif moved is False:
                self._refused += 1


# -- the safety net of a robot following a central plan ------------------------------------------
_SWEEP_STEP = 0.05  # m between the discs standing for a swept disc


def safety_stop(me: RobotView, others: Iterable[RobotView], step: float, margin: float,
                sweep: Mapping[str, tuple[float, float]] | None = None) -> RobotView | None:
    """The robot a robot following a timed path must wait for (WaitKeepDistance) rather than drive
    ``step`` metres on, or None: the closest one whose disc, grown by ``margin`` and swept along
    ``sweep[id]`` (where it may have driven by the end of the step, from its reported position: it
    may have stopped anywhere on the way), lies in my critical area reaching ``step`` beyond my
    own disc (``me.next_waypoint``: where my path goes next). The area is the paper's rectangle,
    so a disc at its front corners stops me a little earlier than it strictly has to.
    """
    if step <= 0 or not me.travelling:
        return None
    area = BehaviorParams(front_length=me.radius + step, front_width=2 * me.radius, critical_margin=0.0)
    hit = []
    for o in others:
        if o.id == me.id:
            continue
        dx, dy = (sweep or {}).get(o.id, (0.0, 0.0))
        n = 1 + int(math.ceil(math.hypot(dx, dy) / _SWEEP_STEP))
        x, y = o.position
        if any(in_critical_area(me, replace(o, position=(x + dx * k / max(n - 1, 1), y + dy * k / max(n - 1, 1)),
                                            radius=o.radius + margin), area) for k in range(n)):
            hit.append(o)
    return min(hit, key=lambda o: math.dist(o.position, me.position), default=None)
