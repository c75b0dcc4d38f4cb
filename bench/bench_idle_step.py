#!/usr/bin/env python3
"""The fleet manager's step with N idle robots, no ROS (issue 9: idle robots cost nothing per step).

N robots stand idle on free spots of a generated warehouse (as in bench_load.py), every robot's status
is fed before each step; with ``--tasks`` a task comes every 4th step (legs are planned then). Prints
the CPU milliseconds of a step (median, max) over ``--steps`` steps after 10 warm-up steps.

    nice .venv/bin/python bench/bench_idle_step.py --robots 500 [--tasks] [--steps 40] [--profile out/step.prof]
"""
from __future__ import annotations

import argparse
import cProfile
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from fleet_planner.fleet import DispatchParams, FleetManager  # noqa: E402
from fleet_planner.fleet.placement import parking_spots, place_robots, warehouse_for  # noqa: E402
from fleet_planner.robots import load_kinds  # noqa: E402
from msg_schemas.records import RobotStatus, Task  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--robots", type=int, default=500)
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--tasks", action="store_true", help="a task every 4th step")
    p.add_argument("--profile", help="cProfile the measured steps into this file")
    opts = p.parse_args()
    kinds = load_kinds()
    wh = warehouse_for(min(opts.robots, 200))
    members = place_robots(wh, kinds, opts.robots)
    fm = FleetManager(wh, kinds, DispatchParams(offline_timeout_s=3.0), parking_spots(wh, members))
    chutes = [s.name for s in wh.stations_of("chute")]
    tags = [t for s in wh.stations_of("storage") for t in s.tags]

    def statuses(t: float) -> None:
        for m in members:
            fm.on_status(RobotStatus(id=m.id, kind=m.kind, x=m.x, y=m.y, yaw=0.0, vx=0.0, vy=0.0, battery=0.9,
                                     mode="idle", progress=1.0, stamp=t, radius=kinds[m.kind].radius), t)

    t = 0.0
    for _ in range(10):
        statuses(t)
        fm.step(t)
        t += 0.5
    works, legs = [], 0
    prof = cProfile.Profile() if opts.profile else None
    for k in range(opts.steps):
        statuses(t)
        if opts.tasks and k % 4 == 0:
            fm.submit(Task(id=f"T{k}", pick=chutes[k % len(chutes)], place=tags[k % len(tags)]), t)
        c0 = time.process_time()
        if prof is not None:
            prof.enable()
        d = fm.step(t)
        if prof is not None:
            prof.disable()
        works.append(time.process_time() - c0)
        legs += len(d.legs)
        t += 0.5
    print(f"{opts.robots} robots{' with tasks' if opts.tasks else ', idle'}: step CPU ms median "
          f"{1e3 * statistics.median(works):.1f}, max {1e3 * max(works):.1f}; {legs} legs in {opts.steps} steps")
    if prof is not None:
        prof.dump_stats(opts.profile)


if __name__ == "__main__":
    main()
