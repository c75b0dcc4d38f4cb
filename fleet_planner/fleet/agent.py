"""The robot's end of the fleet: :class:`RobotAgent`, a :class:`~fleet_planner.robots.RobotModel`
that follows the legs it is sent and, where a leg ends, picks at the chute of its job, places at the
storing site holding the job's address tag, or charges at a charger.

Times are seconds on one clock (the robot's ROS time): ``now`` is always passed in.
"""
from __future__ import annotations

import math

from msg_schemas.records import RobotStatus, Task, TaskEvent, WaitMessageRecord

from ..behavior import BehaviorController, BehaviorParams, RobotView, WaitMessage, safety_stop
from ..model import PlanningError, TimedPath
from ..robots import RobotModel
from ..warehouse import Warehouse
from .legs import CONTROL_PERIOD_S, station_at
from .manager import COORDINATION
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
        station = station_at(self.warehouse, goal)
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

