"""How the robots of a fleet avoid each other: the coordination mode, a strategy used on both ends.

The mode is named in the nodes' parameter ``coordination`` and is the same for the manager and every
agent. What differs between the modes is here, behind one interface, :class:`Coordination`:

* on the planner's end (:class:`~.manager.FleetManager`): how a leg is planned
  (:meth:`~Coordination.plan_leg`) from where (:meth:`~Coordination.start_of`), and whether the
  times and ways of the legs bind: a late robot re-plans (:meth:`~Coordination.is_late`), a leg
  passing near a robot that stopped re-plans (:meth:`~Coordination.must_replan_around`);
* on the robot's end (:class:`~.agent.RobotAgent`): how it drives, a :class:`Driver` per robot
  (:meth:`~Coordination.driver`): its safety net or its behaviour controller, its wait messages and
  the behaviour state its statuses carry.

``central`` (:class:`CentralCoordination`): every leg is planned around the trajectories of all
other robots and the robots drive them as timed. A central robot keeps a safety net of its own:
before it drives on, it checks the other robots' reported discs against its critical area
(:func:`~fleet_planner.behavior.safety_stop`), each grown by :data:`NET_MARGIN_M` and swept along
where it may drive until the end of the step, the area reaching as far as the robot may drive
itself; it waits (reporting ``waiting``) rather than drive into one, and if that lasts, it is late
and the planner re-plans it.

``behavior`` (:class:`BehaviorCoordination`): the robots avoid each other on their own, by the
behaviours of Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance": the planner
still allocates jobs and chargers, but a leg is only a goal (a plain A* path whose times bind
nothing; no delays, no re-planning of late robots), and the robot plans its own path there and
resolves conflicts by the behaviour rules, from the others' statuses (which then carry their
behaviour state) and wait messages (:class:`~fleet_planner.behavior.BehaviorController`).

:func:`get_coordination` looks a mode up by name; :data:`COORDINATION` are the names.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from msg_schemas.records import GateRecord, RobotStatus, WaitMessageRecord

from ..behavior import BehaviorController, BehaviorParams, RobotView, WaitMessage, safety_stop
from ..geometry import arc_lengths, point_at_arc, polyline_passes_near, segment_point_distance
from ..grid import GridMap
from ..model import PlanningError, Point, RobotSpec, TimedPath, timed_path_from_polyline
from ..paths import PathFinder
from ..planners import Planner
from ..robots import RobotModel
from ..warehouse import Warehouse
from .gate import blockers, gate_limit
from .legs import CONTROL_PERIOD_S, station_at
from .obstacles import ObstacleMap
from .state import FleetRobot, Target
from .wire import behavior_state, view_of_status

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


class LegNotPlanned(Exception):
    """No leg to a target now: ``why`` in words, and the robot in the way if one is known."""

    def __init__(self, why: str, blocker: str | None = None):
        super().__init__(why)
        self.why = why
        self.blocker = blocker


# -------------------------------------------------------------------------------------------------
# the interface
# -------------------------------------------------------------------------------------------------
class Driver(ABC):
    """How one robot drives under a coordination mode; its :class:`~.agent.RobotAgent` hands it
    the legs it is sent, the other robots' statuses and the wait messages addressed to it."""

    #: the robot it drives
    model: RobotModel
    #: the robot it holds for this step (the safety net of a central robot), if any
    waits_for: str | None = None
    #: its behaviour controller (behaviour coordination), else None
    controller: BehaviorController | None = None
    #: the obstacles the robot hears (its agent's), for its safety net
    obstacles: ObstacleMap | None = None

    @abstractmethod
    def follow(self, path: TimedPath, t0: float, path_id: int, now: float | None,
               heard: Mapping[str, RobotStatus] | None = None) -> None:
        """Take a leg whose times count from ``t0`` (``now``: the robot's last tick, None before
        the first; ``heard``: the other robots' last statuses); ValueError if it cannot."""

    @abstractmethod
    def drive(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> None:
        """Step the robot's model from ``t`` by ``dt``, given the others' last statuses."""

    def brake(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> None:
        """Step the robot's model from ``t`` by ``dt`` slowing down to a stop (its lease ran out: the
        planner does not hear it, fleet/lease.py): along its path at its ``max_accel`` by default."""
        self.model.step(t, dt, brake=True)

    @abstractmethod
    def behavior_state(self) -> dict[str, Any] | None:
        """The ``behavior`` field of the robot's status (None: it does not coordinate by behaviours)."""

    @abstractmethod
    def on_wait_message(self, msg: WaitMessageRecord) -> None:
        """A wait message addressed to this robot."""

    @abstractmethod
    def take_wait_messages(self) -> list[WaitMessageRecord]:
        """The wait messages the robot sent since the last call, to publish."""

    def on_gate(self, record: GateRecord) -> None:  # noqa: B027 - a hook most drivers ignore
        """The robot's gate record (central coordination, :mod:`.gate`); ignored by default."""

    def refused(self, path_id: int) -> None:  # noqa: B027 - a hook most drivers ignore
        """A leg the robot could not take (it stops where it is, central coordination); ignored by default."""

    def awaits_record(self, path: TimedPath, path_id: int) -> bool:
        """Whether a leg ``path_id`` that came now waits for its gate record before the robot takes it
        (it holds meanwhile, central coordination when gated); False by default."""
        return False


class Coordination(ABC):
    """A coordination mode: what differs between the modes on the planner's end and the robot's."""

    #: the name in the nodes' parameter ``coordination`` and in :data:`COORDINATION`
    name: ClassVar[str]
    #: the robots talk over the wait-message topic
    exchanges_wait_messages: ClassVar[bool] = False
    #: legs are planned around the obstacles of the intelligent space (and re-planned when one threatens them)
    plans_around_obstacles: ClassVar[bool] = False
    #: the planner sends each robot the precedence links of its legs (:mod:`.gate`)
    sends_gates: ClassVar[bool] = False

    # -- the planner's end ------------------------------------------------------------------------
    @abstractmethod
    def start_of(self, robot: FleetRobot, t0: float, limit: float = math.inf) -> Point:
        """Where ``robot`` will be at ``t0``, the start of a new leg (``limit``: how far along the
        path its status names its gate lets it drive)."""

    @abstractmethod
    def plan_leg(self, robot: FleetRobot, start: Point, target: Target, t0: float, *, grid: GridMap,
                 planner: Planner, speed: float, fleet: Iterable[FleetRobot],
                 obstacles: Sequence[TimedPath] = (), margin: float = 0.0) -> TimedPath:
        """A leg for ``robot`` from ``start`` at ``t0`` to ``target`` at ``speed`` (``fleet``: every
        robot, ``robot`` included; ``obstacles``: the predicted obstacles as trajectories, see
        :mod:`.obstacles`; ``margin``: what ``planner`` keeps between discs beyond the sum of radii);
        :class:`LegNotPlanned` if there is none now."""

    @abstractmethod
    def is_late(self, robot: FleetRobot, tolerance_s: float) -> bool:
        """Whether ``robot``, driving its leg, is so far behind the leg's times that it re-plans."""

    @abstractmethod
    def must_replan_around(self, path: TimedPath, now: float, point: Point, clearance: float) -> bool:
        """Whether a robot driving ``path`` re-plans to keep ``clearance`` from a robot that stopped
        at ``point`` (out of order, or held)."""

    # -- the robot's end --------------------------------------------------------------------------
    @abstractmethod
    def driver(self, model: RobotModel, warehouse: Warehouse, params: BehaviorParams, gated: bool = False) -> Driver:
        """How the robot of ``model`` drives (``params``: its behaviour layer, where it has one;
        ``gated``: it respects its legs' precedence links, where the mode has them)."""


# -------------------------------------------------------------------------------------------------
# central: timed paths planned around each other, a safety net on the robots
# -------------------------------------------------------------------------------------------------
class CentralCoordination(Coordination):
    """The manager plans every leg around the trajectories of all other robots; robots drive them
    as timed, with a safety net (:class:`CentralDriver`)."""

    name = "central"
    plans_around_obstacles = True
    sends_gates = True

    def start_of(self, robot: FleetRobot, t0: float, limit: float = math.inf) -> Point:
        """Where it stands, or, driving its leg, a little further along it at the speed its status
        shows (never beyond where its schedule is due, nor beyond ``limit``, where its gate holds
        it); driving a path the manager does not know (back from offline), straight on at its velocity."""
        st = robot.status
        if robot.leg is None or not robot.on_leg:
            ahead = max(0.0, t0 - st.stamp) if st.mode == "driving" else 0.0
            return st.x + st.vx * ahead, st.y + st.vy * ahead
        wp = robot.leg.path.waypoints
        arc = arc_lengths(wp)
        due = float(np.interp(t0, wp[:, 2], arc))
        done = st.travelled_m if st.travelled_m is not None else st.progress * arc[-1]
        s = min(done + math.hypot(st.vx, st.vy) * max(0.0, t0 - st.stamp), due, arc[-1])
        if s > limit:
            s = min(s, max(done, limit - 1e-3))
        return point_at_arc(wp[:, :2], arc, s)

    def plan_leg(self, robot: FleetRobot, start: Point, target: Target, t0: float, *, grid: GridMap,
                 planner: Planner, speed: float, fleet: Iterable[FleetRobot],
                 obstacles: Sequence[TimedPath] = (), margin: float = 0.0) -> TimedPath:
        """Planned with ``planner`` around the trajectories of all other robots and the obstacles
        (participants above every robot); a robot standing so near ``start`` that ``margin`` would
        forbid every leg is kept at the distance it is at now (:func:`room_to_leave`)."""
        kind = robot.kind
        spec = RobotSpec(robot.id, robot.radius, speed, start, target.pose, kind.name,
                         kind.max_accel if math.isfinite(kind.max_accel) else None)
        others = [room_to_leave(o.trajectory(), start, robot.radius, margin, t0) if not o.manual else o.trajectory()
                  for o in fleet if o is not robot] + list(obstacles)
        try:
            return planner.plan_incremental(grid, [spec], others, t0)[0]
        except PlanningError as exc:
            raise LegNotPlanned(f"no leg to {target.name} yet ({'; '.join(exc.failures.values())})",
                                exc.blockers.get(robot.id)) from exc

    def is_late(self, robot: FleetRobot, tolerance_s: float) -> bool:
        return robot.status.lateness_s > tolerance_s

    def must_replan_around(self, path: TimedPath, now: float, point: Point, clearance: float) -> bool:
        """The part of ``path`` from ``now`` on comes closer than ``clearance`` to ``point``."""
        wp = path.waypoints
        ahead = wp[wp[:, 2] > now, :2]
        pts = np.vstack([path.position(now), ahead]) if len(ahead) else np.array([path.position(now)])
        return polyline_passes_near(pts, point, clearance)

    def driver(self, model: RobotModel, warehouse: Warehouse, params: BehaviorParams, gated: bool = False) -> Driver:
        return CentralDriver(model, gated)


#: a robot standing within the planner's margin of a leg's start is planned around as a disc this much
#: (m) smaller than the distance allows (:func:`room_to_leave`): the leg keeps at least the distance less this
LEAVE_SLACK_M = 0.005


def room_to_leave(other: TimedPath, start: Point, radius: float, margin: float, t0: float) -> TimedPath:
    """``other`` (a robot's trajectory) as a leg of a robot of ``radius`` from ``start`` at ``t0`` is
    planned around it: unchanged, unless it stands from ``t0`` on (its last waypoint reached by then)
    nearer to ``start`` than the sum of radii plus ``margin``: then its disc is shrunk so that ``start``
    is just outside it grown by the margin, and the leg never comes nearer to it than it is now
    (less :data:`LEAVE_SLACK_M`). Ours.

    Why: robots stop within the planner's margin of one another (a gate holds one at
    :data:`~.gate.PAD_M`, the safety net at :data:`NET_MARGIN_M`, a robot driving on until its next
    re-plan stops it beside one that was just held), and the planner plans no leg whose start lies
    inside a standing robot's grown disc ("parks on its goal in the way" from the start on). Two
    robots stopped so, each with somewhere to go, each blocked the other for ever (test_obstacles'
    walkers with pipelined dispatch: held 0.952 m apart where the planner needed 1.032 m). Around a
    robot that stands, the margin's lag allowance is not needed either: a robot lagging its leg is
    on the leg's way, which keeps at least the distance of now from the standing disc."""
    wp = other.waypoints
    if wp[-1, 2] > t0 + 1e-9:
        return other   # it still drives after t0: the planner waits for it to leave the start
    gap = math.dist(start, (float(wp[-1, 0]), float(wp[-1, 1])))
    shrunk = gap - radius - margin - LEAVE_SLACK_M
    if shrunk >= other.radius or shrunk <= 0.0:
        return other   # clear of the start already; or nearly on it (nothing sensible to keep)
    return TimedPath(other.robot_id, shrunk, wp[-1:].copy())


#: a new leg's start this near (m) to where the robot is is where it is: no jump the safety net checks. The
#: planner plans from the positions statuses report, rounded to 0.1 mm (``fleet/robot_status@2``): a robot
#: standing within the net's reach of another refused every leg planned from its rounded position, however
#: little it moved it towards the other (100 robots on large: one robot 116 times, four others blocked by it)
JUMP_TOL_M = 1e-3

#: a robot joins a leg that started behind it if it is this close (m) to the leg's way (the leg
#: is string-pulled anew from its start, so its way beside the robot's old one differs by some cm;
#: the step onto it is checked against the other robots like the jump onto a start) ...
JOIN_TOL_M = 0.2
#: ... within this far (m) along it
JOIN_WITHIN_M = 10.0


def join_at(path: TimedPath, t0: float, pos: Point, now: float, limit: float | None = None) -> float:
    """Where (m along ``path``, whose times count from ``t0``) a robot at ``pos`` at ``now`` joins
    it: the first point of its first :data:`JOIN_WITHIN_M` within :data:`JOIN_TOL_M` of ``pos``,
    provided the schedule is due there by ``now`` (a robot never runs ahead of its schedule) or,
    with ``limit`` (a gated robot: how far its gate lets it drive along the path), short of that
    limit (the gate, not the clock, keeps it out of the others' way: a leg planned from standstill
    is due behind a robot that drove on); 0.0 if there is none (it must then stand on the start)."""
    wp = path.waypoints
    if len(wp) < 2:
        return 0.0
    arc = arc_lengths(wp)
    a, b = wp[:-1, :2], wp[1:, :2]
    p = np.asarray(pos, dtype=float)
    ab = b - a
    den = np.sum(ab * ab, axis=1)
    u = np.clip(np.sum((p - a) * ab, axis=1) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    dist = np.hypot(*(a + u[:, None] * ab - p).T)
    s = arc[:-1] + u * np.sqrt(den)
    ok = np.nonzero((dist <= JOIN_TOL_M) & (den > 0) & (s <= JOIN_WITHIN_M))[0]
    if not len(ok):
        return 0.0
    j = float(s[ok[0]])
    if limit is not None:
        return j if j < limit else 0.0
    due = float(np.interp(now - t0, wp[:, 2], arc))
    return j if j <= due + JOIN_TOL_M else 0.0


class CentralDriver(Driver):
    """A robot driving each leg's timed path, with a safety net: it waits rather than drive into a
    robot in its critical area (:meth:`must_wait` says how). ``gated``: it also never drives
    beyond what its gate record allows (:meth:`gate_holds`), whatever the clock says; the clock
    only paces it. A leg it could not take stops it where it is until the next one."""

    def __init__(self, model: RobotModel, gated: bool = False):
        self.model = model
        self.waits_for = None
        self.gated = gated
        self.gate: GateRecord | None = None
        self.stopped = False
        #: a leg that came before its gate record: the robot holds until the record comes (its agent
        #: then takes the leg, joining it where it is by the record's links: :meth:`awaits_record`)
        self.awaiting: int | None = None
        self._arc: tuple[TimedPath, np.ndarray, np.ndarray] | None = None   # its path's arc lengths (_way)

    def follow(self, path: TimedPath, t0: float, path_id: int, now: float | None,
               heard: Mapping[str, RobotStatus] | None = None) -> None:
        """Take the leg (RobotModel.follow puts the robot on its first waypoint, at most its radius
        away); ValueError, and the robot stays where it is, if that jump would bring it closer than
        the sum of radii plus :data:`NET_MARGIN_M` to a robot in ``heard`` (as the net would stop
        it driving there: a leg planned from a stale position must not put it into another).
        A robot that drove on past the leg's start while the leg was on its way joins it where it
        is (:func:`join_at`), if it lies on the leg and no further than the leg's schedule is due."""
        m = self.model
        at = 0.0
        wp0 = path.waypoints[0, :2]
        if now is not None and math.hypot(wp0[0] - m.x, wp0[1] - m.y) > m.kind.radius:
            # gated, the leg's gate (its record comes before the leg) decides how far it may be along,
            # not the clock: it joins only short of the nearest entry it must wait at
            limit = None
            if self.gated:
                limit = gate_limit(self.gate, path_id, heard or {}) if self.gate is not None else 0.0
            at = join_at(path, t0, (m.x, m.y), now, limit)
        if heard:
            start = path.waypoints[0, :2] if at == 0.0 else np.array(point_at_arc(
                path.waypoints[:, :2], arc_lengths(path.waypoints), at))
            if math.hypot(start[0] - m.x, start[1] - m.y) > JUMP_TOL_M:
                way = np.array([[m.x, m.y], start], dtype=float)
                sweep = {st.id: (0.0, 0.0) for st in heard.values()}
                others = [RobotView(st.id, (st.x, st.y), st.radius) for st in heard.values()
                          if math.hypot(st.x - m.x, st.y - m.y) < m.kind.radius * 2 + st.radius + NET_MARGIN_M]
                blocker = self._closing_in(way, others, sweep)
                if blocker is not None:
                    raise ValueError(f"robot {m.id!r}: timed path starts {math.dist(start, (m.x, m.y)):.3f} m "
                                     f"from the robot, towards robot {blocker.id!r}")
        self.model.follow(path, t0, path_id, at=at)
        self.stopped = False
        self.awaiting = None

    def refused(self, path_id: int) -> None:
        self.stopped = True  # the planner no longer keeps the others clear of the old leg's rest
        self.awaiting = None

    def awaits_record(self, path: TimedPath, path_id: int) -> bool:
        """Gated, a leg that starts farther than the robot's radius from it (it must join it where it
        is, :func:`join_at`, short of where the leg's gate record holds it) and whose record has not
        come yet waits for the record, and the robot holds meanwhile (as it does when the record comes
        first: its record is then for a leg it does not drive). Ours: the record and the leg travel on
        two topics, and under load the leg often came first; taken at once, a robot that had driven on
        past the leg's start could not join it (no record: nothing to join short of) and refused it,
        standing in others' way until a re-plan reached it (bench_dispatch --delay 6: 12 of 17
        refusals in the first 200 s)."""
        m = self.model
        if not self.gated or (self.gate is not None and self.gate.path_id >= path_id):
            return False
        x, y = path.waypoints[0, :2]
        if math.hypot(x - m.x, y - m.y) <= m.kind.radius:
            return False   # it takes it where it stands, and waits there for the record
        self.awaiting = path_id
        return True

    def on_gate(self, record: GateRecord) -> None:
        """Keep the newest record (by path, then ``seq``); one for a later leg than the one it awaits
        overtook that leg (dropped by its agent: the later leg comes)."""
        if self.gate is None or (record.path_id, record.seq) >= (self.gate.path_id, self.gate.seq):
            self.gate = record
        if self.awaiting is not None and record.path_id > self.awaiting:
            self.awaiting = None

    def _holds(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> bool:
        """Whether the robot stands this step: the safety net, a refused leg, a leg awaiting its record, the gate."""
        return (self.must_wait(t, dt, heard) or self.stopped or self.awaiting is not None
                or self.gate_holds(dt, heard))

    def drive(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> None:
        self.model.step(t, dt, hold=self._holds(t, dt, heard))

    def brake(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> None:
        """Slow down to a stop along the path, but hold at once where driving would (the safety net, the
        gate, a refused leg, a leg awaiting its record): braking never takes it where driving may not."""
        hold = self._holds(t, dt, heard)
        self.model.step(t, dt, hold=hold, brake=not hold)

    def gate_holds(self, dt: float, heard: Mapping[str, RobotStatus]) -> bool:
        """Whether this step could take the robot beyond where its gate lets it drive (the nearest
        entry of a region whose robot ranked above has not reported leaving it; the start of a
        leg whose record has not come)."""
        m, k = self.model, self.model.kind
        if not self.gated or m.path is None or m.busy_until is not None or m.progress >= 1.0:
            return False
        limit = gate_limit(self.gate, m.path_id, heard)
        if math.isinf(limit):
            return False
        step = min(k.max_speed * (1 + 1e-9), m.speed + k.max_accel * dt) * dt
        if m.travelled + step <= limit:
            return False
        waits = blockers(self.gate, heard, m.travelled + step) if self.gate is not None else []
        self.waits_for = waits[0] if waits else self.waits_for
        return True

    def behavior_state(self) -> dict[str, Any] | None:
        return None

    def on_wait_message(self, msg: WaitMessageRecord) -> None:
        pass  # a central robot waits for nobody's messages

    def take_wait_messages(self) -> list[WaitMessageRecord]:
        return []

    def must_wait(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> bool:
        """Whether the robot must hold this step rather than drive into another robot: one whose
        reported disc, grown by :data:`NET_MARGIN_M` and swept along the way it drives from its
        report to the end of the step (at its reported velocity), lies in the robot's critical
        area reaching as far as it may drive in the step (:func:`~fleet_planner.behavior.safety_stop`);
        the obstacles it hears (:attr:`Driver.obstacles`) likewise, swept along their velocity.
        Robots passing by at their planned distance are not in it: the net stays out of the plan's
        way and only stops a robot that would otherwise drive into one (which the planner then
        re-plans when it gets late)."""
        m, k = self.model, self.model.kind
        ahead = m.ahead()
        self.waits_for = None
        if ahead is None or m.busy_until is not None:
            return False
        step = min(k.max_speed * (1 + 1e-9), m.speed + k.max_accel * dt) * dt
        others, sweep = [], {}
        for st in heard.values():
            # swept to the end of the step at its reported velocity, unless it was silent already
            # when the step began (then it stands: a step longer than STALE_S sweeps it all the same)
            age = t - st.stamp
            ahead_s = t + dt - st.stamp if 0.0 <= age <= STALE_S else 0.0
            dx, dy = st.vx * ahead_s, st.vy * ahead_s
            if math.hypot(st.x - m.x, st.y - m.y) > k.radius + st.radius + step + math.hypot(dx, dy) + 2 * NET_MARGIN_M:
                continue
            sweep[st.id] = (dx, dy)
            others.append(RobotView(st.id, (st.x, st.y), st.radius))
        if self.obstacles is not None:  # people, vehicles, pallets: stopped for like robots
            for oid, (ox, oy), radius, (dx, dy) in self.obstacles.net_discs(t, dt, STALE_S):
                if math.hypot(ox - m.x, oy - m.y) <= k.radius + radius + step + math.hypot(dx, dy):
                    sweep[oid] = (dx, dy)
                    others.append(RobotView(oid, (ox, oy), radius))
        if self.gated:
            blocker = self._closing_in(self._way(step), others, sweep)
        else:
            blocker = safety_stop(RobotView(m.id, (m.x, m.y), k.radius, next_waypoint=ahead), others, step,
                                  NET_MARGIN_M, sweep)
        self.waits_for = blocker.id if blocker is not None else None
        return blocker is not None

    def _way(self, step: float) -> np.ndarray:
        """The polyline the robot may drive along its path in a step of ``step`` m: from where it
        is through every vertex within ``step`` to the point ``step`` along (however densely the
        path has vertices: the whole of the step is looked at, not only up to the next vertex)."""
        m = self.model
        assert m.path is not None
        cached = self._arc
        if cached is None or cached[0] is not m.path:
            wp = m.path.waypoints[:, :2]
            cached = self._arc = (m.path, wp, arc_lengths(wp))
        _, wp, arc = cached
        s0 = m.travelled
        s1 = min(s0 + step, float(arc[-1]))
        inner = (arc > s0) & (arc < s1)
        end = point_at_arc(wp, arc, s1)
        return np.vstack([[m.x, m.y], wp[inner], [end]])

    def _closing_in(self, way: np.ndarray, others: list[RobotView],
                    sweep: Mapping[str, tuple[float, float]]) -> RobotView | None:
        """The safety net of a gated robot: the closest robot whose disc (swept as above) the step
        along ``way`` (:meth:`_way`) would bring closer than the sum of radii plus
        :data:`NET_MARGIN_M`. A disc, not the behaviours' rectangle, so that it never stops a robot
        its gate lets pass (the gate keeps :data:`~.gate.PAD_M` > NET_MARGIN_M between the discs)."""
        m = self.model
        here = way[0]
        if len(way) < 2 or not np.any(np.hypot(*(way[1:] - here).T) > 0.0):
            return None
        a, b = way[:-1], way[1:]
        hit = []
        for o in others:
            dx, dy = sweep.get(o.id, (0.0, 0.0))
            n = 1 + math.ceil(math.hypot(dx, dy) / 0.05)
            pts = np.array(o.position) + np.outer(np.linspace(0.0, 1.0, n), [dx, dy])
            near = float(np.min(segment_point_distance(a[:, None, :], b[:, None, :], pts[None, :, :])))
            now = float(np.min(np.hypot(*(pts - here).T)))
            if near < m.kind.radius + o.radius + NET_MARGIN_M and near < now - 1e-9:
                hit.append(o)
        return min(hit, key=lambda o: math.dist(o.position, (m.x, m.y)), default=None)


# -------------------------------------------------------------------------------------------------
# behaviour: goals only, the robots resolve conflicts themselves
# -------------------------------------------------------------------------------------------------
class BehaviorCoordination(Coordination):
    """The manager gives goals (a plain A* path, around nobody, whose times bind nothing); robots
    plan their own way and resolve conflicts by the behaviour rules (:class:`BehaviorDriver`)."""

    name = "behavior"
    exchanges_wait_messages = True

    def __init__(self) -> None:
        self._finders: dict[tuple[int, float], PathFinder] = {}  # (id of the map, radius) -> finder

    def start_of(self, robot: FleetRobot, t0: float, limit: float = math.inf) -> Point:
        """Where its status says it is: it drives its own path, so where it is now is all that is known."""
        return robot.status.x, robot.status.y

    def plan_leg(self, robot: FleetRobot, start: Point, target: Target, t0: float, *, grid: GridMap,
                 planner: Planner, speed: float, fleet: Iterable[FleetRobot],
                 obstacles: Sequence[TimedPath] = (), margin: float = 0.0) -> TimedPath:
        """The robot's shortest path on the map, around nobody, timed at ``speed`` from ``t0``. Only
        its goal binds the robot, which plans its own way there."""
        points = self._finder(grid, robot.radius).find(start, target.pose)
        if points is None:
            raise LegNotPlanned(f"no way to {target.name} on the map")
        return timed_path_from_polyline(robot.id, robot.radius, points, speed, t0)

    def _finder(self, grid: GridMap, radius: float) -> PathFinder:
        key = (id(grid), radius)  # the finder keeps the map alive, so its id stays its own
        if key not in self._finders:
            self._finders[key] = PathFinder(grid, radius)
        return self._finders[key]

    def is_late(self, robot: FleetRobot, tolerance_s: float) -> bool:
        return False  # the times of a behaviour leg bind nothing

    def must_replan_around(self, path: TimedPath, now: float, point: Point, clearance: float) -> bool:
        return False  # the robots see it and drive round it themselves

    def driver(self, model: RobotModel, warehouse: Warehouse, params: BehaviorParams, gated: bool = False) -> Driver:
        return BehaviorDriver(model, warehouse, params)


class BehaviorDriver(Driver):
    """A robot that takes only the goal of each leg (and the station there, which it docks at one
    robot at a time), plans its own path and drives it at its own speed with a
    :class:`~fleet_planner.behavior.BehaviorController`, from the other robots' statuses and the
    wait messages addressed to it; its statuses carry its behaviour state."""

    controller: BehaviorController

    def __init__(self, model: RobotModel, warehouse: Warehouse, params: BehaviorParams):
        self.model = model
        self.warehouse = warehouse
        self.controller = BehaviorController(warehouse.grid, model.id, model.kind.radius, model.kind.max_speed,
                                             (model.x, model.y), params)
        self._leg_length = 0.0
        self._inbox: list[WaitMessage] = []
        self._outbox: list[WaitMessageRecord] = []

    def follow(self, path: TimedPath, t0: float, path_id: int, now: float | None,
               heard: Mapping[str, RobotStatus] | None = None) -> None:
        """Only the leg's goal counts: ValueError if there is no way there."""
        goal = (float(path.waypoints[-1, 0]), float(path.waypoints[-1, 1]))
        station = station_at(self.warehouse, goal)
        try:
            self.controller.assign(goal, station.name if station else None, now if now is not None else t0)
        except PlanningError as exc:
            raise ValueError(f"robot {self.model.id!r}: {'; '.join(exc.failures.values())}") from None
        self.model.steer(path_id)
        self._leg_length = self.controller.view().remaining

    def drive(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> None:
        """One step of the behaviour controller from ``t``; the model drives where it says."""
        m, c, k = self.model, self.controller, self.model.kind
        views, reach = [], {}
        for st in heard.values():
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

    def behavior_state(self) -> dict[str, Any] | None:
        return behavior_state(self.controller.view())

    def on_wait_message(self, msg: WaitMessageRecord) -> None:
        self._inbox.append(WaitMessage(tuple(msg.waiting)))

    def take_wait_messages(self) -> list[WaitMessageRecord]:
        out, self._outbox = self._outbox, []
        return out


# -------------------------------------------------------------------------------------------------
# lookup by name
# -------------------------------------------------------------------------------------------------
_REGISTRY: dict[str, type[Coordination]] = {c.name: c for c in (CentralCoordination, BehaviorCoordination)}

#: the names of the coordination modes (the values of the nodes' parameter ``coordination``)
COORDINATION = tuple(_REGISTRY)


def coordination_names() -> list[str]:
    return list(_REGISTRY)


def get_coordination(name: str | Coordination) -> Coordination:
    """A coordination mode by name (a fresh one; a :class:`Coordination` is returned as it is);
    ValueError naming the modes for an unknown name."""
    if isinstance(name, Coordination):
        return name
    cls = _REGISTRY.get(name) if isinstance(name, str) else None
    if cls is None:
        raise ValueError(f"coordination: {name!r} is not one of {', '.join(_REGISTRY)}")
    return cls()
