"""Gated execution against today's lateness re-planning (issue 9, deliverable 4): completion time,
closest approach and re-plans when robots are slowed and halted at random.

Two fleets, each run with: ``gated`` (robots respect the (M,D) links of fleet/gate.py, lateness
re-planning off), ``gated+replan`` (both) and ``clock+replan`` (today: robots drive by the clock,
late ones are re-planned after 3 s, a safety net stops them short of a contact).

* ``pure``: the pure fleet of test/gated_sim.py (manager and agents on one simulated clock), four
  robots, ten seeded jobs, eight random slow-downs (0-30 % speed, 10-20 s) per seed;
* ``ros`` (``--ros``): the ROS test's scenario (test/test_ros_gate.py): planner and four agents on
  DDS, six jobs, one robot at 30 % for 20 s and another halted 10 s.

Times are simulated seconds (from the first task to the last job done; ``-`` if not all were
done within the limit); gap is the closest approach minus the sum of radii from the driven
tracks (pure) or the robots' status reports (ros), negative = contact.

    nice .venv/bin/python bench/bench_gate.py --seeds 0-5 [--ros]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "test"))  # the test beds are shared with the tests

from tqdm import tqdm  # noqa: E402

MODES = {"gated": (True, 3600.0), "gated+replan": (True, 3.0), "clock+replan": (False, 3.0)}


def pure(seed: int, gated: bool, lateness: float, limit: float) -> tuple[bool, float, float, int, float]:
    from test_gate import gated_run

    cpu = time.process_time()
    sim, done = gated_run(seed, gated=gated, limit=limit, lateness_tolerance_s=lateness)
    gap = sim.gap()[0]
    replans = sum("late: re-planning" in n for n in sim.notes)
    end = max((e.stamp for e in sim.events if e.event == "done"), default=sim.t)
    return done, end, gap, replans, time.process_time() - cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0-3", help="pure runs: seeds a-b (inclusive) or a,b,c ('' for none)")
    ap.add_argument("--limit", type=float, default=600.0, help="pure runs: simulated s before a run counts as stuck")
    ap.add_argument("--ros", action="store_true", help="also the ROS scenario (real DDS, about a minute per mode)")
    ap.add_argument("--ros-repeat", type=int, default=1, help="ROS runs per mode (DDS timing differs run to run)")
    ap.add_argument("--modes", default=",".join(MODES), help=f"comma-separated, of {', '.join(MODES)}")
    args = ap.parse_args()
    if "-" in args.seeds:
        a, b = args.seeds.split("-")
        seeds = list(range(int(a), int(b) + 1))
    else:
        seeds = [int(s) for s in args.seeds.split(",") if s]
    modes = {m: MODES[m] for m in args.modes.split(",")}
    rows = []
    for seed in tqdm(seeds, desc="pure fleets", file=sys.stderr):
        for mode, (gated, late) in modes.items():
            rows.append(("pure", seed, mode, *pure(seed, gated, late, args.limit)))
    if args.ros:
        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        import rclpy
        from rclpy.context import Context
        from test_ros_gate import slowed_run

        ctx = Context()
        rclpy.init(context=ctx)
        try:
            runs = [(k, m) for k in range(args.ros_repeat) for m in modes]
            for k, mode in tqdm(runs, desc="ros fleets", file=sys.stderr):
                gated, late = modes[mode]
                cpu = time.process_time()
                out = slowed_run(ctx, gated, late)
                rows.append(("ros", k, mode, out.done, out.seconds, out.gap, out.replans, time.process_time() - cpu))
        finally:
            rclpy.try_shutdown(context=ctx)
    print("| fleet | seed | mode | all done | completion (sim s) | closest gap (m) | late re-plans | CPU s |")
    print("|---|---|---|---|---|---|---|---|")
    for fleet, seed, mode, done, end, gap, replans, cpu in rows:
        shown, ok = (f"{end:.1f}", "yes") if done else ("-", "NO")
        print(f"| {fleet} | {seed} | {mode} | {ok} | {shown} | {gap:.3f} | {replans} | {cpu:.1f} |")


if __name__ == "__main__":
    main()
