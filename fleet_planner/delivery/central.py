"""The central methods (md, md-box, prior): event-driven, the robots follow their timed paths exactly.

Each time a robot needs a new leg, the planner's
:meth:`~fleet_planner.planners.base.Planner.plan_incremental` plans it around the trajectories
every other robot is driving (a robot standing still is a one-waypoint trajectory). A leg that
cannot be planned is tried again a little later, once some other robot got a new leg. Where the
robots go is decided by the station discipline of :mod:`fleet_planner.delivery.stations`.
A planner that re-orders legs in flight (md: ``Planner.reorders_legs``) lets a late new leg go first past a
robot driving in its way and times again the robots that waited for a leg that was cut; PRIOR keeps
first come first served.
"""
from __future__ import annotations

import math

import numpy as np

from ..geometry import arc_at_time, points_at_arcs, positions_at_times
from ..model import PlanningError, Point, RobotSpec, TimedPath
from ..planners import get_planner
from .problem import DeliveryProblem
from .result import DeliveryResult, RunLimits, RunTally, SimProgress, check_driven, distance_driven, mean_velocity
from .stations import DEFAULT_QUEUE, EVACUATE_S, PLACE_RULES, _DeliveryRules, _SimRobot

#: a robot whose leg could not be planned tries again at the latest this many ``retry_s`` later
#: (sooner once another robot got a new leg)
RETRY_LATEST = 15
#: queue near, close (ours): a robot handed its station while it drives to a queue place turns to the station
#: at once, its leg cut where it is (:meth:`_CentralRun._turn_to_station`); False: it drives on to the place first
TURN_EN_ROUTE = True
#: queue near, close (ours): a robot docking at a station others queue for has its next leg planned (leaving
#: when its docking ends) this many seconds before its docking ends, so the station is handed over and the next
#: robot's leg planned that much sooner (0: when its docking ends)
HAND_OVER_EARLY_S = 3.0
#: ... under these queue rules
EARLY_RULES = PLACE_RULES
#: planners that re-order legs in flight (md, ``Planner.reorders_legs``): a new leg arriving this many seconds
#: later than driving straight off at top speed tries going first past a robot driving its own leg in its way
#: (:meth:`_CentralRun._go_first`)
SWAP_AFTER_S = 2.0
#: ... trying at most this many of the robots in its way, the one it would meet first first
SWAP_TRIES = 2
#: ... and keeping the swap when the two arrivals' sum drops by more than this (s)
SWAP_GAIN_S = 0.5
#: ... and once a robot's leg is cut (turned to its station, swapped), the robots still waiting on a leg whose
#: route comes near the cut one's are planned again from where they are (:meth:`_CentralRun._retime`): they
#: waited for a trajectory no longer driven; kept when they arrive this much (s) sooner
RETIME_GAIN_S = 0.5


class _CentralRun:
    """One run of a central method: the trajectories being driven, the legs driven, the retries."""

    def __init__(self, problem: DeliveryProblem, method: str, limits: RunLimits, planner_options: dict | None,
                 progress: SimProgress | None, queue: str = DEFAULT_QUEUE):
        self.tally = RunTally()
        self.problem = problem
        self.method = method
        self.limits = limits
        self.progress = progress
        self.planner = get_planner(method, **(planner_options or {}))
        self.rules = _DeliveryRules(problem, claims=True, queue=queue)
        self.robots = self.rules.robots
        n = problem.n_robots
        #: per robot: the legs it drove, waypoints (x, y, t); the first one is where it starts
        self.legs: list[list[np.ndarray]] = [[np.array([[*r.pos, 0.0]])] for r in self.robots]
        #: per robot: the trajectory it is driving, which the others' legs are planned around
        self.driving: list[TimedPath] = [TimedPath(r.id, problem.radius, self.legs[r.idx][0]) for r in self.robots]
        #: per robot: legs started (by all robots) at its last failed attempt, and when that was
        self.legs_at_failure = [-1] * n
        self.failed_at = [0.0] * n
        self.leg_delay_s = 0.0      # over all legs: arrival later than driving straight off at top speed
        self.last_activity = 0.0    # when some robot last arrived, docked or set off
        #: per robot: when its docking ends (HAND_OVER_EARLY_S: its event comes sooner)
        self.dock_end = [0.0] * n
        self.turned = 0             # legs cut to turn to a station handed over en route (TURN_EN_ROUTE)
        self.swaps = 0              # legs that went first past a robot driving already (_go_first)
        self.retimed = 0            # legs planned again after a leg they waited for was cut (_retime)

    def run(self) -> DeliveryResult:
        for r in self.robots:
            self.rules.next_target(r, 0.0)
        t, stop = self._run_events()
        return self._result(t, stop)

    def _run_events(self) -> tuple[float, str]:
        """Handle the robots' events in time order until a stop; returns (time, why it stopped)."""
        rules, limits = self.rules, self.limits
        t = 0.0
        while True:
            if rules.ctime is not None:
                return rules.ctime, "done"
            wake = np.array([r.wake for r in self.robots])
            t_next = float(wake.min())
            if t_next > limits.cap_s:
                return limits.cap_s, "cap"
            if t_next - self.last_activity > limits.stall_s:
                return self.last_activity + limits.stall_s, "stall"
            if self.tally.wall_s() > limits.wall_cap_s:
                return t, "wall"
            t = t_next
            for i in np.nonzero(wake <= t)[0]:
                self._wake(self.robots[int(i)], t)
            # robots that failed before may succeed now that others have new legs
            for r in self.robots:
                if r.phase == "need" and self.legs_at_failure[r.idx] != self.tally.legs:
                    r.wake = min(r.wake, max(t, self.failed_at[r.idx] + limits.retry_s))
                    self.legs_at_failure[r.idx] = self.tally.legs

    def _wake(self, r: _SimRobot, t: float) -> None:
        """r is due at t: its event (arrival, end of docking, deciding again), then the legs it and
        the robots a station was just handed to need."""
        rules = self.rules
        if r.wake > t:
            return
        if r.phase == "drive":
            rules.arrived(r, t)
            self.last_activity = t
            if r.phase == "dock" and HAND_OVER_EARLY_S > 0 and rules.queue_rule in EARLY_RULES:
                self.dock_end[r.idx] = r.wake
                r.wake = max(t, r.wake - HAND_OVER_EARLY_S)   # its next leg is planned this much sooner
        elif r.phase == "dock":
            end = max(t, self.dock_end[r.idx])
            if end > t and not rules.others_queue_here(r):
                r.wake = end                                  # nobody to hand the station to: dock to the end
                return
            rules.docked(r, end)
            self.last_activity = t
            if self.progress:
                self.progress(rules.completed, len(self.problem.deliveries), end)
            if end > t and r.phase == "need" and self._start_leg(r, end, t):
                self.last_activity = t
        elif r.phase == "wait":
            rules.retarget(r, t)
        if r.phase == "need" and r.wake <= t:
            if self._start_leg(r, t):
                self.last_activity = t
        for q in rules.take_handed_over(t):
            if self._start_leg(q, t):
                self.last_activity = t
        for q in rules.take_en_route():
            if TURN_EN_ROUTE and self._turn_to_station(q, t):
                self.last_activity = t

    def _as_fixed(self, q: _SimRobot, now: float) -> TimedPath:
        """q's trajectory as the planner must keep clear of it: once q has arrived, standing there
        from ``now`` on."""
        tp = self.driving[q.idx]
        if len(tp.waypoints) > 1 and tp.waypoints[-1, 2] <= now:
            tp = self.driving[q.idx] = TimedPath(q.id, self.problem.radius, np.array([[*tp.waypoints[-1, :2], now]]))
        return tp

    def _plan_leg(self, r: _SimRobot, goal: Point, others: list[TimedPath], now: float,
                  start: Point | None = None) -> TimedPath | None:
        """r's leg from ``start`` (default: where it stands) to ``goal`` leaving no sooner than ``now``,
        around ``others``; None (counted as a failed plan) when the planner finds none."""
        spec = RobotSpec(r.id, self.problem.radius, self.problem.max_speed, r.pos if start is None else start, goal)
        with self.tally.deciding():
            try:
                return self.planner.plan_incremental(self.problem.grid, [spec], others, now)[0]
            except PlanningError:
                self.tally.failed_plans += 1
                return None

    def _turn_to_station(self, q: _SimRobot, now: float) -> bool:
        """q was handed its station while driving to a queue place (queue near, close): its leg is cut at
        ``now`` and a leg from there to the station planned, when that arrives sooner than going on to the
        place first (it would then drive from the place at best at top speed); else it drives on. A leg not
        begun yet (planned ahead while q docks) is replaced by a leg from its start, leaving no sooner.
        Any leg planned around the others' trajectories keeps clear of them, so cutting q's is safe."""
        tp = self.driving[q.idx]
        if tp.arrival_time <= now + 1e-6:
            return False
        assert q.station is not None and q.target is not None
        station = self.problem.stations[q.station]
        # a leg planned ahead (HAND_OVER_EARLY_S: it docks until the leg begins) is planned again from its start
        begun = tp.waypoints[0, 2] <= now
        at, t0 = (tp.position(now), now) if begun else ((float(tp.waypoints[0, 0]), float(tp.waypoints[0, 1])),
                                                        float(tp.waypoints[0, 2]))
        others = [self._as_fixed(o, now) for o in self.robots if o is not q]
        leg = self._plan_leg(q, station, others, t0, start=at)
        if leg is None or leg.arrival_time >= tp.arrival_time + math.dist(q.target, station) / self.problem.max_speed:
            return False
        if begun:
            self._cut(q, at, now)
        else:
            self.legs[q.idx].pop()
        self.turned += 1
        self._take_leg(q, leg, now)
        self.rules.to_station_now(q, at, now)
        if self.planner.reorders_legs:
            self._retime(q, tp, now)
        return True

    def _late_by(self, tp: TimedPath, now: float) -> float:
        """How much later than driving the rest of its route straight off at top speed from ``now`` the robot on
        ``tp`` arrives (a leg planned at ``now``: its whole route)."""
        return tp.arrival_time - now - (tp.length - arc_at_time(tp.waypoints, now)) / self.problem.max_speed

    def _take_leg(self, r: _SimRobot, leg: TimedPath, now: float) -> None:
        """r drives ``leg`` (planned at ``now``): counted, kept as what the others' legs are planned around,
        appended to what r drove; r's next event is its arrival."""
        self.tally.legs += 1
        self.leg_delay_s += self._late_by(leg, now)
        self.driving[r.idx] = leg
        self.legs[r.idx].append(leg.waypoints)
        r.wake = max(now, leg.arrival_time)

    def _start_leg(self, r: _SimRobot, now: float, at: float | None = None) -> bool:
        """Plan r's leg to its target (or to a parking spot, to clear a station others queue for)
        and set off; on its target already, it arrives at once. False: no leg yet, try again.
        ``at``: the time it is now, when the leg is planned ahead to leave no sooner than ``now``
        (:data:`HAND_OVER_EARLY_S`)."""
        rules = self.rules
        assert r.target is not None
        if math.dist(r.pos, r.target) < 1e-9:
            rules.arrived(r, now)
            return True
        others = [self._as_fixed(q, now if at is None else at) for q in self.robots if q is not r]
        leg = self._plan_leg(r, r.target, others, now)
        swapped: tuple[_SimRobot, TimedPath] | None = None   # the robot r went first past, its leg before
        if rules.others_queue_here(r) and (leg is None or leg.start_time > now + EVACUATE_S):
            spot = rules.spot_near_here(r)
            if spot is not None:
                evac = self._plan_leg(r, rules.spots[spot], others, now)
                if evac is not None and (leg is None or evac.start_time < leg.start_time):
                    rules.evacuate(r, spot)
                    leg = evac
        elif leg is not None and at is None and self.planner.reorders_legs:
            leg, swapped = self._go_first(r, leg, now)
        if leg is None:
            self.legs_at_failure[r.idx], self.failed_at[r.idx] = self.tally.legs, now
            r.wake = now + RETRY_LATEST * self.limits.retry_s
            return False
        self._take_leg(r, leg, now)
        rules.left(r, now)
        rules.enter(r, "drive", now)
        if swapped is not None:
            self._retime(*swapped, now)
        return True

    def _in_the_way(self, r: _SimRobot, leg: TimedPath, now: float) -> list[_SimRobot]:
        """The robots driving a leg (begun, not arrived) that r would meet on ``leg``'s route driven
        straight off at top speed: their discs would overlap; the one met first first."""
        v, length = self.problem.max_speed, leg.length
        ts = np.arange(0.0, length / v + 0.25, 0.2)
        mine = points_at_arcs(leg.waypoints, np.minimum(ts * v, length))
        ts = ts + now
        met: list[tuple[float, _SimRobot]] = []
        for q in self.robots:
            tp = self.driving[q.idx]
            if q is r or q.phase != "drive" or tp.waypoints[0, 2] > now or tp.arrival_time <= now + 1e-6:
                continue
            close = np.nonzero(np.hypot(*(mine - positions_at_times(tp.waypoints, ts)).T)
                               < 2 * self.problem.radius + 0.05)[0]
            if len(close):
                met.append((float(ts[close[0]]), q))
        return [q for _, q in sorted(met, key=lambda m: m[0])]

    def _go_first(self, r: _SimRobot, leg: TimedPath,
                  now: float) -> tuple[TimedPath, tuple[_SimRobot, TimedPath] | None]:
        """md's priority search in the live fleet: r's new ``leg`` arrives more than :data:`SWAP_AFTER_S`
        late; for a robot q driving in its way (:meth:`_in_the_way`), plan r's leg around everybody but q's
        leg from ``now`` on (q stands where it is at ``now``), then q's rest of its leg from there around
        everybody, r's new leg included. Kept (q's leg cut at ``now``, the new one driven) when the sum of the
        two arrivals drops by more than :data:`SWAP_GAIN_S` (q's not counted when it drives to park: it has
        no delivery left; a robot driving to park never goes first). Both new legs are planned around every other
        trajectory, so the swap is as safe as any leg. Returns r's leg and, after a swap, q and its leg before
        (the caller times again the robots that waited for it, :meth:`_retime`, once r drives its leg)."""
        if r.target_kind == "park" or self._late_by(leg, now) <= SWAP_AFTER_S:
            return leg, None
        assert r.target is not None
        for q in self._in_the_way(r, leg, now)[:SWAP_TRIES]:
            tp = self.driving[q.idx]
            at = tp.position(now)
            standing = TimedPath(q.id, self.problem.radius, np.array([[*at, now]]))
            rest = [self._as_fixed(o, now) for o in self.robots if o is not r and o is not q]
            mine = self._plan_leg(r, r.target, [*rest, standing], now)
            if mine is None or mine.arrival_time >= leg.arrival_time - SWAP_GAIN_S:
                continue
            assert q.target is not None
            theirs = self._plan_leg(q, q.target, [*rest, mine], now, start=at)
            if theirs is None:
                continue
            # (a robot driving to park has no delivery left: when it arrives does not count)
            lost = 0.0 if q.target_kind == "park" else theirs.arrival_time - tp.arrival_time
            if leg.arrival_time - mine.arrival_time - lost <= SWAP_GAIN_S:
                continue
            self._cut(q, at, now)
            self._take_leg(q, theirs, now)
            self.swaps += 1
            return mine, (q, tp)
        return leg, None

    def _cut(self, q: _SimRobot, at: Point, now: float) -> None:
        """q's leg as driven ends at ``at`` at ``now`` (a new one follows)."""
        wp = self.legs[q.idx].pop()
        self.legs[q.idx].append(np.vstack([wp[wp[:, 2] < now], [*at, now]]))
        q.pos = at

    def _retime(self, q: _SimRobot, old: TimedPath, now: float) -> None:
        """q's leg ``old`` was cut at ``now``: the robots driving a leg that still holds a wait (they arrive more
        than :data:`RETIME_GAIN_S` after driving their rest straight at top speed) and that would pass within
        0.3 m of ``old`` at the same time (their leg kept clear of it there) may have waited for it: each is
        planned again from where it is, around every trajectory driven now, and takes the new leg when it
        arrives :data:`RETIME_GAIN_S` sooner."""
        keep_off = 2 * self.problem.radius + 0.3
        if old.arrival_time <= now:
            return
        for r in self.robots:
            tp = self.driving[r.idx]
            if r is q or r.phase != "drive" or r.target_kind == "park" or tp.waypoints[0, 2] > now \
                    or tp.arrival_time <= now:
                continue
            if self._late_by(tp, now) <= RETIME_GAIN_S:
                continue
            # did r's leg pass close by q's old one (at the same time), where it was shaped around it?
            ts = np.arange(now, tp.arrival_time + 0.25, 0.25)
            if np.hypot(*(positions_at_times(tp.waypoints, ts) - positions_at_times(old.waypoints, ts)).T).min() \
                    > keep_off:
                continue
            at = tp.position(now)
            assert r.target is not None
            others = [self._as_fixed(o, now) for o in self.robots if o is not r]
            leg = self._plan_leg(r, r.target, others, now, start=at)
            if leg is None or leg.arrival_time >= tp.arrival_time - RETIME_GAIN_S:
                continue
            self._cut(r, at, now)
            self._take_leg(r, leg, now)
            self.retimed += 1

    def _result(self, t: float, stop: str) -> DeliveryResult:
        p, rules, tally = self.problem, self.rules, self.tally
        paths = [TimedPath(r.id, p.radius, np.vstack(self.legs[r.idx])) for r in self.robots]
        collisions, gap, violations = check_driven(p, paths)
        driven = [distance_driven(tp.waypoints, t) for tp in paths]
        per_leg = max(tally.legs, 1)
        return DeliveryResult(
            problem=p.name, method=self.method, n_robots=p.n_robots, n_deliveries=len(p.deliveries),
            completed=rules.completed, stop=stop, ctime=t, lower_bound=rules.lower_bound(),
            avg_velocity=mean_velocity(driven, t), decision_s=tally.decide_wall_s / per_leg, decision_unit="leg",
            planner_wall_s=tally.decide_wall_s, legs=tally.legs, failed_plans=tally.failed_plans,
            collisions=collisions, min_gap=gap,
            deadlocks=rules.deadlocked(t, self.limits.no_progress_s, ("dock", "drive")),
            wall_s=tally.wall_s(), violations=violations, trajectories=paths,
            extra={"mean_leg_delay_s": round(self.leg_delay_s / per_leg, 2), "hold_legs": rules.hold_legs,
                   "turned": self.turned, "swaps": self.swaps, "retimed": self.retimed, "queue": rules.queue_rule,
                   "mean_phase_s": rules.mean_phase_s(t)})


def simulate_central(problem: DeliveryProblem, method: str, limits: RunLimits, planner_options: dict | None = None,
                     progress: SimProgress | None = None, queue: str = DEFAULT_QUEUE) -> DeliveryResult:
    """Run the deliveries with a central method (a planner name of the registry: md, md-box, prior);
    ``queue``: the queue rule (:data:`~fleet_planner.delivery.stations.QUEUE_RULES`)."""
    return _CentralRun(problem, method, limits, planner_options, progress, queue).run()
