#!/usr/bin/env python3
"""Planning time and plan quality of the md planner against the number of robots (issue 2).

For each MovingAI warehouse map and each N, the first N usable start/goal pairs of the map's
``.scen`` file become robots (radius 0.35-0.45 m, top speed 0.7-1.0 m/s, drawn with --seed); each
planner plans them in a child process (killed after --timeout s) and the independent checker
validates every plan. Quality is measured against the no-interference bound: each robot's own
shortest path driven alone (the path finder without avoid discs, length / top speed).

Columns: planning time (s); sum of arrival times / sum of no-interference arrival times; makespan /
longest no-interference arrival time; re-orderings; collision regions (md); and the verdict:
``ok``, ``FAIL (k)`` (the plan breaks the contract: k violations, printed), ``no plan`` (the planner
refused, with a PlanningError), ``timeout`` or ``error``. Exit status 1 when any plan was invalid.
The notes say where md v2's plan came from: ``crowded: dense`` (handed to the dense solver before
planning, :mod:`fleet_planner.planners.md_crowd`), ``better: dense`` (both planned, the dense plan
had the lower sum of arrivals), ``md better than dense``, ``fallback: dense`` (md found no plan).

    .venv/bin/python bench/bench_md.py [--sizes 10,50,100,200,500] [--planners md,md-departure,md-box,prior]
        [--maps warehouse-10-20-10-2-1,...] [--maps-dir DIR] [--seed 0] [--timeout 600] [--time-limit S]
        [--csv out/bench_md.csv] [--plot out/bench_md.png]

    # issue 8's table: md (v2), the paper's method (md-departure) and PRIOR on warehouse-10-20-10-2-1,
    # -10-2-2 and warehouse-20-40-10-2-2 at 100, 200, 400, 500 robots (and 1000 on the two larger maps)
    nice .venv/bin/python bench/bench_md.py --suite issue8 --maps-dir ../shared/data/maps --cpu-limit 40 --timeout 600

Without the maps directory a generated warehouse (1 m cells, 1-cell aisles) with random start/goal
pairs stands in, and the output says so.
"""
from __future__ import annotations

import argparse
import csv
import math
import multiprocessing as mp
import queue
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from fleet_planner.checker import check_plan  # noqa: E402
from fleet_planner.grid import GridMap  # noqa: E402
from fleet_planner.model import PlanningError, RobotSpec  # noqa: E402
from fleet_planner.paths import PathFinder  # noqa: E402
from fleet_planner.planners import get_planner, planner_names  # noqa: E402
from fleet_planner.scenario import ScenarioError, scenario_from_movingai  # noqa: E402

RADIUS = (0.35, 0.45)
SPEED = (0.7, 1.0)

#: presets: maps, sizes, planners, and extra sizes on some maps only
SUITES = {
    "issue8": {"maps": ["warehouse-10-20-10-2-1", "warehouse-10-20-10-2-2", "warehouse-20-40-10-2-2"],
               "sizes": [100, 200, 400, 500], "planners": ["md", "md-departure", "prior"],
               "extra": {"warehouse-10-20-10-2-2": [1000], "warehouse-20-40-10-2-2": [1000]}},
}


@dataclass
class Instance:
    """One map with its robots for the largest N (smaller N take a prefix)."""

    name: str
    grid: GridMap
    robots: list[RobotSpec]


@dataclass
class Row:
    map: str
    n: int
    planner: str
    time_s: float | None = None
    cpu_s: float | None = None
    soc_ratio: float | None = None
    makespan_ratio: float | None = None
    reorders: int | None = None
    regions: int | None = None
    verdict: str = ""
    detail: str = ""
    #: md's priority search and fallback: e.g. "search 3", "fallback crowd"
    notes: str = ""


DEFAULT_MAPS = REPO.parent / "shared" / "data" / "maps"


def add_maps_dir(p: argparse.ArgumentParser) -> None:
    """``--maps-dir`` (shared with bench_dense): see :func:`maps_dir_of`."""
    p.add_argument("--maps-dir", type=Path, default=None,
                   help=f"MovingAI maps and .scen files (default: {DEFAULT_MAPS}; where that is missing, a "
                        "generated warehouse stands in)")


def maps_dir_of(p: argparse.ArgumentParser, args: argparse.Namespace) -> Path:
    """The maps directory: ``--maps-dir`` as given, which must exist (a mistyped path must not bench a
    generated warehouse instead, with only a line on stderr to say so), or the default (which may be
    missing: the benches then run on a generated warehouse, as the suite does without ../shared)."""
    if args.maps_dir is None:
        return DEFAULT_MAPS
    if not args.maps_dir.is_dir():
        p.error(f"--maps-dir: {args.maps_dir} is not a directory")
    return args.maps_dir


def _args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_maps_dir(p)
    p.add_argument("--maps", help="comma-separated map names (default: every warehouse-*.map in --maps-dir)")
    p.add_argument("--scen", default="random-1",
                   help="which .scen of each map: <map>-<SCEN>.scen (default: %(default)s)")
    p.add_argument("--sizes", default="10,50,100,200,500", help="numbers of robots (default: %(default)s)")
    p.add_argument("--planners", default="md,md-box", help=f"of {', '.join(planner_names())} (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="radii and speeds (default: %(default)s)")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds per planning run (default: %(default)s)")
    p.add_argument("--cpu-limit", type=float, dest="cpu_limit",
                   help="also stop a run after this many CPU seconds (a timeout; fair on a loaded machine)")
    p.add_argument("--time-limit", type=float, dest="time_limit",
                   help="md planners: seconds for the priority search before the dense fallback (default: md's own)")
    p.add_argument("--suite", choices=sorted(SUITES),
                   help="a preset of maps, sizes and planners (issue8: md v2, md-departure, prior on three "
                        "warehouses at 100-500 robots, 1000 on the two larger maps); --maps, --sizes, --planners "
                        "given as well override it")
    p.add_argument("--csv", type=Path, help="also write the table as CSV")
    p.add_argument("--plot", type=Path, help="also draw time and quality against N to this PNG")
    args = p.parse_args(argv)
    args.maps_dir = maps_dir_of(p, args)
    if args.suite:
        suite = SUITES[args.suite]
        given = set(argv if argv is not None else sys.argv[1:])
        args.extra = {}
        if "--sizes" not in given:   # the suite's sizes, with its extra sizes on some maps
            args.sizes = ",".join(str(n) for n in suite["sizes"])
            args.extra = suite["extra"]
        if "--planners" not in given:
            args.planners = ",".join(suite["planners"])
        if args.maps is None:
            args.maps = ",".join(suite["maps"])
    else:
        args.extra = {}
    if args.cpu_limit is not None and not (math.isfinite(args.cpu_limit) and args.cpu_limit > 0):
        p.error(f"--cpu-limit: must be a finite number of seconds > 0 (got {args.cpu_limit!r})")
    if args.time_limit is not None and not (math.isfinite(args.time_limit) and args.time_limit > 0):
        p.error(f"--time-limit: must be a finite number of seconds > 0 (got {args.time_limit!r})")
    try:
        args.sizes = sorted({int(s) for s in args.sizes.split(",") if s.strip()})
    except ValueError:
        p.error(f"--sizes: expected comma-separated integers, got {args.sizes!r}")
    if not args.sizes or args.sizes[0] < 1:
        p.error("--sizes: numbers of robots must be >= 1")
    args.planners = [s.strip() for s in args.planners.split(",") if s.strip()]
    unknown = [s for s in args.planners if s not in planner_names()]
    if unknown or not args.planners:
        p.error(f"--planners: unknown {unknown}; choose from {', '.join(planner_names())}")
    if not args.timeout > 0:
        p.error("--timeout: must be > 0")
    return args


# ---------------------------------------------------------------------------------------------
# instances
# ---------------------------------------------------------------------------------------------
def movingai_instances(maps_dir: Path, names: list[str] | None, scen: str, n: int, seed: int) -> list[Instance]:
    if names is None:
        names = sorted(p.stem for p in maps_dir.glob("warehouse-*.map"))
    out = []
    for name in names:
        map_path, scen_path = maps_dir / f"{name}.map", maps_dir / f"{name}-{scen}.scen"
        for path in (map_path, scen_path):
            if not path.is_file():
                sys.exit(f"bench_md: {path} not found (--maps / --scen)")
        try:
            sc = scenario_from_movingai(map_path, scen_path, n, seed, RADIUS, SPEED)
        except ScenarioError as exc:
            sys.exit(f"bench_md: {name}: {exc}")
        out.append(Instance(name, sc.grid, sc.robots))
    return out


def generated_instance(n: int, seed: int) -> Instance:
    """A MovingAI-like warehouse (1 m cells, 1-cell aisles) and random distinct start/goal cells."""
    from fleet_planner.warehouse import generate_warehouse

    grid = generate_warehouse(8, 12, 10, 2, 1, 1.0, "generated-warehouse").grid
    free = PathFinder(grid, RADIUS[1]).free
    rows, cols = np.nonzero(free)
    rng = np.random.default_rng(seed)
    if 2 * n > len(rows):
        sys.exit(f"bench_md: the generated warehouse has {len(rows)} free cells, {n} robots need {2 * n}")
    cells = rng.permutation(len(rows))
    starts, goals = cells[:n], cells[n:2 * n]
    robots = [RobotSpec(f"r{i}", float(rng.uniform(*RADIUS)), float(rng.uniform(*SPEED)),
                        grid.centre(int(cols[s]), int(rows[s])), grid.centre(int(cols[g]), int(rows[g])))
              for i, (s, g) in enumerate(zip(starts, goals))]
    return Instance(grid.name, grid, robots)


class AloneTimes:
    """Each robot's arrival time driven alone: shortest path without avoid discs / top speed."""

    def __init__(self, grid: GridMap):
        self.grid = grid
        self._finders: dict[float, PathFinder] = {}
        self._cache: dict[tuple, float] = {}

    def __call__(self, r: RobotSpec) -> float:
        key = (r.start, r.goal, r.radius, r.max_speed)
        if key not in self._cache:
            pf = self._finders.get(r.radius) or self._finders.setdefault(r.radius, PathFinder(self.grid, r.radius))
            path = pf.find(r.start, r.goal)
            self._cache[key] = math.inf if path is None else \
                float(np.sum(np.hypot(*np.diff(path, axis=0).T))) / r.max_speed
        return self._cache[key]


# ---------------------------------------------------------------------------------------------
# one planning run, in a child process
# ---------------------------------------------------------------------------------------------
def _planner(name: str, time_limit: float | None):
    """The planner ``name``, with the search budget where it takes one (the md variants that search)."""
    planner = get_planner(name)
    if time_limit is not None and getattr(planner, "search", False):
        planner = get_planner(name, time_limit=time_limit)
    return planner


def _child(results, grid: GridMap, robots: list[RobotSpec], name: str, time_limit: float | None = None,
           cpu_limit: float | None = None) -> None:
    if cpu_limit is not None:   # on a loaded machine wall time says little: bound the CPU time
        import resource

        resource.setrlimit(resource.RLIMIT_CPU, (math.ceil(cpu_limit), math.ceil(cpu_limit) + 1))
    try:
        grid = GridMap(grid.blocked.copy(), grid.resolution, grid.name)   # no caches of earlier runs
        planner = _planner(name, time_limit)
        for p in (planner, get_planner("dense")):   # (md may hand over to the dense solver)
            p.warm_up()   # compiled kernels, numba's cache loaded once per process: not planning
        t0, c0 = time.perf_counter(), time.process_time()
        plan = planner.plan(grid, robots)
        elapsed = time.perf_counter() - t0
        plan.network = None   # large and not needed here
        plan.info["cpu_s"] = time.process_time() - c0
        results.put(("ok", elapsed, plan))
    except PlanningError as exc:
        results.put(("no plan", time.perf_counter() - t0, str(exc).splitlines()[1].strip()))
    except Exception:  # noqa: BLE001 - a crash of the planner is a result to report, not to hide
        results.put(("error", None, traceback.format_exc(limit=3)))


def run_one(inst: Instance, n: int, planner: str, timeout: float, alone: AloneTimes,
            time_limit: float | None = None, cpu_limit: float | None = None) -> Row:
    robots = inst.robots[:n]
    row = Row(inst.name, n, planner)
    ctx = mp.get_context("fork")
    results = ctx.Queue()
    proc = ctx.Process(target=_child, args=(results, inst.grid, robots, planner, time_limit, cpu_limit), daemon=True)
    proc.start()
    stop = time.perf_counter() + timeout
    try:
        while True:
            try:
                status, elapsed, payload = results.get(timeout=min(1.0, max(stop - time.perf_counter(), 0.01)))
                break
            except queue.Empty:
                if time.perf_counter() >= stop:
                    status, elapsed, payload = "timeout", None, f"> {timeout:g} s"
                    break
                if not proc.is_alive():   # killed at its CPU limit (or crashed without a word)
                    status, elapsed, payload = "timeout", None, f"> {cpu_limit:g} s CPU" if cpu_limit else "died"
                    break
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join()
        results.close()
    row.time_s = elapsed
    if status != "ok":
        row.verdict, row.detail = status, str(payload)
        return row
    plan = payload
    base = [alone(r) for r in robots]
    arrivals = {p.robot_id: p.arrival_time for p in plan.paths}
    row.soc_ratio = sum(arrivals.values()) / sum(base)
    row.makespan_ratio = max(arrivals.values()) / max(base)
    row.reorders = plan.info.get("reorders")
    row.regions = plan.info.get("regions")
    row.cpu_s = plan.info.get("cpu_s")
    notes = []
    if "fallback" in plan.info:   # md v2 handed over (crowded), found the dense plan better, or failed
        why = str(plan.info.get("why", ""))
        how = "crowded" if why.startswith("crowded") else "better" if "is lower" in why else "fallback"
        notes.append(f"{how}: {plan.info['fallback']}")
    if isinstance(plan.info.get("compared"), dict):
        notes.append("md better than " + ", ".join(plan.info["compared"]))
    if isinstance(plan.info.get("search"), dict):
        notes.append(f"search {plan.info['search'].get('attempts')}")
    if plan.info.get("detours"):
        notes.append(f"detours {plan.info['detours']}")
    if plan.info.get("improved"):   # moves of md's improvement search over priorities that stayed
        notes.append(f"improved {plan.info['improved']}")
    row.notes = ", ".join(notes)
    violations = check_plan(inst.grid, robots, plan)
    if violations:
        row.verdict = f"FAIL ({len(violations)})"
        row.detail = "; ".join(str(v) for v in violations[:5])
    else:
        row.verdict = "ok"
    return row


# ---------------------------------------------------------------------------------------------
# output
# ---------------------------------------------------------------------------------------------
def _fmt(value, spec: str) -> str:
    """``value`` formatted by ``spec`` (e.g. "8.2f"), or a dash as wide."""
    return f"{'-':>{spec.split('.')[0].rstrip('df')}}" if value is None else format(value, spec)


def table(rows: list[Row]) -> str:
    w = max([3] + [len(r.map) for r in rows])
    pw = max([7] + [len(r.planner) for r in rows])
    head = f"{'map':<{w}} {'N':>4} {'planner':<{pw}} {'time s':>8} {'cpu s':>8} {'SoC/free':>8} {'mkspan/free':>11} " \
           f"{'reorders':>8} {'regions':>8}  valid   notes"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.map:<{w}} {r.n:>4} {r.planner:<{pw}} {_fmt(r.time_s, '8.2f')} {_fmt(r.cpu_s, '8.2f')} "
                     f"{_fmt(r.soc_ratio, '8.3f')} {_fmt(r.makespan_ratio, '11.3f')} {_fmt(r.reorders, '8d')} "
                     f"{_fmt(r.regions, '8d')}  {r.verdict:<7} {r.notes}")
    return "\n".join(lines)


def write_csv(rows: list[Row], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["map", "n", "planner", "time_s", "cpu_s", "soc_ratio", "makespan_ratio", "reorders",
                      "regions", "verdict", "notes", "detail"])
        for r in rows:
            out.writerow([r.map, r.n, r.planner, r.time_s, r.cpu_s, r.soc_ratio, r.makespan_ratio, r.reorders,
                          r.regions, r.verdict, r.notes, r.detail])


def plot(rows: list[Row], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_t, ax_q) = plt.subplots(1, 2, figsize=(12, 4.5))
    for (m, planner) in dict.fromkeys((r.map, r.planner) for r in rows):
        mine = [r for r in rows if r.map == m and r.planner == planner and r.verdict == "ok"]
        if not mine:
            continue
        ns = [r.n for r in mine]
        line, = ax_t.plot(ns, [r.time_s for r in mine], "o-", label=f"{m} {planner}")
        ax_q.plot(ns, [r.soc_ratio for r in mine], "o-", color=line.get_color(), label=f"{m} {planner}")
    ax_t.set(xlabel="robots", ylabel="planning time (s)", yscale="log", title="planning time")
    ax_q.set(xlabel="robots", ylabel="sum of arrivals / no-interference", title="plan quality")
    ax_q.axhline(1.0, color="grey", lw=0.5)
    for ax in (ax_t, ax_q):
        ax.grid(alpha=0.3)
    ax_q.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    from tqdm import tqdm

    tqdm.monitor_interval = 0   # no monitor thread: the planning runs are forked
    args = _args(argv)
    extra = {m: [n for n in ns if n not in args.sizes] for m, ns in args.extra.items()}
    if not args.maps_dir.is_dir():
        extra = {}
    n_max = max([args.sizes[-1]] + [n for ns in extra.values() for n in ns])
    if args.maps_dir.is_dir():
        names = [s.strip() for s in args.maps.split(",")] if args.maps else None
        instances = movingai_instances(args.maps_dir, names, args.scen, n_max, args.seed)
    else:
        print(f"bench_md: no maps directory {args.maps_dir}: using a generated warehouse with random "
              f"start/goal pairs instead of MovingAI maps", file=sys.stderr)
        instances = [generated_instance(n_max, args.seed)]
    # import and run every planner once now (and the dense solver md v2 compares with) on a small
    # generated warehouse: imports and numba's cache loads happen once per process, as in a running
    # planner node, so no run pays for them; each run then plans on a fresh copy of its map, so its
    # map set-up (inflated masks, move graphs) is timed
    warm = generated_instance(20, args.seed)
    for name in list(args.planners) + (["dense"] if "dense" in planner_names() else []):
        try:
            _planner(name, args.time_limit).plan(warm.grid, warm.robots)
        except PlanningError:
            pass
    rows: list[Row] = []
    jobs = [(inst, n, p) for inst in instances for n in sorted(args.sizes + extra.get(inst.name, []))
            for p in args.planners]
    alone = {inst.name: AloneTimes(inst.grid) for inst in instances}
    with tqdm(jobs, unit="run", file=sys.stderr) as bar:
        for inst, n, planner in bar:
            bar.set_postfix_str(f"{inst.name} N={n} {planner}")
            row = run_one(inst, n, planner, args.timeout, alone[inst.name], args.time_limit, args.cpu_limit)
            rows.append(row)
            if args.csv:   # as it goes, so that a long run killed half way keeps what it measured
                write_csv(rows, args.csv)
            if row.verdict.startswith("FAIL"):
                bar.write(f"!!! FAIL: invalid plan on {inst.name} N={n} planner={planner} seed={args.seed}: "
                          f"{row.detail}", file=sys.stderr)
            elif row.verdict != "ok":
                bar.write(f"{inst.name} N={n} {planner}: {row.verdict}: {row.detail.strip()}", file=sys.stderr)
    print(table(rows))
    if args.csv:
        write_csv(rows, args.csv)
    if args.plot:
        plot(rows, args.plot)
    invalid = [r for r in rows if r.verdict.startswith("FAIL")]
    if invalid:
        print(f"\n!!! {len(invalid)} INVALID PLAN(S) (seed {args.seed}):", file=sys.stderr)
        for r in invalid:
            print(f"!!!   {r.map} N={r.n} {r.planner}: {r.detail}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
