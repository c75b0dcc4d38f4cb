#!/usr/bin/env python3
"""The live fleet at scale: ``fleet-demo --mode procs --robots N`` for each N, one row each.

Fleets of ``--default`` sizes run on the default warehouse, of ``--large`` sizes on a generated one
(``--warehouse large``); robots are driven by ``fleet-sim`` above 15 (the demo's ``--sim auto``),
one agent process each below. Jobs: ``--jobs-per-robot`` x N, submitted as the demo scales them.
Printed per run: wall time, the simulated-time rate reached (and asked), CPU (% of one core, over
the run) and peak memory of each kind of process (planner, sim clock, fleet-sim or the agents,
the demo's monitor), jobs done, jobs per simulated hour, and the closest approach of two robots
beyond the sum of their radii (from the robots' status stream, as the demo measures it).

Timings on a loaded machine are noisy; CPU time is the better figure.

    nice .venv/bin/python bench/bench_fleet.py [--default 9 15 22 30] [--large 50 100] [--rate 10]
        [--jobs-per-robot 1] [--jobs 60 --interval 2] [--timeout 600] [--same-stream] [--sim on] [--time-use]

Issue 8's series (throughput grows with the fleet, one job stream):
``bench/bench_fleet.py --default 9 15 22 30 --large --same-stream --sim on --rate 5``
"""
from __future__ import annotations

import argparse
import os
import random
import re
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from fleet_planner.ros.demo.procstat import descendants, memory_mb, stat  # noqa: E402
from fleet_planner.ros.demo.procstat import role as process_role  # noqa: E402


def run(n: int, large: bool, opts: argparse.Namespace) -> dict:
    out = REPO / "out" / "bench_fleet" / f"{'large' if large else 'default'}_{n}"
    out.mkdir(parents=True, exist_ok=True)
    jobs = opts.jobs if opts.jobs is not None and not large else max(1, round(opts.jobs_per_robot * n))
    cmd = [sys.executable, "-m", "fleet_planner.ros.demo", "--mode", "procs", "--robots", str(n), "--jobs", str(jobs),
           "--rate", str(opts.rate), "--no-progress", "--out", str(out), "--timeout", str(opts.timeout)]
    if opts.interval is not None and not large:
        cmd += ["--interval", str(opts.interval)]
    if large:
        cmd += ["--warehouse", "large"]
    if opts.sim != "auto":
        cmd += ["--sim", opts.sim]
    if opts.time_use:
        cmd += ["--time-use"]
    env = {**os.environ, "PYTHONPATH": str(REPO), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID", str(random.randint(1, 100)))}
    t0 = time.monotonic()
    demo = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=REPO)
    cpu: dict[int, tuple[str, float]] = {}
    peak: dict[int, float] = {}
    while demo.poll() is None:
        for pid in descendants(demo.pid):
            st = stat(pid)
            if st is not None:
                cpu[pid] = (process_role(st[2]), st[1])
                peak[pid] = max(peak.get(pid, 0.0), memory_mb(pid))
        time.sleep(1.0)
    wall = time.monotonic() - t0
    text = demo.stdout.read() if demo.stdout else ""
    roles: dict[str, list[int]] = defaultdict(list)
    for pid, (role, _) in cpu.items():
        roles[role].append(pid)
    per_role = {role: (max(cpu[p][1] for p in pids) / wall * 100, max(peak[p] for p in pids), len(pids))
                for role, pids in roles.items()}

    def find(pattern: str, default: str = "?") -> str:
        m = re.search(pattern, text)
        return m.group(1) if m else default

    return {"n": n, "where": "large" if large else "default", "wall": wall, "jobs": jobs,
            "done": find(r"jobs: (\d+) done"), "rate": find(r"simulated time ran at ([\d.]+)x"),
            "per_h": find(r"throughput: (\d+) jobs"), "gap": find(r"clearance ([+-][\d.]+) m\)"),
            "roles": per_role, "tail": text[-600:],
            "use": text[text.index("time use of"):text.index("robots:", text.index("time use of"))].rstrip()
            if "time use of" in text else ""}


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--default", type=int, nargs="*", default=[9, 15, 22, 30], help="fleet sizes, default warehouse")
    p.add_argument("--large", type=int, nargs="*", default=[50, 100], help="fleet sizes, generated warehouse")
    p.add_argument("--rate", type=float, default=10.0, help="simulated time rate asked (default 10)")
    p.add_argument("--jobs-per-robot", type=float, default=1.0, help="jobs per robot (default 1)")
    p.add_argument("--jobs", type=int, help="the same number of jobs for every fleet on the default warehouse "
                                            "(instead of --jobs-per-robot; the large runs keep it)")
    p.add_argument("--interval", type=float, help="simulated s between jobs on the default warehouse (default: "
                                                  "the demo's, scaled with the fleet)")
    p.add_argument("--timeout", type=float, default=600.0, help="wall seconds per run at most (default 600)")
    p.add_argument("--same-stream", action="store_true",
                   help="one job stream for every fleet on the default warehouse: issue 10's 100 jobs every 1.2 s "
                        "(what --jobs 100 --interval 1.2 gives; the jobs depend only on the fleet's kinds, so every "
                        "size gets the same jobs: issue 8's 'throughput grows with the fleet' series)")
    p.add_argument("--sim", choices=("auto", "on", "off"), default="auto",
                   help="fleet-demo --sim: on drives every size by fleet-sim (same robot simulation at every size)")
    p.add_argument("--time-use", action="store_true", help="print each run's time use table (fleet-demo --time-use)")
    opts = p.parse_args()
    if opts.same_stream:
        opts.jobs = 100 if opts.jobs is None else opts.jobs
        opts.interval = 1.2 if opts.interval is None else opts.interval
    stream = (f"{opts.jobs} jobs" if opts.jobs is not None else f"{opts.jobs_per_robot:g} jobs per robot") + (
        f" every {opts.interval:g} s" if opts.interval is not None else "")
    print(f"fleet-demo --mode procs at {opts.rate:g}x asked, {stream} (large: {opts.jobs_per_robot:g} per robot)")
    print(f"{'N':>4} {'warehouse':>9} {'wall s':>7} {'sim rate':>8} {'done':>9} {'jobs/h':>7} {'closest':>8}  "
          "CPU % of a core / peak MB per process (count)")
    runs = [(n, False) for n in opts.default] + [(n, True) for n in opts.large]
    for n, large in runs:
        r = run(n, large, opts)
        procs = "  ".join(f"{role} {c:.0f}%/{m:.0f}MB" + (f" (x{k})" if k > 1 else "")
                          for role, (c, m, k) in sorted(r["roles"].items()))
        print(f"{r['n']:>4} {r['where']:>9} {r['wall']:>7.0f} {r['rate']:>8} {r['done']:>4}/{r['jobs']:<4} "
              f"{r['per_h']:>7} {r['gap']:>8}  {procs}", flush=True)
        if r["use"]:
            print("     " + r["use"].replace("\n", "\n     "), flush=True)
        if r["done"] == "?":
            print("     " + r["tail"].replace("\n", "\n     "))


if __name__ == "__main__":
    main()
