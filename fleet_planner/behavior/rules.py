"""The traffic rules of Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance"
(ICRA 2014), section IV.B, as pure functions of :class:`~.views.RobotView` s.

:func:`select_behavior` is the entry point: it dispatches on my behaviour to Algorithms 1-4
(:func:`solve_follow_waypoint_collision`, :func:`solve_avoid_collision`,
:func:`solve_go_through_collision`, :func:`solve_wait_keep_distance_collision`) and
SolveActiveAndWaitCollision, with the paper's helpers :func:`low_order` (priority),
:func:`no_other_active` and :func:`same_goal_station`. :func:`id_key` is the order of robot ids
that breaks ties here and in docking. Where the paper leaves a choice open, the choice and its
reason are written where it is made ("Interpretation").
"""
from __future__ import annotations

import re
from collections.abc import Sequence

from ..model import Behavior
from .areas import Collision, collision_type, in_critical_area
from .params import DEFAULT_PARAMS, BehaviorParams
from .views import RobotView

B = Behavior

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
