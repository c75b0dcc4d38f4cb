#!/usr/bin/env python3
"""The dispatcher on its own: the fleet manager and ``fleet-sim``'s robots (``fleet.sim.SimFleet``,
gated, as in the demo) on one simulated clock in one process, no ROS, so the planner is never short
of wall time and the figures do not depend on the machine's load. The demo's job stream
(``random_jobs``, seed 1; ``--jobs`` jobs every ``--interval`` s, by default the demo's 20/9 per
robot every 36/N s), robots placed as ``fleet-demo --robots N`` places them. Per policy and fleet
size: jobs done, throughput (jobs per simulated hour from the first submission to the last job done,
as the demo's summary), closest approach (from the robots' own positions every 0.5 s) and, with
``--time-use``, where the robots' time went (fleet_planner/ros/demo/timeuse.py).

    nice .venv/bin/python bench/bench_dispatch.py --robots 9 30 --policies legacy new [--jobs 100 --interval 1.2]
        [--limit 4000] [--time-use]
"""
from __future__ import annotations

import argparse
import heapq
import itertools
import math
import random
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import yaml  # noqa: E402

from fleet_planner.fleet import DispatchParams, FleetManager, load_fleet  # noqa: E402
from fleet_planner.fleet.dispatch import LEGACY, PIPELINED, SERIAL, STAGED, DispatchPolicy  # noqa: E402
from fleet_planner.fleet.placement import parking_spots, place_robots  # noqa: E402
from fleet_planner.fleet.sim import SimFleet  # noqa: E402
from fleet_planner.robots import load_kinds  # noqa: E402
from fleet_planner.ros.demo.jobs import random_jobs  # noqa: E402
from fleet_planner.ros.demo.timeuse import sites_of, time_use  # noqa: E402
from fleet_planner.warehouse import config_path, load_warehouse  # noqa: E402

#: "new" is the default (PIPELINED: the chute queue, sites held until "soon"); "s18" the session-18 default (SERIAL)
POLICIES = {"legacy": LEGACY, "new": PIPELINED, "s18": SERIAL,
            "batch": DispatchPolicy(queue=False, sites=False, site_hold="done"), "staged": STAGED,
            "staged-no-queue": DispatchPolicy(staging=True, queue=False, site_hold="done", charge_below=0.6,
                                              leave_charger_at=0.95),
            "queue": DispatchPolicy(queue=True, site_hold="done"),
            "queue-picked": DispatchPolicy(queue=True, site_hold="picked"),
            "soon": DispatchPolicy(queue=False, site_hold="soon")}


def run(n: int, policy: DispatchPolicy, jobs_n: int | None, interval: float | None, limit: float, dt: float = 0.1,
        period: float = 0.5, progress: bool = False, seed: int = 1, delay: float = 0.0, status_delay: float = 0.0,
        notes: list[str] | None = None, lateness: float | None = None) -> dict:
    kinds = load_kinds()
    wh = load_warehouse()
    if n == 0:   # the demo's default fleet (config/fleet.yaml) and parking spots (config/planner_params.yaml)
        members = load_fleet(None, kinds, wh)
        flat = yaml.safe_load(config_path("planner_params.yaml").read_text())["/**"]["ros__parameters"]["parking"]
        parking = list(zip(flat[0::2], flat[1::2]))
        n = len(members)
    else:
        members = place_robots(wh, kinds, n)
        parking = parking_spots(wh, members)
    params = DispatchParams() if lateness is None else DispatchParams(lateness_tolerance_s=lateness)
    fm = FleetManager(wh, kinds, params, parking)
    fm.policy = policy
    fm.step_budget_s = 1e9   # no wall-clock budget: the planner keeps up whatever the load
    sim = SimFleet(members, kinds, wh, gated=True)
    jobs = random_jobs(wh, kinds, members, jobs_n if jobs_n is not None else max(1, round(20 / 9 * n)), seed=seed)
    interval = interval if interval is not None else 36.0 / n
    radius = {m.id: kinds[m.kind].radius for m in members}
    ids = list(radius)
    rad = np.array([radius[i] for i in ids])
    reach = rad[:, None] + rad[None, :]
    np.fill_diagonal(reach, -np.inf)
    modes: dict[str, list] = {}
    tracks: dict[str, list] = {i: [] for i in ids}
    events = []
    last_event: dict[str, str] = {}
    gap = math.inf
    first = 1.0
    submitted = 0
    cpu0 = time.process_time()
    t, k = 0.0, 0
    # messages on the wire (``delay``, ``status_delay``: each one late by up to that many simulated s, drawn
    # at random; in order per robot and topic, as DDS keeps them): (due, n, topic, payload)
    rng = random.Random(seed)
    wire: list[tuple[float, int, str, object]] = []
    due_of: dict[tuple[str, str], float] = {}
    order = itertools.count()

    def send(topic: str, rid: str, payload: object, late: float) -> None:
        due = max(due_of.get((rid, topic), 0.0), t + rng.uniform(0.0, late))
        due_of[rid, topic] = due
        heapq.heappush(wire, (due, next(order), topic, payload))

    def deliver(topic: str, payload) -> None:
        if topic == "status":
            fm.on_status(payload, t)
        elif topic == "gate":
            sim.on_gate(payload)
        else:
            try:
                sim.on_path(payload.robot_id, payload.relative(), payload.t0, payload.path_id)
            except ValueError:
                pass   # (the robot reports it rejected; the manager plans it again)
    while t < limit:
        k += 1
        t = round(k * dt, 9)
        while submitted < len(jobs) and t >= first + submitted * interval:
            sim.on_task(jobs[submitted])
            events += fm.submit(jobs[submitted], t)
            submitted += 1
        statuses = sim.step(t)
        while wire and wire[0][0] <= t:
            _, _, topic, payload = heapq.heappop(wire)
            deliver(topic, payload)
        for st in statuses:
            if status_delay > 0:
                send("status", st.id, st, status_delay)
            else:
                fm.on_status(st, t)
            entry = (st.stamp, st.mode, st.lateness_s > 0.5, st.task_id, bool(st.loaded), st.kind)
            log = modes.setdefault(st.id, [])
            if not log or log[-1][1:] != entry[1:]:
                log.append(entry)
        if k % round(period / dt):
            continue
        if progress and k % round(100.0 / dt) == 0:
            print(f"  t = {t:.0f} s: {sum(e == 'done' for e in last_event.values())} done, {submitted} submitted, "
                  f"CPU {time.process_time() - cpu0:.0f} s", file=sys.stderr, flush=True)
            if notes is not None:   # who waits for whom (the gate), where (to find a jam)
                for rid, a in sim.agents.items():
                    seen, fr = sim.last.get(rid), fm.robots.get(rid)
                    if seen is None or fr is None:
                        continue
                    notes.append(f"{t:.1f} state {rid} ({seen.x:.2f}, {seen.y:.2f}) {seen.mode} waits for "
                                 f"{getattr(a.driver, 'waits_for', None)} path {seen.path_id} leg "
                                 f"{fr.leg.path_id if fr.leg else None} rejected {seen.rejected_path_id} "
                                 f"target {fr.target.name if fr.target else None} trouble {fr.trouble!r}")
        pos = np.array([(st.x, st.y) for st in statuses])
        for st in statuses:
            tracks[st.id].append((st.x, st.y, t))
        dist = np.hypot(pos[:, None, 0] - pos[None, :, 0], pos[:, None, 1] - pos[None, :, 1])
        gap = min(gap, float(np.min(dist - reach)))
        d = fm.step(t)
        if notes is not None:
            notes += [f"{t:.1f} {note}" for note in d.notes]
        for rec in d.gates:   # (the planner node publishes them before the legs)
            if delay > 0:
                send("gate", rec.robot_id, rec, delay)
            else:
                sim.on_gate(rec)
        for leg in d.legs:
            if delay > 0:
                send("leg", leg.robot_id, leg, delay)
            else:
                deliver("leg", leg)
        for ev in d.events:
            sim.on_event(ev)
            events.append(ev)
            last_event[ev.task_id] = ev.event
        if submitted == len(jobs) and all(last_event.get(j.id) in ("done", "failed", "cancelled") for j in jobs):
            break
    done_t = [e.stamp for e in events if e.event == "done"]
    span = (max(done_t) - first) if done_t else None
    out = {"n": n, "jobs": len(jobs), "done": len(done_t), "span": span,
           "per_h": 3600.0 * len(done_t) / span if span else 0.0, "gap": gap, "cpu": time.process_time() - cpu0,
           "events": events, "task": jobs}
    if span:
        chutes = {s.name: s.pose for s in wh.stations_of("chute")}
        out["use"] = time_use(modes, events, jobs, kinds, tracks, chutes, first, first + span, sites=sites_of(wh))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--robots", type=int, nargs="+", default=[9, 30],
                   help="fleet sizes (robots placed as fleet-demo --robots N places them; 0: the demo's default fleet)")
    p.add_argument("--policies", nargs="+", default=["s18", "new"], choices=sorted(POLICIES))
    p.add_argument("--jobs", type=int, help="jobs (default: the demo's, 20/9 per robot)")
    p.add_argument("--interval", type=float, help="simulated s between jobs (default: the demo's, 36/N)")
    p.add_argument("--limit", type=float, default=4000.0, help="simulated s at most (default 4000)")
    p.add_argument("--seed", type=int, default=1, help="seed of the random jobs (default 1, as the demo)")
    p.add_argument("--time-use", action="store_true", help="print where the robots' time went")
    p.add_argument("--delay", type=float, default=0.0,
                   help="legs and gate records reach robots up to this many simulated s late (random; default 0)")
    p.add_argument("--status-delay", type=float, default=0.0,
                   help="statuses reach the planner up to this many simulated s late (random; default 0)")
    p.add_argument("--notes", help="write the planner's notes (and who waits for whom every 100 s) to this file")
    p.add_argument("--lateness", type=float, help="lateness_tolerance_s of the planner (default: DispatchParams')")
    p.add_argument("--progress", action="store_true", help="jobs done every 100 simulated s (on stderr)")
    opts = p.parse_args()
    print(f"{'N':>4} {'policy':>12} {'done':>9} {'span s':>7} {'jobs/h':>7} {'closest':>8} {'CPU s':>6}")
    for n in opts.robots:
        for name in opts.policies:
            notes: list[str] | None = [] if opts.notes else None
            r = run(n, POLICIES[name], opts.jobs, opts.interval, opts.limit, progress=opts.progress,
                    seed=opts.seed, delay=opts.delay, status_delay=opts.status_delay, notes=notes,
                    lateness=opts.lateness)
            if notes is not None:
                Path(opts.notes).write_text("\n".join(notes) + "\n")
            span = f"{r['span']:.0f}" if r["span"] else "-"
            print(f"{r['n']:>4} {name:>12} {r['done']:>4}/{r['jobs']:<4} {span:>7} {r['per_h']:>7.0f} "
                  f"{r['gap']:>+8.3f} {r['cpu']:>6.0f}", flush=True)
            if opts.time_use and "use" in r:
                print("     " + "\n     ".join(r["use"].lines()), flush=True)


if __name__ == "__main__":
    main()
