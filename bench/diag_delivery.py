#!/usr/bin/env python3
"""Where a central method's delivery run loses time (issue 8): per leg, the wait before departing,
the holds en route and the detour (against the shortest path on the empty map), by target kind;
per station, its visits, the time from one robot leaving it to the next one arriving (turnover)
and its span; optionally (``--against prior``)
the same leg planned by another planner on exactly the same situation (its arrival against the
method's).

    nice -n 19 .venv/bin/python bench/diag_delivery.py --maps-dir ../shared/data/maps --map warehouse \
        --n 50 [--seed 0] [--method md] [--against prior]

The problems are bench_delivery.py's (same maps, stations and seeds).
"""
from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

import bench_delivery  # noqa: E402
import numpy as np  # noqa: E402

from fleet_planner.delivery import central  # noqa: E402
from fleet_planner.delivery.result import RunLimits  # noqa: E402
from fleet_planner.geometry import polyline_length  # noqa: E402
from fleet_planner.model import PlanningError, RobotSpec  # noqa: E402
from fleet_planner.paths import PathFinder  # noqa: E402
from fleet_planner.planners import get_planner  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--map", default="warehouse")
    p.add_argument("--n", type=int, default=50)
    p.add_argument("--method", default="md")
    p.add_argument("--against", default="", help="a second planner timing every leg on the same situation")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--deliveries-per-robot", type=int, default=3, dest="per_robot")
    p.add_argument("--maps-dir", type=Path, default=REPO.parent / "shared" / "data" / "maps")
    p.add_argument("--top", type=int, default=6, help="stations shown")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="a planner option of the method (e.g. early_clear=true), repeatable")
    p.add_argument("--dump", type=Path, help="also write every leg's record to this JSON file")
    p.add_argument("--queue", default="auto",
                   help="the queue rule: auto (default), spots, near or close (bench_delivery --queue)")
    args = p.parse_args(argv)
    bargs = bench_delivery._args(["--maps-dir", str(args.maps_dir), "--seed", str(args.seed),
                                  "--deliveries-per-robot", str(args.per_robot)])
    problem = bench_delivery.make_problem(args.map, args.n, bargs)
    finder = PathFinder(problem.grid, problem.radius)
    other = get_planner(args.against) if args.against else None
    legs: list[dict] = []
    station_log: dict[str, list[tuple[str, float, int]]] = defaultdict(list)   # (event, t, robot)

    options = bench_delivery.planner_options(p, args.option)
    run = central._CentralRun(problem, args.method, RunLimits(4 * 3600.0, 600.0, 120.0, 2.0, 7200.0), options or None,
                              None, queue=args.queue)
    plan_leg = run._plan_leg

    def logged_plan_leg(r, goal, others, now, start=None):
        t0 = time.process_time()
        leg = plan_leg(r, goal, others, now, start=start)
        src = r.pos if start is None else start
        cpu = time.process_time() - t0
        rec = {"robot": r.idx, "t": now, "kind": r.target_kind, "cpu": cpu, "ok": leg is not None,
               "from_station": r.on_station is not None, "station": r.station, "on_station": r.on_station,
               "src": [round(float(c), 2) for c in src], "goal": [round(float(c), 2) for c in goal]}
        if leg is not None:
            path = finder.find(src, goal)
            short = polyline_length(path) if path is not None else leg.length
            rec.update(depart=leg.start_time - now, arrive=leg.arrival_time - now, length=leg.length, short=short)
            if other is not None:
                spec = RobotSpec(r.id, problem.radius, problem.max_speed, src, goal)
                try:
                    alt = other.plan_incremental(problem.grid, [spec], others, now)[0]
                    rec["alt_arrive"] = alt.arrival_time - now
                except PlanningError:
                    rec["alt_arrive"] = None
        legs.append(rec)
        return leg

    run._plan_leg = logged_plan_leg
    rules = run.rules
    arrived, left = rules.arrived, rules.left

    def logged_arrived(r, t):
        if r.target_kind in ("pick", "drop"):
            station_log[r.station].append(("arrive", t, r.idx))
        arrived(r, t)

    def logged_left(r, t):
        if r.on_station is not None:
            station_log[r.on_station].append(("leave", t, r.idx))
        left(r, t)

    rules.arrived, rules.left = logged_arrived, logged_left
    wall = time.perf_counter()
    res = run.run()
    print(f"{args.map} N={args.n} seed={args.seed} {args.method}: CTime {res.ctime:.0f} s, bound {res.lower_bound:.0f} "
          f"({res.ctime / res.lower_bound:.2f}), {res.collisions} collisions, {res.legs} legs, "
          f"{res.failed_plans} failed, {time.perf_counter() - wall:.0f} s wall")
    print("mean s per robot by phase:", res.extra["mean_phase_s"])
    ok = [x for x in legs if x["ok"]]
    print("\nlegs by target kind (mean s per leg): depart = wait before leaving, hold = waits en route, "
          "detour = (length - shortest) / v")
    print(f"{'kind':<6} {'legs':>5} {'depart':>7} {'hold':>7} {'detour':>7} {'total':>7} {'sum s':>8}")
    v = problem.max_speed
    for kind in ("pick", "drop", "hold", "evac", "park", "all"):
        sel = [x for x in ok if kind == "all" or x["kind"] == kind]
        if not sel:
            continue
        dep = np.array([x["depart"] for x in sel])
        drive = np.array([x["length"] / v for x in sel])
        hold = np.array([x["arrive"] for x in sel]) - dep - drive
        det = np.array([(x["length"] - x["short"]) / v for x in sel])
        tot = dep + hold + det
        print(f"{kind:<6} {len(sel):>5} {dep.mean():>7.2f} {hold.mean():>7.2f} {det.mean():>7.2f} {tot.mean():>7.2f} "
              f"{tot.sum():>8.0f}")
    cpu = np.array([x["cpu"] for x in legs])
    print(f"leg CPU s: p50 {np.percentile(cpu, 50):.3f} p99 {np.percentile(cpu, 99):.3f} max {cpu.max():.3f}")
    if other is not None:
        both = [x for x in ok if x.get("alt_arrive") is not None]
        diff = np.array([x["arrive"] - x["alt_arrive"] for x in both])
        print(f"\nagainst {args.against} on the same {len(both)} situations: md arrives later on {(diff > 0.5).sum()}, "
              f"sooner on {(diff < -0.5).sum()}; mean {diff.mean():+.2f} s, sum {diff.sum():+.0f} s, "
              f"worst +{diff.max():.1f} s")
        for kind in ("pick", "drop", "hold", "evac", "park"):
            d = np.array([x["arrive"] - x["alt_arrive"] for x in both if x["kind"] == kind])
            if len(d):
                print(f"  {kind:<5} {len(d):>4} legs: mean {d.mean():+.2f} s, later by > 0.5 s on {(d > 0.5).sum()}")
    for flag, label in ((True, "legs leaving a station"), (False, "legs leaving anywhere else")):
        sel = [x for x in ok if x["from_station"] == flag]
        if sel:
            dep = np.array([x["depart"] for x in sel])
            print(f"{label}: {len(sel)}, wait before leaving mean {dep.mean():.2f} s, > 1 s on {(dep > 1).sum()}, "
                  f"sum {dep.sum():.0f} s")
    if args.dump:
        import json

        args.dump.write_text(json.dumps(legs))
    print("\nstations (busiest first): visits, dock s, span (first arrival .. last leave), turnover (a robot "
          "leaving it -> the next one arriving)")
    busy = sorted(station_log, key=lambda s: -len(station_log[s]))[:args.top]
    for s in busy:
        ev = sorted(station_log[s], key=lambda e: e[1])
        arr = [t for e, t, _ in ev if e == "arrive"]
        lv = [t for e, t, _ in ev if e == "leave"]
        gaps = []
        for t_leave in lv:
            nxt = [t for t in arr if t >= t_leave]
            if nxt:
                gaps.append(nxt[0] - t_leave)
        span = (max(lv or arr) - min(arr)) if arr else 0.0
        print(f"  {s:<10} visits {len(arr):>3} dock {len(arr) * problem.dock_s:>5.0f} span {span:>6.0f} "
              f"turnover mean {np.mean(gaps) if gaps else 0:>5.1f} s (n={len(gaps)}) "
              f"first {min(arr):.0f} last {max(arr):.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
