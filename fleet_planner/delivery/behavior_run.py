"""The behaviour-based method (``behavior``): time-stepped with a fixed ``dt``.

:class:`~fleet_planner.behavior.BehaviorFleet` runs the behaviour-based collision avoidance of
Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance" (BBMRCA): each robot plans
its own A* path to the target the rules give it, and the behaviours resolve conflicts locally
(stations by the fleet's docking arbiter, so the rules here claim none). Overlaps are counted at
every step. ``admit`` (ours, issue 13): at most that many robots bound for a station at a time,
the others wait on parking spots out of the crowd round the loading stations (see
:mod:`.stations`); None: every robot drives to its station at once (the paper's fleet).
"""
from __future__ import annotations

import math
from dataclasses import asdict

import numpy as np
from scipy.spatial import cKDTree

from ..behavior import BehaviorFleet
from ..model import PlanningError, RobotSpec
from .problem import DeliveryProblem
from .result import DeliveryResult, RunLimits, RunTally, SimProgress, mean_velocity
from .stations import _DeliveryRules, _SimRobot

#: robots admitted to a station at a time when the behaviour fleet's admission is on (ours; see
#: :mod:`.stations`): the 200-robot stress run on `large` (``bench/diag_behavior.py --admit``). Off by
#: default (``admit=None``): the paper's fleet, and the paper table's rows stay as they were.
ADMIT = 2
#: phases of a busy robot that make no progress by design (docking; queued for its station's admission):
#: neither a stall nor a deadlock
WAITING_PHASES = ("dock", "queued")


class _BehaviorRun:
    """One run of the behaviour fleet: its steps, the distances driven, the overlaps seen."""

    def __init__(self, problem: DeliveryProblem, dt: float, limits: RunLimits, record: bool,
                 progress: SimProgress | None, admit: int | None = None):
        self.tally = RunTally()
        self.problem = problem
        self.dt = dt
        self.limits = limits
        self.progress = progress
        self.rules = _DeliveryRules(problem, claims=False, admit=admit)
        self.robots = self.rules.robots
        specs = [RobotSpec(r.id, problem.radius, problem.max_speed, r.pos, r.pos) for r in self.robots]
        self.fleet = BehaviorFleet(problem.grid, specs)
        self.steps = 0
        self.reach = 2 * problem.radius                      # centres closer than this: discs overlap
        self.overlapping: set[tuple[int, int]] = set()      # pairs of robots overlapping now
        self.overlap_events = 0                              # pairs that started to overlap
        self.min_gap = math.inf
        self.driven = np.zeros(problem.n_robots)             # distance driven per robot
        self.pos = self.fleet.positions()
        self.record = record
        self.log: list[np.ndarray] = [self.pos.copy()] if record else []   # positions at every step
        self.times: list[float] = [0.0] if record else []

    def start(self) -> None:
        """Every robot's first target, and its path when it is not queued for its station."""
        for r in self.robots:
            self.rules.next_target(r, 0.0)
            if r.phase == "need":   # not queued for its station
                self._assign(r, 0.0)

    def run(self) -> DeliveryResult:
        self.start()
        stop = "done"
        while self.rules.ctime is None:
            why = self._stop_now()
            if why is not None:
                stop = why
                break
            self._step()
        t = self.rules.ctime if self.rules.ctime is not None else self.fleet.time
        return self._result(t, stop)

    def _stop_now(self) -> str | None:
        """Why the run must stop before the next step, if it must."""
        t, limits = self.fleet.time, self.limits
        if t >= limits.cap_s:
            return "cap"
        stuck = [r for r in self.robots if self.rules.busy(r) and r.phase not in WAITING_PHASES]
        if stuck and all(t - r.progress_t > limits.stall_s for r in stuck):
            return "stall"
        if self.tally.wall_s() > limits.wall_cap_s:
            return "wall"
        return None

    def _assign(self, r: _SimRobot, now: float) -> None:
        """Hand r's target to the fleet (r plans its own path there); if it cannot, r tries again
        ``retry_s`` later."""
        assert r.target is not None
        with self.tally.deciding():
            try:
                self.fleet.assign(r.id, r.target, r.station if r.target_kind in ("pick", "drop") else None)
            except PlanningError:
                self.tally.failed_plans += 1
                r.wake = now + self.limits.retry_s
                return
        self.tally.legs += 1
        self.rules.left(r, now)
        self.rules.enter(r, "drive", now)
        r.best_left = math.inf

    def _step(self) -> None:
        """One fleet step of ``dt``, then what it did: distances, overlaps, the robots' events."""
        with self.tally.deciding():
            self.fleet.step(self.dt)
        self.steps += 1
        t = self.fleet.time
        new = self.fleet.positions()
        self.driven += np.hypot(*(new - self.pos).T)
        self.pos = new
        if self.record:
            self.log.append(self.pos.copy())
            self.times.append(t)
        self._count_overlaps()
        for r in self.robots:
            self._update(r, t)
        for r in self.rules.take_handed_over(t):   # admitted to their station: on to it now
            self._assign(r, t)

    def _count_overlaps(self) -> None:
        pos, reach = self.pos, self.reach
        now_overlapping = set()
        for a, b in cKDTree(pos).query_pairs(reach + 1.0):
            gap = float(np.hypot(*(pos[a] - pos[b]))) - reach
            self.min_gap = min(self.min_gap, gap)
            if gap < -1e-9:
                now_overlapping.add((a, b))
        self.overlap_events += len(now_overlapping - self.overlapping)
        self.overlapping = now_overlapping

    def _update(self, r: _SimRobot, t: float) -> None:
        """r after a step: its position, progress, arrival, end of docking, a new target."""
        rules = self.rules
        r.pos = (float(self.pos[r.idx, 0]), float(self.pos[r.idx, 1]))
        if r.phase == "drive":   # progress: 1 m less path left than ever before on this leg
            left = self.fleet.controller(r.id).remaining()
            if left <= r.best_left - 1.0:
                r.best_left = left
                r.progress_t = t
        if r.phase == "drive" and self.fleet.arrived(r.id):
            rules.arrived(r, t)
        elif r.phase == "dock" and t >= r.wake - 1e-9:
            rules.docked(r, t)
            if self.progress:
                self.progress(rules.completed, len(self.problem.deliveries), t)
        if r.phase == "need" and t >= r.wake - 1e-9:
            self._assign(r, t)

    def _result(self, t: float, stop: str) -> DeliveryResult:
        p, rules, tally = self.problem, self.rules, self.tally
        stats = self.fleet.stats()   # the fleet's own counters (deadlocks found, re-plans...), as extras
        return DeliveryResult(
            problem=p.name, method="behavior", n_robots=p.n_robots, n_deliveries=len(p.deliveries),
            completed=rules.completed, stop=stop, ctime=t, lower_bound=rules.lower_bound(),
            avg_velocity=mean_velocity(self.driven, t), decision_s=tally.decide_wall_s / max(self.steps, 1),
            decision_unit="step", planner_wall_s=tally.decide_wall_s, legs=tally.legs,
            failed_plans=tally.failed_plans, collisions=self.overlap_events, min_gap=self.min_gap,
            deadlocks=rules.deadlocked(t, self.limits.no_progress_s, WAITING_PHASES), wall_s=tally.wall_s(),
            positions=np.array(self.log) if self.record else None,
            times=np.array(self.times) if self.record else None,
            extra={"mean_phase_s": rules.mean_phase_s(t),
                   **{k: v for k, v in asdict(stats).items() if k != "time"}})


def simulate_behavior(problem: DeliveryProblem, limits: RunLimits, dt: float = 0.1, record: bool = False,
                      progress: SimProgress | None = None, admit: int | None = None) -> DeliveryResult:
    """Run the deliveries with the behaviour fleet, stepped by ``dt``; ``record`` keeps the positions;
    ``admit``: robots admitted to a station at a time (None: no limit, the paper's fleet)."""
    return _BehaviorRun(problem, dt, limits, record, progress, admit).run()
