#!/usr/bin/env python3
"""A burst of new legs in a crowd (issue 11, deliverable 3): the dense solver's own
``plan_incremental`` (safe intervals against exact cell holdings) against PRIOR's.

N robots of ``MAP`` (as ``bench_dense.py``: the first N usable pairs of its random scenarios, mixed
discs) are planned by the dense solver; at t0 = the median arrival, every robot that has arrived
gets a new goal (the goals of the next pairs of the scenario that are nobody's last cell) and the
robots still driving are fixed trajectories. Each planner plans the burst in a child process
(``--timeout``); the checker judges the whole fleet (driven paths, the parked part before t0 and the
new legs). Robots whose new goal is shut off for good by a robot parked in a 1-cell aisle (no
planner can serve them while the others stay fixed) keep parking. Columns: legs served / asked, who
answered, CPU s of plan_incremental, sum of leg times over their free times, the checker's verdict.

    .venv/bin/python bench/bench_dense_legs.py [--maps-dir DIR] [--sizes 100,400] [--map warehouse-10-20-10-2-1]
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import queue
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_dense import FreeTimes, instance  # noqa: E402

from fleet_planner.checker import check_plan  # noqa: E402
from fleet_planner.model import Plan, PlanningError, RobotSpec, TimedPath  # noqa: E402
from fleet_planner.planners.crowd import CrowdPlanner  # noqa: E402
from fleet_planner.planners.prior import PriorPlanner  # noqa: E402


def _child(results, which, grid, new, fixed, t0):
    try:
        planner = CrowdPlanner() if which == "dense" else PriorPlanner()
        if which == "dense":
            from fleet_planner.planners import crowd_kernels, crowd_sipp, crowd_st
            crowd_kernels.warm_up()
            crowd_st.warm_up()
            crowd_sipp.warm_up()
        c0 = time.process_time()
        legs = planner.plan_incremental(grid, new, fixed, t0)
        results.put(("ok", time.process_time() - c0, legs, getattr(planner, "last_incremental", which)))
    except PlanningError as exc:
        results.put(("no plan", None, str(exc).splitlines()[1].strip(), ""))
    except Exception as exc:  # noqa: BLE001
        results.put(("error", None, repr(exc), ""))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--maps-dir", type=Path, default=REPO.parent / "shared" / "data" / "maps")
    p.add_argument("--map", default="warehouse-10-20-10-2-1")
    p.add_argument("--sizes", default="100,400")
    p.add_argument("--timeout", type=float, default=120.0)
    args = p.parse_args(argv)
    print(f"{'map':<24} {'N':>5} {'legs':>7} {'planner':<7} {'by':<6} {'cpu s':>7} {'leg/free':>8}  valid")
    bad = False
    for n in [int(s) for s in args.sizes.split(",")]:
        grid, pool = instance(args.maps_dir, args.map, 2 * n, 0)
        robots = pool[:n]
        plan = CrowdPlanner().plan(grid, robots)
        t0 = float(np.median([q.arrival_time for q in plan.paths]))
        done = [k for k, q in enumerate(plan.paths) if q.arrival_time <= t0]
        driving = [k for k in range(n) if k not in done]
        taken = {tuple(q.waypoints[-1, :2]) for q in plan.paths}
        spare = [r.goal for r in pool[n:] if r.goal not in taken]
        spare = list(dict.fromkeys(spare))[:len(done)]
        done = done[:len(spare)]
        driving = [k for k in range(n) if k not in done]
        new = [RobotSpec(robots[k].id, robots[k].radius, robots[k].max_speed, robots[k].goal, spare[x])
               for x, k in enumerate(done)]
        asked = len(new)
        for _ in range(5):   # robots whose new goal is shut off for good by a parked robot keep parking
            try:
                CrowdPlanner().plan_incremental(grid, new, [plan.paths[k] for k in driving], t0)
                break
            except PlanningError as exc:
                keep = [x for x, r in enumerate(new) if r.id not in exc.failures]
                done, spare, new = [done[x] for x in keep], [spare[x] for x in keep], [new[x] for x in keep]
                driving = [k for k in range(n) if k not in done]
        fixed = [plan.paths[k] for k in driving]
        alone = FreeTimes(grid)
        for which in ("dense", "prior"):
            ctx = mp.get_context("fork")
            results = ctx.Queue()
            proc = ctx.Process(target=_child, args=(results, which, grid, new, fixed, t0), daemon=True)
            proc.start()
            try:
                status, cpu, legs, by = results.get(timeout=args.timeout)
            except queue.Empty:
                status, cpu, legs, by = "timeout", None, None, ""
            finally:
                if proc.is_alive():
                    proc.terminate()
                proc.join()
            ratio, verdict = None, status
            if status == "ok":
                whole = {k: plan.paths[k] for k in driving}
                for x, k in enumerate(done):
                    old = plan.paths[k].waypoints
                    whole[k] = TimedPath(robots[k].id, robots[k].radius,
                                         np.vstack([old[old[:, 2] <= t0], legs[x].waypoints]))
                specs = [robots[k] if k in driving else
                         RobotSpec(robots[k].id, robots[k].radius, robots[k].max_speed, robots[k].start,
                                   spare[done.index(k)]) for k in range(n)]
                violations = check_plan(grid, specs, Plan(which, [whole[k] for k in range(n)], 0.0, {}))
                verdict = f"FAIL ({len(violations)})" if violations else "ok"
                bad |= bool(violations)
                ratio = sum(leg.arrival_time - t0 for leg in legs) / sum(alone(r) for r in new)
            cpu_s = "-" if cpu is None else f"{cpu:7.2f}"
            ratio_s = "-" if ratio is None else f"{ratio:8.3f}"
            legs_s = f"{len(new)}/{asked}"
            print(f"{args.map:<24} {n:>5} {legs_s:>7} {which:<7} {by:<6} {cpu_s:>7} {ratio_s:>8}  {verdict}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
