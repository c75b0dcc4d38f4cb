#!/usr/bin/env python3
"""Instrument a stalled behaviour (BBMRCA) delivery run: at the stop, every robot stuck on a leg
with its behaviour, partner, the wait chain it is in (partner pointers followed to a cycle, a
standing robot or a moving one) and a classification of the chain. Not part of the suite.

    .venv/bin/python bench/diag_behavior.py --maps-dir /work/shared/data/maps --map warehouse --n 40
"""
from __future__ import annotations

import argparse
import collections
import math
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.bench_delivery import make_problem  # noqa: E402
from fleet_planner.delivery.behavior_run import _BehaviorRun  # noqa: E402
from fleet_planner.delivery.result import RunLimits  # noqa: E402


def chain(fleet, rid):
    seen, out = [], rid
    while out is not None and out not in seen:
        seen.append(out)
        out = fleet.controller(out).partner
    return seen, out   # out in seen: cycle; None: ends at a robot without partner


def _pickle_locks() -> None:
    """Snapshots: the path finders' locks pickle as new locks."""
    import copyreg
    import threading

    copyreg.pickle(type(threading.Lock()), lambda _lock: (threading.Lock, ()))
    copyreg.pickle(type(threading.RLock()), lambda _lock: (threading.RLock, ()))


def save(run, path: Path) -> None:
    import pickle

    _pickle_locks()
    progress, run.progress = run.progress, None
    try:
        path.write_bytes(pickle.dumps(run))
    finally:
        run.progress = progress


def load(path: Path):
    """A run saved by :func:`save` (the compiled path search keeps no state that pickling could break)."""
    import pickle

    _pickle_locks()
    return pickle.loads(path.read_bytes())


def report(run, near: bool = False, quiet: bool = False) -> collections.Counter:
    """The robots stuck on a leg (no progress for 120 s) with their wait chains; the kinds counted."""
    fleet = run.fleet
    t = fleet.time
    stuck = [r for r in run.robots if run.rules.busy(r) and r.phase != "dock" and t - r.progress_t > 120]
    kinds: collections.Counter = collections.Counter()
    for r in stuck:
        c = fleet.controller(r.id)
        ids, end = chain(fleet, r.id)
        desc = []
        for i in ids:
            ci = fleet.controller(i)
            v = ci.view()
            nxt = f"->({v.next_waypoint[0]:.1f},{v.next_waypoint[1]:.1f})" if v.next_waypoint else " nopath"
            desc.append(f"{i}:{ci.behavior.value}{'*' if ci.no_space else ''}"
                        f"{'(hold ' + ci.holds[0] + ')' if ci.holds else ''}"
                        f"{'(st ' + str(ci.station) + ')' if ci.station else ''}"
                        f"{'(retreat)' if ci.retreat else ''}{'(esc)' if ci.escape_to is not None else ''}"
                        f"@({v.position[0]:.1f},{v.position[1]:.1f}){nxt}")
        if end is None:
            last = fleet.controller(ids[-1])
            tail = f"ends at {ids[-1]} ({last.behavior.value}, {'no path' if last.path is None else 'has path'})"
            kind = f"chain->{last.behavior.value}{'/nopath' if last.path is None else ''}"
        else:
            tail = f"CYCLE back to {end} (len {len(ids) - ids.index(end)})"
            kind = f"cycle{len(ids) - ids.index(end)}"
        kinds[(c.behavior.value, kind)] += 1
        if quiet:
            continue
        blocked = f" blocked {t - c.blocked_since:.0f}s" if c.blocked_since is not None else ""
        if near:
            for o in fleet.ids:
                co = fleet.controller(o)
                if o != r.id and min(math.dist(co.pos, c.pos), math.dist(co.pos, c.goal or c.pos)) < 3.0:
                    print(f"      near {o}: {co.behavior.value} @({co.pos[0]:.2f},{co.pos[1]:.2f}) "
                          f"path={'none' if co.path is None else len(co.path)} goal={co.goal} esc={co.escapes}")
            print(f"      goal {c.goal} escapes={c.escapes} escape_to={c.escape_to} yields={c.yields}")
        print(f"  {r.id} phase={r.phase} since-progress={t - r.progress_t:.0f}s replans={c.replans} "
              f"fails={c.replan_failures} dl={c.deadlocks} off_path={c.off_path}{blocked}: "
              + " => ".join(desc) + "  " + tail)
    return kinds


def main() -> None:
    import time

    p = argparse.ArgumentParser()
    p.add_argument("--maps-dir", type=Path, default=REPO.parent / "shared" / "data" / "maps")
    p.add_argument("--map", default="warehouse")
    p.add_argument("--n", type=int, default=40)
    p.add_argument("--per-robot", type=int, default=3)
    p.add_argument("--stall", type=float, default=300.0)
    p.add_argument("--cap", type=float, default=4 * 3600.0)
    p.add_argument("--wall-cap", type=float, default=300.0)
    p.add_argument("--near", action="store_true", help="also the robots near each stuck one")
    p.add_argument("--lanes", choices=("none", "armo"), default="none",
                   help="armo: the robots plan along ARMO's road map (the 'armo' method)")
    p.add_argument("--steps", type=int, default=None, help="stop after this many fleet steps (e.g. to profile)")
    p.add_argument("--profile", type=Path, default=None, help="cProfile the steps into this file (pstats)")
    p.add_argument("--report-every", type=float, default=0.0,
                   help="every this many simulated seconds, a one-line summary of the stuck robots")
    p.add_argument("--snapshot-every", type=float, default=0.0,
                   help="every this many simulated seconds, pickle the run to --snapshot (to study a jam)")
    p.add_argument("--snapshot", type=Path, default=Path("out/diag_behavior.pkl"))
    p.add_argument("--resume", type=Path, default=None, help="go on from a snapshot (the map options are ignored)")
    a = p.parse_args()
    if a.resume is not None:
        run = load(a.resume)
        problem = run.problem
    else:
        args = argparse.Namespace(per_robot=a.per_robot, dock=5.0, seed=0, stations=8, maps_dir=a.maps_dir)
        problem = make_problem(a.map, a.n, args)
        if a.lanes == "armo":
            from fleet_planner.delivery import armo_problem

            problem, info = armo_problem(problem)
            print("ARMO:", info)
        limits = RunLimits(cap_s=a.cap, stall_s=a.stall, no_progress_s=120.0, retry_s=2.0, wall_cap_s=a.wall_cap)
        run = _BehaviorRun(problem, 0.1, limits, False, None)
        for r in run.robots:
            run.rules.next_target(r, 0.0)
            run._assign(r, 0.0)
    from tqdm import tqdm

    cpu0, wall0, steps0 = time.process_time(), time.time(), run.steps
    next_report = run.fleet.time + a.report_every
    next_snap = run.fleet.time + a.snapshot_every
    profiler = None
    if a.profile is not None:
        import cProfile

        profiler = cProfile.Profile()
        profiler.enable()
    with tqdm(total=len(problem.deliveries), unit="del", file=sys.stderr, mininterval=5.0) as bar:
        def progress(done: int, total: int, t: float) -> None:   # deliveries done, simulated time
            bar.n = done
            bar.set_postfix_str(f"t={t:.0f} s", refresh=False)
            bar.update(0)                                          # redrawn at most every 5 s

        run.progress = progress
        stop = "done"
        while run.rules.ctime is None:       # _BehaviorRun.run, with the hooks
            why = run._stop_now()
            if why is None and a.steps is not None and run.steps - steps0 >= a.steps:
                why = "steps"
            if why is not None:
                stop = why
                break
            run._step()
            t = run.fleet.time
            if a.report_every > 0 and t >= next_report:
                next_report += a.report_every
                kinds = report(run, quiet=True)
                tqdm.write(f"t={t:.0f} s done={run.rules.completed} stuck={sum(kinds.values())} "
                           f"{dict(kinds.most_common(4))}", file=sys.stdout)
                sys.stdout.flush()
            if a.snapshot_every > 0 and t >= next_snap:
                next_snap += a.snapshot_every
                a.snapshot.parent.mkdir(parents=True, exist_ok=True)
                save(run, a.snapshot)
        res = run._result(run.rules.ctime if run.rules.ctime is not None else run.fleet.time, stop)
    if profiler is not None:
        profiler.disable()
        profiler.dump_stats(a.profile)
    cpu, wall, steps = time.process_time() - cpu0, time.time() - wall0, run.steps - steps0
    print(f"{problem.name} N={problem.n_robots}: stop={res.stop} done={res.completed}/{res.n_deliveries} "
          f"t={res.ctime:.0f} coll={res.collisions} dead={res.deadlocks}")
    print(f"  {steps} steps in {cpu:.1f} s CPU ({steps / max(cpu, 1e-9):.1f} steps/s), {wall:.1f} s wall")
    print("  counters:", {k: v for k, v in res.extra.items() if k not in ("mean_phase_s", "stalled")})
    kinds = report(run, a.near)
    print("summary (own behaviour, chain kind):")
    for k, v in kinds.most_common():
        print(f"  {v:3d} {k}")


if __name__ == "__main__":
    main()
