"""BBMRCA: the behaviour-based multi-robot collision avoidance of Sun, Kleiner & Nebel,
"Behavior-based Multi-Robot Collision Avoidance" (ICRA 2014), section IV; no rclpy.

Every robot plans its own A* path without looking at the others and drives it; when another robot
shows up in its *front area* it picks one of eight behaviours (:class:`~fleet_planner.model.Behavior`)
by the paper's traffic rules. The rules are pure and separately testable; one robot wraps them in a
controller, and many robots make a steppable fleet. By concern, innermost first:

* :mod:`.params`     - :class:`BehaviorParams`, the tuning (metres, seconds);
* :mod:`.views`      - :class:`RobotView`, what a robot knows of itself or hears from a neighbour;
* :mod:`.areas`      - the geometry of traffic: front and critical areas, :func:`front_area_check`,
  :func:`collision_type` (rear-end / head-on / side);
* :mod:`.clearance`  - a robot's distance to the walls from the blocked cells around it (compiled;
  the map's GEOS distance was a large part of a 100-robot step);
* :mod:`.rules`      - the traffic rules: :func:`select_behavior` (Algorithms 1-4,
  SolveActiveAndWaitCollision), :func:`low_order`, :func:`id_key`;
* :mod:`.docking`    - one robot docks at a station at a time: :class:`DockingArbiter` (shared),
  :class:`HeardDocking` (from what one robot hears);
* :mod:`.deadlock`   - wait cycles found by :class:`WaitMessage` s, left by re-planning behind a
  virtual wall (:func:`virtual_wall_cells`);
* :mod:`.controller` - :class:`BehaviorController`, one robot (the agent node in
  ``coordination:=behavior`` calls its ``step``); also our *retreat waves* (issue 13), which let
  chains of robots facing each other in a one-cell aisle back out robot by robot, where the
  paper's WaitMessages and re-planning leave them re-planning back and forth; *escapes* (ours,
  after IV.B.8): a robot whose re-plan finds no way, or that made no progress for
  ``escape_after``, moves into a less crowded place nearby and re-plans from there; and waiting
  robots give way to a Dock robot (IV.B.5);
* :mod:`.simulation` - :class:`BehaviorFleet`, the decentralised fleet as one simulation;
* :mod:`.safety`     - :func:`safety_stop`, the critical area as the safety net of a robot that
  follows a central plan.

Where the paper leaves a choice open, the choice and its reason are written where it is made
(search for "Interpretation"). ``Behavior`` itself lives in :mod:`fleet_planner.model` (it is on
the wire); it is re-exported here for the callers of the behaviour layer.
"""
from ..model import Behavior
from .areas import (
    HEAD_ON_MIN_ANGLE_DEG,
    REAR_END_MAX_ANGLE_DEG,
    Collision,
    collision_type,
    front_area_check,
    front_coords,
    in_critical_area,
    in_front_area,
    robots_in_front,
)
from .controller import BehaviorController
from .deadlock import WaitMessage, on_wait_message, virtual_wall_cells
from .docking import Docking, DockingArbiter, HeardDocking
from .params import DEFAULT_PARAMS, BehaviorParams
from .rules import (
    cooperate,
    id_key,
    low_order,
    no_other_active,
    proper_active,
    same_goal_station,
    select_behavior,
    solve_active_and_wait_collision,
    solve_avoid_collision,
    solve_follow_waypoint_collision,
    solve_go_through_collision,
    solve_wait_keep_distance_collision,
)
from .safety import safety_stop
from .simulation import BehaviorFleet, FleetStats
from .views import RobotView

__all__ = [
    "Behavior",
    # params, views
    "DEFAULT_PARAMS", "BehaviorParams", "RobotView",
    # areas
    "HEAD_ON_MIN_ANGLE_DEG", "REAR_END_MAX_ANGLE_DEG", "Collision", "collision_type", "front_area_check",
    "front_coords", "in_critical_area", "in_front_area", "robots_in_front",
    # rules
    "cooperate", "id_key", "low_order", "no_other_active", "proper_active", "same_goal_station", "select_behavior",
    "solve_active_and_wait_collision", "solve_avoid_collision", "solve_follow_waypoint_collision",
    "solve_go_through_collision", "solve_wait_keep_distance_collision",
    # docking, deadlock
    "Docking", "DockingArbiter", "HeardDocking", "WaitMessage", "on_wait_message", "virtual_wall_cells",
    # one robot, the fleet, the safety net
    "BehaviorController", "BehaviorFleet", "FleetStats", "safety_stop",
]
