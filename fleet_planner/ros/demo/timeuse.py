"""Where the robots' time went in a demo run (``fleet-demo --time-use``): every robot's time from
the first submission to the last job done, cut into what it was doing, from the robots' own status
reports and the planner's task events (as the monitor heard them), not from the planner's state.

Pure (no rclpy): :func:`time_use` takes the monitor's records. Each robot is sampled every ``dt``
simulated seconds; a sample falls into one category of :data:`CATEGORIES`:

* with a job (between its ``assigned`` and ``done`` events, or ``failed``/``cancelled``): driving to
  the chute, picking, driving to the storing site, placing, held on its schedule (``waiting`` and
  on time: a hold the planner put in its leg), held back late (``waiting`` more than
  :data:`~.monitor.LATE_S` behind its schedule: its gate or its safety net stops it), standing with
  a job (``idle``: its leg has not started, or was refused, or it waits for the next);
* without a job: driving (to a charger or parking spot), charging or idle - each split by whether
  a job it could do was queued (accepted, not yet assigned) at a chute nobody was bound for and
  for a storing site no other job was under way to ("a job was free": the dispatcher's loss), only
  such jobs whose site another job was under way to ("its site was taken": the dispatcher's rule of
  one job per site, fleet/dispatch.py; counted only when ``sites`` are given), only at chutes
  another robot was bound for ("its chute was busy": the station's queue), or none ("nothing to do").
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from fleet_planner.fleet.state import can_do
from fleet_planner.robots import RobotKind
from fleet_planner.warehouse import Warehouse
from msg_schemas.records import Task, TaskEvent

#: the categories, in the order they are printed
CATEGORIES = (
    "job: driving to the chute", "job: picking", "job: driving to the storing site", "job: placing",
    "job: held on its schedule", "job: held back late (gate, safety net)", "job: standing (leg not started)",
    "no job: driving (to a charger or parking)", "no job: charging, a job was free",
    "no job: charging, its site was taken", "no job: charging, its chute was busy", "no job: charging, nothing to do",
    "no job: idle, a job was free", "no job: idle, its site was taken", "no job: idle, its chute was busy",
    "no job: idle, nothing to do",
)


@dataclass
class TimeUse:
    """Robot-seconds per category (:data:`CATEGORIES`), and per job the mean seconds queued
    (accepted to assigned), to the chute and picked (assigned to picked), to the site and placed
    (picked to done), and the mean straight-line distance from the robot to the chute when assigned."""

    seconds: dict[str, float]
    span_s: float
    robots: int
    queued_s: float
    to_pick_s: float
    to_place_s: float
    approach_m: float

    def lines(self) -> list[str]:
        total = sum(self.seconds.values()) or 1.0
        out = [f"time use of {self.robots} robots over {self.span_s:.0f} s (share of robot-time):"]
        out += [f"  {name:<44} {100 * s / total:5.1f} %" for name, s in self.seconds.items()]
        out.append(f"per job: queued {self.queued_s:.1f} s, assigned to picked {self.to_pick_s:.1f} s, picked to "
                   f"done {self.to_place_s:.1f} s; robot {self.approach_m:.1f} m from the chute when assigned")
        return out


def time_use(modes: Mapping[str, Sequence[tuple]], events: Iterable[TaskEvent], jobs: Sequence[Task],
             kinds: Mapping[str, RobotKind], tracks: Mapping[str, Sequence[tuple[float, float, float]]],
             chutes: Mapping[str, tuple[float, float]], t0: float, t1: float, dt: float = 0.5,
             sites: Mapping[str, str] | None = None) -> TimeUse:
    """``modes``: per robot its (stamp, mode, late, task_id, loaded, kind) records in any order
    (:attr:`~.monitor.FleetMonitor.modes`); ``events`` the task events heard; ``tracks`` per robot
    (x, y, stamp); ``chutes`` the chutes' poses by name; ``[t0, t1]`` the span (simulated s);
    ``sites``: the storing site of each address tag (:func:`sites_of`), to tell "its site was taken"."""
    ts = np.arange(t0, t1, dt) if t1 > t0 else np.zeros(0)
    index = {j.id: k for k, j in enumerate(jobs)}
    first: dict[tuple[str, str], float] = {}
    robot_of: dict[str, str] = {}
    for ev in sorted(events, key=lambda e: e.stamp):
        if ev.task_id not in index:
            continue
        if ev.event == "assigned" and ev.robot_id:  # (a re-queued job is assigned again: the last one counts)
            first[(ev.task_id, "assigned")] = ev.stamp
            robot_of[ev.task_id] = ev.robot_id
        else:
            first.setdefault((ev.task_id, ev.event), ev.stamp)

    def at(task: str, *names: str) -> float:
        return min((first[(task, n)] for n in names if (task, n) in first), default=np.inf)

    n_jobs = len(jobs)
    accepted = np.array([at(j.id, "accepted") for j in jobs]) if n_jobs else np.zeros(0)
    assigned = np.array([at(j.id, "assigned", "done", "failed", "cancelled", "rejected") for j in jobs])
    picked = np.array([at(j.id, "picked") for j in jobs])
    ended = np.array([at(j.id, "done", "failed", "cancelled", "rejected") for j in jobs])
    queued = (accepted[None, :] <= ts[:, None]) & (ts[:, None] < assigned[None, :])  # samples x jobs
    chute_names = sorted({j.pick for j in jobs})
    chute_of = np.array([chute_names.index(j.pick) for j in jobs], dtype=int)
    bound = (assigned[None, :] <= ts[:, None]) & (ts[:, None] < np.minimum(picked, ended)[None, :])
    busy = np.zeros((len(ts), len(chute_names)), dtype=bool)
    for c in range(len(chute_names)):
        busy[:, c] = bound[:, chute_of == c].any(axis=1)
    chute_busy = busy[:, chute_of] if n_jobs else np.zeros((len(ts), 0), dtype=bool)
    # a job's site is taken while another job for the same site is under way (assigned, not ended)
    site_taken = np.zeros((len(ts), n_jobs), dtype=bool)
    if sites is not None and n_jobs:
        active = (assigned[None, :] <= ts[:, None]) & (ts[:, None] < ended[None, :])
        site_names = sorted({sites.get(j.place, j.place) for j in jobs})
        site_of = np.array([site_names.index(sites.get(j.place, j.place)) for j in jobs], dtype=int)
        for c in range(len(site_names)):
            mask = site_of == c
            site_taken[:, mask] = active[:, mask].any(axis=1, keepdims=True)
    seconds = dict.fromkeys(CATEGORIES, 0.0)
    for rid, log in modes.items():
        if not log:
            continue
        log = sorted(log, key=lambda e: e[0])
        stamps = np.array([e[0] for e in log])
        k = np.searchsorted(stamps, ts, side="right") - 1
        kind = kinds.get(log[-1][5])
        able = np.array([kind is not None and can_do(kind, j) for j in jobs], dtype=bool)
        open_chute = queued & ~chute_busy & able[None, :]
        free_job = (open_chute & ~site_taken).any(axis=1) if n_jobs else np.zeros(len(ts), bool)
        site_job = (open_chute & site_taken).any(axis=1) if n_jobs else np.zeros(len(ts), bool)
        busy_job = (queued & chute_busy & able[None, :]).any(axis=1) if n_jobs else np.zeros(len(ts), bool)
        mine = [i for t, i in index.items() if robot_of.get(t) == rid]
        for s, ki in enumerate(k):
            if ki < 0:
                continue
            _, mode, late, task_id, loaded, _ = log[ki]
            t = ts[s]
            job = next((i for i in mine if assigned[i] <= t < ended[i]), None)
            if job is not None:
                after_pick = t >= picked[job]
                if mode == "driving":
                    name = "job: driving to the storing site" if after_pick else "job: driving to the chute"
                elif mode in ("picking", "placing"):
                    name = f"job: {mode}"
                elif mode == "waiting":
                    name = "job: held back late (gate, safety net)" if late else "job: held on its schedule"
                else:
                    name = "job: standing (leg not started)"
            else:
                why = ("a job was free" if free_job[s] else "its site was taken" if site_job[s]
                       else "its chute was busy" if busy_job[s] else "nothing to do")
                if mode in ("driving", "waiting"):
                    name = "no job: driving (to a charger or parking)"
                elif mode == "charging":
                    name = f"no job: charging, {why}"
                else:
                    name = f"no job: idle, {why}"
            seconds[name] += dt
    approach = []
    for task, rid in robot_of.items():
        i = index[task]
        track = tracks.get(rid)
        pose = chutes.get(jobs[i].pick)
        if not track or pose is None:
            continue
        stamps = np.array([p[2] for p in track])
        last = max(0, int(np.searchsorted(stamps, assigned[i], side="right")) - 1)   # the pose when assigned
        approach.append(float(np.hypot(track[last][0] - pose[0], track[last][1] - pose[1])))
    done = np.isfinite(ended) & np.isfinite(picked)

    def span(start: np.ndarray, end: np.ndarray) -> float:
        """The mean of ``end - start`` over the jobs where both happened (0 if none)."""
        both = np.isfinite(start) & np.isfinite(end)
        return float((end[both] - start[both]).mean()) if both.any() else 0.0

    return TimeUse(seconds, float(t1 - t0), len(modes), span(accepted, assigned), span(assigned[done], picked[done]),
                   span(picked[done], ended[done]), float(np.mean(approach)) if approach else 0.0)


def sites_of(warehouse: Warehouse) -> dict[str, str]:
    """The storing site (station name) of each address tag of ``warehouse``."""
    return {tag: s.name for s in warehouse.stations_of("storage") for tag in s.tags}


__all__ = ["CATEGORIES", "TimeUse", "sites_of", "time_use"]
