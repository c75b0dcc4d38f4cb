"""Jobs for a fleet on the (M,D) planner: both ends of the dispatch protocol, pure (no rclpy).

* :class:`FleetManager` - the planner's side. The planner node feeds it what comes off the wire
  (:meth:`~FleetManager.submit` for tasks, :meth:`~FleetManager.on_status` for robot statuses) and
  calls :meth:`~FleetManager.step` on a timer, which returns :class:`Decisions`: new timed paths
  (:class:`Leg`) and task events to publish.
* :class:`RobotAgent` - the robot's side: a :class:`~fleet_planner.robots.RobotModel` that follows
  the legs it is sent and, where a leg ends, picks at the chute of its job, places at the storing
  site holding the job's address tag, or charges at a charger.
* :func:`load_fleet` - the robots of a fleet file (``config/fleet.yaml``) for a bring-up.

A job's life: ``accepted`` (checked against the warehouse and the robot kinds) -> queued ->
``assigned`` to the nearest online robot able to do it (capabilities, payload, battery) -> a leg
to the pick station, where the robot picks -> ``picked`` -> a leg to the storing site, where it
places -> ``placed``, ``done``. A free robot that is low on battery or idle for ``idle_s`` goes to
a free charger (or, standing at a station with no charger free, to a free parking spot).

Every leg is planned with :meth:`MDPlanner.plan_incremental` around the trajectories of all other
robots (a standing robot is a one-waypoint path), so planned discs never come closer than the sum
of radii plus the planner's margin. Legs are planned with each kind's acceleration (speed ramps
written as short constant-speed pieces, :func:`~fleet_planner.model.drive_profile`) at
``speed_factor`` f of its top speed v; a robot tracking such a leg (never ahead, see
:class:`~fleet_planner.robots.RobotModel`) lags it by at most the ramp approximation,
(f v)^2 / (8 a n^2) for n pieces per ramp, plus what it drives in one control step. The margin is
twice the largest such lag plus ``safety_margin``, so the discs as driven stay apart as well.

When things go wrong: a leg that cannot be planned now (someone is parked in the way) is tried
again at the next step, and an idle robot in the way is sent off first; a robot silent for
``offline_timeout_s`` (or out of battery) is immobile: its last position becomes a fixed obstacle,
its job goes back to the queue (or fails, if it was carrying it with an empty battery) and robots
whose legs pass near it re-plan; a robot more than ``lateness_tolerance_s`` behind its schedule
re-plans the rest of its leg from where it is, around everyone else.

Coordination (``coordination``, the same on both sides): ``central`` is all of the above. A
central robot keeps a safety net of its own: before it drives on, it checks the other robots'
reported discs against its critical area (:func:`~fleet_planner.behavior.safety_stop`), each
grown by :data:`NET_MARGIN_M` and swept along where it may drive until the end of the step, the
area reaching as far as the robot may drive itself; it waits (reporting ``waiting``) rather than
drive into one, and if that lasts, it is late and the planner re-plans it. With ``behavior`` the
robots avoid each other on their own (BBMRCA, paper 002): the planner still allocates jobs and
chargers, but a leg is only a goal (a plain A* path whose times bind nothing; no delays, no
re-planning of late robots), and the robot plans its own path there and resolves conflicts by the
behaviour rules, from the others' statuses (which then carry their BBMRCA state) and wait
messages (:class:`~fleet_planner.behavior.BehaviorController`).

Times are seconds on one clock (the planner's ROS time): ``now`` is always passed in.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from msg_schemas.records import (RecordError, RobotStatus, Schedule, Task, TaskEvent, WaitMessageRecord,
                                 robot_id_problem)

from .behavior import Behavior, BehaviorController, BehaviorParams, RobotView, WaitMessage, safety_stop
from .geometry import point_at_arc, polyline_passes_near
from .model import RAMP_PIECES, Point, PlanningError, RobotSpec, TimedPath, timed_path_from_polyline
from .paths import PathFinder
from .planners.md import MDPlanner
from .robots import RobotKind, RobotModel
from .warehouse import Station, Warehouse, config_path

PURPOSES = ("pick", "place", "charge", "park", "hold")
COORDINATION = ("central", "behavior")
ACTING = {"pick": "picking", "place": "placing"}
FLEET_FILE = "fleet.yaml"

#: a robot this close to a station's pose stands at it (robots stop exactly on the pose)
AT_STATION_M = 0.05
#: an action not seen in any status counts as finished this long after its nominal end
ACTION_SLACK_S = 2.0


class FleetError(ValueError):
    """A fleet file that cannot be used; the message names the file, the robot and the field."""


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

    RANGES = {"speed_factor": (0.05, 1.0), "safety_margin": (0.0, 5.0), "lead_s": (0.0, 60.0),
              "offline_timeout_s": (0.01, 3600.0), "lateness_tolerance_s": (0.01, 3600.0),
              "low_battery": (0.0, 1.0), "min_task_battery": (0.0, 1.0), "idle_s": (0.0, 3600.0)}

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            lo, hi = self.RANGES[f.name]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
                raise ValueError(f"{f.name}: must be a number in [{lo:g}, {hi:g}] (got {value!r})")


#: seconds between two steps of a robot's controller (the agent steps its model at its status rate)
CONTROL_PERIOD_S = 0.1


def lag_allowance(kind: RobotKind, speed_factor: float) -> float:
    """How far (m) a robot of this kind may fall behind a leg planned with its acceleration ramps at
    ``speed_factor`` of its top speed: the ramps' piecewise-constant approximation plus one control
    step of driving."""
    v = speed_factor * kind.max_speed
    ramp = 0.0 if math.isinf(kind.max_accel) else v * v / (8.0 * kind.max_accel * RAMP_PIECES ** 2)
    return ramp + v * CONTROL_PERIOD_S


def can_do(kind: RobotKind, task: Task) -> bool:
    """The kind has every capability the task needs and carries its payload."""
    return set(task.needs) <= kind.capabilities and task.payload_kg <= kind.payload_kg


# -------------------------------------------------------------------------------------------------
# what the fleet manager hands out
# -------------------------------------------------------------------------------------------------
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
    """The outcome of one :meth:`FleetManager.step`: legs to send, events to publish, log lines."""

    legs: list[Leg] = field(default_factory=list)
    events: list[TaskEvent] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class _Target:
    purpose: str
    name: str
    pose: Point


@dataclass
class _Job:
    task: Task
    pick: Station
    place: Station
    seq: int
    state: str = "queued"  # queued | active | done | failed
    robot: str | None = None
    picked: bool = False


@dataclass
class _Robot:
    """What the fleet manager knows about one robot."""

    kind: RobotKind
    status: RobotStatus
    seen: float                       # when its last status arrived
    idle_since: float
    online: bool = True
    immobile: bool = False            # offline or out of battery: a fixed obstacle
    leg: Leg | None = None            # the trajectory it follows (None: it stands where it is)
    target: _Target | None = None     # where it is going and why
    job: str | None = None
    replan: bool = False              # its leg to ``target`` must be (re)planned
    conflict: bool = False            # ... because its current leg runs into an obstacle
    arrived_at: float | None = None   # when it was first seen at the end of its leg
    saw_action: bool = False          # a status showed it picking / placing there
    last_path_id: int = -1
    trouble: str = ""                 # why its last leg could not be planned (noted once)
    stop: bool = False                # back online: stop it wherever it is heading

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
                and self.status.mode not in ("picking", "placing", "error"))

    @property
    def on_leg(self) -> bool:
        """Its status shows it on its current leg, not yet at the end."""
        return (self.leg is not None and self.status.path_id == self.leg.path_id
                and self.status.progress < 1.0)

    def trajectory(self) -> TimedPath:
        """Where it will be: its leg, or standing where its status says for ever."""
        if self.leg is not None and not self.immobile:
            return self.leg.path
        return TimedPath(self.id, self.radius, [[self.status.x, self.status.y, 0.0]])


# -------------------------------------------------------------------------------------------------
# the planner's side
# -------------------------------------------------------------------------------------------------
class FleetManager:
    """Keeps the fleet's state and turns tasks and statuses into legs and task events.

    ``kinds`` are the robot kinds robots may report (their sizes, speeds and abilities);
    ``parking`` are extra places where idle robots may wait out of the way, besides the chargers;
    ``coordination`` is how the robots avoid each other (see the module doc).
    """

    def __init__(self, warehouse: Warehouse, kinds: Mapping[str, RobotKind],
                 params: DispatchParams | None = None, parking: Sequence[Point] = (),
                 coordination: str = "central"):
        if not kinds:
            raise ValueError("kinds: at least one robot kind is needed")
        if coordination not in COORDINATION:
            raise ValueError(f"coordination: {coordination!r} is not one of {', '.join(COORDINATION)}")
        self.coordination = coordination
        self._finders: dict[float, PathFinder] = {}
        self.warehouse = warehouse
        self.kinds = dict(kinds)
        self.params = params or DispatchParams()
        largest = max(k.radius for k in self.kinds.values())
        self.parking: dict[str, Point] = {}
        for i, spot in enumerate(parking):
            x, y = (float(v) for v in spot)
            if not (math.isfinite(x) and math.isfinite(y) and warehouse.grid.disc_is_free(x, y, largest)):
                raise ValueError(f"parking[{i}]: ({x:g}, {y:g}) has no room for a robot of radius {largest:g} m")
            self.parking[f"parking_{i + 1}"] = (x, y)
        self.chargers = {s.name: s.pose for s in warehouse.stations_of("charger")}
        self.work_stops = {s.name: s.pose for s in warehouse.stations.values() if s.type != "charger"}
        self.margin = 2 * max(lag_allowance(k, self.params.speed_factor) for k in self.kinds.values()) \
            + self.params.safety_margin
        self.planner = MDPlanner(margin=self.margin)
        self.robots: dict[str, _Robot] = {}
        self.jobs: dict[str, _Job] = {}
        self._notes: list[str] = []
        self._plan_id = 0

    def set_params(self, params: DispatchParams) -> None:
        """Change thresholds at run time (not the speed factor or margin: the margin depends on them)."""
        if (params.speed_factor, params.safety_margin) != (self.params.speed_factor, self.params.safety_margin):
            raise ValueError("speed_factor and safety_margin cannot change while the fleet runs")
        self.params = params

    # -- input --------------------------------------------------------------------------------------
    def submit(self, raw: str | bytes | Mapping | Task, now: float) -> list[TaskEvent]:
        """Check a task (a Task, its dict or its JSON) and queue it: ``accepted``, or ``rejected``
        with the reason (malformed, unknown station or address tag, nobody able, duplicate id)."""
        try:
            if isinstance(raw, Task):
                task = raw
            elif isinstance(raw, (str, bytes)):
                task = Task.from_json(raw)
            else:
                task = Task.from_dict(raw)
        except RecordError as exc:
            return [_event(_guess_id(raw), "rejected", now, reason=str(exc))]
        problem = self._problem(task)
        if problem:
            return [_event(task.id, "rejected", now, reason=problem)]
        pick = self.warehouse.stations[task.pick]
        place = self._storing_site(task.place)
        self.jobs[task.id] = _Job(task, pick, place, len(self.jobs))
        return [_event(task.id, "accepted", now)]

    def _problem(self, task: Task) -> str | None:
        if task.id in self.jobs:
            return f"task.id: duplicate task id {task.id!r} (already {self.jobs[task.id].state})"
        station = self.warehouse.stations.get(task.pick)
        if station is None:
            chutes = ", ".join(s.name for s in self.warehouse.stations_of("chute"))
            return f"task.pick: unknown station {task.pick!r} (chutes: {chutes})"
        if station.type != "chute":
            return f"task.pick: station {task.pick!r} is a {station.type}, not a chute"
        if self._storing_site(task.place) is None:
            return f"task.place: unknown address tag or storing site {task.place!r}"
        if not any(can_do(k, task) for k in self.kinds.values()):
            needs = "+".join(task.needs)
            equipped = [k.payload_kg for k in self.kinds.values() if set(task.needs) <= k.capabilities]
            if not equipped:
                return f"no robot can do it: no robot kind has {needs}"
            return (f"no robot can do it: it weighs {task.payload_kg:g} kg and robots "
                    f"{'with ' + needs + ' ' if needs else ''}carry at most {max(equipped):g} kg")
        return None

    def _storing_site(self, place: str) -> Station | None:
        try:
            return self.warehouse.station_for_tag(place)
        except KeyError:
            station = self.warehouse.stations.get(place)
            return station if station is not None and station.type == "storage" else None

    def on_status(self, status: RobotStatus, now: float) -> None:
        """Take in a robot's status (``now``: when it arrived). Raises ValueError for a status that
        cannot be from a robot of this fleet (unknown kind, a kind that changed)."""
        kind = self.kinds.get(status.kind)
        if kind is None:
            raise ValueError(f"robot {status.id!r}: kind {status.kind!r} is not one of the known kinds "
                             f"({', '.join(self.kinds)})")
        r = self.robots.get(status.id)
        if r is None:
            self.robots[status.id] = _Robot(kind, status, now, now)
            self._notes.append(f"robot {status.id} ({status.kind}) joined at ({status.x:.2f}, {status.y:.2f})")
            return
        if kind is not r.kind:
            raise ValueError(f"robot {status.id!r}: reports kind {status.kind!r}, earlier {r.kind.name!r}")
        if status.stamp < r.status.stamp:
            return  # an old status overtaken by a newer one
        r.status, r.seen = status, now
        if not r.online:
            r.online, r.immobile, r.idle_since = True, status.mode == "error", now
            r.stop = not r.immobile  # it may still drive a leg the others no longer keep clear of
            self._notes.append(f"robot {r.id} is back online at ({status.x:.2f}, {status.y:.2f})")
            return
        leg, target = r.leg, r.target
        if (leg is not None and target is not None and leg.goal == target.name and not r.replan
                and status.path_id == leg.path_id and status.progress >= 1.0):
            if r.arrived_at is None:
                r.arrived_at = now
            if status.mode == ACTING.get(target.purpose):
                r.saw_action = True

    # -- the periodic decision ------------------------------------------------------------------------
    def step(self, now: float) -> Decisions:
        """Decide what changes now: offline robots, finished picks and places, late robots, legs to
        (re)plan, jobs to assign, robots to send charging or parking."""
        d = Decisions(notes=self._notes)
        self._notes = []
        self._find_immobile(now, d)
        for r in self.robots.values():
            if r.stop and r.online:
                self._hold(r, now, d)
                r.stop = False
        self._arrivals(now, d)
        self._find_late(d)
        self._replan(now, d)
        self._allocate(now, d)
        self._housekeeping(now, d)
        if d.legs:
            self._plan_id += 1
        return d

    def _find_immobile(self, now: float, d: Decisions) -> None:
        for r in self.robots.values():
            if r.online and now - r.seen > self.params.offline_timeout_s:
                r.online = False
                self._immobilise(r, now, d, f"offline: no status for {now - r.seen:.1f} s")
            elif r.online and not r.immobile and r.status.mode == "error":
                self._immobilise(r, now, d, "out of battery")

    def _immobilise(self, r: _Robot, now: float, d: Decisions, why: str) -> None:
        """``r`` stays where it was last seen for good: an obstacle. Its job goes back to the queue
        (or fails, if it holds the goods and is out of battery) and legs passing near it re-plan."""
        r.immobile = True
        r.leg, r.target, r.replan, r.conflict, r.arrived_at = None, None, False, False, None
        d.notes.append(f"robot {r.id} {why}; it is an obstacle at ({r.status.x:.2f}, {r.status.y:.2f})")
        if r.job is not None:
            job = self.jobs[r.job]
            r.job = None
            if job.picked and r.online:
                job.state = "failed"
                d.events.append(_event(job.task.id, "failed", now, r.id, f"robot {r.id} is {why} with the goods"))
            else:
                job.state, job.robot, job.picked = "queued", None, False
                d.notes.append(f"job {job.task.id} is queued again for another robot")
        if self.coordination != "central":
            return  # the robots see it and drive round it themselves
        for o in self.robots.values():
            if o is r or o.leg is None or o.immobile or o.target is None:
                continue
            if _passes_near(o.leg.path, now, r.pos, o.radius + r.radius + self.margin):
                o.replan = o.conflict = True
                d.notes.append(f"robot {o.id} re-plans around {r.id}")

    def _arrivals(self, now: float, d: Decisions) -> None:
        for r in self.robots.values():
            if r.arrived_at is None or r.target is None or not r.online:
                continue
            target = r.target
            if target.purpose in ACTING:
                if r.status.mode == ACTING[target.purpose]:
                    continue
                nominal = r.kind.action_s(target.purpose) + ACTION_SLACK_S
                if not (r.saw_action or now - r.arrived_at >= nominal):
                    continue
                job = self.jobs[r.job]
                if target.purpose == "pick":
                    job.picked = True
                    d.events.append(_event(job.task.id, "picked", now, r.id))
                    r.target = _Target("place", job.place.name, job.place.pose)
                    r.replan = True
                else:
                    job.state = "done"
                    d.events.append(_event(job.task.id, "placed", now, r.id))
                    d.events.append(_event(job.task.id, "done", now, r.id))
                    r.job, r.target, r.idle_since = None, None, now
            else:
                r.target, r.idle_since = None, now
            r.arrived_at, r.saw_action = None, False

    def _find_late(self, d: Decisions) -> None:
        if self.coordination != "central":
            return  # the times of a behaviour leg bind nothing
        for r in self.robots.values():
            if (r.target is not None and not r.replan and r.on_leg and r.status.mode != "error"
                    and r.status.lateness_s > self.params.lateness_tolerance_s):
                r.replan = True
                d.notes.append(f"robot {r.id} is {r.status.lateness_s:.1f} s late: re-planning its leg")

    def _replan(self, now: float, d: Decisions) -> None:
        """Plan the legs of robots that have somewhere to go: those that just picked first (they
        hold a chute), then those re-planning. A robot whose new leg is not yet acknowledged waits."""
        waiting = [r for r in self.robots.values() if r.replan and r.target is not None and not r.immobile
                   and r.online and (r.leg is None or r.status.path_id == r.leg.path_id)]
        waiting.sort(key=lambda r: (r.target.purpose != "place", r.id))
        for r in waiting:
            if self._plan_leg(r, r.target, now, d) is not None:
                r.replan = r.conflict = False
            elif r.conflict and r.on_leg:
                self._hold(r, now, d)

    def _hold(self, r: _Robot, now: float, d: Decisions) -> None:
        """Stop ``r`` where it is now (it keeps any target and re-plans from there); legs of others
        that pass there re-plan too. No lead time: a robot driving a leg nobody keeps clear of any
        more must stop at once, not drive on for another ``lead_s``."""
        path_id = max(round(now * 1e9), r.last_path_id + 1)
        x, y = self._start_of(r, path_id / 1e9)
        leg = Leg(r.id, TimedPath(r.id, r.radius, [[x, y, path_id / 1e9]]), path_id, "hold", "")
        self._give(r, leg, d)
        r.conflict = False
        d.notes.append(f"robot {r.id} holds at ({x:.2f}, {y:.2f})")
        for o in self.robots.values() if self.coordination == "central" else ():
            if o is not r and o.leg is not None and not o.immobile and o.target is not None and \
                    _passes_near(o.leg.path, now, (x, y), o.radius + r.radius + self.margin):
                o.replan = o.conflict = True

    def _allocate(self, now: float, d: Decisions) -> None:
        queued = sorted((j for j in self.jobs.values() if j.state == "queued"),
                        key=lambda j: (-j.task.priority, j.seq))
        for job in queued:
            pose = job.pick.pose
            if self._reserved(pose):
                continue
            able = [r for r in self.robots.values() if r.free and can_do(r.kind, job.task)
                    and r.status.battery >= self.params.min_task_battery]
            if not able:
                continue
            r = min(able, key=lambda r: (math.dist(r.pos, pose), -r.status.battery, r.id))
            occupant = self._occupant(pose, r.radius, exclude=r)
            if occupant is not None:
                if occupant.free:
                    self._send_away(occupant, now, d)
                continue
            if self._plan_leg(r, _Target("pick", job.pick.name, pose), now, d) is None:
                continue
            r.job = job.task.id
            job.state, job.robot = "active", r.id
            d.events.append(_event(job.task.id, "assigned", now, r.id))

    def _housekeeping(self, now: float, d: Decisions) -> None:
        for r in sorted(self.robots.values(), key=lambda r: r.status.battery):
            if not r.free or self._at(r.pos, self.chargers):
                continue
            low = r.status.battery < self.params.low_battery
            idle = now - r.idle_since >= self.params.idle_s
            if not (low or idle):
                continue
            spot = self._free_spot(r, self.chargers)
            if spot is not None:
                self._plan_leg(r, _Target("charge", *spot), now, d)
            elif idle and self._at(r.pos, self.work_stops):
                self._send_away(r, now, d)

    # -- helpers ---------------------------------------------------------------------------------------
    def _send_away(self, r: _Robot, now: float, d: Decisions) -> None:
        """Move a free robot that is in the way to a free charger, else to a free parking spot."""
        if self._at(r.pos, self.chargers) or self._at(r.pos, self.parking):
            return
        spot = self._free_spot(r, self.chargers)
        purpose = "charge"
        if spot is None:
            spot, purpose = self._free_spot(r, self.parking), "park"
        if spot is None:
            d.notes.append(f"robot {r.id} is in the way but no charger or parking spot is free")
            return
        self._plan_leg(r, _Target(purpose, *spot), now, d, clear_way=False)

    def _plan_leg(self, r: _Robot, target: _Target, now: float, d: Decisions,
                  clear_way: bool = True) -> Leg | None:
        """Plan ``r`` from where it is (or will be, if it is driving) to ``target``, around everyone
        else; on success ``r`` gets the leg and the target. On failure None is returned (the caller
        tries again later) and, with ``clear_way``, a free robot named as the blocker is sent off."""
        path_id = self._next_path_id(r, now)
        t0 = path_id / 1e9
        start = self._start_of(r, t0)
        if math.dist(start, target.pose) < 1e-6:
            path = TimedPath(r.id, r.radius, [[*target.pose, t0]])
        elif self.coordination == "behavior":
            path = self._plain_leg(r, start, target.pose, t0)
            if path is None:
                why = f"no way to {target.name} on the map"
                if why != r.trouble:
                    d.notes.append(f"robot {r.id}: {why}")
                r.trouble = why
                return None
        else:
            spec = RobotSpec(r.id, r.radius, r.kind.max_speed * self.params.speed_factor, start,
                             target.pose, r.kind.name,
                             r.kind.max_accel if math.isfinite(r.kind.max_accel) else None)
            others = [o.trajectory() for o in self.robots.values() if o is not r]
            try:
                path = self.planner.plan_incremental(self.warehouse.grid, [spec], others, t0)[0]
            except PlanningError as exc:
                why = f"no leg to {target.name} yet ({'; '.join(exc.failures.values())})"
                if why != r.trouble:
                    d.notes.append(f"robot {r.id}: {why}")
                r.trouble = why
                blocker = self.robots.get(exc.blockers.get(r.id, ""))
                if clear_way and blocker is not None and blocker.free:
                    self._send_away(blocker, now, d)
                return None
        leg = Leg(r.id, path, path_id, target.purpose, target.name)
        self._give(r, leg, d)
        r.target, r.trouble = target, ""
        return leg

    def _plain_leg(self, r: _Robot, start: Point, goal: Point, t0: float) -> TimedPath | None:
        """A behaviour leg: the robot's shortest path on the map, around nobody, timed at the
        planned speed from ``t0``. Only its goal binds the robot, which plans its own way there."""
        if r.radius not in self._finders:
            self._finders[r.radius] = PathFinder(self.warehouse.grid, r.radius)
        points = self._finders[r.radius].find(start, goal)
        if points is None:
            return None
        return timed_path_from_polyline(r.id, r.radius, points, r.kind.max_speed * self.params.speed_factor, t0)

    def _give(self, r: _Robot, leg: Leg, d: Decisions) -> None:
        r.leg, r.last_path_id = leg, leg.path_id
        r.arrived_at, r.saw_action = None, False
        d.legs.append(leg)

    def _next_path_id(self, r: _Robot, now: float) -> int:
        return max(round((now + self.params.lead_s) * 1e9), r.last_path_id + 1)

    def _start_of(self, r: _Robot, t0: float) -> Point:
        """Where ``r`` will be at ``t0``: where it stands, or, driving its leg, a little further along
        it at the speed its status shows (never beyond where its schedule is due); driving a path
        the manager does not know (back from offline), straight on at its velocity."""
        st = r.status
        if self.coordination != "central":
            return st.x, st.y  # it drives its own path: where it is now is all that is known
        if not r.on_leg:
            ahead = max(0.0, t0 - st.stamp) if st.mode == "driving" else 0.0
            return st.x + st.vx * ahead, st.y + st.vy * ahead
        wp = r.leg.path.waypoints
        arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(wp[:, :2], axis=0).T))])
        due = float(np.interp(t0, wp[:, 2], arc))
        s = min(st.progress * arc[-1] + math.hypot(st.vx, st.vy) * max(0.0, t0 - st.stamp), due, arc[-1])
        return point_at_arc(wp[:, :2], arc, s)

    def _occupant(self, pose: Point, radius: float, exclude: _Robot | None = None) -> _Robot | None:
        """A robot standing on, or bound for, a disc of ``radius`` at ``pose``."""
        for o in self.robots.values():
            if o is exclude:
                continue
            near = o.radius + radius
            ends = [o.pos] + ([tuple(o.leg.path.waypoints[-1, :2])] if o.leg is not None and not o.immobile else [])
            if any(math.dist(p, pose) < near for p in ends):
                return o
        return None

    def _reserved(self, pose: Point) -> bool:
        """Some robot is working at ``pose`` or has it as its target."""
        return any(o.target is not None and math.dist(o.target.pose, pose) < AT_STATION_M
                   or o.status.mode in ("picking", "placing") and math.dist(o.pos, pose) < AT_STATION_M
                   for o in self.robots.values())

    def _free_spot(self, r: _Robot, spots: Mapping[str, Point]) -> tuple[str, Point] | None:
        """The nearest spot no other robot stands on or is bound for."""
        free = [(name, p) for name, p in spots.items() if self._occupant(p, r.radius, exclude=r) is None]
        return min(free, key=lambda item: math.dist(item[1], r.pos), default=None)

    @staticmethod
    def _at(pos: Point, spots: Mapping[str, Point]) -> bool:
        return any(math.dist(pos, p) < AT_STATION_M for p in spots.values())

    # -- views for tools -------------------------------------------------------------------------------
    def trajectories(self) -> list[TimedPath]:
        """Every robot's current trajectory (absolute times)."""
        return [r.trajectory() for r in self.robots.values()]

    def statuses(self) -> list[RobotStatus]:
        return [r.status for r in self.robots.values()]

    def schedule(self, now: float) -> Schedule:
        """The current legs as a schedule record: per robot its departure delay from the leg's start
        and its travel time; priority in the order the legs were planned (later legs were planned
        around earlier ones). Collision links are not listed: legs are planned one at a time."""
        order = sorted(self.robots.values(), key=lambda r: r.leg.path_id if r.leg and not r.immobile else -1)
        nodes = {}
        for r in order:
            if r.leg is None or r.immobile:
                nodes[r.id] = {"delay": 0.0, "travel": 0.0}
            else:
                p = r.leg.path
                nodes[r.id] = {"delay": max(0.0, p.start_time - r.leg.t0),
                               "travel": max(0.0, p.arrival_time - p.start_time)}
        return Schedule(plan_id=self._plan_id, stamp=float(now), priority=tuple(nodes), nodes=nodes)


def _event(task_id: str, event: str, now: float, robot_id: str | None = None, reason: str | None = None) -> TaskEvent:
    return TaskEvent(task_id=task_id, event=event, stamp=float(now), robot_id=robot_id, reason=reason)


def _guess_id(raw: Any) -> str:
    """The ``id`` of a task that failed validation, when one can be made out (else "?")."""
    if isinstance(raw, Mapping):
        value = raw.get("id")
        return value if isinstance(value, str) and value.strip() else "?"
    if isinstance(raw, bytes):
        raw = raw.decode("utf-8", "replace")
    if isinstance(raw, str):
        try:
            return _guess_id(json.loads(raw))
        except (ValueError, AttributeError):
            m = re.search(r'"id"\s*:\s*"([^"\\]+)"', raw)
            return m.group(1) if m and m.group(1).strip() else "?"
    return "?"


def _passes_near(path: TimedPath, now: float, point: Point, dist: float) -> bool:
    """True if the part of ``path`` from ``now`` on comes closer than ``dist`` to ``point``."""
    wp = path.waypoints
    ahead = wp[wp[:, 2] > now, :2]
    pts = np.vstack([path.position(now), ahead]) if len(ahead) else np.array([path.position(now)])
    return polyline_passes_near(pts, point, dist)


def samples_to_path(robot_id: str, radius: float, samples: Sequence[tuple[float, float, float]]) -> TimedPath:
    """A timed path through position samples ``(x, y, t)`` (sorted by t, repeated times dropped),
    keeping only the first and last sample of each stretch standing still: the same trajectory,
    with far fewer waypoints for the checker."""
    wp = np.array(sorted(samples, key=lambda p: p[2]), dtype=float).reshape(-1, 3)
    wp = wp[np.concatenate([[True], np.diff(wp[:, 2]) > 0])]
    moved = np.any(np.diff(wp[:, :2], axis=0) != 0, axis=1)
    keep = np.concatenate([[True], moved]) | np.concatenate([moved, [True]])
    return TimedPath(robot_id, radius, wp[keep])


# -------------------------------------------------------------------------------------------------
# the robot's side
# -------------------------------------------------------------------------------------------------
#: a robot's status older than this (s) says it stopped reporting: it counts as standing where it was
STALE_S = 1.0
#: the safety net of a central robot keeps this much (m) beyond the sum of radii (and beyond where
#: the two may drive before the next status)
NET_MARGIN_M = 0.05
#: a behaviour-coordinated robot drives at most this long (s) per control step, however late the
#: step comes: it never jumps further than its safety layer looked
MAX_STEER_S = 2 * CONTROL_PERIOD_S
#: the behaviour layer of a robot on its own: it hears the others a status period late, so its
#: safety layer grows their discs (see BehaviorController.keeps_clear), and passes leave room for that
AGENT_BEHAVIOR = BehaviorParams(safety_margin=0.05, avoid_margin=0.3)


class RobotAgent:
    """A robot doing its jobs: it follows the legs it is sent with its :class:`RobotModel` and, where
    a leg ends, picks (at the chute of its job), places (at the storing site that holds the job's
    address tag, once it carries the goods) or charges (at a charger, with nothing to do).

    It learns its job from the ``assigned`` task event naming it and the job's stations from the
    task itself (:meth:`on_task`); if it never saw the task, any chute or storing site will do.
    It hears the other robots' statuses (:meth:`on_status`).

    ``coordination="central"``: it drives each leg's timed path, with a safety net: it waits rather
    than drive into a robot in its critical area (:meth:`tick` says how). ``"behavior"``: it takes
    only the goal of each leg (and the station there, which it docks at one robot at a time), plans
    its own path and drives it at its own speed with a :class:`BehaviorController`, from the other
    robots' statuses and the wait messages addressed to it (:meth:`on_wait_message`; the ones it
    sends come from :meth:`take_wait_messages`); its statuses carry its BBMRCA state.
    """

    KEEP_TASKS = 10_000  # task details remembered

    def __init__(self, model: RobotModel, warehouse: Warehouse, coordination: str = "central",
                 params: BehaviorParams = AGENT_BEHAVIOR):
        if coordination not in COORDINATION:
            raise ValueError(f"coordination: {coordination!r} is not one of {', '.join(COORDINATION)}")
        self.model = model
        self.warehouse = warehouse
        self.coordination = coordination
        self.tasks: dict[str, Task] = {}
        self.loaded = False
        self.heard: dict[str, RobotStatus] = {}   # the other robots' last statuses
        self.waits_for: str | None = None         # central: the robot its safety net stops for
        self.controller = None if coordination == "central" else BehaviorController(
            warehouse.grid, model.id, model.kind.radius, model.kind.max_speed, (model.x, model.y), params)
        self._leg_length = 0.0
        self._inbox: list[WaitMessage] = []
        self._outbox: list[WaitMessageRecord] = []
        self._acting: str | None = None
        self._last: float | None = None

    @property
    def job(self) -> str | None:
        return self.model.task_id

    def on_task(self, task: Task) -> None:
        if len(self.tasks) >= self.KEEP_TASKS:
            self.tasks.pop(next(iter(self.tasks)))
        self.tasks[task.id] = task

    def on_event(self, event: TaskEvent) -> None:
        """Take a job assigned to this robot; drop one given to another robot, failed or cancelled."""
        me = self.model.id
        if event.event == "assigned" and event.robot_id == me:
            self.model.task_id, self.loaded = event.task_id, False
        elif event.task_id == self.job and (event.event in ("failed", "cancelled")
                                            or event.event == "assigned" and event.robot_id != me):
            self.model.task_id, self.loaded = None, False

    def on_status(self, status: RobotStatus) -> None:
        """Another robot's status (its own and older ones than the last heard are ignored)."""
        last = self.heard.get(status.id)
        if status.id != self.model.id and (last is None or status.stamp >= last.stamp):
            self.heard[status.id] = status

    def on_wait_message(self, msg: WaitMessageRecord) -> None:
        """A wait message on the topic: taken at the next tick if it is addressed to this robot."""
        if self.controller is not None and msg.receiver == self.model.id:
            self._inbox.append(WaitMessage(tuple(msg.waiting)))

    def take_wait_messages(self) -> list[WaitMessageRecord]:
        """The wait messages this robot sent since the last call, to publish."""
        out, self._outbox = self._outbox, []
        return out

    def on_path(self, path: TimedPath, t0: float, path_id: int) -> None:
        """Follow a leg whose times count from ``t0``; ValueError if it cannot (see RobotModel.follow).
        Under behaviour coordination only its goal counts: ValueError if there is no way there."""
        if self.controller is None:
            self.model.follow(path, t0, path_id)
            return
        goal = (float(path.waypoints[-1, 0]), float(path.waypoints[-1, 1]))
        station = self._station_at(goal)
        try:
            self.controller.assign(goal, station.name if station else None,
                                   self._last if self._last is not None else t0)
        except PlanningError as exc:
            raise ValueError(f"robot {self.model.id!r}: {'; '.join(exc.failures.values())}") from None
        self.model.steer(path_id)
        self._leg_length = self.controller.view().remaining

    def tick(self, now: float) -> RobotStatus:
        """Advance to ``now``, start what is due where the robot stands, and report."""
        m = self.model
        if self._last is not None and now > self._last:
            dt = now - self._last
            if self.controller is None:
                m.step(self._last, dt, hold=self._must_wait(self._last, dt))
            else:
                self._steer(self._last, dt)
        if self._last is None or now > self._last:
            self._last = now
        if self._acting is not None and m.busy_until is None:
            if self._acting == "pick":
                self.loaded = True
            else:
                self.loaded, m.task_id = False, None
            self._acting = None
        if m.mode == "idle" and m.speed == 0.0 and m.progress >= 1.0:
            self._act(now)
        state = None if self.controller is None else behavior_state(self.controller.view())
        return RobotStatus(**m.status(now), behavior=state)

    # -- central: the safety net -------------------------------------------------------------------
    def _must_wait(self, t: float, dt: float) -> bool:
        """Whether the robot must hold this step rather than drive into another robot: one whose
        reported disc, grown by :data:`NET_MARGIN_M` and swept along the way it drives from its
        report to the end of the step (at its reported velocity), lies in the robot's critical
        area reaching as far as it may drive in the step (:func:`~fleet_planner.behavior.safety_stop`).
        Robots passing by at their planned distance are not in it: the net stays out of the plan's
        way and only stops a robot that would otherwise drive into one (which the planner then
        re-plans when it gets late)."""
        m, k = self.model, self.model.kind
        ahead = m.ahead()
        self.waits_for = None
        if ahead is None or m.busy_until is not None:
            return False
        step = min(k.max_speed, m.speed + k.max_accel * dt) * dt
        others, sweep = [], {}
        for st in self.heard.values():
            if math.hypot(st.x - m.x, st.y - m.y) > k.radius + st.radius + step + 2 * k.max_speed * STALE_S:
                continue
            ahead_s = t + dt - st.stamp
            ahead_s = ahead_s if 0.0 <= ahead_s <= STALE_S else 0.0   # a silent robot stands
            sweep[st.id] = (st.vx * ahead_s, st.vy * ahead_s)
            others.append(RobotView(st.id, (st.x, st.y), st.radius))
        blocker = safety_stop(RobotView(m.id, (m.x, m.y), k.radius, next_waypoint=ahead), others, step,
                              NET_MARGIN_M, sweep)
        self.waits_for = blocker.id if blocker is not None else None
        return blocker is not None

    # -- behaviour coordination ---------------------------------------------------------------------
    def _steer(self, t: float, dt: float) -> None:
        """One step of the behaviour controller from ``t``; the model drives where it says."""
        m, c, k = self.model, self.controller, self.model.kind
        views, reach = [], {}
        for st in self.heard.values():
            standing = t - st.stamp > STALE_S
            views.append(view_of_status(st, standing))
            reach[st.id] = 0.0 if standing else math.hypot(st.vx, st.vy) * max(0.0, t + dt - st.stamp)
        inbox, self._inbox = self._inbox, []
        free = m.busy_until is None and m.battery > 0.0
        speed = min(k.max_speed, m.speed + k.max_accel * dt)
        for receiver, msg in c.step(t, min(dt, MAX_STEER_S), views, inbox, reach=reach, speed=speed, move=free):
            self._outbox.append(WaitMessageRecord(sender=m.id, receiver=receiver, waiting=msg.waiting, stamp=t))
        if c.arrived or self._leg_length <= 0:
            progress = 1.0
        else:  # below 1 until it arrives: the planner takes 1 for "there"
            progress = min(0.999, max(0.0, 1.0 - c.view().remaining / self._leg_length))
        m.step(t, dt, to=c.position, progress=progress)

    # -- where a leg ends ---------------------------------------------------------------------------
    def _act(self, now: float) -> None:
        m = self.model
        here = self._station_at((m.x, m.y))
        task = self.tasks.get(self.job) if self.job else None
        if self.job is not None and here is not None:
            if not self.loaded and here.type == "chute" and (task is None or task.pick == here.name):
                m.start_action("pick", now)
                self._acting = "pick"
            elif self.loaded and here.type == "storage" and (task is None or task.place == here.name
                                                              or task.place in here.tags):
                m.start_action("place", now)
                self._acting = "place"
        elif self.job is None and here is not None and here.type == "charger" and m.battery < 1.0:
            m.start_charging()

    def _station_at(self, pose: Point) -> Station | None:
        return next((s for s in self.warehouse.stations.values()
                     if math.hypot(s.x - pose[0], s.y - pose[1]) < AT_STATION_M), None)


def behavior_state(view: RobotView) -> dict[str, Any]:
    """A robot's BBMRCA state as the ``behavior`` field of its status (``msg_schemas.records.BEHAVIOR_STATE``)."""
    return {"name": view.behavior.value, "next": list(view.next_waypoint) if view.next_waypoint else None,
            "remaining": view.remaining, "straight": view.straight, "station": view.station,
            "partner": view.partner, "no_space": view.no_space, "docked_at": view.docked_at,
            "dock_since": view.dock_since}


def view_of_status(status: RobotStatus, standing: bool = False) -> RobotView:
    """What a robot's status tells the behaviour layer about it. ``standing`` (it stopped reporting),
    or a status without a BBMRCA state (a robot not coordinating by behaviours): a robot with no
    path, an obstacle to drive round, unless it is seen moving (then heading where it moves)."""
    b = status.behavior
    pos = (status.x, status.y)
    if standing or b is None:
        moving = not standing and math.hypot(status.vx, status.vy) > 1e-3
        ahead = (status.x + status.vx, status.y + status.vy) if moving else None
        return RobotView(status.id, pos, status.radius, next_waypoint=ahead)
    return RobotView(status.id, pos, status.radius, Behavior(b["name"]), b["next"], b["remaining"], b["straight"],
                     b["station"], b["partner"], b["no_space"], b["docked_at"], b["dock_since"])


# -------------------------------------------------------------------------------------------------
# fleet files
# -------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FleetMember:
    """One robot of a fleet file: its id, kind, start pose and battery (fraction of full)."""

    id: str
    kind: str
    x: float
    y: float
    yaw: float = 0.0
    battery: float = 1.0


def load_fleet(path: str | Path | None = None, kinds: Mapping[str, RobotKind] | None = None,
               warehouse: Warehouse | None = None) -> list[FleetMember]:
    """The robots of a fleet file (default: the shipped ``config/fleet.yaml``), a mapping with a list
    ``robots`` of ``{id, kind, x, y[, yaw][, battery]}``. Checked: ids fit in topic names and are
    unique, kinds are among ``kinds``, numbers are finite, and (given ``warehouse``) every robot
    stands in free space clear of the others. Errors name the file, the robot and the field."""
    path = Path(path) if path is not None else config_path(FLEET_FILE)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise FleetError(f"{path}: cannot read fleet file ({exc})") from exc
    if not isinstance(data, dict) or not isinstance(data.get("robots"), list) or not data["robots"]:
        raise FleetError(f"{path}: expected a mapping with a non-empty list 'robots'")
    unknown = sorted(set(data) - {"robots"})
    if unknown:
        raise FleetError(f"{path}: unknown key(s) {', '.join(unknown)} (known: robots)")
    known = [f.name for f in fields(FleetMember)]
    out: list[FleetMember] = []
    for i, item in enumerate(data["robots"]):
        where = f"{path}: robots[{i}]"
        if not isinstance(item, dict):
            raise FleetError(f"{where}: expected a mapping with {', '.join(known)} (got {item!r})")
        bad = sorted(set(item) - set(known))
        if bad:
            raise FleetError(f"{where}.{bad[0]}: unknown field (known: {', '.join(known)})")
        for name in known[:4]:
            if name not in item:
                raise FleetError(f"{where}.{name}: missing")
        problem = robot_id_problem(item["id"])
        if problem:
            raise FleetError(f"{where}.id: {problem}")
        where = f"{path}: robot {item['id']!r}"
        if kinds is not None and item["kind"] not in kinds:
            raise FleetError(f"{where}.kind: {item['kind']!r} is not one of {', '.join(kinds)}")
        for name in ("x", "y", "yaw", "battery"):
            value = item.get(name, 0.0)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise FleetError(f"{where}.{name}: must be a finite number (got {value!r})")
        if not 0.0 <= item.get("battery", 1.0) <= 1.0:
            raise FleetError(f"{where}.battery: must be in [0, 1] (got {item['battery']!r})")
        member = FleetMember(**{k: (float(v) if k not in ("id", "kind") else v) for k, v in item.items()})
        if any(m.id == member.id for m in out):
            raise FleetError(f"{where}.id: used twice")
        if warehouse is not None and kinds is not None:
            radius = kinds[member.kind].radius
            if not warehouse.grid.disc_is_free(member.x, member.y, radius):
                raise FleetError(f"{where}: ({member.x:g}, {member.y:g}) is not free for its radius {radius:g} m")
            for m in out:
                if math.dist((m.x, m.y), (member.x, member.y)) < radius + kinds[m.kind].radius:
                    raise FleetError(f"{where}: overlaps robot {m.id!r} at the start")
        out.append(member)
    return out


__all__ = ["ACTING", "AGENT_BEHAVIOR", "COORDINATION", "DispatchParams", "Decisions", "FleetError", "FleetManager",
           "FleetMember", "Leg", "RobotAgent", "behavior_state", "can_do", "lag_allowance", "load_fleet",
           "samples_to_path", "view_of_status"]
