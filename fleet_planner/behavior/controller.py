"""One BBMRCA robot, :class:`BehaviorController` (Sun, Kleiner & Nebel, "Behavior-based
Multi-Robot Collision Avoidance", ICRA 2014): its own A* path, the traffic rules of :mod:`.rules`
against the robots it senses, docking (:mod:`.docking`), WaitMessages and re-planning
(:mod:`.deadlock`), and the motion its behaviour wants. It knows only what one robot can know.

Where the paper leaves a choice open, the choice and its reason are written where it is made
("Interpretation").
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from ..geometry import polyline_length
from ..grid import GridMap
from ..model import Behavior, PlanningError, Point
from ..paths import PathFinder
from ..roadmap import lanes_of
from .areas import Collision, collision_type, front_coords, in_critical_area, robots_in_front, scan_front_area
from .clearance import Clearance
from .deadlock import WaitMessage, on_wait_message, virtual_wall_cells
from .docking import Docking, HeardDocking
from .params import DEFAULT_PARAMS, EPS, BehaviorParams
from .rules import id_key, low_order, select_behavior
from .views import RobotView

B = Behavior
_COS_STRAIGHT = math.cos(math.radians(10.0))  # a path bending less than this at a waypoint goes on straight
_PROGRESS = 0.05  # m: coming this much closer to the goal (straight line) is progress (stats)
_ESCAPE_HOLD_S = 3.0  # s: an escaped robot stands in its less crowded place at least this long
#: ours (issue 13): a robot whose last escape was in vain (see "a step against the lanes") steps out
#: against the lanes before it escapes again; False: it escapes again (the control of the test)
STEP_OUT_AFTER_VAIN_ESCAPE = True


def _xy(p: np.ndarray) -> tuple[float, float]:
    return float(p[0]), float(p[1])


def _sensed(sensed: Sequence[RobotView], robot_id: str | None) -> RobotView | None:
    """The view of ``robot_id`` among the robots sensed (None if out of range, or no id)."""
    return next((o for o in sensed if o.id == robot_id), None)


def _checked_start(grid: GridMap, robot_id: str, radius: float, max_speed: float, position: Point) -> np.ndarray:
    """The robot's start as an array, once its figures are checked (ValueError names the bad one)."""
    for name, value in (("radius", radius), ("max_speed", max_speed)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f"robot {robot_id!r}: {name} must be a finite number > 0, got {value!r}")
    start = np.asarray(position, dtype=float)
    if start.shape != (2,) or not np.all(np.isfinite(start)):
        raise ValueError(f"robot {robot_id!r}: start must be a finite (x, y), got {position!r}")
    if not grid.disc_is_free(start[0], start[1], radius):
        raise ValueError(f"robot {robot_id!r}: start {_xy(start)} is not free for radius {radius}")
    return start


class BehaviorController:
    """One BBMRCA robot: its own A* path, the traffic rules against the robots it senses, docking,
    WaitMessages and re-planning, and the motion its behaviour wants.

    It knows only what one robot can know: its own state and path, the :class:`RobotView` of the
    robots within ``comm_range`` (what they broadcast) and the :class:`WaitMessage` s addressed to
    it. :class:`~.fleet.BehaviorFleet` steps many of them in one simulation, with a shared
    :class:`~.docking.DockingArbiter` and an exact safety layer; a robot on its own (the agent
    node) calls :meth:`step`, which adds the local safety layer (:meth:`keeps_clear`) and keeps the
    docking agreement from what it hears (:class:`~.docking.HeardDocking`).

    ``docking``: a :class:`~.docking.DockingArbiter` shared by simulated robots, or None for a
    robot on its own (a :class:`~.docking.HeardDocking` of its own). ``finders`` may be shared
    between controllers on the same map (one :class:`~fleet_planner.paths.PathFinder` per radius);
    ``first_message`` is when the robot first checks whether to send a WaitMessage (robots' clocks
    are not synchronised: spread phases make waiting robots seldom send at once).
    """

    def __init__(self, grid: GridMap, robot_id: str, radius: float, max_speed: float, position: Point,
                 params: BehaviorParams = DEFAULT_PARAMS, *, docking: Docking | None = None,
                 finders: dict[float, PathFinder] | None = None, first_message: float = 0.0) -> None:
        start = _checked_start(grid, robot_id, radius, max_speed, position)
        self.grid, self.params = grid, params
        self.id, self.radius, self.max_speed = robot_id, float(radius), float(max_speed)
        finders = {} if finders is None else finders
        if self.radius not in finders:
            finders[self.radius] = PathFinder(grid, self.radius)
        self.finder = finders[self.radius]
        self.clearance = Clearance.of(grid)
        self._heard_docking: HeardDocking | None = None
        if docking is None:
            docking = self._heard_docking = HeardDocking(robot_id)
        self.docking: Docking = docking
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
        self.retreat: tuple[float, str] | None = None  # the retreat wave it belongs to (see RobotView.retreat)
        self.retreat_at = -math.inf           # when it joined that wave
        self.yield_after = -math.inf          # no new attempt to give way to a retreat before this time
        self.escape_to: np.ndarray | None = None  # the less crowded place it drives to (see _escape)
        self.escape_end = -math.inf           # the escape ends then at the latest
        self.escape_hold = -math.inf          # standing in the less crowded place at least until then
        self.escape_ready = -math.inf         # no new escape before this time
        self.escape_again = False             # the escape moved on from a place in someone's way (ours)
        self.escaped_from: tuple[str, np.ndarray, np.ndarray] | None = None  # (partner, its place, mine) at the
                                              # last escape (see _escaped_in_vain)
        self.seen_standing: dict[str, tuple[Point, float]] = {}  # robots seen standing in its way (see _remember)
        self.making_way: tuple[str, float] | None = None  # (robot, until): Dock making way (see _dock_make_way)
        self.deadlocks = self.replans = self.replan_failures = self.yields = self.escapes = self.steps_out = 0
        self.ways_made = 0        # times it made way for a robot pinned in its approach (``_dock_make_way``)
        self.nearly_reached = 0   # waypoints counted reached a few cm short (``_reached_nearly``)
        self.slides = 0           # steps slid round a standing robot (``_slide_past_standing``)

    # -- public ---------------------------------------------------------------------------
    @property
    def position(self) -> Point:
        return float(self.pos[0]), float(self.pos[1])

    def assign(self, goal: Point, station: str | None = None, now: float | None = None) -> None:
        """Go to ``goal`` (at ``station``, if given, which it docks at one robot at a time).

        The robot plans its own path from where it is, ignoring the other robots (section II of
        the paper). Raises ValueError for a bad goal and PlanningError when no path exists.
        """
        if now is not None:
            self.time = float(now)
        g = np.asarray(goal, dtype=float)
        if g.shape != (2,) or not np.all(np.isfinite(g)):
            raise ValueError(f"robot {self.id!r}: goal must be a finite (x, y), got {goal!r}")
        if not self.grid.disc_is_free(g[0], g[1], self.radius):
            raise ValueError(f"robot {self.id!r}: goal {_xy(g)} is not free for radius {self.radius}")
        path = self.finder.find(self.position, (float(g[0]), float(g[1])))
        if path is None:
            raise PlanningError({self.id: f"no path from {self.position} to {_xy(g)}"})
        if self.station is not None and self.holds is None:
            self.docking.withdraw(self.station, self.id)
            self.dock_since = None
        self.goal, self.station, self.arrived = (float(g[0]), float(g[1])), station, False
        self.seen_standing = {}
        self.escape_to = self.escaped_from = None
        self._set_path(path)
        self.best_distance, self.progress_at = math.dist(self.pos, g), self.time
        self._set(B.DOCK if self.holds else B.FOLLOW_WAYPOINT, None)

    def view(self) -> RobotView:
        """What the robot broadcasts about itself."""
        nxt, remaining, straight = None, 0.0, 0.0
        x, y = self.pos.tolist()
        if self.path is not None:
            assert self.tail is not None and self.run is not None   # set with the path
            nxt = tuple(self.path[self.wp].tolist())
            ahead = math.dist((x, y), nxt)
            remaining, straight = ahead + float(self.tail[self.wp]), ahead + float(self.run[self.wp])
            if self.escape_to is not None and self.goal is not None:   # escaping: still bound for the goal
                remaining += math.dist(self.escape_to, self.goal)
        return RobotView(self.id, (x, y), self.radius, self.behavior, nxt, remaining, straight,
                         self.station, self.partner, self.no_space,
                         self.holds[0] if self.holds else None, self.dock_since, self.retreat)

    def remaining(self) -> float:
        """``view().remaining`` (the length of the rest of the path), without building the view; but a
        robot standing in the place it escaped to (no path, still bound for its goal) has the
        straight way to its goal left, not 0: else a run measuring progress by it saw the leg all
        but done and any later progress as none (issue 13: ARMO, warehouse, 50 robots, "stalled")."""
        if self.path is None:
            if self.escape_to is not None and self.goal is not None:
                return math.dist(tuple(self.pos.tolist()), self.goal)
            return 0.0
        assert self.tail is not None   # set with the path
        remaining = math.dist(tuple(self.pos.tolist()), tuple(self.path[self.wp].tolist())) + float(self.tail[self.wp])
        if self.escape_to is not None and self.goal is not None:
            remaining += math.dist(self.escape_to, self.goal)
        return remaining

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
        out = self._read_inbox(now, inbox, sensed)
        self.decide(now, sensed)
        own = self.wait_message(now)
        if own is not None:
            out.append(own)
        if move:
            self.move(now, dt, sensed, self.keeps_clear(sensed, reach or {}), speed)
        self.track_progress(now + dt)
        return out

    def _read_inbox(self, now: float, inbox: Sequence[WaitMessage],
                    sensed: Sequence[RobotView]) -> list[tuple[str, WaitMessage]]:
        """Receive the WaitMessages whose sender (the last id) is in range; the ones to forward."""
        out = []
        in_range = {v.id for v in sensed}
        for msg in inbox:
            if msg.waiting and msg.waiting[-1] in in_range:
                forward = self.receive(now, msg, sensed)
                if forward is not None:
                    out.append(forward)
        return out

    def receive(self, now: float, msg: WaitMessage, sensed: Sequence[RobotView]) -> tuple[str, WaitMessage] | None:
        """A WaitMessage addressed to me: the message to forward to the robot I wait for, or None.
        A wait cycle through me (a deadlock) makes me re-plan (IV.C)."""
        self.time = float(now)
        deadlock, forward = on_wait_message(self.view(), msg)
        if deadlock:
            self.deadlocks += 1
            # a retreating robot is given way to (see _yield_to_retreat), so another robot of the
            # cycle re-plans; a cycle of retreating robots only: see _turns_in_retreat_cycle
            # a Dock robot making way (_dock_make_way) keeps to its approach: the other robot re-plans
            if self.making_way is None and (self.retreat is None or self._turns_in_retreat_cycle(msg, sensed)):
                self.retreat = None
                self._replan(sensed)
        if forward is None:
            return None
        assert self.partner is not None   # only a robot waiting for a partner forwards
        return self.partner, forward

    def decide(self, now: float, sensed: Sequence[RobotView], me: RobotView | None = None) -> None:
        """Sensing and behaviour selection from the views of the robots in range (``me``: my
        :meth:`view` now, if the caller has it already).

        A behaviour left and taken up again within the step on the same path (e.g. Avoid completed
        for one partner and started for the next) keeps its start time, so the timeouts see one
        behaviour.
        """
        self.time = float(now)
        sensed = list(sensed)
        before, path, since, blocked_since = self.behavior, self.path, self.since, self.blocked_since
        self._select(self.view() if me is None else me, sensed)
        if self.behavior is before and self.path is path:
            self.since, self.blocked_since = since, blocked_since

    def wait_message(self, now: float) -> tuple[str, WaitMessage] | None:
        """The WaitMessage a waiting robot sends its partner every ``wait_msg_period``, when due."""
        period = self.params.wait_msg_period
        if now + EPS >= self.msg_tick:
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
            self.blocked_since = None
            self._move_to(q, wp)
            return True
        if not candidates:
            return None
        self._reached_nearly()
        if self.blocked_since is None:
            self.blocked_since = self.time
        slide = self._slide_past_standing(candidates[0][0], sensed)
        if slide is not None and self._map_clear(slide) and (robot_ok is None or robot_ok(slide)):
            self.slides += 1
            self._move_to(slide, -1)     # still blocked on its path: it slides on while that lasts
            return True
        return False

    def _move_to(self, q: np.ndarray, wp: int) -> None:
        """Take the motion to ``q`` (``wp``: the next waypoint index after it, -1 unchanged); a robot
        leaving its station lets it go once out of the docking region."""
        self.pos = q
        self._advance(wp)
        if self.holds is not None and math.dist(self.pos, self.holds[1]) > self.params.dock_region:
            self.docking.release(self.holds[0], self.id)   # left the docking region
            self.holds, self.dock_since = None, None
            self._set(B.FOLLOW_WAYPOINT, None)

    def _slide_past_standing(self, wanted: np.ndarray, sensed: Sequence[RobotView]) -> np.ndarray | None:
        """Interpretation (ours, issue 13): a robot driving along its path whose motion a standing
        robot a few cm off its disc has refused for half ``blocked_timeout`` (a re-plan, at
        ``blocked_timeout``, starts the count again) slides past it: the part of the wanted step
        that points at the standing robot is dropped and the rest, at least half the step, taken -
        round the standing disc, the distance never shrinking. The safety layer refuses any motion
        that brings two discs closer inside the safety margin, so a robot that stopped there with
        its path bearing even slightly towards a parked robot stood for good, and its re-plans,
        which cannot keep out of a disc they start in, all began the same way (measured: BBMRCA
        on `large`, 40 robots, r14 leaving chute_7 0.74 m from r20 parked at its home, 130
        re-plans in 600 s, 119/120). Returns the position slid to, or None.
        """
        if (self.behavior not in (B.FOLLOW_WAYPOINT, B.GO_THROUGH, B.DOCK) or self.blocked_since is None
                or self.time - self.blocked_since <= self.params.blocked_timeout / 2):
            return None
        v = wanted - self.pos
        step = math.hypot(v[0], v[1])
        if step < EPS:
            return None
        near = [o for o in sensed if math.dist(o.position, self.pos) < self.radius + o.radius + step
                + self.params.safety_margin]
        if len(near) != 1 or near[0].travelling:   # one robot refuses it, and that one stands
            return None
        n = np.asarray(near[0].position) - self.pos
        n /= math.hypot(n[0], n[1])
        along = float(v @ n)
        slide = v - along * n
        if along <= 0 or math.hypot(slide[0], slide[1]) < step / 2:
            return None
        return self.pos + slide

    def _reached_nearly(self) -> None:
        """Interpretation (ours, issue 13): a robot driving along its path whose move the safety
        layer refused ``waypoint_reach`` or less short of a waypoint (not the goal) has reached it
        and heads for the next one, if the straight way there is free of walls. Two robots a few cm
        short of waypoints 0.71 m apart (diagonal cells of a road map), each refused by the
        other's disc, else stand for good: the path turns there, so neither front area, a few cm
        long, holds the other and no rule applies, and every re-plan starts with the same move
        (measured: ARMO on `large`, 100 robots, r46 leaving chute_3 and r67, stuck from t = 187 s,
        65 robots queued behind). Heading on, each sees the other ahead and the rules (IV.B) take
        over. No disc moves here, so the safety layer is untouched."""
        if self.path is None or self.behavior not in (B.FOLLOW_WAYPOINT, B.GO_THROUGH, B.DOCK):
            return
        if (self.wp < len(self.path) - 1 and math.dist(self.pos, self.path[self.wp]) <= self.params.waypoint_reach
                and self.finder.segment_free(self.position, tuple(self.path[self.wp + 1]))):
            self.wp += 1
            self.nearly_reached += 1

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
        distance = 0.0
        if self.path is not None:
            assert self.goal is not None   # a robot with a path has a goal
            distance = math.dist(self.pos, self.goal)
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
            cos = float(np.dot(a, b)) / max(math.hypot(*a) * math.hypot(*b), EPS)
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
        """My behaviour this step, in this order: a station lost to an earlier request, no path, a
        station held, the station rules, a path repaired or short-cut, the end of the running
        behaviour, the traffic rules, and a re-plan when the behaviour failed."""
        if self.holds is not None and not self.docking.keeps(self.holds[0], self.id):
            self.holds = None                   # another robot asked to dock earlier: queue again
        if self.escape_to is not None:
            self._end_escape(sensed)
        if self.path is None:                   # idle, or parked on its goal (docked if it holds)
            if self.holds is not None and self.holds[0] != self.station and self.escape_to is None:
                self._parked_in_docking_region()
            self._set(B.DOCK if self.holds else B.FOLLOW_WAYPOINT, None)
            return
        if self.holds is not None:              # IV.B.5: Dock keeps moving, the others give way
            self._select_holding(me, sensed)
            return
        if self.station is not None and self._docking(self.station):
            return
        path = self.path
        if self.off_path:
            self._repair()
            if self.path is None:
                return
        if self._skip_covered_waypoints(sensed) or self.path is not path:
            me = self.view()
        front = scan_front_area(me, sensed, self.params)
        in_front = [o for o, _ in front]
        self._end_retreat(in_front)
        if self._yield_to_retreat(me, sensed, in_front):
            return
        self._complete(me, sensed, in_front)
        # the paper's FrontAreaCheck over my front area (front_area_check, from the same pass)
        checked = next((o for o, critical in front if critical), in_front[0] if in_front else None)
        me = self._apply_rules(me, in_front, sensed, checked)
        if self._failed(me, sensed, in_front):
            self._replan(sensed)
        elif (self.params.escape_after > 0 and self.escape_to is None and self.behavior is not B.WAIT_FOR_DOCKING
              and self.time - self.progress_at > self.params.escape_after and self.time >= self.escape_ready):
            self._escape_for_no_progress(sensed)

    def _escape_for_no_progress(self, sensed: Sequence[RobotView]) -> None:
        """The robot came no closer to its goal for ``escape_after``: it escapes (IV.B.8, see
        :meth:`_escape_or_step_out`), remembering the robots standing in range as a failed re-plan
        does (:meth:`_remember`).

        Interpretation (ours, issue 13): only a failed re-plan remembered them, so a robot that
        escaped from standing robots it could not pass without failing a behaviour planned its way
        back, out of their range, straight into them again (measured: the 200-robot stress run on
        `large`, r87's way east between two rows of robots parked 2 m apart ran at a slant, its
        Avoid switched sides between one row and the other every step, no progress, an escape
        every 30 s and the same way back, from t = 5264 s: 599/600, stalled)."""
        self._remember(sensed)
        self._escape_or_step_out(sensed)

    def _parked_in_docking_region(self) -> None:
        """Interpretation (ours, issue 13): a robot that left the station it held for a goal inside
        that station's docking region (a parking spot 1.5 m away, ``dock_region``) never left the
        region, so it held the station for good once parked there (IV.A releases a station when the
        robot leaves); arrived at a goal that is not that station, it has left it. Measured: 200
        robots on `large` with admission, r77 parked 1.5 m from B098 after its last delivery, the two
        robots bound for B098 waiting for it 1200 s (597/600, stall)."""
        assert self.holds is not None
        self.docking.release(self.holds[0], self.id)
        self.holds, self.dock_since = None, None

    def _select_holding(self, me: RobotView, sensed: list[RobotView]) -> None:
        """A robot holding its station docks (IV.B.5), unless it leaves the station and must give
        way to a rival (:meth:`_dock_rival`)."""
        if self.off_path:
            # Interpretation (ours, issue 13): the paper re-plans "whenever the next waypoint in
            # the path is fully blocked by obstacles" (section I); a docking robot pushed off its
            # path (WaitForDocking backs off) whose straight approach grazes a wall corner is that
            # case too, so Dock re-plans from where it is instead of pressing against the corner.
            self._repair()
            if self.path is None:
                self._set(B.DOCK, None)
                return
            me = self.view()
        rival = self._dock_make_way(me, sensed) or self._dock_rival(me, sensed)
        self._set(B.DOCK if rival is None else B.WAIT_KEEP_DISTANCE, None if rival is None else rival.id)
        # a standing robot in the way does not give way (IV.C.1); Interpretation (ours, issue 13):
        # nor does a waiting one that has no room to (pinned between the leaving robot and a
        # wall: measured, a robot leaving its station blocked 857 s by one queued for it, ARMO on
        # `large`, 20 robots): after ``blocked_timeout`` the leaving robot re-plans round it
        if rival is None and self._leaving() and self._stalled():
            in_way = [o for o in sensed if in_critical_area(me, o, self.params)]
            if any(self._does_not_give_way(o) for o in in_way):
                self._replan(sensed)
            elif any(self._given_up_on(o) for o in in_way) and self.time >= self.replan_after:
                self._replan_round(in_way)

    def _dock_make_way(self, me: RobotView, sensed: list[RobotView]) -> RobotView | None:
        """The robot a Dock robot driving to its station makes way for now (or None).

        Interpretation (ours, issue 13): Dock keeps moving and "the other robots will automatically
        give way" (IV.B.5); a robot that cannot (its Avoid pressed against a wall beside the Dock
        robot's approach, its queue behind it) waits for the Dock robot, which waits for it to move:
        a wait cycle the WaitMessages do not find, since a Dock robot does not wait (measured: ARMO
        on warehouse-10-20-10-2-1, 100 robots, r12 docking at S4 diagonally from the side aisle
        into the top aisle, r19 bound east along the top aisle 0.73 m from it, stopped from t = 825
        s, 16 robots queued behind them, 284/300). So a Dock robot approaching its station, refused
        its motion for ``avoid_timeout`` with a robot in its critical area that waits for it or
        drives round it (partner: the Dock robot), makes way: WaitKeepDistance with that robot as
        partner - it backs off from it to the kept gap (the robots queued behind it keep theirs, so
        they back off too), and the other, seeing a robot that waits for it out of its drive channel,
        passes (Algorithm 4, case 3: GoThrough). It docks again once the other is out of its
        critical area and no longer about it, or after ``avoid_timeout``; it does not re-plan on
        the wait cycle the two may form meanwhile (the other does), nor back off out of the docking
        region (it keeps its station). Measured with it: that run 300/300 at t = 1258 s, one way
        made; the runs of 50 robots (BBMRCA, ARMO; `large`, warehouse-10-20-10-2-1) make none.
        """
        if self.holds is None or self.holds[0] != self.station:
            self.making_way = None
            return None
        if self.making_way is not None:
            rid, until = self.making_way
            other = _sensed(sensed, rid)
            if (other is not None and self.time < until
                    and (other.partner == self.id or in_critical_area(me, other, self.params))):
                return other
            self.making_way = None
            return None
        if self.blocked_since is None or self.time - self.blocked_since <= self.params.avoid_timeout:
            return None
        for o, critical in scan_front_area(me, sensed, self.params):
            if critical and o.partner == self.id and o.travelling and o.behavior is not B.DOCK:
                self.making_way = (o.id, self.time + self.params.avoid_timeout)
                self.ways_made += 1
                return o
        return None

    def _given_up_on(self, other: RobotView) -> bool:
        """Interpretation (ours, issue 13): a robot in the way of a leaving Dock robot that has
        not given way in ``avoid_timeout`` (the leaving robot stopped that long) cannot: it is
        pinned between the Dock robot and a wall, its Avoid finding no side and its re-plans
        starting into the Dock robot again (measured: ARMO on `large`, 100 robots, r75 in Avoid
        pressed against the wall above r63 leaving chute_5, both stopped 1044 s). The paper's
        "the others give way" (IV.B.5) assumes they can; so the Dock robot re-plans round it, as
        round an obstacle (IV.C.1), whatever its behaviour."""
        assert self.blocked_since is not None   # only asked of a stalled robot
        return other.travelling and self.time - self.blocked_since > self.params.avoid_timeout

    def _replan_round(self, in_way: Sequence[RobotView]) -> None:
        """A leaving Dock robot re-plans round the robots in its way that could not give way
        (:meth:`_given_up_on`), each an obstacle it must not touch (IV.C.1). Interpretation (ours):
        without a virtual wall and with keep-out discs only the robots' radii and the safety margin
        wide: the robot stands within the usual keep-out (radii + critical margin) of the robot
        pinned next to it, so that disc would be dropped as containing the start, and on one-way
        lanes the wall cut every lane its way goes on (measured, the scene above: both eastbound
        rows of the main aisle), so the paper's re-plan found no way in 1044 s."""
        assert self.goal is not None   # a leaving robot has a path, so a goal
        self.replan_after = self.time + self.params.blocked_timeout
        avoid = [(o.position, self.radius + o.radius + self.params.safety_margin) for o in in_way]
        path = self.finder.find(self.position, self.goal, avoid=avoid)
        if path is None:
            self.replan_failures += 1
            return
        self.replans += 1
        self._set_path(path)

    @staticmethod
    def _does_not_give_way(other: RobotView) -> bool:
        """A robot in the way of a leaving Dock robot that will not move for it: one standing
        (the paper's obstacle) or, ours, one waiting (see :meth:`_select_holding`)."""
        return not other.travelling or other.behavior.is_wait

    def _apply_rules(self, me: RobotView, in_front: list[RobotView], sensed: list[RobotView],
                     other: RobotView | None) -> RobotView:
        """The traffic rules (IV.B) against the robot the front area check selects; returns my view
        as the rules saw it (with the behaviour left by :meth:`_complete`). A retreating robot
        facing a robot it cannot pass waits for it to give way (:meth:`_yield_to_retreat`) instead
        of starting an Exchange that would turn it round again. ``other``: the robot
        :func:`~.areas.front_area_check` selects from ``in_front``."""
        if other is None:
            return me
        if me.behavior is not self.behavior or me.partner != self.partner:
            me = replace(me, behavior=self.behavior, partner=self.partner)
        if self.retreat is not None and self._cannot_pass(me, other, sensed):
            self._set(B.WAIT_KEEP_DISTANCE, other.id)
            return me
        new = select_behavior(me, other, in_front, self.params)
        if new is not None:
            self._set(new, other.id)
        elif self.behavior is B.WAIT_KEEP_DISTANCE:
            self.partner = other.id   # I wait for whoever blocks my front area now (WaitMessages go there)
        return me

    # -- retreats: chains facing each other without room to pass (ours) -----------------------
    # Interpretation (ours, issue 13): the paper breaks a two-robot deadlock by the traffic rules
    # (Algorithm 4) and longer wait cycles by WaitMessages and a re-plan with a virtual wall
    # (IV.C); the re-planning robot is assumed to find a free way. In a one-cell aisle it does not:
    # the way back is taken by the robots queued behind it, which wait for it, so it faces them
    # head-on, fails its Exchange again, re-plans back towards its first partner, and so on for
    # ever (measured: the e/w chains of test_behavior_chains.py). We add a *retreat wave*: a robot
    # that re-planned (it now drives back, behind a virtual wall) says so in its view
    # (``RobotView.retreat``); a robot that meets it head-on in its critical area with no room to
    # pass re-plans behind a virtual wall too (it backs out of the way) and joins the wave, and the
    # retreating robot waits for it rather than turning round. Two waves meeting: the younger
    # gives way to the older (then the smaller id of their founders). So a chain of any length
    # facing another in an aisle backs out robot by robot; the order is total, so no two robots
    # make each other back out in turn.

    def _cannot_pass(self, me: RobotView, other: RobotView, sensed: list[RobotView]) -> bool:
        """The other robot comes at me head-on in my critical area and neither side leaves room
        to pass it."""
        if not in_critical_area(me, other, self.params):
            return False
        if collision_type(me, other, self.params) is not Collision.HEAD_ON:
            return False
        if self._frame() is None:
            return False
        return not any(self._side_is_free(other, side, sensed) for side in (-1, 1))

    def _turns_in_retreat_cycle(self, msg: WaitMessage, sensed: Sequence[RobotView]) -> bool:
        """Interpretation (ours, issue 13): a wait cycle whose robots all retreat (two waves met,
        or two robots of one wave face each other) has nobody to re-plan, since retreating robots
        do not: only ``retreat_timeout`` (30 s) ended it (seen in the 200-robot stress run on
        `large2x`, where a cross aisle meets a rack aisle, with robots queued behind). Then the
        robot of the youngest wave re-plans (ties: the larger id) and leaves the wave, the others
        keep waiting; the order is total, so exactly one of the cycle turns."""
        assert self.retreat is not None
        views = {o.id: o for o in sensed}
        others = [views.get(i) for i in msg.waiting if i != self.id]
        if any(o is None or o.retreat is None for o in others):
            return False
        mine = (self.retreat, id_key(self.id))
        return all(mine > (o.retreat, id_key(o.id)) for o in others if o is not None and o.retreat is not None)

    def _end_retreat(self, in_front: list[RobotView]) -> None:
        """A retreat ends when the robot's front area is free of robots coming at it, or after
        ``retreat_timeout`` (a wave does not give right of way for ever)."""
        if self.retreat is None:
            return
        me = self.view()
        facing = any(o.travelling and collision_type(me, o, self.params) is Collision.HEAD_ON for o in in_front)
        if not facing or self.time - self.retreat_at > self.params.retreat_timeout:
            self.retreat = None

    def _yield_to_retreat(self, me: RobotView, sensed: list[RobotView], in_front: list[RobotView]) -> bool:
        """Give way to a retreating robot I cannot pass (it comes at me head-on, no side is free):
        re-plan behind a virtual wall towards it and join its wave. True when I did (or must wait,
        the re-plan having found no way: then I wait for it and try again a second later)."""
        wave = None
        for o in in_front:
            if o.retreat is None or (self.retreat is not None and self.retreat <= o.retreat):
                continue
            if self._cannot_pass(me, o, sensed):
                wave = o
                break
        if wave is None:
            return False
        if self.time < self.yield_after:
            self._set(B.WAIT_KEEP_DISTANCE, wave.id)
            return True
        assert wave.retreat is not None
        self.replan_after = -math.inf          # a yield is not limited by the re-plan cooldown
        n = self.replans
        self._replan(sensed, join=wave.retreat)
        if self.replans == n:
            self.yield_after = self.time + 1.0
            self._set(B.WAIT_KEEP_DISTANCE, wave.id)
        else:
            self.yields += 1
        return True

    # -- escapes: into a less crowded place (ours) ----------------------------------------------
    # Interpretation (ours, issue 13): the paper's way out of a deadlock is a re-plan behind a
    # virtual wall, assuming "the robot that executed the re-planning can always find an
    # alternative path" (IV.C). In a jam it finds none (measured: a robot failed 101 re-plans in a
    # row at the crossing of the default warehouse, 40 robots), and a robot in an active behaviour
    # (an Exchange without room) is not even reached by WaitMessages. The paper already lets a
    # robot waiting to dock "move back or move into a less crowded area" (IV.B.8); we let any
    # robot do that when its re-plan finds no way, or when it came no closer to its goal for
    # ``escape_after`` seconds: it drives to the least crowded free place within
    # ``escape_reach`` that it can reach without touching a robot it senses, then plans its path
    # to the goal again. One escape per ``escape_after`` at most.

    def _escape(self, sensed: Sequence[RobotView], again: bool = False) -> bool:
        """Start an escape into a less crowded place; True when one was found. ``again``: a robot
        standing in its less crowded place moves on to another (:meth:`_end_escape`); the escape
        keeps its end (ours). Not for a robot holding its station: docking, it would leave the
        station the queue waits for; leaving, it re-plans round the robots that do not give way
        (:meth:`_select_holding`). Measured (issue 13, ARMO on `large`, 100 robots, t = 600-2000 s):
        38 escapes refused so, all one robot leaving chute_5, blocked 38 s at most; none of the 43
        robots left at session 23's stall held one."""
        if self.goal is None or self.holds is not None:
            return False
        if not again:
            self.escape_ready = self.time + self.params.escape_after
        free = self.finder.free
        res = self.grid.resolution
        reach = self.params.escape_reach
        c0, r0 = self.grid.cell_of(*self.position)
        k = int(math.ceil(reach / res))
        rows, cols = np.nonzero(free[max(r0 - k, 0):r0 + k + 1, max(c0 - k, 0):c0 + k + 1])
        if not len(rows):
            return False
        centres = np.column_stack([cols + max(c0 - k, 0) + 0.5, rows + max(r0 - k, 0) + 0.5]) * res
        d_me = np.hypot(*(centres - self.pos).T)
        keep = (d_me <= reach) & (d_me >= res)
        centres, d_me = centres[keep], d_me[keep]
        if not len(centres):
            return False
        others = np.array([o.position for o in sensed]).reshape(-1, 2)
        if len(others):
            room = np.min(np.hypot(centres[:, None, 0] - others[None, :, 0], centres[:, None, 1] - others[None, :, 1]),
                          axis=1)
        else:
            room = np.full(len(centres), np.inf)
        need = 2 * self.radius + self.params.critical_margin
        ok = room >= need
        # not in the way of the robots driving nearby (the channel from each to its next waypoint)
        in_way = np.zeros(len(centres), dtype=bool)
        for o in sensed:
            if o.next_waypoint is None:
                continue
            a, b = np.asarray(o.position), np.asarray(o.next_waypoint)
            ab = b - a
            t = np.clip(((centres - a) @ ab) / max(float(ab @ ab), EPS), 0.0, 1.0)
            clear = self.radius + o.radius + self.params.critical_margin
            in_way |= np.hypot(*(centres - (a + t[:, None] * ab)).T) < clear
        if (ok & ~in_way).any():
            ok &= ~in_way
        if not ok.any():
            return False
        centres, room, d_me = centres[ok], room[ok], d_me[ok]
        order = np.lexsort((d_me, -np.minimum(room, 3 * need)))   # most room first (capped), then closest
        avoid = [(o.position, self.radius + o.radius + self.params.safety_margin) for o in sensed]
        for j in order[:4]:
            target = (float(centres[j, 0]), float(centres[j, 1]))
            path = self.finder.find(self.position, target, avoid=avoid)
            if path is not None and len(path) >= 2:
                self.escapes += 1
                self.escape_to = np.array(target)
                if not again:
                    self.escape_end = self.time + self.params.escape_after / 2
                    partner = _sensed(sensed, self.partner)
                    self.escaped_from = (None if partner is None
                                         else (partner.id, np.asarray(partner.position), self.pos.copy()))
                self.escape_again = again
                self.retreat = None
                self._set_path(path)
                self._set(B.FOLLOW_WAYPOINT, None)
                return True
        return False

    def _end_escape(self, sensed: Sequence[RobotView]) -> None:
        """An escaping robot: back to its goal when the escape took too long, or once it stood
        ``_ESCAPE_HOLD_S`` in its less crowded place; but at once when it stands in the way of a
        robot driving nearby, into another less crowded place off the ways (:meth:`_escape`), else
        back to its goal.

        Interpretation (ours, issue 13): it used to stand on while in someone's way (until the
        escape ended, ``escape_after`` / 2) and leave early only when in nobody's way - the wrong
        way round: the place it escaped to was meant to leave room, and a robot standing in
        another's channel is an obstacle the other can only Avoid (or fail at, in a one-robot
        aisle). Measured on ``large2x`` at 200 robots, t = 500 s: 15 of 32 wait chains ended at
        such a robot (up to 7 robots behind one)."""
        if self.time >= self.escape_end:
            self._resume(sensed)                # took too long: back to the goal
        elif self.path is None and self._in_the_way(sensed):
            if not self._escape(sensed, again=True):
                self._resume(sensed)
        elif self.path is None and self.time >= self.escape_hold:
            self._resume(sensed)                # made room: back to the goal

    def _in_the_way(self, sensed: Sequence[RobotView]) -> bool:
        """A robot driving nearby has me in its way (my disc near its channel to its next waypoint)."""
        reach = self.params.front_length + self.radius
        for o in sensed:
            if o.next_waypoint is None or math.dist(o.position, self.pos) > reach + o.radius:
                continue
            a, b = np.asarray(o.position), np.asarray(o.next_waypoint)
            ab = b - a
            t = min(max(float((self.pos - a) @ ab) / max(float(ab @ ab), EPS), 0.0), 1.0)
            if math.dist(self.pos, a + t * ab) < self.radius + o.radius + self.params.critical_margin:
                return True
        return False

    def _resume(self, sensed: Sequence[RobotView] = ()) -> None:
        """End an escape: the path to the goal from here, round the robots standing in range (the
        paper's obstacles, IV.C.1), else walls only; the robots it meets driving are the
        behaviours' business.

        Interpretation (ours, issue 13): walls only, a robot that had escaped from a pocket shut by
        robots parked at their homes planned straight back into it, failed there, escaped again,
        and so on (measured: ARMO, default warehouse, 50 robots: the last robot 59 escapes and 860
        s for its last leg)."""
        assert self.goal is not None
        keep = [(o.position, self.radius + o.radius + self.params.critical_margin) for o in sensed if not o.travelling]
        keep += self._remembered(sensed)
        path = self.finder.find(self.position, self.goal, avoid=keep) if keep else None
        if path is None:
            path = self.finder.find(self.position, self.goal)
        if path is None:               # no way from here (the map): stand, and try again in a second
            self.path = self.tail = self.run = None
            self.escape_end = self.time + 1.0
            return
        self.escape_to = None
        self._set_path(path)
        self._set(B.FOLLOW_WAYPOINT, None)

    # -- a step against the lanes (ours) ----------------------------------------------------------
    # Interpretation (ours, issue 13), after the paper's deadlock detection and re-plan (IV.C): on
    # a road map of one-way lanes (ARMO, a lanes file) a robot's re-plan, and its escape, may only
    # use the moves the lanes allow. A robot standing in the corner cell of a junction (a pocket,
    # reached by an escape or a sidestep) whose one allowed way out runs past the disc of the robot
    # it waits for, in a one-robot lane, is then shut in: the partner's own way runs past the
    # pocket, the wait cycle is found again and again and never broken (measured: ARMO on `large`,
    # 100 robots, seed 0: r96 in the pocket at (72.25, 10.25) of the southbound side aisle and r14
    # above it, from t = 660 s, r14 376 failed re-plans, the cycle found 20,440 times, 41 robots
    # queued behind them; r62 and r83 the same 5 m further south; with a wall-following back-out of
    # the lane robot, r71 and r90 at a junction of a cross aisle, where a crowd left no room behind).
    # So a robot whose escape found no place, in a wait cycle with its partner (each the other's
    # partner: the cycles measured), re-plans from a neighbouring cell instead: one move
    # that the lanes may forbid (the disc fits, it touches no robot), then a path along the lanes
    # to its goal that keeps out of its partner and of the robots standing in range. The shortest
    # such way wins; the paper's re-plan is kept for every other case.
    # The same robot whose escape *did* find a place may be no better off: the escape's path keeps
    # only the robots' discs apart, so it may run past the partner inside its critical area, and the
    # rules stop it at once (it waits for the partner that waits for it; the pair's Exchange finds
    # no side, its re-plan (IV.C) leads back past the partner, the partner's re-plans fail on the
    # lanes), and the next escape, 30 s later, does the same again (measured: ARMO on `large`, 100
    # robots, seed 0, the run's one stall, 299/300: r48 in the junction pocket (1.75, 26.25) of the
    # southbound side aisle x = 1.25, r76 waiting for it in that aisle, from t = 2497 s, r48
    # escaping east every 30 s). So when an escape is due and the last one was in vain - the robot
    # and the same partner stand where they stood then, still waiting for each other - the robot
    # steps out first (``STEP_OUT_AFTER_VAIN_ESCAPE``). Without lanes that restrict a move it never
    # acts; with them only in that repeated stand-off.

    def _escape_or_step_out(self, sensed: Sequence[RobotView]) -> bool:
        """An escape (:meth:`_escape`), else a step against the lanes (:meth:`_step_out`); but the
        step first after an escape in vain (:meth:`_escaped_in_vain`). True when either was taken."""
        if STEP_OUT_AFTER_VAIN_ESCAPE and self._escaped_in_vain(sensed) and self._step_out(sensed):
            self.escape_ready = self.time + self.params.escape_after   # counts as the escape due now
            return True
        return self._escape(sensed) or self._step_out(sensed)

    def _escaped_in_vain(self, sensed: Sequence[RobotView]) -> bool:
        """My last escape left me where I was, waiting for the partner I waited for then, which
        stands where it stood then and waits for me (a two-robot wait cycle the escape did not
        break; see "a step against the lanes")."""
        if self.escaped_from is None:
            return False
        pid, there, here = self.escaped_from
        partner = _sensed(sensed, pid)
        return (partner is not None and self.partner == pid and partner.partner == self.id
                and math.dist(partner.position, there) <= self.radius and math.dist(self.pos, here) <= self.radius)

    def _step_out(self, sensed: Sequence[RobotView]) -> bool:
        """Re-plan with a first move against the lanes (see above); True when a way was found."""
        lanes = lanes_of(self.grid)
        if lanes is None or not lanes.restricts or self.partner is None or self.goal is None or self.holds:
            return False
        partner = _sensed(sensed, self.partner)
        if partner is None or partner.partner != self.id:   # only a wait cycle of the two of us
            return False
        touch = [(o.position, self.radius + o.radius + self.params.safety_margin) for o in sensed]
        keep = [(o.position, self.radius + o.radius + self.params.critical_margin) for o in sensed
                if o.id == partner.id or not o.travelling]
        c0, r0 = self.grid.cell_of(*self.position)
        best: tuple[float, np.ndarray] | None = None
        for dc, dr in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)):
            c, r = c0 + dc, r0 + dr
            if not (self.grid.in_bounds(c, r) and self.finder.free[r, c]):
                continue
            q = self.grid.centre(c, r)
            if not self.finder.segment_free(self.position, q, avoid=touch):
                continue
            path = self.finder.find(q, self.goal, avoid=keep)
            if path is None:
                continue
            length = math.dist(self.pos, q) + polyline_length(path)
            if best is None or length < best[0]:
                best = (length, path)
        if best is None:
            return False
        self.steps_out += 1
        self.retreat = None
        self.escaped_from = None
        self._set_path(best[1])
        self._set(B.FOLLOW_WAYPOINT, None)
        return True

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
        partner = _sensed(sensed, self.partner)
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
            # Interpretation (ours, issue 13): also when the safety layer refused its motion for
            # blocked_timeout, as Avoid and Exchange fail (IV.C.2-3): its partner waits in its channel
            # with no room to leave it sideways (measured: large, 200 robots, t = 500 s: 39 of 62
            # stuck robots in chains ending at one such pair, blocked 15 s of the 30 s timeout)
            return self.time - self.since > p.go_through_timeout or stalled
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
        assert self.goal is not None   # a robot with a path has a goal
        self.off_path = False
        path = self.finder.find(self.position, self.goal)
        if path is not None:
            self._set_path(path)

    def _skip_covered_waypoints(self, sensed: list[RobotView]) -> bool:
        """Interpretation: a waypoint (not the goal) on which a robot stands cannot be reached; the
        robot heads for the next one instead if the straight way there is free of walls (it will
        avoid the standing robot on the way); otherwise the behaviours fail and it re-plans."""
        assert self.path is not None
        skipped = False
        standing = [o for o in sensed if not o.travelling]
        if not standing:
            return False
        while self.wp < len(self.path) - 1 and any(
                math.dist(o.position, self.path[self.wp]) < self.radius + o.radius for o in standing):
            if not self.finder.segment_free(self.position, tuple(self.path[self.wp + 1])):
                break
            self.wp += 1
            skipped = True
        return skipped

    def _docking(self, station: str) -> bool:
        """Station rules (IV.A, IV.B.8) at ``station``, the robot's goal; True when they decided the
        robot's behaviour."""
        assert self.goal is not None   # a robot with a path has a goal
        p = self.params
        dist = math.dist(self.pos, self.goal)
        if dist <= p.dock_region or (self.behavior is B.WAIT_FOR_DOCKING and dist <= p.dock_give_up):
            if self.dock_since is None:
                self.dock_since = self.time
            if self.docking.request(station, self.id, self.time):
                self.holds = (station, np.array(self.goal))
                self._set(B.DOCK, None)
            else:
                waiting_for = self.docking.holder(station) or self.docking.first_waiting(station)
                self._set(B.WAIT_FOR_DOCKING, waiting_for)
            return True
        if self.behavior is B.WAIT_FOR_DOCKING:  # pushed too far from the station: give up waiting
            self.docking.withdraw(station, self.id)
            self.dock_since = None
            self._set(B.FOLLOW_WAYPOINT, None)
        return False

    def _frame(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(u, n) of the robot's front frame."""
        if self.path is None:
            return None
        d = self.path[self.wp] - self.pos
        length = math.hypot(*d)
        if length < EPS:
            return None
        u = d / length
        return u, np.array([-u[1], u[0]])

    def _sidestep(self, partner: RobotView, side: int) -> float:
        """Lateral offset (in my frame) that passes the partner on ``side`` with the margin."""
        frame = self._frame()
        assert frame is not None   # asked only while the robot has a direction
        _, n = frame
        l_p = float(np.dot(np.asarray(partner.position) - self.pos, n))
        clear = self.radius + partner.radius + self.params.avoid_margin
        return min(0.0, l_p - clear) if side < 0 else max(0.0, l_p + clear)

    def _side_is_free(self, partner: RobotView, side: int, sensed: list[RobotView]) -> bool:
        """Free space for the sidestep: my disc fits beside me and beside the partner, clear of
        the walls and of the other robots I sense."""
        frame = self._frame()
        assert frame is not None   # asked only while the robot has a direction
        u, n = frame
        lat = self._sidestep(partner, side)
        s_p = max(0.0, float(np.dot(np.asarray(partner.position) - self.pos, u)))
        for s in (0.0, s_p):
            q = self.pos + u * s + n * lat
            if not self.clearance.disc_is_free(float(q[0]), float(q[1]), self.radius):
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
        partner = _sensed(sensed, self.partner)
        if partner is None or self._frame() is None:
            return False
        if not stalled:
            for side in self._sides_to_try(me, partner):
                if self._side_is_free(partner, side, sensed):
                    self.side, self.no_space = side, False
                    return False
        self.side, self.no_space = 0, True
        if self.behavior is B.AVOID:
            return self._no_space_to_avoid(partner, in_front)
        return self._no_space_to_exchange(partner, stalled)

    def _sides_to_try(self, me: RobotView, partner: RobotView) -> list[int]:
        """The sides to pass the partner on, preferred first (+1 left, -1 right): an Exchange passes
        on the right; an Avoid keeps the side it chose, then tries the side away from the partner,
        then the other."""
        if self.behavior is B.EXCHANGE:
            return [-1]                        # both pass on their right
        c = front_coords(me, partner)
        away = -1 if c is None or c[1] >= 0 else 1
        sides = [self.side] if self.side else []
        sides += [s for s in (away, -away) if s not in sides]
        return sides

    def _no_space_to_avoid(self, partner: RobotView, in_front: list[RobotView]) -> bool:
        """IV.C.2: an Avoid without free space fails (True: re-plan) when no robot but the partner
        is in front; otherwise the robot waits for the partner."""
        if not any(o.id != partner.id and o.travelling for o in in_front):
            return True
        self._set(B.WAIT_KEEP_DISTANCE, partner.id)
        return False

    def _no_space_to_exchange(self, partner: RobotView, stalled: bool) -> bool:
        """IV.C.3: when both exchanging robots find no free space, the lower id re-plans (True) and
        the higher id waits (still saying it found no space, so that the lower id learns it). A
        partner that has not tried yet gets its turn (it cooperates with my Exchange), one with
        room passes me while I hold still, and one that is not about me is waited for."""
        about_me = partner.partner == self.id
        if (about_me and partner.no_space) or stalled:
            if id_key(self.id) < id_key(partner.id):
                return True
            self._set(B.WAIT_KEEP_DISTANCE, partner.id)
            self.no_space = True
        elif not about_me:
            self._set(B.WAIT_KEEP_DISTANCE, partner.id)
        return False

    def _replan(self, sensed: Sequence[RobotView], join: tuple[float, str] | None = None) -> None:
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
        self._remember(sensed)
        if self.time >= self.replan_after:
            path = self._find_detour(sensed)
            self.replan_after = self.time + self.params.blocked_timeout
        if path is None:
            if self.params.escape_after > 0 and self.time >= self.escape_ready and self._escape_or_step_out(sensed):
                return
            if self.partner is not None and self.behavior.is_active:
                self._set(B.WAIT_KEEP_DISTANCE, self.partner)
            return
        self.replans += 1
        self.escape_to = None
        self._set_path(path)
        self._set(B.FOLLOW_WAYPOINT, None)
        # ours: the robot now backs away from what it could not pass (see _yield_to_retreat)
        if self.params.retreat_timeout > 0:
            self.retreat = join if join is not None else (self.time, self.id)
            self.retreat_at = self.time

    def _ahead(self, cut: bool = False) -> list[Point]:
        """Where the virtual wall goes: from the robot to its next waypoint and, when that is
        closer than a front length, on along the path for a front length (interpretation: our
        straightened paths have few waypoints, and a wall shorter than the robot's front area
        leaves the blocked way open). ``cut``: the wall ends after a front length even when the
        next waypoint is farther (see :meth:`_find_detour`)."""
        assert self.path is not None
        points, left = [self.position], self.params.front_length
        for q in self.path[self.wp:]:
            step = math.dist(points[-1], q)
            if step >= left and (cut or len(points) > 1):
                (x, y), t = points[-1], left / step
                points.append((x + (q[0] - x) * t, y + (q[1] - y) * t))
                break
            points.append((float(q[0]), float(q[1])))
            left -= step
            if left <= 0:
                break
        return points

    # Interpretation (ours, issue 13): a robot re-plans round the robots standing in range (IV.C.1),
    # but forgot them once out of range: an escaped robot planned its way back straight into the
    # robot parked in it, failed, re-planned away, escaped, ... (measured: ARMO on the default
    # warehouse, 50 robots, the last robot circling for 860 s between robots parked at their
    # homes, one-way lanes leaving it one way in). So it remembers, for the rest of its leg, the
    # robots it saw standing when it had to re-plan, and keeps out of them while they are out of
    # range; one seen again moving or elsewhere is forgotten.
    def _remember(self, sensed: Sequence[RobotView]) -> None:
        """Note the robots standing in range now (when a behaviour failed)."""
        for o in sensed:
            if not o.travelling:
                self.seen_standing[o.id] = (o.position, o.radius)

    def _remembered(self, sensed: Sequence[RobotView]) -> list[tuple[Point, float]]:
        """Keep-out discs of the robots remembered standing that are not in range now (those in
        range are seen as they are; one seen moving or moved is forgotten)."""
        if not self.seen_standing:
            return []
        for o in sensed:
            seen = self.seen_standing.get(o.id)
            if seen is not None and (o.travelling or math.dist(o.position, seen[0]) > _PROGRESS):
                del self.seen_standing[o.id]
        here = {o.id for o in sensed}
        return [(p, self.radius + r + self.params.critical_margin) for i, (p, r) in self.seen_standing.items()
                if i not in here]

    def _find_detour(self, sensed: Sequence[RobotView]) -> np.ndarray | None:
        """The re-planned path, or None (counted as a failed re-plan)."""
        assert self.goal is not None   # a robot with a path has a goal
        wall = virtual_wall_cells(self.grid, self._ahead(), self.goal, self.radius)
        reach = self.params.front_length + 2 * self.radius

        # Interpretation (ours, issue 13): the first try also keeps out of the partner the
        # behaviour failed on, whatever it does: on maps finer than a robot (0.5 m cells) a
        # one-cell virtual wall leaves a parallel way past the same partner, and the robot
        # re-planned into the same Exchange over and over (measured: 125 re-plans of one robot).
        def keep_out(with_waiting: bool) -> list[tuple[Point, float]]:
            return [(o.position, self.radius + o.radius + self.params.critical_margin) for o in sensed
                    if not o.travelling or (with_waiting and (o.behavior.is_wait or o.id == self.partner)
                                            and math.dist(o.position, self.pos) <= reach + o.radius)]

        remembered = self._remembered(sensed)   # robots seen standing, out of range now (see _remember)
        path = self.finder.find(self.position, self.goal, avoid=keep_out(True) + remembered, blocked_cells=wall)
        if path is None:
            path = self.finder.find(self.position, self.goal, avoid=keep_out(False) + remembered, blocked_cells=wall)
        if path is None and remembered:   # they may have left: the robots in range only
            path = self.finder.find(self.position, self.goal, avoid=keep_out(False), blocked_cells=wall)
        if path is None:
            # Interpretation (ours, issue 13): the paper's A* paths have a waypoint per cell, ours
            # may run straight across a whole hall to the next waypoint, and a wall that long can
            # cut the hall in two (measured: a robot queued behind a parked one failed every
            # re-plan for ever). Then the wall ends a front length ahead.
            short = virtual_wall_cells(self.grid, self._ahead(cut=True), self.goal, self.radius)
            if short != wall:
                path = self.finder.find(self.position, self.goal, avoid=keep_out(False), blocked_cells=short)
        if path is None:
            self.replan_failures += 1
        return path

    # -- motion ---------------------------------------------------------------------------------
    def _map_clear(self, q: np.ndarray) -> bool:
        """The disc at ``q`` is in free space (the clearance measured last is reused while it settles it)."""
        if self.clear_at[2] - math.dist(q, self.clear_at[:2]) < self.radius:   # not sure from the last measurement
            self.clear_at = (float(q[0]), float(q[1]), self.clearance(float(q[0]), float(q[1])))
            if self.clear_at[2] < self.radius - EPS:
                return False
        return True

    def _advance(self, wp: int) -> None:
        """Commit the waypoint index after a move; arriving at the goal ends the path."""
        if self.path is None or wp < 0:
            return
        self.wp = wp
        if wp >= len(self.path) and self.escape_to is not None:   # reached the less crowded place: stand there
            self.path = self.tail = self.run = None
            self.escape_hold = self.time + _ESCAPE_HOLD_S
            if not self.escape_again:   # a second place (in someone's way at the first) keeps the end
                self.escape_end = self.time + self.params.escape_after / 2
            return
        if wp >= len(self.path):
            self.path = self.tail = self.run = None
            self.arrived = True
            self._set(B.DOCK if self.holds else B.FOLLOW_WAYPOINT, None)

    def _along_path(self, distance: float) -> tuple[np.ndarray, int]:
        """The point ``distance`` further along the path and the index of the next waypoint there."""
        assert self.path is not None
        p, wp = self.pos.copy(), self.wp
        while distance > EPS and wp < len(self.path):
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
        partner = _sensed(sensed, self.partner)
        if b in (B.FOLLOW_WAYPOINT, B.GO_THROUGH, B.DOCK) or (b in (B.AVOID, B.EXCHANGE) and partner is None):
            return [self._along_path(step), self._along_path(step / 2)]
        if b in (B.AVOID, B.EXCHANGE) and partner is not None:
            return self._pass_motions(partner, step)
        if b is B.WAIT_FOR_GO_THROUGH and partner is not None and partner.direction is not None:
            leave = self._leave_channel(partner, step)
            if leave is not None:
                return leave
        # Interpretation (ours, issue 13): "the other robots will automatically give way" to a Dock
        # robot (IV.B.5): a waiting robot standing in the drive channel of a Dock robot close by
        # leaves the channel sideways (or, where it cannot, drives on ahead of it), instead of
        # holding in its way for ever (measured: a robot leaving its station blocked for 443 s by
        # a queue waiting for it).
        give_way = self._give_way_to_dock(sensed, step)
        # waits: hold, backing off from a robot closer than the kept gap
        others = [partner] if b is not B.WAIT_FOR_DOCKING and partner is not None else list(sensed)
        motions = give_way + self._back_off(others, step / 2)
        if self.making_way is not None and self.holds is not None:   # ours: it keeps its station (_dock_make_way)
            motions = [(q, wp) for q, wp in motions if math.dist(q, self.holds[1]) < self.params.dock_region]
        return motions

    def _give_way_to_dock(self, sensed: Sequence[RobotView], step: float) -> list[tuple[np.ndarray, int]]:
        """Motions out of the way of a travelling Dock robot whose critical area I stand in."""
        me = None
        for o in sensed:
            if (o.behavior is not B.DOCK or o.direction is None
                    or math.dist(o.position, self.pos) > self.params.give_way_reach):
                continue
            me = self.view() if me is None else me
            if not in_critical_area(o, me, self.params):
                continue
            out = self._leave_channel(o, step) or []
            du = np.asarray(o.direction)
            out.append((self.pos + du * step / 2, -1))     # ahead of it, along its way
            return out
        return []

    def _pass_motions(self, partner: RobotView, step: float) -> list[tuple[np.ndarray, int]]:
        """Avoid / Exchange: step aside towards the chosen side (at most ``step``), driving on with
        what is left of ``step``; none while no side is free."""
        if not self.side:
            return []
        frame = self._frame()
        assert self.path is not None and frame is not None   # a side is chosen only with a direction
        u, n = frame
        lat = max(-step, min(step, self._sidestep(partner, self.side)))
        fwd = math.sqrt(max(step * step - lat * lat, 0.0))
        out = []
        for q in (self.pos + u * fwd + n * lat, self.pos + n * lat, self.pos + u * fwd / 2 + n * lat / 2):
            # a waypoint passed close by while stepping aside counts as reached (not the goal)
            passed = self.wp < len(self.path) - 1 and math.dist(q, self.path[self.wp]) <= step
            out.append((q, self.wp + 1 if passed else -1))
        return out

    def _leave_channel(self, partner: RobotView, step: float) -> list[tuple[np.ndarray, int]] | None:
        """WaitForGoThrough: make the intersection free by leaving the going-through robot's drive
        channel sideways, when I stand in it ahead of that robot (else None)."""
        du = np.asarray(partner.direction)
        rel = self.pos - np.asarray(partner.position)
        lateral = float(rel[0] * -du[1] + rel[1] * du[0])
        half = partner.radius + self.params.critical_margin / 2 + self.radius
        if float(np.dot(rel, du)) > 0 and abs(lateral) < half:
            away = np.array([-du[1], du[0]]) * (1.0 if lateral >= 0 else -1.0)
            return [(self.pos + away * min(step, half - abs(lateral) + EPS), -1)]
        return None

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
        if length < EPS:
            return []
        away /= length
        dist = min(step, self.params.keep_gap - gap)
        out = []
        for angle in (0.0, math.pi / 4, -math.pi / 4):
            c, s = math.cos(angle), math.sin(angle)
            out.append((self.pos + dist * np.array([c * away[0] - s * away[1], s * away[0] + c * away[1]]), -1))
        return out
