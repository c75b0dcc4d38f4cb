"""``fleet-plan``: plan a scenario file offline and write the plan file.

    fleet-plan SCENARIO.yaml --out PLAN.json [--planner md|md-box|prior|md-departure] [--holds none|anywhere]
        [--mode exact|box] [--time-limit S] [--plot PLAN.png] [--check] [--quiet]

The planners are the registered variants (:func:`fleet_planner.planners.planner_names`).

Every plan goes through the independent checker before it is written; a plan that fails it is a
planner bug and is never written. Exit codes: 0 plan written, 2 bad input or no plan possible
(the reasons are printed), 3 the planner returned an invalid plan (the violations are printed).
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from .checker import check_plan, min_separation
from .grid import MapError
from .model import COLLISION_TESTS, Plan, PlanningError, RobotSpec
from .planners import get_planner, planner_names, planner_summary
from .scenario import ScenarioError, load_scenario, write_plan
from .scheduler import HOLDS

EXIT_OK, EXIT_INPUT, EXIT_INVALID_PLAN = 0, 2, 3


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fleet-plan", description="Plan collision-free timed paths for a robot fleet.")
    p.add_argument("scenario", type=Path, help="scenario YAML (map and robots)")
    p.add_argument("--out", type=Path, required=True, help="plan JSON to write")
    p.add_argument("--planner", choices=planner_names(), default="md",
                   help="planner (default: %(default)s): " + "; ".join(
                       f"{name}: {planner_summary(name)}" for name in planner_names()))
    p.add_argument("--mode", choices=sorted(COLLISION_TESTS, reverse=True),   # exact first: md's default
                   help="md: collision test, exact regions (default) or the paper's boxes (as md-box)")
    p.add_argument("--holds", type=_holds,
                   help="md: where a robot may wait on its path: anywhere (md's default with exact regions: at "
                        "any vertex, with route choice) or none (departure delays only, the paper's method)")
    p.add_argument("--order", choices=["parking", "given", "shortest", "longest"],
                   help="initial priority order (default: the planner's own; md: shortest, prior: given; "
                        "parking is md only)")
    p.add_argument("--margin", type=float,
                   help="md, prior: metres added to every pair's sum of radii (default: 0.02)")
    p.add_argument("--time-limit", type=_seconds, dest="time_limit",
                   help="md: CPU seconds for the priority search when greedy re-ordering gives up, then the "
                        "dense fallback (default: 10)")
    p.add_argument("--plot", type=Path, help="also draw the plan to this PNG")
    p.add_argument("--check", action="store_true",
                   help="also report the checker's verdict and the smallest clearance between robots")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def _seconds(value: str) -> float:
    import math

    try:
        seconds = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds (got {value!r})") from None
    if not (math.isfinite(seconds) and seconds > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds > 0 (got {value!r})")
    return seconds


def _holds(value: str) -> str:
    if value not in HOLDS:
        raise argparse.ArgumentTypeError(f"must be one of {', '.join(HOLDS)} (got {value!r})")
    return value


def schedule_table(robots: Sequence[RobotSpec], plan: Plan) -> str:
    """The plan as a table: one line per robot, then the totals."""
    specs = {r.id: r for r in robots}
    width = max([5] + [len(p.robot_id) for p in plan.paths])
    head = (f"{'robot':<{width}}  {'kind':<20} {'radius':>6} {'speed':>6} {'delay':>8} "
            f"{'arrival':>8} {'length':>8}")
    lines = [head, "-" * len(head)]
    for p in plan.paths:
        s = specs[p.robot_id]
        lines.append(f"{p.robot_id:<{width}}  {s.kind:<20} {s.radius:6.2f} {s.max_speed:6.2f} "
                     f"{p.start_time:8.2f} {p.arrival_time:8.2f} {p.length:8.2f}")
    lines.append("-" * len(head))
    lines.append(f"robots {len(plan.paths)}   sum of arrivals {plan.sum_of_arrivals:.2f} s   "
                 f"makespan {plan.makespan:.2f} s   planning time {plan.planning_time_s:.3f} s ({plan.planner})")
    return "\n".join(lines)


class _ProgressBar:
    """Feeds a tqdm bar from the planner's ``progress(done, total, what)`` callback."""

    def __init__(self, enabled: bool, stream: TextIO):
        from tqdm import tqdm

        self.bar = tqdm(total=0, file=stream, disable=not enabled, unit="step", leave=False)

    def __call__(self, done: int, total: int, what: str) -> None:
        if self.bar.total != total:
            self.bar.reset(total=total)
        self.bar.n = done
        self.bar.set_description_str(what, refresh=False)
        self.bar.refresh()

    def close(self) -> None:
        self.bar.close()


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        scenario = load_scenario(args.scenario)
    except (ScenarioError, MapError) as exc:
        print(f"fleet-plan: {args.scenario}: {exc}", file=sys.stderr)
        return EXIT_INPUT
    grid, robots = scenario.grid, scenario.robots
    # only what was asked for: each planner has its own defaults
    options = {k: v for k, v in (("margin", args.margin), ("order", args.order), ("mode", args.mode),
                                 ("holds", args.holds), ("time_limit", args.time_limit)) if v is not None}
    try:
        planner = get_planner(args.planner, **options)
    except TypeError as exc:   # an option this planner does not have
        print(f"fleet-plan: --planner {args.planner} does not take that option ({exc})", file=sys.stderr)
        return EXIT_INPUT
    except ValueError as exc:
        print(f"fleet-plan: {exc}", file=sys.stderr)
        return EXIT_INPUT
    bar = _ProgressBar(not args.quiet and sys.stderr.isatty(), sys.stderr)
    try:
        plan = planner.plan(grid, robots, progress=bar)
    except PlanningError as exc:
        bar.close()
        print(f"fleet-plan: {args.planner} found no valid plan; nothing written", file=sys.stderr)
        for rid, why in exc.failures.items():
            print(f"  {rid}: {why}", file=sys.stderr)
        return EXIT_INPUT
    bar.close()

    violations = check_plan(grid, robots, plan)
    if violations:
        print(f"fleet-plan: planner {args.planner!r} returned an INVALID plan ({len(violations)} violation(s)); "
              "nothing written. This is a planner bug:", file=sys.stderr)
        for v in violations:
            print(f"  {v}", file=sys.stderr)
        return EXIT_INVALID_PLAN

    print(schedule_table(robots, plan))
    if args.check:
        gap, a, b, t = min_separation(plan.paths)
        closest = "no pair" if a is None else f"closest pair {a}/{b}: clearance {gap:.3f} m at t={t:.2f} s"
        print(f"check: valid (starts, goals, speeds, walls, no overlaps); {closest}")
    write_plan(plan, args.out)
    print(f"plan written to {args.out}")
    if args.plot:
        from .plot import plot_plan

        plot_plan(grid, robots, plan, args.plot)
        print(f"plot written to {args.plot}")
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
