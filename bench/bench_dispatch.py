#!/usr/bin/env python3
"""The dispatcher on its own: the fleet manager and ``fleet-sim``'s robots (``fleet.sim.SimFleet``,
gated, as in the demo) on one simulated clock in one process, no ROS, so the planner is never short
of wall time and the figures do not depend on the machine's load. The demo's job stream
(``random_jobs``, seed 1; ``--jobs`` jobs every ``--interval`` s, by default the demo's 20/9 per
robot every 36/N s), robots placed as ``fleet-demo --robots N`` places them. Per policy and fleet
size: jobs done, throughput (jobs per simulated hour from the first submission to the last job done,
as the demo's summary), closest approach (from the robots' own positions every 0.5 s), the
manager's longest steps (wall and CPU s) and, with ``--time-use``, where the robots' time went
(fleet_planner/ros/demo/timeuse.py). ``--warehouse large`` (or a number of robots) runs on the
generated warehouse ``fleet-demo --warehouse`` runs on; ``--rate R`` gives the manager and the
planner the wall-clock budgets the planner node gives them on a clock R times real time, and lets
the clock run on while the manager steps, as it does in ROS (its legs reach the robots R x the
step's CPU seconds later; by default none of this: the planner always keeps up); ``--profile``
prints cProfile's top lines of the longest step.

    nice .venv/bin/python bench/bench_dispatch.py --robots 9 30 --policies legacy new [--jobs 100 --interval 1.2]
        [--limit 4000] [--time-use]
    nice -n 19 .venv/bin/python bench/bench_dispatch.py --robots 100 --warehouse large --policies new \
        --rate 10 --progress --profile
"""
from __future__ import annotations

import argparse
import cProfile
import heapq
import io
import itertools
import math
import pstats
import random
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import yaml  # noqa: E402

from fleet_planner.fleet import DispatchParams, FleetManager, load_fleet  # noqa: E402
from fleet_planner.fleet.dispatch import LEGACY, PIPELINED, SERIAL, STAGED, DispatchPolicy  # noqa: E402
from fleet_planner.fleet.manager import paced_budgets  # noqa: E402
from fleet_planner.fleet.placement import generated_warehouse, parking_spots, place_robots  # noqa: E402
from fleet_planner.fleet.sim import SimFleet  # noqa: E402
from fleet_planner.robots import load_kinds  # noqa: E402
from fleet_planner.ros.demo.jobs import random_jobs  # noqa: E402
from fleet_planner.ros.demo.timeuse import sites_of, time_use  # noqa: E402
from fleet_planner.warehouse import config_path, load_warehouse  # noqa: E402
from msg_schemas.records import RobotStatus  # noqa: E402

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
        notes: list[str] | None = None, lateness: float | None = None, warehouse: str | None = None,
        rate: float | None = None, profile: bool = False, pace: bool = True, probe=None) -> dict:
    kinds = load_kinds()
    wh = generated_warehouse(warehouse, n) or load_warehouse(Path(warehouse) if warehouse else None)
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
    if rate is None:
        fm.step_budget_s = 1e9   # no wall-clock budget: the planner keeps up whatever the load
    else:   # the planner node's budgets on a clock ``rate`` times real time
        fm.step_budget_s, leg_limit = paced_budgets(fm.params.lead_s, rate, getattr(fm.planner, "leg_time_limit", None))
        if leg_limit is not None:
            fm.planner.leg_time_limit = leg_limit  # type: ignore[attr-defined]
    legs_cpu: list[tuple[float, bool]] = []   # CPU s of each leg the planner planned, and whether it failed
    plan_incremental = fm.planner.plan_incremental

    def timed_leg(*args, **kwargs):
        c = time.process_time()
        try:
            out = plan_incremental(*args, **kwargs)
        except Exception:
            legs_cpu.append((time.process_time() - c, True))
            raise
        legs_cpu.append((time.process_time() - c, False))
        return out
    fm.planner.plan_incremental = timed_leg  # type: ignore[method-assign]
    steps: list[tuple[float, float, float]] = []   # (wall s, CPU s, simulated t) of each step
    worst: tuple[float, cProfile.Profile | None] = (-1.0, None)   # the longest step's wall s and profile
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

    latest: dict[str, RobotStatus] = {}   # the statuses since the last step, the latest of each robot
    busy_until = -math.inf   # (``rate``) the planner is still busy with its last step until then

    def send(topic: str, rid: str, payload: object, late: float, fixed: float = 0.0) -> None:
        due = max(due_of.get((rid, topic), 0.0), t + fixed + rng.uniform(0.0, late))
        due_of[rid, topic] = due
        heapq.heappush(wire, (due, next(order), topic, payload))

    def deliver(topic: str, payload) -> None:
        if topic == "status":
            fm.on_status(payload, t)
        elif topic == "gate":
            sim.on_gate(payload)
        elif topic == "event":
            sim.on_event(payload)
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
                latest[st.id] = st
            entry = (st.stamp, st.mode, st.lateness_s > 0.5, st.task_id, bool(st.loaded), st.kind)
            log = modes.setdefault(st.id, [])
            if not log or log[-1][1:] != entry[1:]:
                log.append(entry)
        if k % round(period / dt):
            continue
        for st in latest.values():   # each robot's latest status, as the planner node reads it off the wire
            fm.on_status(RobotStatus.from_json(st.to_compact_json()), t)   # (positions rounded to 0.1 mm)
        latest.clear()
        if progress and k % round(100.0 / dt) == 0:
            print(f"  t = {t:.0f} s: {sum(e == 'done' for e in last_event.values())} done, {submitted} submitted, "
                  f"CPU {time.process_time() - cpu0:.0f} s, closest {gap:+.3f} m", file=sys.stderr, flush=True)
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
        if t < busy_until:
            continue   # (the planner node's timer fires again only once its step is done)
        prof = cProfile.Profile() if profile else None
        w0, c0 = time.perf_counter(), time.process_time()
        if prof is not None:
            prof.enable()
        d = fm.step(t)
        if prof is not None:
            prof.disable()
        steps.append((time.perf_counter() - w0, time.process_time() - c0, t))
        # on a clock ``rate`` times real time, the clock runs on while the planner thinks: what it decided
        # reaches the robots that much later (its CPU time, not wall: the same on a loaded machine)
        late = rate * steps[-1][1] if rate is not None else 0.0
        busy_until = t + late
        if rate is not None and pace:
            fm.note_pace(rate, steps[-1][1])   # (as the planner node does, with its wall time)
        if steps[-1][0] > worst[0] and t > 10.0:   # (the first legs load numba's compiled kernels)
            worst = (steps[-1][0], prof)
        if probe is not None:   # (a diagnostic's look at the fleet every period: probe(t, manager, sim, decisions))
            probe(t, fm, sim, d)
        if notes is not None:
            notes += [f"{t:.1f} {note}" for note in d.notes]
        for rec in d.gates:   # (the planner node publishes them before the legs)
            if delay > 0 or late > 0:
                send("gate", rec.robot_id, rec, delay, late)
            else:
                sim.on_gate(rec)
        for leg in d.legs:
            if delay > 0 or late > 0:
                send("leg", leg.robot_id, leg, delay, late)
            else:
                deliver("leg", leg)
        for ev in d.events:
            if late > 0:
                send("event", ev.robot_id or "", ev, 0.0, late)
            else:
                sim.on_event(ev)
            events.append(ev)
            last_event[ev.task_id] = ev.event
        if submitted == len(jobs) and all(last_event.get(j.id) in ("done", "failed", "cancelled") for j in jobs):
            break
    done_t = [e.stamp for e in events if e.event == "done"]
    span = (max(done_t) - first) if done_t else None
    longest = sorted(steps, reverse=True)[:5]
    report = None
    if worst[1] is not None:
        buf = io.StringIO()
        pstats.Stats(worst[1], stream=buf).sort_stats("cumulative").print_stats(25)
        report = buf.getvalue()
    out = {"n": n, "jobs": len(jobs), "done": len(done_t), "span": span, "longest": longest, "profile": report,
           "steps_cpu": sum(c for _, c, _ in steps), "done_by": sorted(done_t), "legs": legs_cpu,
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
    p.add_argument("--warehouse", help="warehouse YAML (default: the default warehouse), or 'large' or a number of "
                                       "robots: the generated warehouse fleet-demo --warehouse runs on")
    p.add_argument("--rate", type=float, help="a clock this many times real time: the planner node's wall-clock "
                   "budgets, and the clock runs on while the planner steps (its decisions reach the robots rate x "
                   "the step's CPU s later; default: none, the planner always keeps up)")
    p.add_argument("--profile", action="store_true", help="print cProfile's top lines of the longest step")
    p.add_argument("--no-pace", action="store_true", help="with --rate: the manager is not told the pace "
                   "(FleetManager.note_pace: legs of standing robots start no later for the steps' time)")
    opts = p.parse_args()
    print(f"{'N':>4} {'policy':>12} {'done':>9} {'span s':>7} {'jobs/h':>7} {'closest':>8} {'CPU s':>6}")
    for n in opts.robots:
        for name in opts.policies:
            notes: list[str] | None = [] if opts.notes else None
            r = run(n, POLICIES[name], opts.jobs, opts.interval, opts.limit, progress=opts.progress,
                    seed=opts.seed, delay=opts.delay, status_delay=opts.status_delay, notes=notes,
                    lateness=opts.lateness, warehouse=opts.warehouse, rate=opts.rate, profile=opts.profile,
                    pace=not opts.no_pace)
            if notes is not None:
                Path(opts.notes).write_text("\n".join(notes) + "\n")
            span = f"{r['span']:.0f}" if r["span"] else "-"
            print(f"{r['n']:>4} {name:>12} {r['done']:>4}/{r['jobs']:<4} {span:>7} {r['per_h']:>7.0f} "
                  f"{r['gap']:>+8.3f} {r['cpu']:>6.0f}", flush=True)
            by = " ".join(f"{sum(x <= 1.0 + k for x in r['done_by'])}@{k:.0f}"
                          for k in range(300, int(opts.limit) + 1, 300))
            print(f"     jobs done by simulated s: {by}; steps CPU {r['steps_cpu']:.0f} s; longest steps "
                  "(wall s / CPU s at t): " + ", ".join(f"{w:.2f}/{c:.2f}@{t:.0f}" for w, c, t in r["longest"]),
                  flush=True)
            legs = np.array(r["legs"], dtype=float).reshape(-1, 2)
            if len(legs):
                failed = legs[legs[:, 1] > 0, 0]
                print(f"     legs planned: {len(legs)} ({len(failed)} failed), CPU s mean {legs[:, 0].mean():.3f}, "
                      f"p99 {np.percentile(legs[:, 0], 99):.3f}, max {legs[:, 0].max():.3f}; failed ones: mean "
                      f"{failed.mean() if len(failed) else 0:.3f}, CPU in failed legs {failed.sum():.0f} s", flush=True)
            if r["profile"]:
                print(r["profile"], flush=True)
            if opts.time_use and "use" in r:
                print("     " + "\n     ".join(r["use"].lines()), flush=True)


if __name__ == "__main__":
    main()
