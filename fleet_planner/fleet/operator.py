"""The operator's hand on the planner's end (paper 001's remote-operated controller): pause and
resume, e-stop, cancel a job, change its priority, send a robot to a station, and what manual
drive and deadlines mean for the plan. :class:`Operator` drives a
:class:`~.manager.FleetManager` through small, named methods; each returns an :class:`Outcome`
(accepted or not, a message, and the legs and task events to publish at once). Nothing here
raises on bad input: an unknown robot, a finished job, a wrong type get ``ok=False`` and a reason
that starts with the field at fault (``robot_id: unknown robot 'r9' (known: r1, r2)``).

* **pause** (one robot or the fleet): a robot driving a leg holds where it is safe to hold: where
  it is, if no other robot's trajectory passes there, else (central, on time) it drives on along
  its own leg as planned to the first place within :data:`DRIVE_ON_M` that none passes, and holds
  there; failing that, where it is. The others re-plan around it as a parked obstacle (the
  manager's ``_replan_around``). One that stands at the
  end of its leg, or is picking or placing, is already where it is safe to hold and just gets no
  new leg (an action under way finishes, and the job moves on when it is resumed). Robots that
  join while the fleet is paused are paused too.
* **e-stop**: the manager is halted (no new legs); the ROS glue latches the stop on every agent at
  once (``/fleet/estop``), each of which holds until it gets a leg planned after the stop. On
  release every robot that was on a leg gets a fresh hold where it stands and re-plans.
* **cancel**: event ``cancelled`` (with the robot, which then drops the job); a robot on its way to
  pick is released where it is; one that carries the goods is sent to the nearest free storing
  site as a drop-off, and the event's reason says where the goods go (or that none is free).
* **priority**: the job's task gets the new priority (kept in the job store too); allocation
  takes it from the next step.
* **send**: a free robot gets a target at a station (or parking spot), planned at the next step.
* **manual drive** is switched on the robot (its agent, :mod:`.manual`); the status says so and
  :meth:`Operator.step` sees it: the robot's leg is dropped, it becomes an obstacle grown by
  :data:`~.state.MANUAL_GROWTH_M` that the others re-plan around whenever it has moved that far;
  leaving manual drive it re-plans to its target from where it is (re-joins the plan).
* **deadlines** (``task.deadline``): allocation takes the earliest deadline first among equal
  priorities (in the manager); a job still open when its deadline passes gets one ``late`` event.

Times are seconds on the planner's clock: ``now`` is always passed in.
"""
from __future__ import annotations

import math
import sqlite3
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from msg_schemas.records import INT_MAX, INT_MIN, Command, TaskEvent

from ..geometry import arc_lengths, point_at_arc
from ..model import Point, TimedPath
from .legs import Decisions, Leg
from .manager import FleetManager
from .state import MANUAL_GROWTH_M, FleetRobot, Job, Target

#: the job states from which nothing more happens
CLOSED = ("done", "failed", "cancelled")
#: how far (m) along its leg a paused robot may drive on to a place where it is in nobody's way
DRIVE_ON_M = 4.0
#: a robot later than this (s) on its leg, or further (m) from where it is due, is held where it is
LATE_S, ON_LEG_M = 0.5, 0.1
_SAMPLE_M = 0.25   # m between the places tried along the leg
#: how many known names a rejection lists at most
_LIST_AT_MOST = 12


class OperatorError(ValueError):
    """A command that cannot be carried out; the message starts with the field at fault."""


@dataclass
class Outcome:
    """What a command did: ``ok``, a message in words, and the legs / events to publish now."""

    ok: bool
    message: str
    decisions: Decisions = field(default_factory=Decisions)


def _names(items: Any) -> str:
    names = sorted(items)
    shown = ", ".join(names[:_LIST_AT_MOST])
    return shown + (f", ... ({len(names)} in all)" if len(names) > _LIST_AT_MOST else "") if names else "none"


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


class Operator:
    """The operator's commands on ``fleet``. Call :meth:`step` instead of ``fleet.step`` (it
    takes in manual drive before the manager plans and reports late jobs after)."""

    def __init__(self, fleet: FleetManager):
        self.fleet = fleet
        self.fleet_paused = False
        self._held: set[str] = set()        # robots this module gave a hold (they re-plan on resume)
        self._late: set[str] = set()        # jobs reported late
        self._manual_at: dict[str, Point] = {}  # where each manual robot was last planned around

    @property
    def estopped(self) -> bool:
        return self.fleet.halted

    # -- one entry for the JSON commands ------------------------------------------------------------
    def execute(self, command: Command, now: float) -> Outcome:
        """Carry out a ``fleet/command@1`` record."""
        c = command
        if c.command == "pause":
            return self.pause(c.robot_id, now)
        if c.command == "resume":
            return self.resume(c.robot_id, now)
        if c.command == "estop":
            return self.estop(now)
        if c.command == "release":
            return self.release(now)
        if c.command == "cancel":
            return self.cancel(c.task_id, now, c.reason)
        if c.command == "priority":
            return self.set_priority(c.task_id, c.priority, now)
        return self.send(c.robot_id, c.station, now)

    def _guard(self, action: Any, *args: Any) -> Outcome:
        try:
            return action(*args)
        except OperatorError as exc:
            return Outcome(False, str(exc))

    # -- pause and resume ----------------------------------------------------------------------------
    def pause(self, robot_id: str | None, now: float) -> Outcome:
        """Pause one robot (``robot_id``) or, with None, the whole fleet."""
        return self._guard(self._pause, robot_id, now)

    def _pause(self, robot_id: str | None, now: float) -> Outcome:
        d = Decisions()
        if robot_id is None:
            self.fleet_paused = True
            for r in self.fleet.robots.values():
                self._pause_robot(r, now, d)
            d.notes.append("the fleet is paused")
            return Outcome(True, f"fleet paused ({len(self.fleet.robots)} robots)", d)
        r = self._robot(robot_id)
        if r.paused:
            return Outcome(True, f"robot {r.id} was already paused", d)
        self._pause_robot(r, now, d)
        return Outcome(True, f"robot {r.id} paused at ({r.pos[0]:.2f}, {r.pos[1]:.2f})", d)

    def _pause_robot(self, r: FleetRobot, now: float, d: Decisions) -> None:
        if r.paused:
            return
        r.paused = True
        d.notes.append(f"robot {r.id} is paused")
        if _on_the_move(r) and not self.fleet.halted:
            if not self._hold_clear(r, now, d):
                self.fleet._hold(r, now, d)
            self._held.add(r.id)

    def _hold_clear(self, r: FleetRobot, now: float, d: Decisions) -> bool:
        """Hold a central robot that is on time where it is in nobody's way: where it is, if no
        other robot's trajectory from now on passes there, else the first place along the rest of
        its leg (within :data:`DRIVE_ON_M`, never its goal) that none passes, reached on its leg as
        planned (the leg up to there, then standing there). False: none found (hold it where it is)."""
        fm, leg = self.fleet, r.leg
        if fm.strategy.name != "central" or leg is None or r.status.lateness_s > LATE_S:
            return False
        wp = leg.path.waypoints
        path_id = max(round(now * 1e9), r.last_path_id + 1)
        t_new = path_id / 1e9
        arc = arc_lengths(wp)
        s_now = float(np.interp(t_new, wp[:, 2], arc))
        due = point_at_arc(wp[:, :2], arc, s_now)
        if math.dist(due, fm.strategy.start_of(r, t_new)) > ON_LEG_M:
            return False
        others = [o for o in fm.robots.values() if o is not r]

        def clear(p: Point) -> bool:
            return not any(fm.strategy.must_replan_around(o.trajectory(), now, p, o.radius + r.radius + fm.margin)
                           for o in others)

        if clear(due):
            return False  # where it is is in nobody's way: an ordinary hold
        end = min(float(arc[-1]) - _SAMPLE_M, s_now + DRIVE_ON_M)
        s = s_now + _SAMPLE_M
        while s <= end:
            p = point_at_arc(wp[:, :2], arc, s)
            if clear(p):
                k = int(np.searchsorted(arc, s, side="left"))  # arc[k-1] < s <= arc[k]: a moving piece
                t_p = float(wp[k - 1, 2] + (s - arc[k - 1]) / (arc[k] - arc[k - 1]) * (wp[k, 2] - wp[k - 1, 2]))
                rows = [[*due, t_new]] + [list(w) for a, w in zip(arc, wp) if s_now <= a < s and w[2] > t_new]
                rows.append([*p, max(t_p, rows[-1][2])])
                path = TimedPath(r.id, r.radius, np.array(rows, dtype=float))
                fm._give(r, Leg(r.id, path, path_id, "hold", ""), d, now)
                r.conflict = False
                d.notes.append(f"robot {r.id} drives on {s - s_now:.1f} m along its leg to hold at "
                               f"({p[0]:.2f}, {p[1]:.2f}), out of the others' way")
                fm._replan_around(r, p, now)
                return True
            s += _SAMPLE_M
        return False

    def resume(self, robot_id: str | None, now: float) -> Outcome:
        """Resume one robot or, with None, the whole fleet (every paused robot)."""
        return self._guard(self._resume, robot_id, now)

    def _resume(self, robot_id: str | None, now: float) -> Outcome:
        d = Decisions()
        if robot_id is None:
            self.fleet_paused = False
            robots = [r for r in self.fleet.robots.values() if r.paused]
            for r in robots:
                self._resume_robot(r, d)
            d.notes.append("the fleet is resumed")
            return Outcome(True, f"fleet resumed ({len(robots)} robots were paused)", d)
        r = self._robot(robot_id)
        if not r.paused:
            return Outcome(True, f"robot {r.id} was not paused", d)
        self._resume_robot(r, d)
        return Outcome(True, f"robot {r.id} resumed", d)

    def _resume_robot(self, r: FleetRobot, d: Decisions) -> None:
        r.paused = False
        if r.id in self._held:
            self._held.discard(r.id)
            r.replan = r.target is not None
        d.notes.append(f"robot {r.id} is resumed" + (f", on to {r.target.name}" if r.target else ""))

    # -- e-stop --------------------------------------------------------------------------------------
    def estop(self, now: float) -> Outcome:
        """Engage the e-stop: no new legs until :meth:`release` (the agents stop on their own)."""
        d = Decisions()
        if self.fleet.halted:
            return Outcome(True, "the e-stop was already engaged", d)
        self.fleet.halted = True
        d.notes.append("E-STOP engaged: every robot stops, no new legs until it is released")
        return Outcome(True, "e-stop engaged", d)

    def release(self, now: float) -> Outcome:
        """Release the e-stop: every robot that was on a leg holds where it stands and re-plans."""
        d = Decisions()
        if not self.fleet.halted:
            return Outcome(True, "the e-stop was not engaged", d)
        self.fleet.halted = False
        held = 0
        for r in self.fleet.robots.values():
            if r.online and not r.immobile and not r.manual and _on_the_move(r):
                self.fleet._hold(r, now, d)
                held += 1
                if r.paused:
                    self._held.add(r.id)
                else:
                    r.replan = r.target is not None
        d.notes.append(f"e-stop released: {held} robots re-plan from where they stand")
        return Outcome(True, f"e-stop released ({held} robots re-plan)", d)

    # -- jobs ----------------------------------------------------------------------------------------
    def cancel(self, task_id: str | None, now: float, reason: str | None = None) -> Outcome:
        """Cancel an open job (event ``cancelled``); its robot is released, goods it carries go to
        a drop-off."""
        return self._guard(self._cancel, task_id, now, reason)

    def _cancel(self, task_id: str | None, now: float, reason: str | None) -> Outcome:
        job = self._open_job(task_id, "cancel")
        d = Decisions()
        why = "cancelled by the operator" + (f": {reason}" if reason else "")
        r = self.fleet.robots.get(job.robot) if job.robot is not None else None
        try:  # committed first: if the store cannot take it, nothing changes and the operator is told
            self.fleet._record(job, "cancelled", now, why, state="cancelled")
        except sqlite3.Error as exc:
            raise OperatorError(f"job {job.task.id}: the job store cannot record the cancel ({exc})") from None
        if r is not None and r.job == job.task.id:
            r.job = None
            if job.picked:
                why += "; " + self._drop_off(r)
            else:
                r.target, r.replan, r.arrived_at, r.saw_action = None, False, None, False
                if _on_the_move(r) and not r.manual and not self.fleet.halted:
                    if not self._hold_clear(r, now, d):
                        self.fleet._hold(r, now, d)
                    r.idle_since = now
                why += f"; robot {r.id} is released"
        d.events.append(TaskEvent(task_id=job.task.id, event="cancelled", stamp=float(now),
                                  robot_id=r.id if r is not None else None, reason=why))
        return Outcome(True, f"job {job.task.id} {why}", d)

    def _drop_off(self, r: FleetRobot) -> str:
        """Send ``r``, which carries a cancelled job's goods, to the nearest free storing site;
        says where they go (or that no site is free and they must be taken off by hand)."""
        sites = {s.name: s.pose for s in self.fleet.warehouse.stations_of("storage")}
        spot = self.fleet._free_spot(r, sites)
        r.arrived_at, r.saw_action = None, False
        if spot is None or r.manual:
            r.target, r.replan = None, False
            return (f"robot {r.id} carries the goods: no drop-off free, take them off by hand at "
                    f"({r.pos[0]:.2f}, {r.pos[1]:.2f})")
        r.target, r.replan = Target("park", spot[0], spot[1]), True
        return f"robot {r.id} carries the goods to the drop-off {spot[0]}"

    def set_priority(self, task_id: str | None, priority: Any, now: float) -> Outcome:
        """Change an open job's priority (higher goes first)."""
        return self._guard(self._set_priority, task_id, priority, now)

    def _set_priority(self, task_id: str | None, priority: Any, now: float) -> Outcome:
        if isinstance(priority, bool) or not isinstance(priority, int) or not INT_MIN <= priority <= INT_MAX:
            raise OperatorError(f"priority: must be an integer (got {_show(priority)})")
        job = self._open_job(task_id, "change the priority of")
        old = job.task.priority
        job.task = replace(job.task, priority=priority)
        if self.fleet.store is not None:
            self.fleet.store.replace_task(job.task, "priority", now, f"priority {old} -> {priority}")
        d = Decisions(notes=[f"job {job.task.id}: priority {old} -> {priority}"])
        effect = "" if job.state == "queued" else " (it is under way: the priority orders only queued jobs)"
        return Outcome(True, f"job {job.task.id}: priority {old} -> {priority}{effect}", d)

    # -- robots --------------------------------------------------------------------------------------
    def send(self, robot_id: str | None, station: str | None, now: float) -> Outcome:
        """Send a free robot to a station or parking spot (planned at the next step)."""
        return self._guard(self._send, robot_id, station, now)

    def _send(self, robot_id: str | None, station: str | None, now: float) -> Outcome:
        r = self._robot(robot_id)
        stations = self.fleet.warehouse.stations
        if not isinstance(station, str) or (station not in stations and station not in self.fleet.parking):
            raise OperatorError(f"station: unknown station {_show(station)} "
                                f"(known: {_names(list(stations) + list(self.fleet.parking))})")
        if self.fleet.halted:
            raise OperatorError("robot_id: the e-stop is engaged; release it first")
        problem = self._busy(r)
        if problem:
            raise OperatorError(f"robot_id: robot {r.id} {problem}")
        pose = stations[station].pose if station in stations else self.fleet.parking[station]
        occupant = self.fleet._occupant(pose, r.radius, exclude=r)
        if occupant is not None:
            raise OperatorError(f"station: {station} is taken by robot {occupant.id}")
        purpose = "charge" if station in stations and stations[station].type == "charger" else "park"
        r.target, r.replan, r.arrived_at = Target(purpose, station, pose), True, None
        d = Decisions(notes=[f"robot {r.id} is sent to {station} by the operator"])
        return Outcome(True, f"robot {r.id} goes to {station}", d)

    def _busy(self, r: FleetRobot) -> str | None:
        if not r.online or r.immobile:
            return "is offline or out of order"
        if r.manual:
            return "is in manual drive"
        if r.paused:
            return "is paused; resume it first"
        if r.job is not None:
            return f"is on job {r.job}; cancel it first"
        if r.status.mode in ("picking", "placing"):
            return f"is {r.status.mode}"
        return None

    # -- the periodic part -----------------------------------------------------------------------------
    def step(self, now: float) -> Decisions:
        """Manual drive taken in, the manager's step, then late jobs: what to publish now."""
        d = Decisions()
        self._manual(now, d)
        if self.fleet_paused:
            for r in self.fleet.robots.values():
                self._pause_robot(r, now, d)
        done = self.fleet.step(now)
        done.notes[:0] = d.notes
        done.legs[:0] = d.legs
        done.events[:0] = d.events
        self._report_late(now, done)
        return done

    def _manual(self, now: float, d: Decisions) -> None:
        for r in self.fleet.robots.values():
            reported = bool(r.status.manual) and r.online and not r.immobile
            if reported and not r.manual:
                r.manual = True
                r.leg, r.replan, r.conflict, r.arrived_at, r.saw_action = None, False, False, None, False
                self._held.discard(r.id)
                self._manual_at[r.id] = r.pos
                d.notes.append(f"robot {r.id} is in manual drive: planned around as a moving obstacle")
                self.fleet._replan_around(r, r.pos, now)
            elif reported and math.dist(r.pos, self._manual_at.get(r.id, r.pos)) > MANUAL_GROWTH_M / 2:
                self._manual_at[r.id] = r.pos
                self.fleet._replan_around(r, r.pos, now)
            elif r.manual and not reported:
                r.manual = False
                self._manual_at.pop(r.id, None)
                r.replan = r.target is not None
                d.notes.append(f"robot {r.id} left manual drive: it re-joins the plan"
                               + (f", on to {r.target.name}" if r.target else ""))

    def _report_late(self, now: float, d: Decisions) -> None:
        for job in self.fleet.jobs.values():
            deadline = job.task.deadline
            if deadline is None or job.state in CLOSED or now <= deadline or job.task.id in self._late:
                continue
            self._late.add(job.task.id)
            reason = f"deadline t={deadline:.1f} s passed at t={now:.1f} s ({job.state}"
            reason += f", on robot {job.robot})" if job.robot else ")"
            d.events.append(TaskEvent(task_id=job.task.id, event="late", stamp=float(now), robot_id=job.robot,
                                      reason=reason))

    # -- lookups ---------------------------------------------------------------------------------------
    def _robot(self, robot_id: Any) -> FleetRobot:
        if not isinstance(robot_id, str):
            raise OperatorError(f"robot_id: must be a robot id (got {_show(robot_id)})")
        r = self.fleet.robots.get(robot_id)
        if r is None:
            raise OperatorError(f"robot_id: unknown robot {_show(robot_id)} (known: {_names(self.fleet.robots)})")
        return r

    def _open_job(self, task_id: Any, what: str) -> Job:
        if not isinstance(task_id, str):
            raise OperatorError(f"task_id: must be a job id (got {_show(task_id)})")
        job = self.fleet.jobs.get(task_id)
        if job is None:
            raise OperatorError(f"task_id: unknown job {_show(task_id)}")
        if job.state in CLOSED:
            raise OperatorError(f"task_id: job {task_id} is already {job.state}; nothing to {what}")
        return job


def _on_the_move(r: FleetRobot) -> bool:
    """``r`` has a leg it has not finished (or not yet started), and is not picking or placing."""
    if r.leg is None or r.status.mode in ("picking", "placing"):
        return False
    finished = r.status.path_id == r.leg.path_id and r.status.progress >= 1.0
    return len(r.leg.path.waypoints) > 1 and not finished
