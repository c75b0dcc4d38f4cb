"""The robot's end of the fleet: :class:`RobotAgent`, a :class:`~fleet_planner.robots.RobotModel`
that follows the legs it is sent and, where a leg ends, picks at the chute of its job, places at the
storing site holding the job's address tag, or charges at a charger. How it drives its legs and keeps
clear of the others depends on the coordination mode (:mod:`.coordination`).

Times are seconds on one clock (the robot's ROS time): ``now`` is always passed in.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

from msg_schemas.records import GateRecord, Heard, ObstacleRecord, RobotStatus, Task, TaskEvent, WaitMessageRecord

from ..behavior import BehaviorController, BehaviorParams
from ..model import TimedPath
from ..robots import RobotModel
from ..warehouse import Warehouse
from .coordination import AGENT_BEHAVIOR, Coordination, get_coordination
from .gate import watched_robots
from .lease import Lease
from .legs import MAX_CLOCK_SKEW_S, station_at
from .manual import OperatorHand
from .obstacles import ObstacleMap


class RobotAgent:
    """A robot doing its jobs: it follows the legs it is sent with its :class:`RobotModel` and, where
    a leg ends, picks (at the chute of its job), places (at the storing site that holds the job's
    address tag, once it carries the goods) or charges (at a charger, with nothing to do).

    It learns its job from the ``assigned`` task event naming it and the job's stations from the
    task itself (:meth:`on_task`; the first task heard with an id is kept, as the planner keeps
    it: a duplicate it rejects never replaces it); if it never saw the task, any chute or storing
    site will do. It acts only on the planner's word about its own job: an event about another
    job, or a ``failed`` / ``cancelled`` that does not name this robot, is ignored, and with
    ``planner`` set (the planner's node name) so is every event whose ``sender`` is another node.
    It hears the other robots' statuses (:meth:`on_status`, each one; or :meth:`on_neighbours`, the
    planner's relay of those within its safety range) and the obstacles of the intelligent space
    (:meth:`on_obstacle`): its safety net stops for both.

    ``coordination`` (a name of :data:`~.coordination.COORDINATION` or a
    :class:`~.coordination.Coordination`) says how it drives (its :attr:`driver`): ``"central"``,
    each leg's timed path, with a safety net: it waits rather than drive into a robot in its
    critical area (:meth:`CentralDriver.must_wait <.coordination.CentralDriver.must_wait>` says
    how); ``"behavior"``, only to the goal of each leg (and the station there, which it docks at one
    robot at a time), on its own path at its own speed with a :class:`BehaviorController`, from the
    other robots' statuses and the wait messages addressed to it (:meth:`on_wait_message`; the ones
    it sends come from :meth:`take_wait_messages`); its statuses then carry its behaviour state.

    ``gated`` (central coordination): it never drives into a collision region before the robot
    ranked above it there reported leaving it (:mod:`.gate`; its records come in by
    :meth:`on_gate`), whatever the clock says; without a record for its current leg it waits.
    Its statuses carry the path it follows and how far it drove along it (``travelled_m``), the
    last leg it could not take (``rejected_path_id``; it stops where it is until the next one), its
    job and whether it carries the job's goods (``task_id``, ``loaded``) and the last job whose goods
    it placed (``placed_task_id``): a planner restarted mid-job re-adopts it from them.
    :attr:`speed_scale` slows it down (a speed limit: 0 halts it).

    Its :attr:`lease` (:mod:`.lease`): once a planner's heard record (:meth:`on_heard`) named it, a
    robot that planner has not heard for longer than the record's ``lease_s`` brakes to a stop and
    stands until it is heard again on a leg the planner keeps clear (or gets a new leg).
    """

    KEEP_TASKS = 10_000  # task details remembered

    def __init__(self, model: RobotModel, warehouse: Warehouse, coordination: str | Coordination = "central",
                 params: BehaviorParams = AGENT_BEHAVIOR, planner: str | None = None, gated: bool = False):
        self.strategy = get_coordination(coordination)
        self.model = model
        self.warehouse = warehouse
        self.tasks: dict[str, Task] = {}
        self.loaded = False
        self.placed: str | None = None            # the last job whose goods it placed
        self.heard: dict[str, RobotStatus] = {}   # the other robots' last statuses
        self.driver = self.strategy.driver(model, warehouse, params, gated)
        self.obstacles = ObstacleMap(max_clock_skew_s=MAX_CLOCK_SKEW_S)   # what the intelligent space reports
        self.driver.obstacles = self.obstacles
        self._acting: str | None = None
        self._last: float | None = None
        self.planner = planner
        self.hand = OperatorHand(model, warehouse)  # e-stop and manual drive (.manual)
        self.rejected: int | None = None          # the last leg it could not take
        self._pending: tuple[TimedPath, float, int] | None = None  # a leg waiting for its gate record
        self._kind = model.kind
        self._scale = 1.0
        self.lease = Lease(model.id)

    @property
    def speed_scale(self) -> float:
        """The fraction of its top speed it may drive at (1: no limit, 0: halted)."""
        return self._scale

    @speed_scale.setter
    def speed_scale(self, scale: float) -> None:
        if not 0.0 <= scale <= 1.0:
            raise ValueError(f"speed_scale: must be in [0, 1] (got {scale!r})")
        self._scale = float(scale)
        if scale > 0.0:
            self.model.kind = replace(self._kind, max_speed=self._kind.max_speed * scale)

    @property
    def coordination(self) -> str:
        """The name of its coordination mode."""
        return self.strategy.name

    @property
    def controller(self) -> BehaviorController | None:
        """Its behaviour controller (behaviour coordination), else None."""
        return self.driver.controller

    @property
    def waits_for(self) -> str | None:
        """The robot its safety net stops for (central coordination), if any."""
        return self.driver.waits_for

    @property
    def gate(self) -> GateRecord | None:
        """Its current gate record (central coordination), if any."""
        return getattr(self.driver, "gate", None)

    def watches(self) -> set[str]:
        """The robots whose statuses its gate still needs (:func:`~.gate.watched_robots`)."""
        return watched_robots(self.gate, self.heard)

    @property
    def job(self) -> str | None:
        return self.model.task_id

    def on_task(self, task: Task) -> None:
        """A task on the wire: remembered unless its id is known (the first one is what the
        planner accepted; a later one with the same id is a duplicate it rejects)."""
        if task.id in self.tasks:
            return
        if len(self.tasks) >= self.KEEP_TASKS:
            self.tasks.pop(next(iter(self.tasks)))
        self.tasks[task.id] = task

    def on_event(self, event: TaskEvent, sender: str | None = None) -> bool:
        """Take a job assigned to this robot; drop its job when the planner gives it to another
        robot, or says it failed or is cancelled for this robot. ``sender``: the node that published
        the event, where the wire tells (checked against ``planner`` if that is set). True if the
        event changed the robot's job."""
        if self.planner is not None and sender != self.planner:
            return False
        me = self.model.id
        if event.event == "assigned" and event.robot_id == me:
            if self.job != event.task_id:
                self.model.task_id, self.loaded = event.task_id, False
                return True
            return False
        if event.task_id != self.job or self.job is None:
            return False
        if (event.event in ("failed", "cancelled") and event.robot_id == me
                or event.event == "assigned" and event.robot_id != me):
            self.model.task_id, self.loaded, self._acting = None, False, None
            return True
        return False

    def on_status(self, status: RobotStatus, now: float | None = None) -> None:
        """Another robot's status (its own and older ones than the last heard are ignored, and so
        is one stamped more than ``MAX_CLOCK_SKEW_S`` ahead of ``now``, by default the last tick)."""
        clock = now if now is not None else self._last
        if clock is not None and status.stamp > clock + MAX_CLOCK_SKEW_S:
            return
        last = self.heard.get(status.id)
        if status.id != self.model.id and (last is None or status.stamp >= last.stamp):
            self.heard[status.id] = status

    def on_neighbours(self, statuses: Iterable[RobotStatus], now: float | None = None) -> None:
        """The planner's relay of the robots this robot must hear (``fleet/neighbours@1``, see
        :mod:`.neighbours`): they replace what it heard (a newer status already heard of one of them
        is kept; robots no longer relayed are forgotten: they are out of range). Its own status and
        ones stamped more than ``MAX_CLOCK_SKEW_S`` ahead of ``now`` (default: the last tick) are ignored."""
        clock = now if now is not None else self._last
        heard: dict[str, RobotStatus] = {}
        for st in statuses:
            if st.id == self.model.id or clock is not None and st.stamp > clock + MAX_CLOCK_SKEW_S:
                continue
            last = self.heard.get(st.id)
            heard[st.id] = last if last is not None and last.stamp > st.stamp else st
        self.heard = heard
    def on_obstacle(self, ob: ObstacleRecord, now: float | None = None) -> None:
        """An obstacle on the wire (see :class:`~.obstacles.ObstacleMap`), for the safety net; ValueError
        (naming the field) for one stamped too far ahead of ``now`` (by default the last tick)."""
        clock = now if now is not None else self._last
        self.obstacles.update(ob, clock if clock is not None else ob.stamp)

    def on_heard(self, record: Heard, now: float | None = None) -> None:
        """Whom the planner hears (``fleet/heard@1``): renews this robot's lease if it names it; ValueError
        (naming the field) for a stamp of it more than ``MAX_CLOCK_SKEW_S`` ahead of ``now`` (by default
        the last tick)."""
        self.lease.on_heard(record, now if now is not None else self._last)

    def on_wait_message(self, msg: WaitMessageRecord) -> None:
        """A wait message on the topic: taken at the next tick if it is addressed to this robot."""
        if msg.receiver == self.model.id:
            self.driver.on_wait_message(msg)

    def take_wait_messages(self) -> list[WaitMessageRecord]:
        """The wait messages this robot sent since the last call, to publish."""
        return self.driver.take_wait_messages()

    def on_path(self, path: TimedPath, t0: float, path_id: int) -> None:
        """Follow a leg whose times count from ``t0``; ValueError if it cannot (see RobotModel.follow):
        then its statuses name the leg as rejected (and a central robot stops where it is).
        Under behaviour coordination only its goal counts: ValueError if there is no way there.
        In manual drive legs are ignored (the planner sends none; a late one must not take over)."""
        if self.hand.manual:
            return
        if self.driver.awaits_record(path, path_id):   # gated: taken when its record comes (on_gate); it holds
            self._pending = (path, t0, path_id)
            return
        self._pending = None
        try:
            self.driver.follow(path, t0, path_id, self._last, self.heard)
        except ValueError:
            self.rejected = path_id
            self.driver.refused(path_id)
            raise

    def on_gate(self, record: GateRecord) -> None:
        """A gate record on the wire: kept if it is for this robot and newer than the one it has. A
        leg that came before it is taken now (or refused, as :meth:`on_path` says); one that a record
        for a later leg overtook is dropped (the later leg comes)."""
        if record.robot_id != self.model.id:
            return
        self.driver.on_gate(record)
        pending, gate = self._pending, self.gate
        if pending is None or gate is None or gate.path_id < pending[2]:
            return
        self._pending = None
        if gate.path_id > pending[2]:
            return   # (it holds all the same: its record is for a leg it does not drive yet)
        try:
            self.on_path(*pending)
        except ValueError:
            pass   # its statuses name the leg rejected; the planner plans it again from where it stands

    def tick(self, now: float) -> RobotStatus:
        """Advance to ``now``, start what is due where the robot stands, and report."""
        m = self.model
        self.obstacles.expire(now)
        if self._last is not None and now > self._last and not self.hand.drive(self._last, now - self._last,
                                                                                self.heard):
            if self.lease.holds(now, m.path_id):  # not heard: it brakes and stands (.lease)
                self.driver.brake(self._last, now - self._last, self.heard)
            elif self._scale > 0.0:
                self.driver.drive(self._last, now - self._last, self.heard)
            else:  # halted: it stands (and the clock goes on)
                m.step(self._last, now - self._last, hold=True)
        if self._last is None or now > self._last:
            self._last = now
        if self._acting is not None and m.busy_until is None:
            if self._acting == "pick":
                self.loaded = True
            else:
                self.loaded, self.placed, m.task_id = False, m.task_id, None
            self._acting = None
        if m.mode == "idle" and m.speed == 0.0 and m.progress >= 1.0 and not (self.hand.manual or self.hand.estopped):
            self._act(now)
        state = self.driver.behavior_state()
        return RobotStatus(**m.status(now), behavior=state, travelled_m=m.travelled if m.path is not None else None,
                           rejected_path_id=self.rejected, loaded=self.loaded, placed_task_id=self.placed,
                           **self.hand.status_fields())

    # -- where a leg ends ---------------------------------------------------------------------------
    def _act(self, now: float) -> None:
        m = self.model
        here = station_at(self.warehouse, (m.x, m.y))
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

