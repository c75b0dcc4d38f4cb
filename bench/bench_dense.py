#!/usr/bin/env python3
"""The dense-crowd solver against md and PRIOR on 1-cell-aisle warehouses (issue 11's targets).

Each run is ``MAP:N[,N...]``: the first N usable start/goal pairs of ``<MAP>-random-1.scen`` (then
``-random-2``, ``-random-3`` of the same map when N is larger than one file holds) become robots
with mixed discs as in ``bench_md.py`` (radius 0.35-0.45 m, 0.7-1.0 m/s, seeded). Each planner
plans in a child process killed after its timeout (short for md and PRIOR, which are here for
comparison where they finish), and the independent checker judges every plan.

Columns: wall and CPU seconds of planning (the machine may be shared: CPU is the steadier one);
sum of arrivals / sum of no-interference arrivals (SoC/free, each robot's own shortest path driven
alone at its top speed) and makespan / longest no-interference arrival; the checker's verdict
(``ok``, ``FAIL (k)``, ``no plan``, ``timeout``, ``error``); for the dense solver its LNS
iterations (the timed LNS's after a timed first plan). Exit status 1 when any plan was invalid.

    .venv/bin/python bench/bench_dense.py [warehouse-10-20-10-2-1:400,1000 warehouse-20-40-10-2-2:2000]
        [--planners dense,md,prior] [--timeout 60] [--dense-timeout 300] [--refine 1.0] [--timed-refine 1.2]
        [--maps-dir DIR] [--seed 0] [--csv out/bench_dense.csv]
"""
from __future__ import annotations

import argparse
import csv
import math
import multiprocessing as mp
import queue
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, replace
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from bench_md import RADIUS, SPEED, AloneTimes, add_maps_dir, generated_instance, maps_dir_of  # noqa: E402

from fleet_planner.checker import check_plan  # noqa: E402
from fleet_planner.grid import GridMap  # noqa: E402
from fleet_planner.model import PlanningError, RobotSpec  # noqa: E402
from fleet_planner.planners import get_planner, planner_names  # noqa: E402
from fleet_planner.scenario import ScenarioError, scenario_from_movingai  # noqa: E402

DEFAULT_RUNS = ["warehouse-10-20-10-2-1:400,1000", "warehouse-20-40-10-2-2:2000"]


@dataclass
class Row:
    map: str
    n: int
    planner: str
    wall_s: float | None = None
    cpu_s: float | None = None
    soc_ratio: float | None = None
    makespan_ratio: float | None = None
    lns: int | None = None
    verdict: str = ""
    detail: str = ""


def _args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="*", default=DEFAULT_RUNS, help="MAP:N[,N...] (default: %(default)s)")
    add_maps_dir(p)
    p.add_argument("--planners", default="dense,md,prior", help="comma-separated (default: %(default)s)")
    p.add_argument("--timeout", type=float, default=60.0, help="seconds per run of md and prior (default: %(default)s)")
    p.add_argument("--dense-timeout", type=float, default=300.0,
                   help="seconds per run of the dense solver (default: %(default)s)")
    p.add_argument("--refine", type=float, default=None,
                   help="CPU seconds of the dense solver's LNS refinement (default: the planner's own)")
    p.add_argument("--timed-refine", type=float, default=None,
                   help="CPU seconds of the dense solver's timed LNS (default: the planner's own; its "
                        "timed_refine_s)")
    p.add_argument("--seed", type=int, default=0, help="radii and speeds (default: %(default)s)")
    p.add_argument("--csv", type=Path, help="also write the table as CSV")
    args = p.parse_args(argv)
    args.maps_dir = maps_dir_of(p, args)
    runs = []
    for spec in args.runs:
        name, _, sizes = spec.partition(":")
        try:
            ns = sorted({int(s) for s in sizes.split(",") if s.strip()})
        except ValueError:
            p.error(f"run {spec!r}: expected MAP:N[,N...]")
        if not name or not ns or ns[0] < 1:
            p.error(f"run {spec!r}: expected MAP:N[,N...] with N >= 1")
        runs.append((name, ns))
    args.runs = runs
    args.planners = [s.strip() for s in args.planners.split(",") if s.strip()]
    unknown = [s for s in args.planners if s not in planner_names()]
    if unknown or not args.planners:
        p.error(f"--planners: unknown {unknown}; choose from {', '.join(planner_names())}")
    if not (args.timeout > 0 and args.dense_timeout > 0):
        p.error("--timeout, --dense-timeout: must be > 0")
    for name, value in (("--refine", args.refine), ("--timed-refine", args.timed_refine)):
        if value is not None and not value >= 0:
            p.error(f"{name}: must be >= 0")
    return args


def instance(maps_dir: Path, name: str, n: int, seed: int) -> tuple[GridMap, list[RobotSpec]]:
    """The first n usable pairs of the map's random-1 .scen, continued by random-2 and random-3."""
    map_path = maps_dir / f"{name}.map"
    scens = [maps_dir / f"{name}-random-{k}.scen" for k in (1, 2, 3)]
    scens = [s for s in scens if s.is_file()]
    if not map_path.is_file() or not scens:
        sys.exit(f"bench_dense: {map_path} or {name}-random-1.scen not found in {maps_dir}")
    with tempfile.TemporaryDirectory() as tmp:
        joined = Path(tmp) / f"{name}-joined.scen"
        lines = ["version 1"]
        for s in scens:
            lines += [ln for ln in s.read_text().splitlines()[1:] if ln.strip()]
        joined.write_text("\n".join(lines) + "\n")
        try:
            sc = scenario_from_movingai(map_path, joined, n, seed, RADIUS, SPEED)
        except ScenarioError as exc:
            sys.exit(f"bench_dense: {name}: {exc}")
    return sc.grid, sc.robots


def _child(results, grid: GridMap, robots: list[RobotSpec], name: str, options: dict) -> None:
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        planner = get_planner(name, **options)
        for p in (planner, get_planner("dense")):   # (md may hand over to the dense solver)
            p.warm_up()   # compiled kernels, numba's cache loaded once per process: not planning
        t0, c0 = time.perf_counter(), time.process_time()
        plan = planner.plan(grid, robots)
        timing = (time.perf_counter() - t0, time.process_time() - c0)
        plan.network = None   # large and not needed here
        results.put(("ok", timing, plan))
    except PlanningError as exc:
        results.put(("no plan", (time.perf_counter() - t0, time.process_time() - c0),
                     str(exc).splitlines()[1].strip()))
    except Exception:  # noqa: BLE001 - a crash of the planner is a result to report, not to hide
        results.put(("error", (None, None), traceback.format_exc(limit=3)))


def run_one(grid: GridMap, robots: list[RobotSpec], label: str, planner: str, timeout: float, options: dict,
            alone: AloneTimes) -> Row:
    row = Row(label, len(robots), planner)
    ctx = mp.get_context("fork")
    results = ctx.Queue()
    proc = ctx.Process(target=_child, args=(results, grid, robots, planner, options), daemon=True)
    proc.start()
    try:
        status, (row.wall_s, row.cpu_s), payload = results.get(timeout=timeout)
    except queue.Empty:
        status, payload = "timeout", f"> {timeout:g} s"
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join()
        results.close()
    if status != "ok":
        row.verdict, row.detail = status, str(payload)
        return row
    plan = payload
    base = [alone(r) for r in robots]
    arrivals = [p.arrival_time for p in plan.paths]
    row.soc_ratio = sum(arrivals) / sum(base)
    row.makespan_ratio = max(arrivals) / max(base)
    row.lns = plan.info.get("lns_iterations", plan.info.get("timed_lns_iterations"))
    violations = check_plan(grid, robots, plan)
    row.verdict = f"FAIL ({len(violations)})" if violations else "ok"
    row.detail = "; ".join(str(v) for v in violations[:5])
    return row


class FreeTimes(AloneTimes):
    """bench_md's no-interference arrivals, with the path finder's radius rounded down to 1 cm
    (one path finder per 1 cm class instead of one per robot; a smaller disc's path is no longer,
    so the bound only gets lower and the ratios above it no better)."""

    def __call__(self, r: RobotSpec) -> float:
        return super().__call__(replace(r, radius=math.floor(r.radius * 100 + 1e-9) / 100))


def _fmt(value, spec: str) -> str:
    return f"{'-':>{spec.split('.')[0].rstrip('df')}}" if value is None else format(value, spec)


def table(rows: list[Row]) -> str:
    w = max([3] + [len(r.map) for r in rows])
    head = f"{'map':<{w}} {'N':>5} {'planner':<7} {'wall s':>7} {'cpu s':>7} {'SoC/free':>8} {'mkspan/free':>11} " \
           f"{'LNS it':>6}  valid"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.map:<{w}} {r.n:>5} {r.planner:<7} {_fmt(r.wall_s, '7.2f')} {_fmt(r.cpu_s, '7.2f')} "
                     f"{_fmt(r.soc_ratio, '8.3f')} {_fmt(r.makespan_ratio, '11.3f')} {_fmt(r.lns, '6d')}  {r.verdict}")
    return "\n".join(lines)


def dense_options(args: argparse.Namespace) -> dict:
    """The dense solver's options from the command line (its time limit, and its LNS budgets where given)."""
    options: dict = {"time_limit": args.dense_timeout}
    if args.refine is not None:
        options["refine_s"] = args.refine
    if args.timed_refine is not None:
        options["timed_refine_s"] = args.timed_refine
    return options


def main(argv=None) -> int:
    from tqdm import tqdm

    tqdm.monitor_interval = 0   # no monitor thread: the planning runs are forked
    args = _args(argv)
    for name in args.planners:   # import every planner now, so that all runs use the same code
        get_planner(name)
    if "dense" in args.planners or "crowd" in args.planners:
        from fleet_planner.planners import crowd_kernels, crowd_sipp, crowd_st

        crowd_kernels.warm_up()  # compile once, before the children fork
        crowd_st.warm_up()
        crowd_sipp.warm_up()
    jobs = []
    for name, sizes in args.runs:
        if args.maps_dir.is_dir():
            grid, robots = instance(args.maps_dir, name, sizes[-1], args.seed)
        else:
            print(f"bench_dense: no maps directory {args.maps_dir}: a generated warehouse stands in for {name}",
                  file=sys.stderr)
            inst = generated_instance(sizes[-1], args.seed)
            grid, robots = inst.grid, inst.robots
        alone = FreeTimes(grid)
        jobs += [(name, grid, robots[:n], p, alone) for n in sizes for p in args.planners]
    rows: list[Row] = []
    with tqdm(jobs, unit="run", file=sys.stderr) as bar:
        for name, grid, robots, planner, alone in bar:
            bar.set_postfix_str(f"{name} N={len(robots)} {planner}")
            dense = planner in ("dense", "crowd")
            options = dense_options(args) if dense else {}
            row = run_one(grid, robots, name, planner, args.dense_timeout if dense else args.timeout, options, alone)
            rows.append(row)
            if row.verdict != "ok":
                bar.write(f"{name} N={len(robots)} {planner}: {row.verdict}: {row.detail.strip()[:300]}",
                          file=sys.stderr)
    print(table(rows))
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with args.csv.open("w", newline="") as f:
            out = csv.writer(f)
            out.writerow(list(Row.__dataclass_fields__))
            for r in rows:
                out.writerow([getattr(r, k) for k in Row.__dataclass_fields__])
    return 1 if any(r.verdict.startswith("FAIL") for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
