"""Jobs for a fleet of warehouse robots: both ends of the dispatch protocol, pure (no rclpy).

Where each concept lives:

* :mod:`.legs` - what the manager hands out and the numbers that shape it: :class:`Leg`,
  :class:`Decisions`, :class:`DispatchParams`, :func:`lag_allowance`, the leg purposes;
* :mod:`.jobstore` - the durable job store, :class:`JobStore` (SQLite): every accepted job and its
  state changes, so a restarted manager takes up the open jobs;
* :mod:`.state` - what the manager knows: its robots, jobs and targets, and :func:`can_do`;
* :mod:`.manager` - the planner's end, :class:`FleetManager`: tasks and statuses in, legs and task
  events out;
* :mod:`.agent` - the robot's end, :class:`RobotAgent`: a robot model following its legs and
  picking, placing and charging where they end;
* :mod:`.lease` - a robot the planner cannot hear stops: :class:`~.lease.Lease` (the robot's end) and
  the planner's heard records and the way it keeps for a robot marked offline until it must have stopped;
* :mod:`.coordination` - the coordination mode, a strategy used on both ends: :class:`Coordination`
  (:class:`CentralCoordination`, :class:`BehaviorCoordination`), looked up by name with
  :func:`get_coordination`; how a robot drives under it, a :class:`Driver`;
* :mod:`.operator` - the operator's commands on the manager, :class:`~.operator.Operator`: pause,
  e-stop, cancel, priority, send to a station, manual drive and deadlines as the plan sees them;
* :mod:`.manual` - the operator's hand on the robot, :class:`~.manual.OperatorHand`: the e-stop and
  manual drive by velocity commands (:func:`~.manual.check_twist`);
* :mod:`.wire` - status <-> behaviour views (:func:`view_of_status`, :func:`behavior_state`) and
  status samples as a timed path (:func:`samples_to_path`);
* :mod:`.fleet_file` - the robots of a bring-up (:func:`load_fleet`, :class:`FleetMember`,
  :class:`FleetError`).

A job's life: ``accepted`` (checked against the warehouse and the robot kinds) -> queued ->
``assigned`` to the nearest online robot able to do it (capabilities, payload, battery) -> a leg
to the pick station, where the robot picks -> ``picked`` -> a leg to the storing site, where it
places -> ``placed``, ``done``. A free robot that is low on battery or idle for ``idle_s`` goes to
a free charger (or, standing at a station with no charger free, to a free parking spot).

Coordination (``coordination``, the same on both ends): ``central``, the robots drive the timed
paths the manager plans around each other, with a safety net of their own; ``behavior``, the
robots avoid each other on their own by the behaviours of Sun, Kleiner & Nebel, "Behavior-based
Multi-Robot Collision Avoidance", and the manager only allocates jobs and chargers and gives goals.
The topics both ends talk over are described in docs/ARCHITECTURE.md.
"""
from .agent import RobotAgent
from .coordination import (
    AGENT_BEHAVIOR,
    COORDINATION,
    BehaviorCoordination,
    CentralCoordination,
    Coordination,
    Driver,
    LegNotPlanned,
    coordination_names,
    get_coordination,
)
from .fleet_file import FleetError, FleetMember, load_fleet
from .jobstore import DuplicateJob, JobStore
from .legs import ACTING, PURPOSES, Decisions, DispatchParams, Leg, lag_allowance
from .manager import FleetManager
from .state import can_do
from .wire import behavior_state, samples_to_path, view_of_status

__all__ = ["ACTING", "AGENT_BEHAVIOR", "COORDINATION", "PURPOSES", "BehaviorCoordination", "CentralCoordination",
           "Coordination", "Decisions", "DispatchParams", "Driver", "DuplicateJob", "FleetError", "FleetManager",
           "FleetMember", "JobStore", "Leg", "LegNotPlanned", "RobotAgent", "behavior_state", "can_do",
           "coordination_names", "get_coordination", "lag_allowance", "load_fleet", "samples_to_path",
           "view_of_status"]
