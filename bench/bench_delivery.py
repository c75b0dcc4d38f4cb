#!/usr/bin/env python3
"""Delivery benchmark: md, prior and behavior on the same deliveries.

In the style of section V of Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance":
N robots (0.5 m x 0.5 m, a disc of radius 0.354 m, top speed 0.8 m/s) serve one seeded sequence of
#Del = N x --deliveries-per-robot deliveries: drive to station k, dock (--dock s), drive to station
l, dock; each robot takes the next delivery when it has finished one. Simulated faster than real time by
:func:`fleet_planner.delivery.simulate`; see that package for the methods and the station discipline.

Maps: ``warehouse`` (the default warehouse of config/: load at chutes, unload at storing sites),
``large`` (a generated 74 m x 31.5 m warehouse whose rack aisles fit one robot only; it parks about
100 robots at most), ``large2x`` (the same rack blocks twice across, 146 m x 31.5 m, 22 chutes: room
for 200 robots, the stress run of issue 13), and MovingAI
maps from --maps-dir by name (--stations stations spread over the free space, seeded).

Columns: CTime (s, completion of the last delivery; with a ``!`` when the run stopped unfinished,
then it is the stop time), the lower bound (each robot's own deliveries driven alone, maximum
over robots) and CTime / bound, average velocity over robots (m/s), planning time per planned leg
(md, prior) or decision time per fleet step of --dt (behavior) in ms, overlapping disc pairs
(exact, must be 0), robots left deadlocked (no progress for 120 s at the end), why the run stopped
and its wall time. Exit status 1 when any run had a collision (or an invalid trajectory).

One seed is one problem, and a run hands its deliveries out in its own order: one row's CTime (and its
bound, which depends on who drove what) moves by some 10% from seed to seed and with any small rule
change. ``--seeds 0-4`` (or ``0,2,5``; instead of ``--seed``) runs every row once per seed (the same
problem for every method within a seed; a seed column in the table and the CSV) and adds a summary per
map, N and method: mean and min-max of CTime and of CTime / bound (each run over its own bound), mean
avg. v, totals of deliveries done, collisions, deadlocks and unfinished runs; and per map and N where md
and PRIOR both ran, on how many seeds md finished sooner and the mean of md's CTime / PRIOR's. With
several seeds ``--paper002`` prints the means per row and ``--plot`` draws the mean CTime with min-max
bars; ``--from-csv`` summarises the seeds of the rows it reads (CSVs without a seed column: seed 0).

    .venv/bin/python bench/bench_delivery.py [--quick] [--maps warehouse,large,warehouse-10-20-10-2-1]
        [--sizes 20,40,50,100] [--methods md,prior,behavior] [--deliveries-per-robot 3] [--seed 0 | --seeds 0-4]
        [--csv out/bench_delivery.csv] [--plot out/bench_delivery.png] [--lanes config/lanes_warehouse.yaml]
    .venv/bin/python bench/bench_delivery.py --paper002     # paper 002's Tables I-III: ARMO, PRIOR, BBMRCA, md
    .venv/bin/python bench/bench_delivery.py --paper002 --from-csv out/rows/*.csv   # one table of several runs
    .venv/bin/python bench/bench_delivery.py --maps warehouse --sizes 20,50 --methods md,prior --seeds 0-4
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from fleet_planner import budget  # noqa: E402
from fleet_planner.delivery import (  # noqa: E402
    DEFAULT_QUEUE,
    METHODS,
    QUEUE_RULES,
    DeliveryProblem,
    DeliveryResult,
    delivery_problem,
    simulate,
    spread_stations,
    warehouse_problem,
)
from fleet_planner.grid import GridMap  # noqa: E402
from fleet_planner.warehouse import generate_warehouse, load_warehouse  # noqa: E402

BUILTIN_MAPS = ("warehouse", "large", "large2x")
QUICK = {"maps": "warehouse", "sizes": "20", "methods": "md,prior,behavior", "per_robot": 2}
#: paper 002's comparison: the open default warehouse, `large` (long one-robot rack aisles) and the
#: confined MovingAI warehouse, with its three methods and ours
PAPER002 = {"maps": "warehouse,large,warehouse-10-20-10-2-1", "sizes": "20,50,100",
            "methods": "armo,prior,behavior,md"}
#: the paper's names of the methods
PAPER_NAMES = {"armo": "ARMO", "prior": "PRIOR", "behavior": "BBMRCA", "md": "md"}


@dataclass
class Row:
    map: str
    n: int
    method: str
    deliveries: int
    completed: int
    ctime: float
    lower_bound: float
    avg_velocity: float
    decision_ms: float
    decision_unit: str
    collisions: int
    deadlocks: int
    stop: str
    wall_s: float
    failed_plans: int
    min_gap: float
    violations: int      # central: other breaches of the plan contract on the driven trajectories
    precompute_s: float = 0.0   # armo: wall time of the road map's program
    cpu_s: float = 0.0          # CPU seconds of the run (this process)
    backstops: int = 0          # central: leg budgets that ran out on their wall-clock backstop (load-dependent)
    budgets_out: int = 0        # central: planning budgets that ran out (CPU or backstop)
    queue: str = DEFAULT_QUEUE  # central methods: the queue rule (QUEUE_RULES)
    seed: int = 0               # the problem's seed (CSVs written before it had one: 0)


def parse_seeds(text: str) -> list[int]:
    """The seeds of ``--seeds``: comma-separated integers >= 0 and ranges ``A-B`` (both included), e.g.
    ``0-4`` or ``0,2,5``, in the order given, each once (ValueError on anything else)."""
    seeds: list[int] = []
    for item in text.split(","):
        item = item.strip()
        first, dash, last = item.partition("-")
        if not first.strip().isdigit() or (dash and not last.strip().isdigit()):
            raise ValueError(f"expected comma-separated seeds >= 0 or ranges A-B, got {text!r}")
        a, b = int(first), int(last) if dash else int(first)
        if b < a:
            raise ValueError(f"range {item!r} runs backwards")
        seeds += [k for k in range(a, b + 1) if k not in seeds]
    return seeds


def planner_options(p: argparse.ArgumentParser, items: list[str]) -> dict:
    """The planner options of repeated ``--option KEY=VALUE`` arguments: true / false, numbers, else
    the text (the parser's error for an item without ``=``)."""
    options: dict = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            p.error(f"--option: expected KEY=VALUE (got {item!r})")
        low = value.lower()
        options[key] = True if low == "true" else False if low == "false" else float(value) \
            if value.replace(".", "", 1).isdigit() else value
    return options


def _args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true",
                   help=f"a small subset, under 2 minutes: {QUICK['maps']}, N={QUICK['sizes']}, "
                        f"{QUICK['per_robot']} deliveries per robot, {QUICK['methods']} (options given win)")
    p.add_argument("--maps", default=None,
                   help="comma-separated: warehouse, large, or MovingAI map names in --maps-dir "
                        "(default: warehouse,large,warehouse-10-20-10-2-1 - the last if --maps-dir exists)")
    p.add_argument("--maps-dir", type=Path, default=REPO.parent / "shared" / "data" / "maps",
                   help="MovingAI maps (default: %(default)s)")
    p.add_argument("--sizes", default="20,40,50,100", help="numbers of robots (default: %(default)s)")
    p.add_argument("--methods", default="md,prior,behavior", help=f"of {', '.join(METHODS)} (default: %(default)s)")
    p.add_argument("--deliveries-per-robot", dest="per_robot", type=int, default=3,
                   help="#Del = N x this (default: %(default)s; Sun, Kleiner & Nebel: 2.5-10)")
    p.add_argument("--stations", type=int, default=8, help="stations on a MovingAI map (default: %(default)s)")
    p.add_argument("--dock", type=float, default=5.0, help="docking time at a station, s (default: %(default)s)")
    p.add_argument("--dt", type=float, default=0.1, help="behavior time step, s (default: %(default)s)")
    p.add_argument("--cap", type=float, default=4 * 3600.0, help="simulated-time cap per run, s (default: 4 h)")
    p.add_argument("--wall-cap", type=float, default=900.0, help="wall-clock cap per run, s (default: %(default)s)")
    seeds = p.add_mutually_exclusive_group()
    seeds.add_argument("--seed", type=int, default=0, help="deliveries, homes, stations (default: %(default)s)")
    seeds.add_argument("--seeds", default=None, metavar="SEEDS",
                       help="run every row once per seed (e.g. 0-4 or 0,2,5; each seed its own problem, the same "
                            "for every method) and add a summary over the seeds: mean and min-max of CTime and of "
                            "CTime / bound per map, N and method, and md against PRIOR seed by seed")
    p.add_argument("--csv", type=Path, help="also write the table as CSV")
    p.add_argument("--plot", type=Path, help="also draw CTime per method and N to this PNG")
    p.add_argument("--paper002", action="store_true",
                   help="paper 002's comparison (its Tables I-III): ARMO, PRIOR, BBMRCA and md on "
                        f"{PAPER002['maps']} at N={PAPER002['sizes']}, printed in the paper's layout "
                        "(options given win; --plot defaults to out/paper002.png)")
    p.add_argument("--queue", default=DEFAULT_QUEUE,
                   help="comma-separated queue rules of the central methods, each run in turn: spots (wait for a "
                        "station on parking spots near it, session 25's rule), near (on queue places a few metres "
                        "from it, moving up; ours), close (near's, with the busy stations' places in the room next "
                        "to them, placed before the other parking spots; ours) or auto (close where every busy "
                        "loading station gets enough places, else spots; ours; the queue column names the rule "
                        "chosen) (default: %(default)s)")
    p.add_argument("--backstop", type=float, default=math.inf,
                   help="md's leg budgets are CPU seconds; they also stop after this many times their seconds of wall "
                        "time (the planners' default 10: a starved run then plans less, and its CTime depends on the "
                        "load; default here: %(default)s, never); column 'bk' counts the budgets it stopped")
    p.add_argument("--lanes", type=Path, default=None,
                   help="a lanes file (config/lanes_*.yaml): every method plans along its road map")
    p.add_argument("--from-csv", nargs="+", type=Path, default=None, metavar="CSV",
                   help="run nothing: the table (and --csv, --plot) of the rows in these CSVs (written by --csv, "
                        "e.g. by several processes), ordered by --maps, N and --methods")
    args = p.parse_args(argv)
    if args.seeds is None:
        args.seeds = [args.seed]
    else:
        try:
            args.seeds = parse_seeds(args.seeds)
        except ValueError as exc:
            p.error(f"--seeds: {exc}")
    if args.paper002:
        args.maps = args.maps or PAPER002["maps"]
        for name in ("sizes", "methods"):
            if getattr(args, name) == p.get_default(name):
                setattr(args, name, PAPER002[name])
        args.plot = args.plot or REPO / "out" / "paper002.png"
    if args.quick:   # what the command line leaves at its default
        args.maps = args.maps or QUICK["maps"]
        for name in ("sizes", "methods", "per_robot"):
            if getattr(args, name) == p.get_default(name):
                setattr(args, name, QUICK[name])
    if args.maps is None:
        args.maps = "warehouse,large" + (",warehouse-10-20-10-2-1" if args.maps_dir.is_dir() else "")
    args.maps = [m.strip() for m in args.maps.split(",") if m.strip()]
    try:
        args.sizes = sorted({int(s) for s in args.sizes.split(",") if s.strip()})
    except ValueError:
        p.error(f"--sizes: expected comma-separated integers, got {args.sizes!r}")
    if not args.sizes or args.sizes[0] < 1:
        p.error("--sizes: numbers of robots must be >= 1")
    args.methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in args.methods if m not in METHODS]
    if unknown or not args.methods:
        p.error(f"--methods: unknown {unknown}; choose from {', '.join(METHODS)}")
    args.queue = [q.strip() for q in args.queue.split(",") if q.strip()]
    if not args.queue or any(q not in QUEUE_RULES for q in args.queue):
        p.error(f"--queue: expected comma-separated rules of {', '.join(QUEUE_RULES)} (got {args.queue})")
    if not args.backstop >= 1:
        p.error("--backstop: must be >= 1")
    if args.per_robot < 1:
        p.error("--deliveries-per-robot: must be >= 1")
    if args.stations < 2:
        p.error("--stations: must be >= 2")
    for name in ("dock", "dt", "cap", "wall_cap"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value >= (0 if name == "dock" else 1e-9)):
            p.error(f"--{name.replace('_', '-')}: must be a finite number {'>= 0' if name == 'dock' else '> 0'}")
    for m in args.maps if args.from_csv is None else ():   # (rows from CSVs load no map)
        if m not in BUILTIN_MAPS and not (args.maps_dir / f"{m}.map").is_file():
            p.error(f"--maps: {m!r} is neither {' nor '.join(BUILTIN_MAPS)} nor a map in {args.maps_dir}")
    return args


def make_problem(name: str, n: int, args: argparse.Namespace, seed: int | None = None) -> DeliveryProblem:
    """The problem of map ``name`` with ``n`` robots for ``seed`` (default: ``args.seed``)."""
    deliveries = n * args.per_robot
    seed = args.seed if seed is None else seed
    common = {"dock_s": args.dock}
    if name == "warehouse":
        return warehouse_problem(load_warehouse(), n, deliveries, seed, **common)
    if name in ("large", "large2x"):
        blocks_x = 5 if name == "large" else 10
        return warehouse_problem(generate_warehouse(blocks_x, 10, 24, 2, 3, 0.5, name), n, deliveries, seed,
                                 **common)
    grid = GridMap.from_movingai(args.maps_dir / f"{name}.map")
    stations = spread_stations(grid, args.stations, seed)
    return delivery_problem(grid, stations, n, deliveries, seed, name=name, **common)


def to_row(name: str, res: DeliveryResult) -> Row:
    return Row(name, res.n_robots, res.method, res.n_deliveries, res.completed, res.ctime, res.lower_bound,
               res.avg_velocity, 1000 * res.decision_s, res.decision_unit, res.collisions, res.deadlocks, res.stop,
               res.wall_s, res.failed_plans, res.min_gap, len(res.violations))


def several_seeds(rows: list[Row]) -> bool:
    return len({r.seed for r in rows}) > 1


def table(rows: list[Row]) -> str:
    """One line per run (with a seed column when the rows have several seeds)."""
    w = max([3] + [len(r.map) for r in rows])
    seeds = several_seeds(rows)
    head = (f"{'map':<{w}} {'N':>4} " + (f"{'seed':>4} " if seeds else "") +
            f"{'method':<8} {'#Del':>5} {'done':>5} {'CTime':>9} {'bound':>7} "
            f"{'ratio':>6} {'avg v':>6} {'plan ms':>12} {'coll':>4} {'dead':>4} {'stop':<5} {'wall s':>7} "
            f"{'CPU s':>7} {'out':>4} {'bk':>3} queue")
    lines = [head, "-" * len(head)]
    for r in rows:
        mark = " " if r.stop == "done" else "!"
        lines.append(f"{r.map:<{w}} {r.n:>4} " + (f"{r.seed:>4} " if seeds else "") +
                     f"{r.method:<8} {r.deliveries:>5} {r.completed:>5} {r.ctime:>8.0f}{mark} "
                     f"{r.lower_bound:>7.0f} {r.ctime / r.lower_bound:>6.2f} {r.avg_velocity:>6.3f} "
                     f"{r.decision_ms:>7.2f}/{r.decision_unit:<4} {r.collisions:>4} {r.deadlocks:>4} {r.stop:<5} "
                     f"{r.wall_s:>7.1f} {r.cpu_s:>7.1f} {r.budgets_out:>4} {r.backstops:>3} {r.queue}")
    lines.append("")
    lines.append("CTime with '!': the run stopped unfinished (stop: cap = simulated-time cap, stall = nothing "
                 "moved for 600 s, wall = wall-clock cap) and CTime is the stop time.")
    lines.append("CPU s: the run's CPU seconds; out: planning budgets that ran out; bk: of them, stopped by their "
                 "wall-clock backstop (--backstop); "
                 "queue: the central methods' queue rule (--queue).")
    lines.append("plan ms: wall time per planned leg (md, prior: central, one call of plan_incremental) or per "
                 "fleet step of dt (behavior: every robot's decisions and motion).")
    return "\n".join(lines)


def _rule(r: Row) -> str:
    """The queue rule the run was asked for (``auto``, not the rule auto chose)."""
    return r.queue.partition(":")[0]


@dataclass
class Summary:
    """One (map, N, method, queue rule) over its seeds."""
    map: str
    n: int
    method: str
    queue: str              # the rule asked for; auto: with the rules it chose over the seeds (e.g. auto:close/spots)
    seeds: list[int]
    deliveries: int         # per run
    ctime_mean: float
    ctime_min: float
    ctime_max: float
    ratio_mean: float       # CTime / bound, the mean of the runs' ratios (each run over its own bound)
    ratio_min: float
    ratio_max: float
    v_mean: float
    completed: int          # totals over the seeds
    collisions: int
    deadlocks: int
    unfinished: int         # runs that stopped unfinished (their CTime is the stop time)
    precompute_mean: float


def summarise(rows: list[Row]) -> list[Summary]:
    """Per (map, N, method, queue rule) of the rows, in the order they first come: mean and min-max of CTime
    and of CTime / bound, mean avg. v, and totals of deliveries done, collisions, deadlocks and unfinished runs."""
    groups: dict[tuple, list[Row]] = {}
    for r in rows:
        groups.setdefault((r.map, r.n, r.method, _rule(r)), []).append(r)
    out = []
    for (m, n, method, rule), rs in groups.items():
        ctimes = [r.ctime for r in rs]
        ratios = [r.ctime / r.lower_bound for r in rs]
        chosen = sorted({r.queue.partition(":")[2] for r in rs} - {""})
        out.append(Summary(
            m, n, method, rule + (":" + "/".join(chosen) if chosen else ""), [r.seed for r in rs],
            rs[0].deliveries, sum(ctimes) / len(rs), min(ctimes), max(ctimes), sum(ratios) / len(rs), min(ratios),
            max(ratios), sum(r.avg_velocity for r in rs) / len(rs), sum(r.completed for r in rs),
            sum(r.collisions for r in rs), sum(r.deadlocks for r in rs), sum(r.stop != "done" for r in rs),
            sum(r.precompute_s for r in rs) / len(rs)))
    return out


@dataclass
class Paired:
    """md against PRIOR on one (map, N, queue rule), seed by seed (the same problem within a seed)."""
    map: str
    n: int
    queue: str
    seeds: list[int]        # the seeds both ran
    md_sooner: int          # seeds where md's CTime < PRIOR's
    ties: int
    ratios: list[float]     # md's CTime / PRIOR's, per seed

    @property
    def ratio_mean(self) -> float:
        return sum(self.ratios) / len(self.ratios)


def paired(rows: list[Row]) -> list[Paired]:
    """md against PRIOR per (map, N, queue rule) where both ran on at least one common seed."""
    by: dict[tuple, dict[str, dict[int, Row]]] = {}
    for r in rows:
        if r.method in ("md", "prior"):
            by.setdefault((r.map, r.n, _rule(r)), {}).setdefault(r.method, {})[r.seed] = r
    out = []
    for (m, n, rule), runs in by.items():
        md, prior = runs.get("md", {}), runs.get("prior", {})
        seeds = [s for s in md if s in prior]
        if seeds:
            out.append(Paired(m, n, rule, seeds, sum(md[s].ctime < prior[s].ctime for s in seeds),
                              sum(md[s].ctime == prior[s].ctime for s in seeds),
                              [md[s].ctime / prior[s].ctime for s in seeds]))
    return out


def summary_table(rows: list[Row]) -> str:
    """Per map, N and method over the seeds of the rows; then md against PRIOR seed by seed."""
    sums = summarise(rows)
    w = max([3] + [len(s.map) for s in sums])
    head = (f"{'map':<{w}} {'N':>4} {'method':<8} {'seeds':>5} {'CTime':>8} {'min-max':>11} {'ratio':>6} "
            f"{'min-max':>11} {'avg v':>6} {'done':>11} {'coll':>4} {'dead':>4} {'unf':>3} queue")
    lines = [head, "-" * len(head)]
    for s in sums:
        mark = " " if not s.unfinished else "!"
        lines.append(f"{s.map:<{w}} {s.n:>4} {s.method:<8} {len(s.seeds):>5} {s.ctime_mean:>7.0f}{mark} "
                     f"{f'{s.ctime_min:.0f}-{s.ctime_max:.0f}':>11} {s.ratio_mean:>6.2f} "
                     f"{f'{s.ratio_min:.2f}-{s.ratio_max:.2f}':>11} {s.v_mean:>6.3f} "
                     f"{f'{s.completed}/{s.deliveries * len(s.seeds)}':>11} {s.collisions:>4} {s.deadlocks:>4} "
                     f"{s.unfinished:>3} {s.queue}")
    pairs = paired(rows)
    if pairs:
        lines.append("")
    for c in pairs:
        ties = f" ({c.ties} tied)" if c.ties else ""
        lines.append(f"{c.map} N={c.n}" + ("" if c.queue == DEFAULT_QUEUE else f" queue={c.queue}") +
                     f": md sooner than PRIOR on {c.md_sooner} of {len(c.seeds)} seeds{ties}; md/PRIOR CTime "
                     f"mean {c.ratio_mean:.3f} (min-max {min(c.ratios):.3f}-{max(c.ratios):.3f})")
    lines.append("")
    lines.append("Over the seeds: CTime mean (with '!' when any run stopped unfinished: then its stop time counts) "
                 "and min-max; ratio: the mean of the runs' CTime / bound (each run over its own bound) and "
                 "min-max; avg v: mean; done (of #Del x seeds), coll, dead, unf (unfinished runs): totals.")
    if pairs:
        lines.append("md against PRIOR on the same problem (seed by seed): the seeds where md's CTime is below "
                     "PRIOR's, and the mean of md's CTime / PRIOR's.")
    return "\n".join(lines)


def paper_table(rows: list[Row]) -> str:
    """The rows in the layout of paper 002's Tables I-III: per map, #R, M, #Del., avg. v, CTime
    (and, ours, how many were done, collisions, robots deadlocked, ARMO's pre-computation). Rows of several
    seeds: one line per map, N and method with the means of avg. v and CTime over the seeds."""
    sums = summarise(rows)
    several = several_seeds(rows)
    seeds = sorted({r.seed for r in rows})
    out = []
    for m in dict.fromkeys(s.map for s in sums):
        out.append(f"{m}")
        out.append(f"{'#R':>4}  {'M':<7} {'#Del.':>6} {'avg. v (m/s)':>13} {'CTime (s)':>10}   "
                   f"{'done':>5} {'coll':>4} {'dead':>4} {'pre s':>6}" + (f" {'seeds':>5}" if several else ""))
        for n in sorted({s.n for s in sums if s.map == m}):
            for k, s in enumerate(s for s in sums if s.map == m and s.n == n):
                ctime = f"{s.ctime_mean:.0f}" + ("" if not s.unfinished else "!")
                pre = f"{s.precompute_mean:.0f}" if s.method == "armo" else ""
                out.append(f"{n if k == 0 else '':>4}  {PAPER_NAMES.get(s.method, s.method):<7} {s.deliveries:>6} "
                           f"{s.v_mean:>13.2f} {ctime:>10}   {s.completed:>5} {s.collisions:>4} "
                           f"{s.deadlocks:>4} {pre:>6}" + (f" {len(s.seeds):>5}" if several else ""))
        out.append("")
    if not several:
        out.append("CTime with '!': unfinished (the stop time). pre s: wall time of ARMO's road map program "
                   "(loaded machine). ARMO = robots planning along ARMO's road map, kept apart by the behaviours.")
        return "\n".join(out)
    out.append(f"avg. v and CTime: means over the seeds {_seed_text(seeds)} ({len(seeds)} problems, the same for every "
               "method within a seed); done, coll, dead: totals over the seeds (#Del. per seed); pre s: mean. "
               "CTime with '!': some run unfinished (its stop time counted). ARMO = robots planning along ARMO's "
               "road map, kept apart by the behaviours.")
    return "\n".join(out)


def _seed_text(seeds: list[int]) -> str:
    """``0-4`` for consecutive seeds, else ``0,2,5``."""
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}-{seeds[-1]}"
    return ",".join(map(str, seeds))


def write_csv(rows: list[Row], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as f:
        out = csv.DictWriter(f, fieldnames=list(asdict(rows[0])))
        out.writeheader()
        for r in rows:
            out.writerow(asdict(r))


def read_csv(path: Path) -> list[Row]:
    """The rows of a CSV written by :func:`write_csv` (columns not in :class:`Row` ignored)."""
    kinds = {f.name: {"int": int, "float": float}.get(str(f.type), str) for f in fields(Row)}
    with path.open(newline="") as f:
        return [Row(**{k: kinds[k](v) for k, v in rec.items() if k in kinds}) for rec in csv.DictReader(f)]


def ordered(rows: list[Row], maps: list[str], methods: list[str]) -> list[Row]:
    """The rows by map (in the order of ``maps``, then others as they come), N, seed and method (likewise)."""
    def rank(order: list[str], key: str) -> int:
        return order.index(key) if key in order else len(order)

    return sorted(rows, key=lambda r: (rank(maps, r.map), r.n, r.seed, rank(methods, r.method)))


def plot(rows: list[Row], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    maps = list(dict.fromkeys(r.map for r in rows))
    fig, axes = plt.subplots(1, len(maps), figsize=(5 * len(maps), 4.2), squeeze=False)
    if several_seeds(rows):
        _plot_means(rows, maps, axes[0])
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=120)
        return
    for ax, m in zip(axes[0], maps):
        for method in dict.fromkeys(r.method for r in rows):
            mine = sorted((r for r in rows if r.map == m and r.method == method), key=lambda r: r.n)
            if not mine:
                continue
            done = [r for r in mine if r.stop == "done"]
            bad = [r for r in mine if r.stop != "done"]
            line, = ax.plot([r.n for r in done], [r.ctime for r in done], "o-", label=method)
            ax.plot([r.n for r in bad], [r.ctime for r in bad], "x", ms=12, mew=2, color=line.get_color())
        bound = sorted({(r.n, r.lower_bound) for r in rows if r.map == m and r.method == "md"} or
                       {(r.n, r.lower_bound) for r in rows if r.map == m})
        ax.plot([b[0] for b in bound], [b[1] for b in bound], "_:", ms=14, color="grey", label="bound (md run)")
        ax.set(title=m, xlabel="robots", ylabel="CTime (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("completion time of all deliveries (x: unfinished, stop time)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def _plot_means(rows: list[Row], maps: list[str], axes) -> None:
    """Mean CTime over the seeds per method and N, with min-max bars (x: some run unfinished)."""
    sums = summarise(rows)
    rules = {}
    for s in sums:
        rules.setdefault(s.method, set()).add(_rule_of(s))
    lines = list(dict.fromkeys((s.method, _rule_of(s)) for s in sums))
    for ax, m in zip(axes, maps):
        shift = 0.012 * max(s.n for s in sums if s.map == m)   # the lines' bars side by side
        for k, (method, rule) in enumerate(lines):
            mine = sorted((s for s in sums if s.map == m and s.method == method and _rule_of(s) == rule),
                          key=lambda s: s.n)
            if not mine:
                continue
            label = method if len(rules[method]) == 1 else f"{method} {rule}"
            x = [s.n + (k - (len(lines) - 1) / 2) * shift for s in mine]
            bars = ax.errorbar(x, [s.ctime_mean for s in mine], capsize=4, fmt="o-", label=label,
                               yerr=[[s.ctime_mean - s.ctime_min for s in mine],
                                     [s.ctime_max - s.ctime_mean for s in mine]])
            bad = [(xi, s) for xi, s in zip(x, mine) if s.unfinished]
            ax.plot([xi for xi, _ in bad], [s.ctime_mean for _, s in bad], "x", ms=12, mew=2,
                    color=bars.lines[0].get_color())
        bound: dict[int, list[float]] = {}
        for r in rows:
            if r.map == m and r.method == "md":
                bound.setdefault(r.n, []).append(r.lower_bound)
        ns = sorted(bound)
        ax.plot(ns, [sum(bound[n]) / len(bound[n]) for n in ns], "_:", ms=14, color="grey", label="bound (md, mean)")
        ax.set(title=m, xlabel="robots", ylabel="CTime (s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    seeds = sorted({r.seed for r in rows})
    axes[0].figure.suptitle(f"completion time of all deliveries: mean over seeds {_seed_text(seeds)}\n"
                            "bars min-max (x: some run unfinished, stop time)", fontsize=10)
    axes[0].figure.tight_layout()


def _rule_of(s: Summary) -> str:
    return s.queue.partition(":")[0]


def run(problem: DeliveryProblem, m: str, method: str, args: argparse.Namespace, bar,
        queue: str = DEFAULT_QUEUE, seed: int | None = None) -> Row:
    """One simulation, its progress on the bar and a loud line if it went wrong."""
    seed = args.seed if seed is None else seed
    several = len(getattr(args, "seeds", ())) > 1
    label = (f"{m} N={problem.n_robots} {method}" + ("" if queue == DEFAULT_QUEUE else f" queue={queue}")
             + (f" seed={seed}" if several else ""))
    bar.set_postfix_str(label)
    shown = [0.0]

    def progress(done: int, total: int, t: float) -> None:
        now = time.monotonic()
        if now - shown[0] > 0.5:
            shown[0] = now
            bar.set_postfix_str(f"{label}: {done}/{total} deliveries, t={t:.0f} s")

    pre = 0.0
    if method == "armo" and getattr(problem.grid, "lanes", None) is None:
        from fleet_planner.delivery import armo_problem

        bar.set_postfix_str(f"{label}: road map")
        t0 = time.perf_counter()
        problem = armo_problem(problem)[0]
        pre = time.perf_counter() - t0
    cpu0, backstops0, out0 = time.process_time(), budget.Budget.backstops, budget.Budget.spent
    res = simulate(problem, method, dt=args.dt, cap_s=args.cap, wall_cap_s=args.wall_cap, progress=progress,
                   queue=queue)
    if res.collisions or res.violations:
        where = label + ("" if several else f" seed={seed}")   # (several seeds: the label has it)
        bar.write(f"!!! FAIL: {where}: {res.collisions} overlapping pair(s), min gap "
                  f"{res.min_gap:.4f} m; {'; '.join(res.violations[:3])}", file=sys.stderr)
    elif res.stop != "done":
        bar.write(f"{label}: unfinished ({res.stop}) after {res.ctime:.0f} s simulated: "
                  f"{res.completed}/{res.n_deliveries} deliveries, {res.deadlocks} robot(s) deadlocked",
                  file=sys.stderr)
    row = to_row(m, res)
    row.precompute_s = pre
    row.cpu_s = time.process_time() - cpu0
    row.backstops = budget.Budget.backstops - backstops0
    row.budgets_out = budget.Budget.spent - out0
    row.queue = queue if queue != "auto" else f"auto:{res.extra.get('queue', '?')}"   # (the rule it chose)
    row.seed = seed
    return row


def main(argv=None) -> int:
    args = _args(argv)
    if args.from_csv is not None:
        return report(ordered([r for path in args.from_csv for r in read_csv(path)], args.maps, args.methods), args)
    before = budget.WALL_BACKSTOP
    budget.WALL_BACKSTOP = args.backstop   # for these runs only (a caller's process keeps its own)
    try:
        return _run(args)
    finally:
        budget.WALL_BACKSTOP = before


def _run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    if not args.maps_dir.is_dir() and any(m not in BUILTIN_MAPS for m in args.maps):
        sys.exit(f"bench_delivery: no maps directory {args.maps_dir}")
    rows: list[Row] = []
    runs = [(method, q) for method in args.methods for q in (args.queue if method not in ("behavior", "armo")
                                                             else ["spots"])]
    total = len(args.maps) * len(args.sizes) * len(args.seeds) * len(runs)
    with tqdm(total=total, unit="run", file=sys.stderr) as bar:
        for m in args.maps:
            for n in args.sizes:
                for seed in args.seeds:
                    try:
                        problem = make_problem(m, n, args, seed)   # the same problem for every method
                        if args.lanes is not None:
                            from fleet_planner.delivery import lanes_problem
                            from fleet_planner.roadmap import load_lanes

                            problem = lanes_problem(problem, load_lanes(args.lanes, problem.grid, problem.radius))
                    except ValueError as exc:
                        bar.write(f"{m} N={n} seed={seed}: skipped: {exc}", file=sys.stderr)
                        bar.update(len(runs))
                        continue
                    for method, queue in runs:
                        rows.append(run(problem, m, method, args, bar, queue, seed))
                        bar.update()
                        if args.csv:   # as it goes: a long run stopped early keeps what it measured
                            write_csv(rows, args.csv)
    return report(rows, args)


def report(rows: list[Row], args: argparse.Namespace) -> int:
    """The tables, CSV and plot of the rows; 1 when there are none or any run had a collision."""
    if not rows:
        print("bench_delivery: nothing ran", file=sys.stderr)
        return 1
    print(table(rows))
    if several_seeds(rows):
        print()
        print(summary_table(rows))
    if args.paper002:
        print()
        print(paper_table(rows))
    if args.csv:
        write_csv(rows, args.csv)
    if args.plot:
        plot(rows, args.plot)
    bad = [r for r in rows if r.collisions or r.violations]
    if bad:
        print(f"\n!!! {len(bad)} RUN(S) WITH COLLISIONS OR INVALID TRAJECTORIES: "
              + ", ".join(f"{r.map} N={r.n} {r.method} seed={r.seed}" for r in bad), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
