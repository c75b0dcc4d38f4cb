#!/usr/bin/env python3
"""Instrument a stalled behaviour (BBMRCA) delivery run: at the stop, every robot stuck on a leg
with its behaviour, partner, the wait chain it is in (partner pointers followed to a cycle, a
standing robot or a moving one) and a classification of the chain. Not part of the suite.

    .venv/bin/python bench/diag_behavior.py --maps-dir /work/shared/data/maps --map warehouse --n 40

``--budget``: where the driving robots' time goes (:class:`Budget`); ``--lanes FILE``: along a
road map (e.g. config/lanes_large.yaml).
"""
from __future__ import annotations

import argparse
import collections
import dataclasses
import math
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.bench_delivery import make_problem  # noqa: E402
from fleet_planner.delivery.behavior_run import ADMIT, WAITING_PHASES, _BehaviorRun  # noqa: E402
from fleet_planner.delivery.result import RunLimits  # noqa: E402


def chain(fleet, rid):
    seen, out = [], rid
    while out is not None and out not in seen:
        seen.append(out)
        out = fleet.controller(out).partner
    return seen, out   # out in seen: cycle; None: ends at a robot without partner


def _pickle_locks() -> None:
    """Snapshots: the path finders' locks pickle as new locks."""
    import copyreg
    import threading

    copyreg.pickle(type(threading.Lock()), lambda _lock: (threading.Lock, ()))
    copyreg.pickle(type(threading.RLock()), lambda _lock: (threading.RLock, ()))


def save(run, path: Path) -> None:
    import pickle

    _pickle_locks()
    progress, run.progress = run.progress, None
    try:
        path.write_bytes(pickle.dumps(run))
    finally:
        run.progress = progress


def load(path: Path):
    """A run saved by :func:`save` (the compiled path search keeps no state that pickling could break)."""
    import pickle

    _pickle_locks()
    run = pickle.loads(path.read_bytes())
    # a snapshot taken by older code: its controllers get the attributes added since, as a new robot has them
    from fleet_planner.behavior import BehaviorController

    fleet = run.fleet
    run.rules.__dict__.setdefault("admission", None)   # older code: no station admission
    # move graphs of older code: the search's fields added since start empty (made at first use)
    for graph in getattr(run.problem.grid, "_path_move_graphs", {}).values():
        graph.__dict__.setdefault("_landmarks", None)
        graph.__dict__.setdefault("symmetric", None)
    for rid in fleet.ids:
        c = fleet.controller(rid)
        for graph in getattr(c.grid, "_path_move_graphs", {}).values():
            graph.__dict__.setdefault("_landmarks", None)
            graph.__dict__.setdefault("symmetric", None)
        fresh = BehaviorController(c.grid, c.id, c.radius, c.max_speed, c.position, c.params,
                                   finders={c.radius: c.finder})
        for k, v in vars(fresh).items():
            c.__dict__.setdefault(k, v)
    return run


def report(run, near: bool = False, quiet: bool = False) -> collections.Counter:
    """The robots stuck on a leg (no progress for 120 s) with their wait chains; the kinds counted."""
    fleet = run.fleet
    t = fleet.time
    stuck = [r for r in run.robots
             if run.rules.busy(r) and r.phase not in WAITING_PHASES and t - r.progress_t > 120]
    kinds: collections.Counter = collections.Counter()
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
                        f"{'(retreat)' if ci.retreat else ''}{'(esc)' if ci.escape_to is not None else ''}"
                        f"@({v.position[0]:.1f},{v.position[1]:.1f}){nxt}")
        if end is None:
            last = fleet.controller(ids[-1])
            tail = f"ends at {ids[-1]} ({last.behavior.value}, {'no path' if last.path is None else 'has path'})"
            kind = f"chain->{last.behavior.value}{'/nopath' if last.path is None else ''}"
        else:
            tail = f"CYCLE back to {end} (len {len(ids) - ids.index(end)})"
            kind = f"cycle{len(ids) - ids.index(end)}"
        kinds[(c.behavior.value, kind)] += 1
        if quiet:
            continue
        blocked = f" blocked {t - c.blocked_since:.0f}s" if c.blocked_since is not None else ""
        if near:
            for o in fleet.ids:
                co = fleet.controller(o)
                if o != r.id and min(math.dist(co.pos, c.pos), math.dist(co.pos, c.goal or c.pos)) < 3.0:
                    print(f"      near {o}: {co.behavior.value} @({co.pos[0]:.2f},{co.pos[1]:.2f}) "
                          f"path={'none' if co.path is None else len(co.path)} goal={co.goal} esc={co.escapes}")
            print(f"      goal {c.goal} escapes={c.escapes} escape_to={c.escape_to} yields={c.yields}")
        print(f"  {r.id} phase={r.phase} since-progress={t - r.progress_t:.0f}s replans={c.replans} "
              f"fails={c.replan_failures} dl={c.deadlocks} off_path={c.off_path}{blocked}: "
              + " => ".join(desc) + "  " + tail)
    return kinds


class Budget:
    """Where the driving robots' time goes (``--budget``): robot-seconds by behaviour, moving or
    standing, the standing ones by place (near a station, at a junction of aisles, in a narrow
    aisle, in a wide one), and the distance driven per leg against the leg's first path."""

    def __init__(self, run) -> None:
        from scipy import ndimage

        grid = run.problem.grid
        free = ~grid.blocked
        self.res = grid.resolution
        self.grid = grid
        # free run through each cell, across (rows) and along (columns), in cells
        self.run_x = self._runs(free)
        self.run_y = self._runs(free.T).T
        # local free width, m: a cell k cells from the nearest wall cell lies in a passage of 2k - 1 cells
        self.width = (2 * ndimage.distance_transform_edt(free) - 1) * grid.resolution
        import numpy as np

        self.stations = np.asarray(list(run.problem.stations.values()), dtype=float)
        self.time: collections.Counter = collections.Counter()   # (behaviour, moving) -> robot-seconds
        self.place: collections.Counter = collections.Counter()  # (place, behaviour) -> standing robot-seconds
        self.prev = run.pos.copy()
        self.leg_plan = {}                                          # robot -> path length at assignment
        self.leg_driven = {}
        self.planned = self.driven_on_legs = 0.0
        self.legs: list[tuple[float, float, int]] = []
        self.dist: collections.Counter = collections.Counter()   # behaviour -> metres driven

    @staticmethod
    def _runs(free):
        import numpy as np

        out = np.zeros(free.shape, dtype=int)
        for r in range(free.shape[0]):
            row, c = free[r], 0
            while c < len(row):
                if not row[c]:
                    c += 1
                    continue
                e = c
                while e < len(row) and row[e]:
                    e += 1
                out[r, c:e] = e - c
                c = e
        return out

    def where(self, pos, target) -> str:
        import numpy as np

        if target is not None and math.dist(pos, target) < 4.0:
            return "own target<4m"
        if len(self.stations) and float(np.min(np.hypot(*(self.stations - pos).T))) < 1.5:
            return "other station<1.5m"
        c, r = self.grid.cell_of(float(pos[0]), float(pos[1]))
        w = float(self.width[r, c])
        long_x, long_y = self.run_x[r, c] * self.res > 4.0, self.run_y[r, c] * self.res > 4.0
        if long_x and long_y:
            return "junction"
        return "aisle<2m (one robot)" if w < 2.0 else "aisle>=2m"

    def observe(self, run, dt: float) -> None:
        import numpy as np

        pos = run.pos
        step = np.hypot(*(pos - self.prev).T)
        self.prev = pos.copy()
        fleet = run.fleet
        for r in run.robots:
            c = fleet.controller(r.id)
            if r.phase != "drive":
                leg = self.leg_plan.pop(r.id, None)
                if leg is not None:   # a leg ended: (first path, driven, re-planned/escaped in it)
                    plan, driven, n0 = leg
                    self.legs.append((plan, driven, c.replans + c.escapes + c.yields - n0))
                continue
            if r.id not in self.leg_plan:            # a new leg: its first path (without the step just driven)
                self.leg_plan[r.id] = [c.remaining() + float(step[r.idx]), 0.0, c.replans + c.escapes + c.yields]
                self.planned += self.leg_plan[r.id][0]
            self.leg_plan[r.id][1] += float(step[r.idx])
            self.driven_on_legs += float(step[r.idx])
            moving = step[r.idx] > 0.2 * run.problem.max_speed * dt
            b = c.behavior.value
            self.time[(b, moving)] += dt
            self.dist[b + ("(escape)" if c.escape_to is not None else "")] += float(step[r.idx])
            if not moving:
                self.place[(self.where(pos[r.idx], r.target), b)] += dt

    def print(self) -> None:
        total = sum(self.time.values())
        print(f"budget: {total:.0f} robot-s driving legs; driven {self.driven_on_legs:.0f} m on legs whose "
              f"first paths were {self.planned:.0f} m (x{self.driven_on_legs / max(self.planned, 1e-9):.2f})")
        moving = sum(v for (_, m), v in self.time.items() if m)
        print(f"  moving {moving / total:.1%}, standing {1 - moving / total:.1%}")
        for (b, m), v in sorted(self.time.items(), key=lambda kv: -kv[1]):
            print(f"  {b:<18} {'moving' if m else 'standing':<9} {v:9.0f} robot-s {v / total:6.1%}")
        plain = [(p, d) for p, d, k in self.legs if k == 0]
        turned = [(p, d) for p, d, k in self.legs if k > 0]
        for name, legs in (("legs without re-plan/escape/yield", plain), ("legs with one or more", turned)):
            if legs:
                p_sum, d_sum = sum(p for p, _ in legs), sum(d for _, d in legs)
                print(f"  {name}: {len(legs)}, first paths {p_sum:.0f} m, driven {d_sum:.0f} m "
                      f"(x{d_sum / max(p_sum, 1e-9):.2f})")
        print("  metres driven by behaviour:", {k: round(v) for k, v in self.dist.most_common()})
        stand = sum(self.place.values())
        by_place: collections.Counter = collections.Counter()
        for (pl, _), v in self.place.items():
            by_place[pl] += v
        print("  standing by place:", {k: f"{v / stand:.1%}" for k, v in by_place.most_common()})
        for (pl, b), v in self.place.most_common(10):
            print(f"    {pl:<20} {b:<18} {v / stand:6.1%}")


def main() -> None:
    import time

    p = argparse.ArgumentParser()
    p.add_argument("--maps-dir", type=Path, default=REPO.parent / "shared" / "data" / "maps")
    p.add_argument("--map", default="warehouse")
    p.add_argument("--n", type=int, default=40)
    p.add_argument("--per-robot", type=int, default=3)
    p.add_argument("--stall", type=float, default=300.0)
    p.add_argument("--cap", type=float, default=4 * 3600.0)
    p.add_argument("--wall-cap", type=float, default=300.0)
    p.add_argument("--near", action="store_true", help="also the robots near each stuck one")
    p.add_argument("--lanes", default="none",
                   help="armo: the robots plan along ARMO's road map (the 'armo' method); or a lanes file "
                        "(config/lanes_*.yaml): along its road map")
    p.add_argument("--steps", type=int, default=None, help="stop after this many fleet steps (e.g. to profile)")
    p.add_argument("--profile", type=Path, default=None, help="cProfile the steps into this file (pstats)")
    p.add_argument("--report-every", type=float, default=0.0,
                   help="every this many simulated seconds, a one-line summary of the stuck robots")
    p.add_argument("--snapshot-every", type=float, default=0.0,
                   help="every this many simulated seconds, pickle the run to --snapshot (to study a jam)")
    p.add_argument("--snapshot", default="out/diag_behavior.pkl",
                   help="the snapshot file; a '{t}' in it is replaced by the simulated time (keeps every snapshot)")
    p.add_argument("--resume", type=Path, default=None, help="go on from a snapshot (the map options are ignored)")
    p.add_argument("--admit", type=int, default=0,
                   help=f"robots admitted to a station at a time, the others wait out of the crowd (ours; e.g. "
                        f"{ADMIT}); 0: no limit, the paper's fleet (default: %(default)s)")
    p.add_argument("--budget", action="store_true",
                   help="where the driving robots' time goes (behaviour, moving/standing, place) and detours")
    a = p.parse_args()
    if a.resume is not None:
        run = load(a.resume)
        problem = run.problem
        # the wall-clock cap counts from the resume (the snapshot's clock started in another process); the
        # simulated-time cap is the one given now (a run stopped at its --cap goes on)
        run.limits = dataclasses.replace(run.limits, wall_cap_s=a.wall_cap, cap_s=a.cap)
        run.tally.started = time.perf_counter()
    else:
        args = argparse.Namespace(per_robot=a.per_robot, dock=5.0, seed=0, stations=8, maps_dir=a.maps_dir)
        problem = make_problem(a.map, a.n, args)
        if a.lanes == "armo":
            from fleet_planner.delivery import armo_problem

            problem, info = armo_problem(problem)
            print("ARMO:", info)
        elif a.lanes != "none":
            from fleet_planner.delivery import lanes_problem
            from fleet_planner.roadmap import load_lanes

            problem = lanes_problem(problem, load_lanes(a.lanes, problem.grid, problem.radius))
        limits = RunLimits(cap_s=a.cap, stall_s=a.stall, no_progress_s=120.0, retry_s=2.0, wall_cap_s=a.wall_cap)
        run = _BehaviorRun(problem, 0.1, limits, False, None, a.admit or None)
        run.start()
    from tqdm import tqdm

    cpu0, wall0, steps0 = time.process_time(), time.time(), run.steps
    budget = Budget(run) if a.budget else None
    next_report = run.fleet.time + a.report_every
    next_snap = run.fleet.time + a.snapshot_every
    profiler = None
    if a.profile is not None:
        import cProfile

        profiler = cProfile.Profile()
        profiler.enable()
    with tqdm(total=len(problem.deliveries), unit="del", file=sys.stderr, mininterval=5.0) as bar:
        def progress(done: int, total: int, t: float) -> None:   # deliveries done, simulated time
            bar.n = done
            bar.set_postfix_str(f"t={t:.0f} s", refresh=False)
            bar.update(0)                                          # redrawn at most every 5 s

        run.progress = progress
        stop = "done"
        while run.rules.ctime is None:       # _BehaviorRun.run, with the hooks
            why = run._stop_now()
            if why is None and a.steps is not None and run.steps - steps0 >= a.steps:
                why = "steps"
            if why is not None:
                stop = why
                break
            run._step()
            if budget is not None:
                budget.observe(run, run.dt)
            t = run.fleet.time
            if a.report_every > 0 and t >= next_report:
                next_report += a.report_every
                kinds = report(run, quiet=True)
                queued = sum(r.phase == "queued" for r in run.robots)
                tqdm.write(f"t={t:.0f} s done={run.rules.completed} stuck={sum(kinds.values())} queued={queued} "
                           f"{dict(kinds.most_common(4))}", file=sys.stdout)
                sys.stdout.flush()
            if a.snapshot_every > 0 and t >= next_snap:
                next_snap += a.snapshot_every
                snap = Path(a.snapshot.replace("{t}", f"{t:.0f}"))
                snap.parent.mkdir(parents=True, exist_ok=True)
                save(run, snap)
        res = run._result(run.rules.ctime if run.rules.ctime is not None else run.fleet.time, stop)
    if profiler is not None:
        profiler.disable()
        profiler.dump_stats(a.profile)
    cpu, wall, steps = time.process_time() - cpu0, time.time() - wall0, run.steps - steps0
    print(f"{problem.name} N={problem.n_robots}: stop={res.stop} done={res.completed}/{res.n_deliveries} "
          f"t={res.ctime:.0f} coll={res.collisions} dead={res.deadlocks}")
    print(f"  {steps} steps in {cpu:.1f} s CPU ({steps / max(cpu, 1e-9):.1f} steps/s), {wall:.1f} s wall")
    print("  counters:", {k: v for k, v in res.extra.items() if k not in ("mean_phase_s", "stalled")})
    ctl = [run.fleet.controller(i) for i in run.fleet.ids]
    print(f"  escapes {sum(c.escapes for c in ctl)}, yields {sum(c.yields for c in ctl)}, "
          f"steps against the lanes {sum(c.steps_out for c in ctl)}, ways made by Dock {sum(c.ways_made for c in ctl)}")
    if budget is not None:
        budget.print()
    kinds = report(run, a.near)
    print("summary (own behaviour, chain kind):")
    for k, v in kinds.most_common():
        print(f"  {v:3d} {k}")


if __name__ == "__main__":
    main()
