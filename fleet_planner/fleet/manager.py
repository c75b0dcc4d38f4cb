"""The planner's end of the fleet: :class:`FleetManager` keeps the fleet's state and turns tasks
and robot statuses into legs and task events.

The planner node feeds it what comes off the wire (:meth:`~FleetManager.submit` for tasks,
:meth:`~FleetManager.on_status` for robot statuses) and calls :meth:`~FleetManager.step` on a
timer, which returns :class:`~.legs.Decisions`: new timed paths (:class:`~.legs.Leg`) and task
events to publish. The job's life and the coordination modes are described in :mod:`fleet_planner.fleet`.

Under central coordination every leg is planned with the planner's ``plan_incremental`` (by
default the (M,D) planner of You & Ji, "Design of a Multi-robot Bin Packing System in an Automatic
Warehouse", :class:`~fleet_planner.planners.md.MDPlanner`) around the trajectories of all other
robots (a standing robot is a one-waypoint path), so planned discs never come closer than the sum
of radii plus the planner's margin. Legs are planned with each kind's acceleration
(speed ramps written as short constant-speed pieces, :func:`~fleet_planner.model.drive_profile`)
at ``speed_factor`` f of its top speed v; a robot tracking such a leg (never ahead, see
:class:`~fleet_planner.robots.RobotModel`) lags it by at most the ramp approximation,
(f v)^2 / (8 a n^2) for n pieces per ramp, plus what it drives in one control step. The margin is
twice the largest such lag plus ``safety_margin``, so the discs as driven stay apart as well.

When things go wrong: a leg that cannot be planned now (someone is parked in the way) is tried
again at the next step, and an idle robot in the way is sent off first; a robot silent for
``offline_timeout_s`` (or out of battery; when no robot at all is heard, after ``DEAF_FACTOR`` times
that: the planner's input is late, not every robot at once) is immobile: its last position becomes a fixed obstacle,
its job goes back to the queue (or fails, if it was carrying it with an empty battery) and, under
central coordination, robots whose legs pass near it re-plan; a central robot more than
``lateness_tolerance_s`` behind its schedule re-plans the rest of its leg from where it is, around
everyone else.

Times are seconds on one clock (the planner's ROS time): ``now`` is always passed in.
"""
from __future__ import annotations

import math
import re
import sqlite3
import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, cast

import numpy as np

from msg_schemas.records import (
    EVENTS_NEEDING_REASON,
    MAX_NAME_CHARS,
    MAX_RECORD_BYTES,
    Heard,
    ObstacleRecord,
    RecordError,
    RobotStatus,
    Schedule,
    Task,
    TaskEvent,
    load_json,
    nonempty,
)

from ..model import Point, TimedPath
from ..planners import Planner, get_planner
from ..robots import RobotKind
from ..warehouse import Station, Warehouse
from .coordination import Coordination, LegNotPlanned, get_coordination, room_to_leave
from .dispatch import Candidate, DispatchPolicy, TravelTimes, assign, queue_spots, staging_spots
from .gate import GateBook
from .intake import Roster
from .jobstore import CLOSED, RESENT, DuplicateJob, JobStore, Transition, current_event
from .lease import STRETCH_STEP_M, heard_record, reachable, stopped_by
from .legs import ACTING, AT_STATION_M, EVADE, MAX_CLOCK_SKEW_S, Decisions, DispatchParams, Leg, lag_allowance
from .obstacles import OBSTACLE_LOOKAHEAD, ObstacleMap, ObstacleParams
from .state import FleetRobot, Job, Occupancy, Target, can_do
from .waits import cycles, wait_for_graph

#: a free robot that could not get a leg to a charger or parking spot tries again this much (s) later
SPOT_RETRY_S = 2.0
#: a robot whose leg could not be planned tries again this much (s) later, doubled with each refusal
#: in a row up to LEG_RETRY_MAX_S (a refused leg costs the planner its whole time budget: tried at
#: every step, a few of them stall the step, and the fleet's statuses wait meanwhile)
LEG_RETRY_S, LEG_RETRY_MAX_S = 0.5, 4.0
#: a standing robot whose new leg the gate refused (it would start in a region another robot may be in)
#: tries again this much (s) later, once the robots in that region re-planned around it
GATE_RETRY_S = 2.0
#: (ours) wait cycles (.waits) are looked for this often (s of the clock) ...
WAITS_EVERY_S = 1.0
#: ... broken once they have lasted this long (s; one seen at every look: 22 robots with messages 6 s late had
#: cycles of "leg" edges that resolved themselves, and breaking them at once did 33 jobs by 700 s, not 53) ...
CYCLE_LASTS_S = 20.0
#: ... and a robot the breaker held is not held again by it for this long (s)
BREAK_AGAIN_S = 10.0
#: a robot stepping aside from a moving obstacle tries this many refuges, nearest first; when none
#: can be reached it holds and tries again this much later (s)
EVADE_TRIES, EVADE_RETRY_S = 8, 0.5
#: a standing robot watches a moving obstacle's way this many prediction horizons ahead (it needs
#: longer to get going than a driving one needs to turn)
STANDING_LOOKAHEAD = 1.5
#: wall seconds of leg planning per step, at most (the planner node lowers it on a fast clock): what
#: is left waits for the next step (legs to places first, then re-plans, new jobs, charging, parking)
STEP_BUDGET_S = 0.5
#: (ours) a leg of a standing robot starts this much later than ``lead_s`` at most for the time its step takes
#: (:meth:`FleetManager.note_pace`)
MAX_DECISION_LAG_S = 10.0
#: ... estimated from the steps' durations: the longest one, fading by this factor per step
STEP_TIME_FADE = 0.9
#: wall seconds of leg planning per step at least, however fast the clock (one leg always goes)
MIN_STEP_BUDGET_S = 0.05
#: wall seconds the planner may spend on one leg at least (md's leg_time_limit)
MIN_LEG_LIMIT_S = 0.1
#: the default md planner plans the live fleet's legs on the map's own cells (md's ``leg_lattice``; the delivery
#: simulation uses md's "auto", a lattice 3x finer on the 0.5 m default warehouse). Measured in session 31 with "auto":
#: `bench_fleet.py --default 9 15 22 30 --same-stream --sim on --rate 5` did 216 / 298 / 295 jobs per simulated hour
#: at 9 / 15 / 22 robots (on the map's cells 210 / 283 / 310), but at 30 robots the planner node took 84% of a core
#: and the clock fell from 5x to 1.1x (41 of 100 jobs in 600 s wall): its legs cost about 3.5x the CPU
LIVE_LEG_LATTICE = 1
#: finished jobs kept in memory (the latest ones); older ones are only in the job store, which
#: still answers a re-sent id with its state (without a store such an id is a new job again)
MAX_CLOSED_JOBS = 1000
#: (ours) when no robot at all has been heard for half the offline timeout, the planner's own input is
#: late (a starved planner, its network), not every robot at once: robots go offline only after this
#: many offline timeouts then (a single robot's silence amid others' statuses still counts at once)
DEAF_FACTOR = 3.0


def paced_budgets(lead_s: float, rate: float, leg_limit: float | None) -> tuple[float, float | None]:
    """The step's planning budget and the planner's limit per leg (wall s) on a clock running ``rate``
    times faster than the wall: a leg starts ``lead_s`` of clock time after it is planned, so the legs
    of one step must be planned within about ``lead_s / rate`` wall seconds (a quarter of it here) or
    they reach the robots after they were due to start (and are refused); ``leg_limit``: the planner's
    own limit (None: it has none)."""
    budget = 0.25 * lead_s / max(1.0, rate)
    step = min(STEP_BUDGET_S, max(MIN_STEP_BUDGET_S, budget))
    return step, None if leg_limit is None else min(leg_limit, max(MIN_LEG_LIMIT_S, budget))


class _Same:
    """The value of an argument left as it was."""


SAME = _Same()


class FleetManager:
    """Keeps the fleet's state and turns tasks and statuses into legs and task events.

    ``kinds`` are the robot kinds robots may report (their sizes, speeds and abilities);
    ``parking`` are extra places where idle robots may wait out of the way, besides the chargers;
    ``coordination`` is how the robots avoid each other: a name of
    :data:`~.coordination.COORDINATION` or a :class:`~.coordination.Coordination`;
    ``planner`` plans the legs of central coordination (anything with ``plan_incremental``, see
    :class:`~fleet_planner.planners.Planner`), by default the registry's ``md`` planner keeping
    :attr:`margin` (one handed in should keep at least that much between discs); ``gated``: send
    each leg's precedence links (:mod:`.gate`; central coordination), for agents that respect them.
    """

    def __init__(self, warehouse: Warehouse, kinds: Mapping[str, RobotKind],
                 params: DispatchParams | None = None, parking: Sequence[Point] = (),
                 coordination: str | Coordination = "central", planner: Planner | None = None,
                 store: JobStore | None = None, roster: Iterable[str] | None = None,
                 max_clock_skew_s: float = MAX_CLOCK_SKEW_S, obstacle_params: ObstacleParams | None = None,
                 gated: bool = True):
        if not kinds:
            raise ValueError("kinds: at least one robot kind is needed")
        self.strategy = get_coordination(coordination)
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
        #: how jobs are allocated and where idle robots wait (fleet/dispatch.py)
        self.policy = DispatchPolicy()
        self.travel = TravelTimes(warehouse)
        for chute in warehouse.stations_of("chute"):  # (made now, not inside a step's time budget)
            self.travel.field(chute.name)
        self.staging = {f"staging_{i + 1}": p for i, p in enumerate(staging_spots(warehouse, largest))}
        #: chute -> the staging spot where the robot with its next job waits (policy ``queue``)
        self.queue_spot = queue_spots({s.name: s.pose for s in warehouse.stations_of("chute")}, self.staging)
        self._soonest: dict[str, float] = {}   # storing site -> _soonest_at
        self.work_stops = {s.name: s.pose for s in warehouse.stations.values() if s.type != "charger"}
        self.margin = 2 * max(lag_allowance(k, self.params.speed_factor) for k in self.kinds.values()) \
            + self.params.safety_margin
        # the live fleet paces its legs in wall-clock seconds (paced_budgets, MIN_LEG_LIMIT_S)
        self.planner = planner if planner is not None else get_planner("md", margin=self.margin, leg_clock="wall",
                                                                         leg_lattice=LIVE_LEG_LATTICE)
        warm_up = getattr(self.planner, "warm_up", None)   # (a planner is anything with plan_incremental)
        if warm_up is not None:
            warm_up()   # its compiled kernels, loaded now: not inside the first steps' budgets
        self.robots: dict[str, FleetRobot] = {}
        self.jobs: dict[str, Job] = {}
        #: finished jobs still in ``jobs``, oldest first, with why they ended (at most MAX_CLOSED_JOBS)
        self._closed: dict[str, str | None] = {}
        self._notes: list[str] = []
        self._plan_id = 0
        self.store = store
        if not 0.0 <= max_clock_skew_s <= 3600.0:
            raise ValueError(f"max_clock_skew_s: must be a number in [0, 3600] (got {max_clock_skew_s!r})")
        self.max_clock_skew_s = float(max_clock_skew_s)
        #: the obstacles of the intelligent space: participants above every robot (fleet/obstacles.py)
        self.obstacles = ObstacleMap(obstacle_params, self.max_clock_skew_s)
        self.roster = Roster(roster)  # (None: anyone joins)
        self._started: float | None = None  # the first step (robots re-adopt their jobs from then on)
        self._deaf = False   # no robot heard for half the offline timeout (noted once: _find_immobile)
        self._seq = 0
        #: events committed and not handed out yet: before a restart and not announced then
        #: (JobStore.unannounced), or of a step that raised; the next step's
        self._replay: list[TaskEvent] = []
        self._committed_n = self._announced_n = 0   # the store's last transition committed / announced
        #: the store's first transition whose events wait in ``_replay`` (None: none wait): the outbox
        #: never moves past it before they went out (:attr:`handed_out`)
        self._held_from: int | None = None
        self.halted = False  # the e-stop is engaged: nobody gets a new leg (fleet.operator)
        #: the precedence links of every robot's leg (central coordination; fleet/gate.py)
        self.gates = GateBook() if gated and self.strategy.sends_gates else None
        #: break wait cycles of gated execution (:meth:`_break_waits`); when it next looks for them
        self.break_waits, self._waits_at = True, -math.inf
        self._cycles_since: dict[tuple[str, ...], float] = {}   # the cycles seen last time, since when
        # indexes valid for one step (docs/ARCHITECTURE.md: every step proportional to what changed)
        self._occ: Occupancy | None = None
        self._free_spots: dict[tuple[int, float], list[tuple[str, Point]]] = {}
        self._reserved_at: list[Point] | None = None
        self._reserved_arr: np.ndarray | None = None
        self._spot_trees: dict[int, Any] = {}
        self.step_budget_s = STEP_BUDGET_S
        self._step_deadline = math.inf   # (time.monotonic) no more legs this step after it
        #: clock s between ``now`` of a step and its legs reaching the robots (:meth:`note_pace`)
        self.decision_lag_s = 0.0
        self._step_s = 0.0
        if store is not None:
            self._reload(store)

    def _reload(self, store: JobStore) -> None:
        """Take up the open jobs of ``store`` (a restart): a queued one is queued again; one that was
        on a robot waits for that robot to report on it (:meth:`_adopt`: it takes the job up again
        where its status says it got to, or the job is done if it says it placed the goods); one
        whose robot does not report it within ``offline_timeout_s`` of the first step is queued
        again if its goods were not picked, and fails, with the reason, if they were (never picked
        again, :meth:`_orphans`)."""
        self._seq = store.next_seq()
        self._replay = [ev for job_id, t in store.unannounced() for ev in replayed(job_id, t)]
        for stored in store.open_jobs():
            task = stored.task
            pick = self.warehouse.stations.get(task.pick)
            place = self._storing_site(task.place)
            job = Job(task, pick, place, stored.seq) if pick is not None and place is not None else None
            if job is None:
                gone = "the warehouse no longer has its stations"
                self._committed_n = store.update(task.id, "failed", "failed", stored.robot, stored.picked, 0.0, gone)
                self._replay.append(_event(task.id, "failed", 0.0, stored.robot, gone))
                self._notes.append(f"job {task.id}: failed on reload, its stations are gone")
                continue
            self.jobs[task.id] = job
            if stored.state == "active" and stored.robot is not None:
                job.state, job.robot, job.picked = "active", stored.robot, stored.picked
                self._notes.append(f"job {task.id}: reloaded, {'picked by' if stored.picked else 'on'} "
                                   f"{stored.robot}; waiting for it")
            else:
                self._committed_n = store.update(task.id, "reloaded", "queued", None, False, 0.0)
                self._notes.append(f"job {task.id}: reloaded and queued")
        if self._replay:   # (every transition after the outbox's mark is replayed, or not announced at all)
            self._held_from = store.announced_upto() + 1

    @property
    def coordination(self) -> str:
        """The name of the coordination mode."""
        return self.strategy.name

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
                task = cast(Task, Task.from_json(raw))
            else:
                task = cast(Task, Task.from_dict(raw))
        except RecordError as exc:
            return [_event(_guess_id(raw), "rejected", now, reason=str(exc))]
        try:
            known = self._known(task.id, now)
        except sqlite3.Error as exc:
            return [_event(task.id, "rejected", now, reason=f"job store: cannot check the id ({exc})")]
        if known is not None:  # ids are idempotent: the job's state, never a second job
            return [known]
        problem = self._problem(task)
        if problem:
            return [_event(task.id, "rejected", now, reason=problem)]
        pick = self.warehouse.stations[task.pick]
        place = self._storing_site(task.place)
        assert place is not None  # _problem found it
        seq = self._seq
        if self.store is not None:  # committed before it is acknowledged
            try:
                self._committed_n = self.store.add(task, seq, now)
            except DuplicateJob as exc:
                return [_event(task.id, "rejected", now, reason=str(exc))]
            except sqlite3.Error as exc:
                return [_event(task.id, "rejected", now, reason=f"job store: cannot record it ({exc})")]
        self._seq += 1
        self.jobs[task.id] = Job(task, pick, place, seq)
        return [_event(task.id, "accepted", now)]

    def _record(self, job: Job, event: str, now: float, reason: str | None = None, *, state: str | None = None,
                robot: str | None | _Same = SAME, picked: bool | None = None) -> None:
        """Change ``job`` (its ``state``, ``robot``, ``picked``: those given) and commit the change to the
        store (if any) first: the store's error (sqlite3.Error, a full disk) leaves the job as it was,
        and nothing is announced that is not committed. A finished job stays in ``jobs`` until
        MAX_CLOSED_JOBS later ones finished (then only the store has it)."""
        new_state = job.state if state is None else state
        new_robot = job.robot if isinstance(robot, _Same) else robot
        new_picked = job.picked if picked is None else picked
        if self.store is not None:
            self._committed_n = self.store.update(job.task.id, event, new_state, new_robot, new_picked, now, reason)
        job.state, job.robot, job.picked = new_state, new_robot, new_picked
        if job.state in CLOSED:
            self._closed.pop(job.task.id, None)
            self._closed[job.task.id] = reason
            while len(self._closed) > MAX_CLOSED_JOBS:
                old = next(iter(self._closed))
                del self._closed[old]
                if old in self.jobs and self.jobs[old].state in CLOSED:
                    del self.jobs[old]

    def _commit(self, job: Job, event: str, now: float, d: Decisions, reason: str | None = None, *,
                state: str | None = None, robot: str | None | _Same = SAME, picked: bool | None = None) -> bool:
        """:meth:`_record` within a step: False (noted, nothing changed) if the store cannot take it;
        the caller changes nothing else then and the step tries it again later."""
        try:
            self._record(job, event, now, reason, state=state, robot=robot, picked=picked)
        except sqlite3.Error as exc:
            d.notes.append(f"job {job.task.id}: the job store cannot record {event!r} ({exc}): tried again later")
            return False
        return True

    def _known(self, task_id: str, now: float) -> TaskEvent | None:
        """The event of the job's current state if ``task_id`` is a job's (in memory or in the
        store), its reason starting with RESENT; None for a new id."""
        job = self.jobs.get(task_id)
        if job is not None:
            state, picked, robot = job.state, job.picked, job.robot
            reason = self._closed.get(task_id)
            if reason is None and state in CLOSED and self.store is not None:
                reason = self.store.reason(task_id)
        else:
            stored = self.store.get(task_id) if self.store is not None else None
            if stored is None:
                return None
            state, picked, robot = stored.state, stored.picked, stored.robot
            reason = self.store.reason(task_id) if state in CLOSED and self.store is not None else None
        return _event(task_id, current_event(state, picked), now, robot,
                      f"{RESENT}; {reason}" if reason else RESENT)

    def _problem(self, task: Task) -> str | None:
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
        cannot be from a robot of this fleet (unknown kind, a kind that changed, an id not on the
        ``roster``: once per id, later ones are dropped silently) or that is stamped more than
        ``max_clock_skew_s`` ahead of ``now`` (kept, it would make every later status look old and
        the robot offline for good)."""
        if status.stamp > now + self.max_clock_skew_s:
            raise ValueError(f"robot {status.id!r}: status stamped {status.stamp - now:.3g} s ahead of the "
                             f"planner's clock (at most {self.max_clock_skew_s:g} s)")
        known, warning = self.roster.admit(status.id)
        if not known:  # one warning per unknown id (at most MAX_STRANGERS); it never joins the fleet
            if warning:
                raise ValueError(warning)
            return
        kind = self.kinds.get(status.kind)
        if kind is None:
            raise ValueError(f"robot {status.id!r}: kind {status.kind!r} is not one of the known kinds "
                             f"({', '.join(self.kinds)})")
        r = self.robots.get(status.id)
        if r is None:
            r = self.robots[status.id] = FleetRobot(kind, status, now, now)
            self._notes.append(f"robot {status.id} ({status.kind}) joined at ({status.x:.2f}, {status.y:.2f})")
            return
        if kind is not r.kind:
            raise ValueError(f"robot {status.id!r}: reports kind {status.kind!r}, earlier {r.kind.name!r}")
        if status.stamp < r.status.stamp:
            return  # an old status overtaken by a newer one
        if r.leg is not None and status.path_id == r.leg.path_id != r.status.path_id:
            r.took_late = status.lateness_s   # the first word that it took its leg: late by so much already
        r.status, r.seen = status, now
        if not r.online:
            if r.unheard is not None and not r.immobile:  # back before it must have stopped: it kept its job
                r.replan = r.target is not None         # (fleet/lease.py), re-planned from where it holds
            r.online, r.immobile, r.idle_since = True, status.mode == "error", now
            r.unheard, r.reach = None, None
            r.stop = not r.immobile  # it may still drive a leg the others no longer keep clear of
            self._notes.append(f"robot {r.id} is back online at ({status.x:.2f}, {status.y:.2f})")
            return
        self._note_arrival(r, now)

    def on_obstacle(self, ob: ObstacleRecord, now: float) -> None:
        """Take in an obstacle of the intelligent space (``now``: when it arrived); ValueError (naming
        the field) for one stamped more than ``max_clock_skew_s`` ahead of ``now``."""
        note = self.obstacles.update(ob, now)
        if note:
            self._notes.append(note)

    def _watch_obstacles(self, now: float, d: Decisions) -> None:
        """Obstacles gone (cleared or expired): the legs re-planned for them re-plan again; legs an
        obstacle now threatens re-plan around it (or the robot holds, where none can be planned)."""
        for ob in self.obstacles.expire(now):
            if not ob.persistent and now - ob.stamp > self.obstacles.params.stale_s:  # else: cleared, noted
                d.notes.append(f"obstacle {ob.id} ({ob.kind}) expired: nothing heard for {now - ob.stamp:.1f} s")
            for rid in self.obstacles.take_affected(ob.id):
                r = self.robots.get(rid)  # one driving on re-plans only if its leg can start where it will be
                if (r is not None and r.target is not None and r.on_leg and not r.immobile
                        and math.hypot(r.status.vx, r.status.vy) * self.params.lead_s < r.radius / 2):
                    r.replan = True
        if not self.strategy.plans_around_obstacles or not len(self.obstacles):
            return
        driving = [(r.id, r.leg.path, r.radius) for r in self.robots.values()
                   if r.leg is not None and r.target is not None and r.on_leg and r.online and not r.immobile
                   and not r.replan]
        for rid, oid in self.obstacles.threats(driving, now, self.margin).items():
            r = self.robots[rid]
            r.replan = r.conflict = True   # a robot with no leg now holds (_replan)
            d.notes.append(f"robot {rid} re-plans around obstacle {oid}")
        if self.halted:
            return   # (an e-stop holds everyone where they are)
        # a robot standing (held, idle, waiting) where a moving obstacle is about to walk steps aside:
        # a blind person does not stop for it, and standing still is then no safe place (ours: the
        # paper's intelligent space only says the planner knows the moving obstacles)
        acting = set(ACTING.values())
        standing = [r for r in self.robots.values()
                    if r.online and not r.immobile and not r.manual and not r.paused and not r.on_leg
                    and r.status.mode not in acting and now >= r.evade_retry_at
                    and (r.leg is None or r.status.path_id == r.leg.path_id)]
        for rid, walker in self._walk_into(standing, now).items():
            self._evade(self.robots[rid], walker, now, d)

    def _walk_into(self, robots: Sequence[FleetRobot], now: float) -> dict[str, str]:
        """Robot id -> the moving obstacle that would walk into it if it stood where it is (or stops)."""
        if not robots or not self.strategy.plans_around_obstacles or not len(self.obstacles):
            return {}
        here = [(r.id, TimedPath(r.id, r.radius, np.array([[*r.pos, now]])), r.radius) for r in robots]
        return self.obstacles.threats(here, now, self.margin, STANDING_LOOKAHEAD)

    def _adopt(self, r: FleetRobot, now: float, d: Decisions) -> None:
        """After a restart: a robot without a job here whose status names an open job it was on
        takes it up again where its status says it got to: ``loaded`` (the goods on board, picked
        now if the store did not know it yet: announced once) it heads for the storing site,
        else for the chute; a robot whose status says it placed the goods of a job that was on it
        (``placed_task_id``: while the planner was down) finishes that job, once. A queued job
        the robot still names (queued again while nobody heard from it) goes back to it; so does one
        it picked or placed while nobody heard from it, even if another robot got it meanwhile (that
        one has not picked it: it is released, never a second pick)."""
        st = r.status
        if r.job is not None or not r.online or r.immobile or (st.task_id is None and st.placed_task_id is None):
            return
        placed = self.jobs.get(st.placed_task_id) if st.placed_task_id is not None else None
        if (placed is not None and st.task_id != placed.task.id and st.loaded is not True
                and (placed.state == "active" and placed.robot == r.id and not self._held(placed)
                     or self._unpicked_elsewhere(placed, r))):
            if placed.robot != r.id and not self._take_back(placed, r, now, d):
                return
            r.job = placed.task.id
            if ((placed.picked or self._action_done(r, Target("pick", placed.pick.name, placed.pick.pose), now, d))
                    and self._action_done(r, Target("place", placed.place.name, placed.place.pose), now, d)):
                d.notes.append(f"robot {r.id} placed the goods of job {placed.task.id} while the planner was down")
            else:
                r.job, r.target, r.replan = None, None, False   # (the store failed: tried again next step)
            return
        job = self.jobs.get(st.task_id) if st.task_id is not None else None
        if job is None:
            return
        if st.loaded is True and self._unpicked_elsewhere(job, r):
            if not self._take_back(job, r, now, d):   # it carries the goods: the job is its
                return
        elif self._held(job) or not (job.state == "queued" or job.state == "active" and job.robot == r.id):
            return
        if job.picked and st.loaded is False:
            return  # it says the goods are not on board: the job waits for its word (or fails, _orphans)
        if job.state == "queued":
            if not self._commit(job, "assigned", now, d, state="active", robot=r.id):
                return
            d.events.append(_event(job.task.id, "assigned", now, r.id))
        r.job = job.task.id
        if st.loaded and not job.picked:  # picked while the planner was down
            if not self._action_done(r, Target("pick", job.pick.name, job.pick.pose), now, d):
                r.job = None   # (the store failed: tried again next step)
                return
        else:
            target = (Target("place", job.place.name, job.place.pose) if job.picked
                      else Target("pick", job.pick.name, job.pick.pose))
            # one at its station and already acting finishes there (its word ends it, _arrivals)
            r.target, r.replan = target, st.mode != ACTING[target.purpose]
        d.notes.append(f"robot {r.id} is on job {job.task.id} again: on to {r.target.name if r.target else '?'}"
                       f"{' with the goods' if job.picked else ''}")

    def _unpicked_elsewhere(self, job: Job, r: FleetRobot) -> bool:
        """``job`` is open, not picked as far as the planner knows, and queued or on another robot."""
        return (not job.picked and (job.state == "queued" or job.state == "active" and job.robot != r.id))

    def _take_back(self, job: Job, r: FleetRobot, now: float, d: Decisions) -> bool:
        """``r`` says it has the goods of ``job`` (or placed them) while nobody heard from it: the job is
        its again (``assigned``); a robot that got it meanwhile drops it before picking. False if
        the store cannot take it (nothing changed)."""
        other = self.robots.get(job.robot) if job.state == "active" and job.robot is not None else None
        if not self._commit(job, "assigned", now, d, state="active", robot=r.id):
            return False
        d.events.append(_event(job.task.id, "assigned", now, r.id))
        if other is not None and other.job == job.task.id:
            other.job, other.target, other.replan, other.arrived_at, other.saw_action = None, None, False, None, False
            other.idle_since = now
            d.notes.append(f"robot {other.id} drops job {job.task.id}: robot {r.id} has its goods")
            if other.on_leg and other.online and not other.immobile:
                self._hold(other, now, d)   # not on to the chute: it stands, and is sent on from there
        return True

    def _held(self, job: Job) -> bool:
        """Some robot here has ``job``."""
        return any(o.job == job.task.id for o in self.robots.values())

    def _orphans(self, now: float, d: Decisions) -> None:
        """Reloaded jobs whose robot has not reported being on them within ``offline_timeout_s`` of
        the first step: queued again if their goods were not picked; failed (with the reason) if
        they were, never picked again."""
        if self._started is None:
            self._started = now
        if now - self._started <= self.params.offline_timeout_s:
            return
        held = {r.job for r in self.robots.values()}
        for job in self.jobs.values():
            if job.state != "active" or job.task.id in held:
                continue
            if job.picked:
                reason = (f"robot {job.robot} held the goods when the planner restarted and has not "
                          "reported carrying them")
                if self._commit(job, "failed", now, d, reason, state="failed"):
                    d.events.append(_event(job.task.id, "failed", now, job.robot, reason))
            elif self._commit(job, "requeued", now, d, state="queued", robot=None):
                d.notes.append(f"job {job.task.id}: the robot it was on has not reported being on it since the "
                               "restart: queued again")

    def _note_arrival(self, r: FleetRobot, now: float) -> None:
        """Note when ``r``'s status first shows it at the end of the leg to its target, and whether
        it shows it doing what it went there for."""
        status, leg, target = r.status, r.leg, r.target
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
        d = Decisions(notes=self._notes, events=self._replay)
        held, first = self._held_from, self._committed_n + 1
        self._notes, self._replay, self._held_from = [], [], None
        self._occ, self._free_spots, self._reserved_at, self._reserved_arr = None, {}, None, None
        self._step_deadline = time.monotonic() + self.step_budget_s
        try:
            self._decide(now, d)
        except BaseException:   # its changes are committed, their events never returned: the next step's
            self._replay, self._held_from = d.events, first if held is None else held
            raise
        finally:
            self._occ, self._free_spots, self._reserved_at, self._reserved_arr = None, {}, None, None
        if d.legs:
            self._plan_id += 1
        return d

    @property
    def handed_out(self) -> int:
        """The number of the store's last transition whose events were handed out (by :meth:`submit`,
        :meth:`step`, the operator) with those of every transition before it; 0 without a store. What a
        publisher passes to :meth:`announced` once what it published by then reached its subscribers."""
        return self._committed_n if self._held_from is None else min(self._committed_n, self._held_from - 1)

    @property
    def replaying(self) -> bool:
        """The next step announces events committed before (a restart's replay, or a step that raised)."""
        return bool(self._replay)

    def announced(self, upto: int | None = None) -> None:
        """The events of the store's transitions up to ``upto`` (default, and at most: :attr:`handed_out`)
        reached their subscribers: the publisher calls it once they did (the planner node: once every
        matched subscriber acknowledged them). A planner killed before that (in the middle of a step:
        its changes committed, their events not yet published; or published and not yet delivered)
        has the next one on the store announce them in its first step (at least once, the original
        stamps; ``JobStore.unannounced``). sqlite3.Error if the store cannot take it (they are
        announced again after a restart then)."""
        upto = self.handed_out if upto is None else min(upto, self.handed_out)
        if self.store is not None and upto > self._announced_n:
            self.store.mark_announced(upto)
            self._announced_n = upto

    def note_pace(self, rate: float, step_s: float) -> None:
        """The caller's clock runs ``rate`` times faster than the wall, and its last step took ``step_s``
        wall seconds: the legs of a step reach the robots about ``rate`` x a step's time after the
        ``now`` they were planned at, so a standing robot's leg starts that much later besides ``lead_s``
        (at most :data:`MAX_DECISION_LAG_S`; the step's time estimated by the longest recent one, fading by
        :data:`STEP_TIME_FADE` a step). Ours. Without it, on a fast clock where one leg takes longer to plan
        than ``lead_s`` of clock time, every leg reached its robot late (100 robots on large at 10x: a
        leg 0.12 s CPU on average, 1.2 s of clock): robots re-planned as late, refused legs that started
        behind them, and stood in others' ways."""
        self._step_s = max(float(step_s), STEP_TIME_FADE * self._step_s)
        self.decision_lag_s = min(MAX_DECISION_LAG_S, max(0.0, float(rate)) * self._step_s)

    def _decide(self, now: float, d: Decisions) -> None:
        self._find_immobile(now, d)
        self._watch_obstacles(now, d)
        self._find_rejected(now, d)
        if self.store is not None:
            for r in self.robots.values():
                self._adopt(r, now, d)
            self._orphans(now, d)
        for r in self.robots.values():
            if r.stop and r.online:
                self._hold(r, now, d)
                r.stop = False
        self._arrivals(now, d)
        if not self.halted:
            self._find_late(d)
            self._break_waits(now, d)
            self._replan(now, d)
            self._allocate(now, d)
            self._housekeeping(now, d)

    def _find_immobile(self, now: float, d: Decisions) -> None:
        timeout = self.params.offline_timeout_s
        heard = max((r.seen for r in self.robots.values() if r.online), default=now)
        deaf = now - heard > timeout / 2   # nobody heard: the planner's input is late (see DEAF_FACTOR)
        if deaf and not self._deaf:
            d.notes.append(f"no status from any robot for {now - heard:.1f} s: the planner's input is late, not "
                           f"every robot at once; robots go offline only after {DEAF_FACTOR * timeout:g} s of silence")
        self._deaf = deaf
        for r in self.robots.values():
            silent = now - r.seen
            if r.online and silent > timeout and (not deaf or silent > DEAF_FACTOR * timeout):
                r.online = False
                why = f"offline: no status for {silent:.1f} s"
                until = stopped_by(r, now, self.params.silence)
                r.unheard = (until, why) if r.leg is not None else None   # it may drive its leg unheard until then
                if r.unheard is not None and until > now:  # its leg is kept meanwhile (fleet/lease.py)
                    d.notes.append(f"robot {r.id} {why}; its leg is kept clear until it must have stopped "
                                   f"(t = {until:.1f} s: lease {self.params.lease:g} s, silence "
                                   f"{self.params.silence:g} s, braking)")
                else:
                    self._immobilise(r, now, d, why)
            elif not r.online and not r.immobile and r.unheard is not None and now >= r.unheard[0]:
                self._immobilise(r, now, d, r.unheard[1])
            elif r.online and not r.immobile and r.status.mode == "error":
                self._immobilise(r, now, d, "out of battery")
            elif r.immobile and r.job is not None:  # its job could not be released (the store failed): again
                self._release(r, now, d, "offline" if not r.online else "out of battery")

    def _find_rejected(self, now: float, d: Decisions) -> None:
        """A robot whose status names its latest leg as rejected stands where it is (it stopped):
        its leg is planned again from there, never assumed driven, and legs of others planned
        around the leg it never took re-plan if they pass where it stands."""
        for r in self.robots.values():
            if r.leg is not None and r.status.rejected_path_id == r.leg.path_id and not r.immobile:
                d.notes.append(f"robot {r.id} could not take leg {r.leg.path_id}: planning it again from "
                               f"({r.status.x:.2f}, {r.status.y:.2f})")
                r.leg, r.replan = None, r.target is not None
                self._changed(r)
                for o in self._replan_around(r, r.pos, now):
                    if self.gates is not None:  # their links keep them off it: an optimisation, not a hold
                        o.conflict = False

    def _immobilise(self, r: FleetRobot, now: float, d: Decisions, why: str) -> None:
        """``r`` stays where it was last seen for good: an obstacle. Its job goes back to the queue
        (or fails, if it holds the goods and is out of battery) and legs passing near it re-plan.
        One that went unheard on a leg is an obstacle wherever it may be: the stretch of its leg it
        could have driven before it must have stopped (fleet/lease.py), not only its last heard point."""
        where = np.array([r.pos])
        if r.unheard is not None and r.leg is not None:
            paths = dict(self.gates.paths.get(r.id, {})) if self.gates is not None else {}
            paths[r.leg.path_id] = r.leg.path
            limits = (self.gates.reach_limits(r, self.robots.values(), r.unheard[0], self.max_clock_skew_s)
                      if self.gates is not None else None)
            where = reachable(r, paths, r.unheard[0], limits)
        r.reach, r.unheard = (where if len(where) > 1 else None), None
        r.immobile = True
        r.leg, r.target, r.replan, r.conflict, r.arrived_at = None, None, False, False, None
        self._changed(r)
        if r.reach is None:
            d.notes.append(f"robot {r.id} {why}; it is an obstacle at ({r.status.x:.2f}, {r.status.y:.2f})")
        else:
            (x0, y0), (x1, y1) = where.min(axis=0).tolist(), where.max(axis=0).tolist()
            d.notes.append(f"robot {r.id} {why}; it is an obstacle anywhere it could have driven unheard "
                           f"(in x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f})")
        self._release(r, now, d, why)
        marked: dict[str, FleetRobot] = {}
        for point in where[::5]:   # (points 0.5 m apart: the clearance covers the rest)
            marked.update((o.id, o) for o in self._replan_around(r, (float(point[0]), float(point[1])), now))
        for o in marked.values():
            d.notes.append(f"robot {o.id} re-plans around {r.id}")
        if self.gates is not None:  # robots waiting for it that do not pass it go on; the others re-plan
            records, stuck = self.gates.forget(r, self.robots.values(), now, where)
            d.gates += records
            for oid in stuck:
                o = self.robots[oid]
                if o.target is not None and not o.replan:
                    o.replan = o.conflict = True
                    d.notes.append(f"robot {o.id} re-plans around {r.id} (its gate waits for it)")

    def _release(self, r: FleetRobot, now: float, d: Decisions, why: str) -> None:
        """The job of ``r``, which stopped for good, goes back to the queue, or fails if it holds the
        goods (never picked twice); if the store cannot take that, ``r`` keeps it and the next step
        tries again."""
        if r.job is None:
            return
        job = self.jobs[r.job]
        if job.picked:  # never picked twice: the goods are on the robot that stopped
            reason = f"robot {r.id} is {why} with the goods"
            if not self._commit(job, "failed", now, d, reason, state="failed"):
                return
            d.events.append(_event(job.task.id, "failed", now, r.id, reason))
        else:
            if not self._commit(job, "requeued", now, d, state="queued", robot=None, picked=False):
                return
            d.notes.append(f"job {job.task.id} is queued again for another robot")
        r.job = None

    def _arrivals(self, now: float, d: Decisions) -> None:
        """Robots at the end of their legs: a pick or place done moves the job on, and done means
        the robot reported it: a status showed it picking / placing there and a later one shows it
        no longer at it, with the goods on board after a pick and off it after a place where the
        status says (``loaded``); the clock alone never finishes one. Any other target is simply reached."""
        for r in self.robots.values():
            target = r.target
            if target is None or not r.online:
                continue
            if target.purpose in ACTING and r.job is not None and self._reported_done(r, target.purpose):
                if self._action_done(r, target, now, d):  # its word, even where no status showed it acting
                    r.arrived_at, r.saw_action = None, False
                continue
            if r.arrived_at is None:
                continue
            if target.purpose in ACTING:
                if r.status.mode == ACTING[target.purpose] or not r.saw_action:
                    continue
                if r.status.loaded is not None and r.status.loaded != (target.purpose == "pick"):
                    continue  # it says the goods are not (or still) on board: not done, whatever the clock
                if not self._action_done(r, target, now, d):
                    continue  # (the store failed: tried again next step)
            else:
                r.target, r.idle_since = None, now
            r.arrived_at, r.saw_action = None, False

    @staticmethod
    def _reported_done(r: FleetRobot, purpose: str) -> bool:
        """``r``'s status says it did the ``purpose`` (pick | place) of its job: it carries the job's
        goods, or it names the job as the last whose goods it placed and no longer carries them."""
        st = r.status
        if purpose == "pick":
            return st.loaded is True and st.task_id == r.job
        return st.placed_task_id == r.job and st.task_id != r.job and st.loaded is not True

    def _action_done(self, r: FleetRobot, target: Target, now: float, d: Decisions) -> bool:
        """``r`` picked (it heads for the storing site next) or placed (its job is done); False if
        the store could not take it (nothing changed)."""
        assert r.job is not None  # a robot picks and places only for its job
        job = self.jobs[r.job]
        if target.purpose == "pick":
            if not self._commit(job, "picked", now, d, picked=True):
                return False
            d.events.append(_event(job.task.id, "picked", now, r.id))
            r.target = Target("place", job.place.name, job.place.pose)
            r.replan = True
        else:
            if not self._commit(job, "done", now, d, state="done"):
                return False
            d.events.append(_event(job.task.id, "placed", now, r.id))
            d.events.append(_event(job.task.id, "done", now, r.id))
            r.job, r.target, r.idle_since = None, None, now
        return True

    def _find_late(self, d: Decisions) -> None:
        """Robots more than ``lateness_tolerance_s`` behind their legs re-plan, beyond the lateness they
        took their leg with (ours: a leg that reached its robot late, which the robot cannot make up,
        was re-planned at once, and its new leg reached it late again: under late messages robots
        spent their time halted between legs; bench_dispatch --delay 6)."""
        for r in self.robots.values():
            if (r.target is not None and not r.replan and r.on_leg and r.status.mode != "error"
                    and self.strategy.is_late(r, self.params.lateness_tolerance_s + r.took_late)):
                r.replan = True
                d.notes.append(f"robot {r.id} is {r.status.lateness_s:.1f} s late: re-planning its leg")

    def _replan(self, now: float, d: Decisions) -> None:
        """Plan the legs of robots that have somewhere to go, in turn: those not refused since their
        last leg first (of them, those that just picked first: they hold a chute), then the refused
        ones, whose retry came due longest ago first. A robot whose new leg is not yet acknowledged
        waits; so does one refused a leg (the back-off), but, ungated, one driving a leg (late or in
        conflict, it is held when no new leg comes; gated, its old leg's links still hold)."""
        waiting = [(r, r.target) for r in self.robots.values() if r.replan and r.target is not None
                   and not r.immobile and r.online and not r.paused and not r.manual
                   and (r.leg is None or r.status.path_id == r.leg.path_id)
                   and (now >= r.leg_retry_at or r.on_leg and self.gates is None)]
        # (ours) in turn: the step's budget holds about one leg on a fast clock; in a fixed order the robots
        # refused at every step (held by their gates, re-planning in vain) took it at every step and a robot
        # standing after a refused leg, which they all waited for, was never planned (100 robots on large)
        waiting.sort(key=lambda item: (item[0].leg_retry_at, item[1].purpose != "place", item[0].id))
        for r, target in waiting:
            if self._out_of_time():
                return   # the rest next step (a robot on its leg drives on meanwhile; it re-plans then)
            if self._plan_leg(r, target, now, d) is not None:
                r.replan = r.conflict = False
            elif r.on_leg and (r.conflict or self.gates is None and r.leg is not None and r.leg.goal != EVADE):
                # late or in conflict and no new leg yet (one stepping aside from an obstacle drives on to its refuge):
                walker = self._walk_into([r], now).get(r.id)
                if walker is None or not self._evade(r, walker, now, d):
                    self._hold(r, now, d)  # stand still, so the others plan around where it is, not around a leg
                # it no longer keeps (gated and only late: it keeps its leg, the gates keep the others clear)

    def _break_waits(self, now: float, d: Decisions) -> None:
        """Break a wait cycle (:mod:`.waits`; ours) that lasted :data:`CYCLE_LASTS_S`, looked for every
        :data:`WAITS_EVERY_S`: of its robots, one
        its gate holds for another of them, preferably one whose leg waits for it, gets a hold leg where its
        gate lets it stand (the gate's own rules apply to it: refused if it would start in a region another may
        be in), and the robots waiting for it are planned next, around it standing. It keeps its target and
        re-plans after :data:`GATE_RETRY_S`. A robot held so is not held again for :data:`BREAK_AGAIN_S`."""
        if self.gates is None or not self.break_waits or now < self._waits_at:
            return
        self._waits_at = now + WAITS_EVERY_S
        graph = wait_for_graph(self.gates, self.robots.values(), now)
        pieces = cycles(graph)
        # (a cycle is broken only once it has lasted CYCLE_LASTS_S: most resolve themselves, late messages above all)
        self._cycles_since = {key: self._cycles_since.get(key, now) for key in map(tuple, pieces)}
        for piece in pieces:
            members = set(piece)
            if now - self._cycles_since[tuple(piece)] < CYCLE_LASTS_S:
                continue
            if any(now - self.robots[rid].broken_at < BREAK_AGAIN_S for rid in piece):
                continue
            # (its robots whose legs wait for it)
            waited = {rid: sorted(oid for oid in members if graph.get(oid, {}).get(rid) == "leg") for rid in piece}
            held = [rid for rid in piece if self.robots[rid].on_leg
                    and any(why == "gate" and oid in members for oid, why in graph.get(rid, {}).items())]
            held.sort(key=lambda rid: (not waited[rid], rid))
            for rid in held:
                r = self.robots[rid]
                marked = self._hold(r, now, d)
                if marked is None:
                    continue   # refused (it would start in a region another robot may be in): the next one
                for o in marked:   # their links keep them off it: an optimisation, not a hold (as _find_rejected)
                    o.conflict = False
                r.broken_at = now
                r.replan = r.target is not None
                r.leg_retry_at = max(r.leg_retry_at, now + GATE_RETRY_S)
                waiting = waited[rid]
                for oid in waiting:   # planned next, around it standing
                    o = self.robots[oid]
                    o.leg_retry_at, o.retry_at, o.waits_on = min(o.leg_retry_at, now), min(o.retry_at, now), ()
                    if o.target is not None:
                        o.replan = True
                d.notes.append(f"wait cycle {' -> '.join(piece)}: robot {rid} holds where its gate lets it stand"
                               f"{', so that ' + ', '.join(waiting) + ' can be planned around it' if waiting else ''}")
                break

    def _hold(self, r: FleetRobot, now: float, d: Decisions) -> list[FleetRobot] | None:
        """Stop ``r`` where it is now (it keeps any target and re-plans from there); legs of others
        that pass there re-plan too (returned; None: the gate refused the hold). No lead time: a robot
        driving a leg nobody keeps clear of any more must stop at once, not drive on for another ``lead_s``."""
        path_id = max(round(now * 1e9), r.last_path_id + 1)
        x, y = self.strategy.start_of(r, path_id / 1e9, self._gate_limit(r))
        leg = Leg(r.id, TimedPath(r.id, r.radius, np.array([[x, y, path_id / 1e9]])), path_id, "hold", "")
        if not self._give(r, leg, d, now):
            return None  # gated: it keeps its leg, whose links still hold
        r.conflict = False
        d.notes.append(f"robot {r.id} holds at ({x:.2f}, {y:.2f})")
        return self._replan_around(r, (x, y), now)

    def _evade(self, r: FleetRobot, oid: str, now: float, d: Decisions) -> bool:
        """``r`` stands where the moving obstacle ``oid`` is about to walk: it gets a leg to the nearest
        refuge (:meth:`.obstacles.ObstacleMap.refuges`) that the planner can time round everyone,
        obstacles included; it keeps its target and plans its way there again from the refuge."""
        grid = self.warehouse.grid

        def free(x: float, y: float) -> bool:
            return grid.disc_is_free(x, y, r.radius) and self._occupant((x, y), r.radius, exclude=r) is None

        path_id = self._next_path_id(r, now)
        t0 = path_id / 1e9
        start = self.strategy.start_of(r, t0, self._gate_limit(r))
        for spot in self.obstacles.refuges(start, r.radius, self.margin, now, free, most=EVADE_TRIES):
            if self._out_of_time():
                return False   # tried again next step
            try:
                path = self._leg_path(r, start, Target("hold", EVADE, spot), t0, now)
            except LegNotPlanned:
                continue
            if not self._give(r, Leg(r.id, path, path_id, "hold", EVADE), d, now):
                break
            r.replan, r.conflict = r.target is not None, False
            d.notes.append(f"robot {r.id} steps aside from obstacle {oid} to ({spot[0]:.2f}, {spot[1]:.2f})")
            return True
        r.evade_retry_at = now + EVADE_RETRY_S
        why = f"no refuge from obstacle {oid} within reach: it holds"
        if why != r.trouble:
            d.notes.append(f"robot {r.id}: {why}")
        r.trouble = why
        return False

    def _replan_around(self, r: FleetRobot, point: Point, now: float) -> list[FleetRobot]:
        """Mark the robots whose legs must now keep clear of ``r`` standing at ``point`` to re-plan
        (as the coordination mode says); they are returned."""
        marked = []
        for o in self.robots.values():
            if o is r or o.leg is None or o.immobile or o.target is None:
                continue
            if self.strategy.must_replan_around(o.leg.path, now, point, o.radius + r.radius + self.margin):
                o.replan = o.conflict = True
                marked.append(o)
        return marked

    def _allocate(self, now: float, d: Decisions) -> None:
        queued = sorted((j for j in self.jobs.values() if j.state == "queued"),  # earliest deadline among equals
                        key=lambda j: (-j.task.priority, math.inf if j.task.deadline is None else j.task.deadline,
                                       j.seq))
        if self.policy.batch:  # (also with nothing queued: robots waiting by a chute go on when it is free)
            self._allocate_batch(queued, now, d)
            return
        if not queued:
            return
        free = [r for r in self.robots.values() if r.free and r.status.battery >= self.params.min_task_battery
                and now >= r.leg_retry_at]
        for job in queued:
            pose = job.pick.pose
            if not free or self._out_of_time():
                return
            if self._reserved(pose):
                continue
            able = [r for r in free if r.free and can_do(r.kind, job.task)]
            if not able:
                continue
            r = min(able, key=lambda r: (math.dist(r.pos, pose), -r.status.battery, r.id))
            self._try_assign(r, job, now, d)

    def _available(self, r: FleetRobot, now: float) -> bool:
        """``r`` may take a job now: free, or only on its way to wait somewhere (a staging or parking
        spot, or a charger it does not need), its last leg acknowledged; with battery enough."""
        if r.status.battery < self.params.min_task_battery or now < r.leg_retry_at:
            return False
        if r.free:
            return True
        t = r.target
        return (t is not None and r.job is None and r.online and not r.immobile and not r.paused and not r.manual
                and not r.replan and r.status.mode not in ("picking", "placing", "error")
                and (r.leg is None or r.status.path_id == r.leg.path_id)
                and (t.purpose == "park" or t.purpose == "charge" and r.status.battery >= self.policy.charge_below))

    def _allocate_batch(self, queued: list[Job], now: float, d: Decisions) -> None:
        """Free robots and the first job of each free chute paired by the smallest sum of estimated
        arrival times (fleet/dispatch.py); with policy ``queue`` the robots waiting for a chute go
        on when it is free, and the next job of a taken chute goes to a robot that waits by it."""
        waiting = self._waiting_for_chutes() if self.policy.queue else {}
        for chute, r in waiting.items():
            if self._out_of_time():
                return
            job = self.jobs.get(r.job) if r.job is not None else None
            if job is None:
                continue
            stuck = self._stopped_on(chute, r.radius, exclude=r)
            if stuck is not None:   # nobody picks there: the job goes back to the queue (committed first)
                if self._commit(job, "requeued", now, d, state="queued", robot=None):
                    r.job = None
                    d.notes.append(f"job {job.task.id} is queued again: {stuck.id} stands on {chute} for good")
            elif not self._reserved(self.work_stops[chute]) and self._may_plan(r, now):
                occupant = self._occupant(job.pick.pose, r.radius, exclude=r)
                if occupant is None or self._leaving(occupant, job.pick.pose):
                    self._plan_leg(r, Target("pick", job.pick.name, job.pick.pose), now, d)
                elif occupant.free:
                    self._send_away(occupant, now, d)   # (sooner than its idle time would send it)
        free = {r.id: r for r in self.robots.values() if self._available(r, now)} if queued else {}
        if not free:
            return
        jobs = [(j.task.id, j.pick.name) for j in queued]

        def able(rid: str, jid: str) -> bool:
            return can_do(free[rid].kind, self.jobs[jid].task)

        def cands() -> list[Candidate]:
            return [Candidate(r.id, r.pos, r.kind.max_speed * self.params.speed_factor, r.status.battery)
                    for r in free.values()]

        sites = self.policy.sites
        site_of = (lambda jid: self.jobs[jid].place.name) if sites else None

        def taken() -> set[str]:
            return self._taken_sites() if sites else set()

        pairs = assign(cands(), jobs, able, self.travel.length,
                       busy=lambda chute: chute in waiting or self._reserved(self.work_stops[chute]),
                       site_of=site_of, taken_sites=taken())
        for rid, jid, _ in pairs:
            if self._out_of_time():
                return
            if self._try_assign(free[rid], self.jobs[jid], now, d):
                del free[rid]
        if not (self.policy.queue and free):
            return
        # taken chutes with nobody waiting for them yet: the next job's robot waits on the chute's spot
        open_spot = {}
        for chute, spot in self.queue_spot.items():
            if chute in waiting or not self._reserved(self.work_stops[chute]):
                continue
            if self._stopped_on(chute, max(r.radius for r in free.values())) is not None:
                continue   # nobody waits for it
            occupant = self._occupant(self.staging[spot], max(r.radius for r in free.values()))
            if occupant is None or occupant.id in free:
                open_spot[chute] = spot
        if not open_spot:
            return
        pairs = assign(cands(), [(j, c) for j, c in jobs if c in open_spot and self.jobs[j].state == "queued"],
                       able, self.travel.length, site_of=site_of, taken_sites=taken())
        for rid, jid, _ in pairs:
            if self._out_of_time():
                return
            r, job = free[rid], self.jobs[jid]
            spot = open_spot[job.pick.name]
            occupant = self._occupant(self.staging[spot], r.radius, exclude=r)
            if occupant is not None:
                continue   # another free robot stands there (it could not do this job)
            if self._plan_leg(r, Target("park", spot, self.staging[spot]), now, d) is None:
                continue
            if not self._commit(job, "assigned", now, d, state="active", robot=r.id):
                continue   # (it parks there without the job; the job stays queued)
            r.job = job.task.id
            d.events.append(_event(job.task.id, "assigned", now, r.id))
            d.notes.append(f"robot {r.id} waits at {spot} for {job.pick.name} (job {job.task.id})")

    def _stopped_on(self, chute: str, radius: float, exclude: FleetRobot | None = None) -> FleetRobot | None:
        """A robot stopped for good (offline, out of battery) on ``chute``, where a robot of ``radius``
        would pick (policy ``queue``: nobody waits for such a chute, and a robot waiting for it lets its job go)."""
        o = self._occupant(self.work_stops[chute], radius, exclude)
        return o if o is not None and o.immobile else None

    def _leaving(self, o: FleetRobot, pose: Point) -> bool:
        """``o`` stands at ``pose`` but drives off: it has the goods of its job and a leg it took that
        ends elsewhere (the next robot's leg there is timed behind it; no need to wait until it is off)."""
        job = self.jobs.get(o.job) if o.job is not None else None
        return (job is not None and job.picked and o.leg is not None and not o.immobile
                and o.status.path_id == o.leg.path_id
                and math.dist(tuple(o.leg.path.waypoints[-1, :2]), pose) > o.radius + AT_STATION_M)

    def _taken_sites(self) -> set[str]:
        """Storing sites no new job may go to yet (policy ``sites``): those of active jobs, but with
        ``site_hold`` "picked" only of jobs not yet picked, with "soon" also of picked jobs whose robot
        will not have placed before a robot given a job there now could get there (its way there and
        the place at its kind's speed, against the quickest pick and the shortest way from a chute)."""
        hold = self.policy.site_hold
        out: set[str] = set()
        for j in self.jobs.values():
            site = j.place.name
            if j.state != "active" or site in out:
                continue
            r = self.robots.get(j.robot) if j.robot is not None else None
            if hold == "done" or not j.picked or r is None:
                out.add(site)
            elif hold == "soon":
                way = float(self.travel.length(site, np.array([r.pos]))[0])
                left = way / (r.kind.max_speed * self.params.speed_factor) + r.kind.action_s("place")
                if left > self._soonest_at(site):
                    out.add(site)
        return out

    def _soonest_at(self, site: str) -> float:
        """Simulated s at least before a robot given a job for ``site`` now can be there with the goods."""
        out = self._soonest.get(site)
        if out is None:
            chutes = np.array([s.pose for s in self.warehouse.stations_of("chute")], dtype=float).reshape(-1, 2)
            fastest = max(k.max_speed for k in self.kinds.values()) * self.params.speed_factor
            way = float(np.min(self.travel.length(site, chutes))) if len(chutes) else 0.0
            out = self._soonest[site] = way / fastest + min(k.action_s("pick") for k in self.kinds.values())
        return out

    def _waiting_for_chutes(self) -> dict[str, FleetRobot]:
        """Chute -> the robot whose job is there but that is not yet bound for it (it waits by it)."""
        out = {}
        for r in self.robots.values():
            job = self.jobs.get(r.job) if r.job is not None else None
            if (job is not None and job.state == "active" and not job.picked and not r.immobile
                    and (r.target is None or r.target.purpose != "pick")):
                out[job.pick.name] = r
        return out

    def _may_plan(self, r: FleetRobot, now: float) -> bool:
        """``r`` may get a new leg now: online, not paused or driven by hand, its last leg acknowledged."""
        return (r.online and not r.immobile and not r.paused and not r.manual and now >= r.leg_retry_at
                and (r.leg is None or r.status.path_id == r.leg.path_id))

    def _try_assign(self, r: FleetRobot, job: Job, now: float, d: Decisions) -> bool:
        """Give ``job`` to ``r`` if its leg to the chute can be planned (a free robot standing on the
        chute is sent off first, and the job waits)."""
        pose = job.pick.pose
        occupant = self._occupant(pose, r.radius, exclude=r)
        if occupant is not None:
            if occupant.free:
                self._send_away(occupant, now, d)
            return False
        if self._plan_leg(r, Target("pick", job.pick.name, pose), now, d) is None:
            return False
        if not self._commit(job, "assigned", now, d, state="active", robot=r.id):
            r.target = None   # it drives to the chute without the job (which stays queued), and does nothing there
            return False
        r.job = job.task.id
        d.events.append(_event(job.task.id, "assigned", now, r.id))
        return True

    def _housekeeping(self, now: float, d: Decisions) -> None:
        due = sorted((r for r in self.robots.values() if r.free and now >= r.retry_at), key=lambda r: r.status.battery)
        if not due:
            return
        staging = self.policy.staging and bool(self.staging)
        where = np.array([r.pos for r in due], dtype=float)   # (one test for all: idle robots cost little)
        at_charger, at_stop = self._at_all(where, self.chargers), self._at_all(where, self.work_stops)
        for r, charging, stopped in zip(due, at_charger, at_stop):
            if self._out_of_time():
                return
            if not r.free:
                continue
            low = r.status.battery < self.params.low_battery
            idle = now - r.idle_since >= self.params.idle_s
            if staging:
                self._wait_near_chutes(r, low, idle, now, d)
                continue
            if charging or not (low or idle):
                continue
            spot = self._free_spot(r, self.chargers)
            if spot is not None:
                if self._plan_leg(r, Target("charge", *spot), now, d) is None:
                    r.retry_at = now + SPOT_RETRY_S  # not planned again at every step
            elif idle and stopped:
                self._send_away(r, now, d)

    def _wait_near_chutes(self, r: FleetRobot, low: bool, idle: bool, now: float, d: Decisions) -> None:
        """Where a free robot waits (fleet/dispatch.py, policy ``staging``): low on battery, or idle
        and below ``charge_below``, at a charger; otherwise idle at a staging spot near the chutes
        (a robot at a charger once charged to ``leave_charger_at``); else as before."""
        battery = r.status.battery
        if self._at(r.pos, self.chargers):
            if low or not idle or battery < self.policy.leave_charger_at:
                return
            spot = self._free_spot(r, self.staging)
            if spot is not None and self._plan_leg(r, Target("park", *spot), now, d) is None:
                r.retry_at = now + SPOT_RETRY_S
            return
        if not (low or idle) or (self._at(r.pos, self.staging) and not low):
            return
        goals = [(self.chargers, "charge"), (self.staging, "park")]
        if not (low or battery < self.policy.charge_below):
            goals.reverse()
        for spots, purpose in goals:
            spot = self._free_spot(r, spots)
            if spot is not None:
                if self._plan_leg(r, Target(purpose, *spot), now, d) is None:
                    r.retry_at = now + SPOT_RETRY_S
                return
        if idle and self._at(r.pos, self.work_stops):
            self._send_away(r, now, d)

    # -- helpers ---------------------------------------------------------------------------------------
    def _send_away(self, r: FleetRobot, now: float, d: Decisions) -> None:
        """Move a free robot that is in the way to a free staging spot (policy ``staging``), else a free
        charger, else a free parking spot."""
        if now < r.retry_at or now < r.leg_retry_at:
            return   # its last leg off was refused: not planned again at every step
        if self._at(r.pos, self.chargers) or self._at(r.pos, self.parking):
            return
        spot, purpose = None, "park"
        if self.policy.staging and not self._at(r.pos, self.staging):
            spot = self._free_spot(r, self.staging)
        if spot is None:
            spot, purpose = self._free_spot(r, self.chargers), "charge"
        if spot is None:
            spot, purpose = self._free_spot(r, self.parking), "park"
        if spot is None:
            why = "in the way but no charger or parking spot is free"
            if r.trouble != why:  # noted once, not at every step
                d.notes.append(f"robot {r.id} is {why}")
            r.trouble = why
            return
        if self._plan_leg(r, Target(purpose, *spot), now, d, clear_way=False) is None:
            r.retry_at = now + SPOT_RETRY_S

    def _plan_leg(self, r: FleetRobot, target: Target, now: float, d: Decisions,
                  clear_way: bool = True) -> Leg | None:
        """Plan ``r`` from where it is (or will be, if it is driving) to ``target``, as the
        coordination mode plans legs; on success ``r`` gets the leg and the target. On failure None
        is returned (the caller tries again later; why is noted once) and, with ``clear_way``, a free
        robot named as the blocker is sent off."""
        path_id = self._next_path_id(r, now)
        t0 = path_id / 1e9
        start = self.strategy.start_of(r, t0, self._gate_limit(r))
        if math.dist(start, target.pose) < 1e-6:
            path = TimedPath(r.id, r.radius, np.array([[*target.pose, t0]]))
        else:
            try:
                path = self._leg_path(r, start, target, t0, now)
            except LegNotPlanned as exc:
                if exc.blocker is not None:
                    r.waits_on, r.waits_since = (exc.blocker,), now
                if exc.why != r.trouble:
                    d.notes.append(f"robot {r.id}: {exc.why}")
                r.trouble = exc.why
                self._back_off(r, now)
                blocker = self.robots.get(exc.blocker) if exc.blocker is not None else None
                if clear_way and blocker is not None and blocker.free:
                    self._send_away(blocker, now, d)
                return None
        leg = Leg(r.id, path, path_id, target.purpose, target.name)
        if not self._give(r, leg, d, now):
            self._back_off(r, now)   # (a gate refused it: tried again later, as a leg not planned)
            return None  # (why is noted)
        r.target, r.trouble, r.waits_on = target, "", ()
        r.leg_retry_at, r.leg_failures = -math.inf, 0
        if self._reserved_at is not None:
            self._reserved_at.append(target.pose)
        return leg

    @staticmethod
    def _back_off(r: FleetRobot, now: float) -> None:
        """``r`` was refused a leg: it is tried again after a wait that doubles with each refusal in a row,
        or later if a retry was already set later (a standing robot the gate refused waits ``GATE_RETRY_S``)."""
        # (the exponent capped: 2 ** 1024 failures overflowed a float: every step of the planner then failed)
        r.leg_retry_at = max(r.leg_retry_at, now + min(LEG_RETRY_MAX_S, LEG_RETRY_S * 2 ** min(r.leg_failures, 16)))
        r.leg_failures += 1

    def _leg_path(self, r: FleetRobot, start: Point, target: Target, t0: float, now: float) -> TimedPath:
        """``r``'s timed path from ``start`` at ``t0`` to ``target``, as the coordination mode plans it
        round the fleet, the obstacles (followed OBSTACLE_LOOKAHEAD horizons) and the stretches robots
        that stopped unheard may stand on; LegNotPlanned if none."""
        return self.strategy.plan_leg(r, start, target, t0, grid=self.warehouse.grid, planner=self.planner,
                                      speed=r.kind.max_speed * self.params.speed_factor, fleet=self.robots.values(),
                                      obstacles=self.obstacles.trajectories(now, OBSTACLE_LOOKAHEAD)
                                      + self._reaches(start, r.radius, t0), margin=self.margin)

    def _reaches(self, start: Point, radius: float, t0: float) -> list[TimedPath]:
        """Every point robots that stopped unheard may stand on (fleet/lease.py), as standing discs (a
        leg starting near one keeps at least the distance of now from it, as from a robot)."""
        out = []
        gap = 2 * STRETCH_STEP_M   # discs this far apart, grown by the sag between two of them, cover the stretch
        for o in self.robots.values():
            if o.immobile and o.reach is not None:
                grown = o.radius + o.radius - math.sqrt(max(0.0, o.radius ** 2 - (gap / 2) ** 2))
                pts = o.reach[1:]   # (the first is its status: the robot itself)
                for k, (x, y) in enumerate(np.vstack([pts[::2], pts[-1:]]).tolist()):
                    disc = TimedPath(f"{o.id}~{k}", grown, np.array([[x, y, t0]]))
                    out.append(room_to_leave(disc, start, radius, self.margin, t0))
        return out

    def heard(self, now: float) -> Heard:
        """Whom the planner hears now, for the robots' leases (``fleet/heard@1``; fleet/lease.py)."""
        return heard_record(self.robots.values(), now, self.params.lease, self.params.silence)

    def _out_of_time(self) -> bool:
        """This step has spent its leg-planning budget (``step_budget_s`` wall seconds)."""
        return time.monotonic() >= self._step_deadline

    def _give(self, r: FleetRobot, leg: Leg, d: Decisions, now: float) -> bool:
        if self.gates is not None:  # its links, and the links others get where it passes first
            # a leg is not taken if it starts in a region another robot may be in (fleet/gate.py): one
            # replacing a leg it drives keeps that leg, whose links still hold (a re-plan is only an
            # optimisation); one for a robot that stands keeps it standing, and the robots in that region
            # re-plan around it. Ours (after session 20's safety22): taken, it ranked the other first,
            # whose way passes where it stands: the other's net stopped it short of the standing robot,
            # which waited for it at its gate (late messages: the other was behind the schedule the
            # leg was planned around; bench_dispatch --delay 6, five robots in one aisle at t = 500 s)
            records = self.gates.on_leg(r, leg.path_id, leg.path, self.robots.values(), now, refuse_conflicts=True)
            if records is None:
                others = sorted(set(self.gates.conflicts))
                why = f"a new leg would start in a region {', '.join(others)} may be in"
                if why != r.trouble:
                    d.notes.append(f"robot {r.id}: {why}: it {'keeps its leg' if r.on_leg else 'stands'}")
                r.trouble = why
                r.waits_on, r.waits_since = tuple(others), now
                if not r.on_leg:
                    r.leg_retry_at = max(r.leg_retry_at, now + GATE_RETRY_S)
                    for oid in others:
                        o = self.robots.get(oid)
                        if o is not None and o.on_leg and o.target is not None and not o.replan:
                            o.replan = True
                            d.notes.append(f"robot {o.id} re-plans around {r.id} (it stands in its way)")
                return False
            d.gates += records
        r.leg, r.last_path_id = leg, leg.path_id
        r.arrived_at, r.saw_action = None, False
        d.legs.append(leg)
        self._changed(r)
        return True

    def _changed(self, r: FleetRobot) -> None:
        """``r``'s leg changed during this step: the step's indexes learn it."""
        if self._occ is not None:
            self._occ.touch(r)
        self._free_spots.clear()

    def _gate_limit(self, r: FleetRobot) -> float:
        """How far along its path ``r``'s gate lets it drive (a new leg never starts beyond it)."""
        return self.gates.limit_of(r, self.robots.values()) if self.gates is not None else math.inf

    def _next_path_id(self, r: FleetRobot, now: float) -> int:
        lead = self.params.lead_s
        if r.on_leg and math.hypot(r.status.vx, r.status.vy) * lead > r.radius / 2:
            # re-planned while it drives on: a leg starting lead_s ahead would start further along
            # its way than its radius, and the robot refuses a leg that starts beyond it (one that
            # starts behind it on its way, once it drove on, it joins where it is: CentralDriver.follow)
            lead = 0.0
        else:
            lead += self.decision_lag_s   # (it stands: it waits on the leg's start until its leg reaches it)
        return max(round((now + lead) * 1e9), r.last_path_id + 1)

    def _occupant(self, pose: Point, radius: float, exclude: FleetRobot | None = None) -> FleetRobot | None:
        """A robot standing on, or bound for, a disc of ``radius`` at ``pose`` (from the step's
        index, :class:`~.state.Occupancy`)."""
        if self._occ is None:
            self._occ = Occupancy(list(self.robots.values()))
        return self._occ.occupant(pose, radius, exclude)

    def _reserved(self, pose: Point) -> bool:
        """Some robot is working at ``pose`` or has it as its target (the places are gathered once a step)."""
        if self._reserved_at is None:
            self._reserved_at = [o.target.pose for o in self.robots.values() if o.target is not None]
            self._reserved_at += [o.pos for o in self.robots.values() if o.status.mode in ("picking", "placing")]
        if not self._reserved_at:
            return False
        at = self._reserved_arr
        if at is None or len(at) != len(self._reserved_at):  # (places are only ever added during a step)
            at = self._reserved_arr = np.asarray(self._reserved_at, dtype=float)
        return bool(np.any(np.hypot(at[:, 0] - pose[0], at[:, 1] - pose[1]) < AT_STATION_M))

    def _free_spot(self, r: FleetRobot, spots: Mapping[str, Point]) -> tuple[str, Point] | None:
        """The nearest spot no other robot stands on or is bound for. The free spots are found once
        per step and robot size (until a leg changes): ``r`` is free and stands on none of them
        (its callers ask only then), so leaving it out changes nothing."""
        key = (id(spots), r.radius)
        free = self._free_spots.get(key)
        if free is None:
            free = self._free_spots[key] = [(name, p) for name, p in spots.items()
                                            if self._occupant(p, r.radius, exclude=r) is None]
        return min(free, key=lambda item: math.dist(item[1], r.pos), default=None)

    def _at(self, pos: Point, spots: Mapping[str, Point]) -> bool:
        """``pos`` is at one of ``spots`` (a fixed table of the manager's: chargers, parking, work stops)."""
        if not spots:
            return False
        table = self._spot_trees.get(id(spots))
        if table is None:  # the table itself is kept too, so its id stays its own
            table = self._spot_trees[id(spots)] = (spots, np.asarray(list(spots.values()), dtype=float))
        at = table[1]
        return bool(np.min(np.hypot(at[:, 0] - pos[0], at[:, 1] - pos[1])) < AT_STATION_M)

    def _at_all(self, where: np.ndarray, spots: Mapping[str, Point]) -> np.ndarray:
        """For each row of ``where`` (x, y), whether it is at one of ``spots`` (as :meth:`_at`)."""
        if not spots:
            return np.zeros(len(where), dtype=bool)
        self._at(tuple(where[0]), spots)  # (builds the table)
        at = self._spot_trees[id(spots)][1]
        gaps = np.hypot(where[:, None, 0] - at[None, :, 0], where[:, None, 1] - at[None, :, 1])
        return gaps.min(axis=1) < AT_STATION_M

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


#: the task events a committed transition was announced with (placed and done: one transition)
_ANNOUNCED_AS = {"accepted": ("accepted",), "assigned": ("assigned",), "picked": ("picked",),
                 "done": ("placed", "done"), "failed": ("failed",), "cancelled": ("cancelled",)}


def replayed(job_id: str, t: Transition) -> list[TaskEvent]:
    """The task events the transition ``t`` of job ``job_id`` was (or was to be) announced with, as
    then: stamp, robot and reason of the transition (none for a change that is not announced:
    requeued, reloaded, a priority)."""
    with_reason = (*EVENTS_NEEDING_REASON, "cancelled")
    return [_event(job_id, name, t.stamp, t.robot, t.reason if name in with_reason else None)
            for name in _ANNOUNCED_AS.get(t.event, ())]


def _guess_id(raw: Any) -> str:
    """The ``id`` of a task that failed validation, when one can be made out and is itself a valid
    id (else "?": a rejection never echoes an oversized or unprintable id)."""
    value: Any = None
    if isinstance(raw, Mapping):
        value = raw.get("id")
    elif isinstance(raw, (str, bytes)):
        try:
            data = load_json(raw, "task")
            value = data.get("id") if isinstance(data, Mapping) else None
        except RecordError:
            if isinstance(raw, bytes):
                raw = raw[:MAX_RECORD_BYTES].decode("utf-8", "replace")
            m = re.search(r'"id"\s*:\s*"([^"\\]{1,' + str(MAX_NAME_CHARS) + '})"', raw[:MAX_RECORD_BYTES])
            value = m.group(1) if m else None
    try:
        return nonempty(value, "task.id")
    except RecordError:
        return "?"
