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


def main() -> None:
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
    a = p.parse_args()
    args = argparse.Namespace(per_robot=a.per_robot, dock=5.0, seed=0, stations=8, maps_dir=a.maps_dir)
    problem = make_problem(a.map, a.n, args)
    if a.lanes == "armo":
        from fleet_planner.delivery import armo_problem

        problem, info = armo_problem(problem)
        print("ARMO:", info)
    limits = RunLimits(cap_s=a.cap, stall_s=a.stall, no_progress_s=120.0, retry_s=2.0, wall_cap_s=a.wall_cap)
    from tqdm import tqdm

    with tqdm(total=len(problem.deliveries), unit="del", file=sys.stderr, mininterval=5.0) as bar:
        def progress(done: int, total: int, t: float) -> None:   # deliveries done, simulated time
            bar.n = done
            bar.set_postfix_str(f"t={t:.0f} s", refresh=False)
            bar.update(0)                                          # redrawn at most every 5 s

        run = _BehaviorRun(problem, 0.1, limits, False, progress)
        res = run.run()
    fleet = run.fleet
    print(f"{a.map} N={a.n}: stop={res.stop} done={res.completed}/{res.n_deliveries} t={res.ctime:.0f} "
          f"coll={res.collisions} dead={res.deadlocks}")
    print("  counters:", {k: v for k, v in res.extra.items() if k not in ("mean_phase_s", "stalled")})
    t = fleet.time
    stuck = [r for r in run.robots if run.rules.busy(r) and r.phase != "dock" and t - r.progress_t > 120]
    kinds = collections.Counter()
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
                        f"@({v.position[0]:.1f},{v.position[1]:.1f}){nxt}")
        if end is None:
            last = fleet.controller(ids[-1])
            tail = f"ends at {ids[-1]} ({last.behavior.value}, {'no path' if last.path is None else 'has path'})"
            kind = f"chain->{last.behavior.value}{'/nopath' if last.path is None else ''}"
        else:
            tail = f"CYCLE back to {end} (len {len(ids) - ids.index(end)})"
            kind = f"cycle{len(ids) - ids.index(end)}"
        kinds[(c.behavior.value, kind)] += 1
        blocked = f" blocked {t - c.blocked_since:.0f}s" if c.blocked_since is not None else ""
        if a.near:
            for o in fleet.ids:
                co = fleet.controller(o)
                if o != r.id and min(math.dist(co.pos, c.pos), math.dist(co.pos, c.goal or c.pos)) < 3.0:
                    print(f"      near {o}: {co.behavior.value} @({co.pos[0]:.2f},{co.pos[1]:.2f}) "
                          f"path={'none' if co.path is None else len(co.path)} goal={co.goal} esc={co.escapes}")
            print(f"      goal {c.goal} escapes={c.escapes} escape_to={c.escape_to} yields={c.yields}")
        print(f"  {r.id} phase={r.phase} since-progress={t - r.progress_t:.0f}s replans={c.replans} "
              f"fails={c.replan_failures} dl={c.deadlocks} off_path={c.off_path}{blocked}: "
              + " => ".join(desc) + "  " + tail)
    print("summary (own behaviour, chain kind):")
    for k, v in kinds.most_common():
        print(f"  {v:3d} {k}")


if __name__ == "__main__":
    main()
