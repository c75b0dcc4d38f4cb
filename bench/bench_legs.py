#!/usr/bin/env python3
"""Planning time per leg in the lifelong delivery simulation (issue 8, deliverable 5): every call
of the planner's ``plan_incremental`` is timed (wall and CPU), and the percentiles are printed with
the run's completion time and collisions.

    nice .venv/bin/python bench/bench_legs.py [--map large] [--sizes 100] [--methods md,md-departure]
        [--deliveries-per-robot 1] [--wall-cap 900]

The problems are bench_delivery.py's (same maps, stations and seeds).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

import bench_delivery  # noqa: E402
import numpy as np  # noqa: E402

from fleet_planner.delivery import simulate  # noqa: E402
from fleet_planner.planners import get_planner  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--map", default="large")
    p.add_argument("--sizes", default="100")
    p.add_argument("--methods", default="md,md-departure")
    p.add_argument("--deliveries-per-robot", type=int, default=1, dest="per_robot")
    p.add_argument("--wall-cap", type=float, default=900.0, help="seconds of wall clock per run")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--dock", type=float, default=5.0)
    p.add_argument("--stations", type=int, default=20)
    p.add_argument("--maps-dir", type=Path, default=REPO.parent / "shared" / "data" / "maps")
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="a planner option for every method (e.g. early_holds=true), repeatable")
    args = p.parse_args(argv)
    options = bench_delivery.planner_options(p, args.option)
    print(f"{'map':<10} {'N':>4} {'method':<13} {'legs':>5} {'p50 ms':>7} {'p90 ms':>7} {'p99 ms':>7} "
          f"{'max ms':>7} {'cpu p50':>7} {'cpu p99':>7} {'cpu s':>7} {'done':>9} {'CTime':>8} {'coll':>4} stop")
    for n in [int(s) for s in args.sizes.split(",")]:
        for method in args.methods.split(","):
            cls = type(get_planner(method))
            original = cls.plan_incremental
            wall: list[float] = []
            cpu: list[float] = []

            def timed(self, *a, _orig=original, _wall=wall, _cpu=cpu, **k):
                t, c = time.perf_counter(), time.process_time()
                try:
                    return _orig(self, *a, **k)
                finally:
                    _wall.append(time.perf_counter() - t)
                    _cpu.append(time.process_time() - c)

            cls.plan_incremental = timed
            try:
                problem = bench_delivery.make_problem(args.map, n, args)
                res = simulate(problem, method, wall_cap_s=args.wall_cap, planner_options=options or None)
            finally:
                cls.plan_incremental = original
            w, c = 1000 * np.array(wall or [0.0]), 1000 * np.array(cpu or [0.0])
            print(f"{args.map:<10} {n:>4} {method:<13} {len(wall):>5} {np.percentile(w, 50):7.1f} "
                  f"{np.percentile(w, 90):7.1f} {np.percentile(w, 99):7.1f} {w.max():7.1f} "
                  f"{np.percentile(c, 50):7.1f} {np.percentile(c, 99):7.1f} {c.sum() / 1000:7.1f} "
                  f"{res.completed:>4}/{res.n_deliveries:<4} {res.ctime:8.1f} {res.collisions:>4} {res.stop}",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
