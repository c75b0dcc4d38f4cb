"""The fleet demo: the planner and a mixed fleet on the default warehouse, fed a stream of jobs.

``fleet-demo`` brings up a simulated clock (``--rate`` x real time), the planner node and one agent
per robot of ``config/fleet.yaml``, then submits ``--jobs`` random pick-and-place jobs on
``/fleet/tasks`` and shows progress until all are done. Nodes share one process and one executor
(``--mode inproc``, the default) or run as separate processes (``--mode procs``: the console
scripts, or ``python -m`` where a script is not installed, in the same ROS environment).
``--people N`` adds N simulated people walking between random points (obstacles on
``/fleet/obstacles``, planned around); ``--record run.mcap`` records the run's topics (MCAP, ROS 2
encoding; ``fleet-replay run.mcap --plot out.png`` draws it). ``--coordination behavior`` runs
the same fleet with the robots avoiding each other by the BBMRCA behaviours instead of timed paths
(the planner only allocates and gives goals).

At the end it prints a summary (jobs done, completion time, average speed, and the smallest
distance ever seen between two robots against the sum of their radii, computed here from the
robots' own status reports, not by the planner, and the CPU and peak memory of each process) and
draws the robots' trajectories over the map to ``out/fleet_demo.png``. Ctrl-C or SIGTERM ends the run
early the same way, with the summary of what was done so far (exit status 130); every process it
started is stopped (and ends by itself should the demo be killed outright). Each run's planner keeps
its jobs in ``out/jobs.sqlite``, emptied when the run starts (the job ids repeat from run to run; a
store left from the last run is not reloaded).
"""
from __future__ import annotations

import argparse
import math
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import rclpy
import yaml
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import LoggingSeverity
from rclpy.node import Node
from rclpy.parameter import Parameter
from tqdm import tqdm

from fleet_planner.fleet import COORDINATION, FleetMember, load_fleet
from fleet_planner.fleet.jobstore import emptied
from fleet_planner.fleet.placement import generated_warehouse, parking_spots, place_robots
from fleet_planner.robots import load_kinds
from fleet_planner.ros.demo.bringup import (
    Fleet,
    bring_up,
    parking_of,
    start_processes,
    stop_processes,
    write_fleet_file,
)
from fleet_planner.ros.demo.jobs import TERMINAL, random_jobs
from fleet_planner.ros.demo.monitor import FleetMonitor, spin_until
from fleet_planner.ros.demo.procstat import Usage, usage, usage_lines
from fleet_planner.ros.demo.summary import Summary, plot_run, summarise
from fleet_planner.ros.entry import ros_session
from fleet_planner.warehouse import Warehouse, config_path, load_warehouse, save_warehouse
from msg_schemas.records import Task

DEMO_PARAMS = "planner_params.yaml"
#: the demo planner's job store in --out, emptied when a run starts
DEMO_STORE = "jobs.sqlite"
#: with --sim auto, fleets larger than this are driven by fleet-sim
SIM_ABOVE = 15
#: the default job stream: 20 jobs, one every 4 s, for the default nine robots
JOBS_PER_ROBOT, INTERVAL_ROBOT_S = 20 / 9, 4.0 * 9


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fleet-demo", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--mode", choices=("inproc", "procs"), default="inproc",
                   help="nodes in this process on one executor (default), or one process each")
    p.add_argument("--coordination", choices=COORDINATION, default="central",
                   help="central: timed paths planned around each other (default); behavior: the robots "
                        "get only goals and avoid each other by BBMRCA behaviours")
    p.add_argument("--jobs", type=int, help="how many jobs to submit (default 20, scaled with --robots)")
    p.add_argument("--interval", type=float,
                   help="simulated seconds between jobs (default 4, scaled down with --robots)")
    p.add_argument("--rate", type=float, default=10.0, help="simulated seconds per wall second, at most (default 10)")
    p.add_argument("--fleet", type=Path, help="fleet file (default: config/fleet.yaml)")
    p.add_argument("--robots", type=int, help="N robots of the four kinds on free spots instead of a fleet file "
                                                "(their start spots become the planner's parking spots)")
    p.add_argument("--warehouse", help="warehouse YAML (default: config/warehouse.yaml), or 'large' (a generated "
                                       "warehouse sized for the robots), or a number of robots to size one for")
    p.add_argument("--sim", choices=("auto", "on", "off"), default="auto",
                   help="robots simulated together in one fleet-sim node/process (on), one agent each (off), or "
                        f"fleet-sim above {SIM_ABOVE} robots (auto, the default)")
    p.add_argument("--params", type=Path, help="planner ros__parameters YAML (default: config/planner_params.yaml)")
    p.add_argument("--people", type=int, default=0,
                   help="simulated people walking between random points, reported on /fleet/obstacles (default 0)")
    p.add_argument("--record", type=Path, metavar="RUN.mcap",
                   help="record the run's topics to this MCAP file (ROS 2 encoding; fleet-replay draws it)")
    p.add_argument("--seed", type=int, default=1, help="seed of the random jobs (default 1)")
    p.add_argument("--out", type=Path, default=Path("out"), help="where the picture goes (default out/)")
    p.add_argument("--timeout", type=float, default=600.0, help="give up after this many wall seconds (default 600)")
    p.add_argument("--time-use", action="store_true",
                   help="print where the robots' time went (driving, held, picking, idle with jobs queued, ...)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--verbose", action="store_true", help="show the nodes' info messages (in-process mode)")
    p.add_argument("--console", type=int, metavar="PORT", help="serve the web operator console on localhost:PORT "
                   "(0: any free port); its URL is printed")
    p.add_argument("--linger", type=float, default=0.0, help="with --console: keep the fleet and the console up "
                   "this many wall seconds after the last job (default 0)")
    return p


def main(args: list[str] | None = None) -> None:
    argv = sys.argv if args is None else args
    # DDS stays on this machine and on a domain of its own unless the caller chose one (before
    # rclpy.init, which reads them)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    opts = _parser().parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    if opts.robots is not None and opts.robots < 1:
        _parser().error("--robots must be >= 1")
    n = opts.robots or 9
    opts.jobs = opts.jobs if opts.jobs is not None else max(1, round(JOBS_PER_ROBOT * n))
    opts.interval = opts.interval if opts.interval is not None else INTERVAL_ROBOT_S / n
    if opts.jobs < 1 or not opts.rate > 0 or not opts.interval >= 0 or not 0 <= opts.people <= 100:
        _parser().error("--jobs must be >= 1, --rate > 0, --interval >= 0 and --people in 0..100")

    opts.out.mkdir(parents=True, exist_ok=True)
    kinds = load_kinds()
    warehouse_file: Path | None = None
    generated = generated_warehouse(opts.warehouse, n)
    if generated is not None:
        warehouse = generated
        warehouse_file = save_warehouse(warehouse, opts.out / "warehouse_generated.yaml",
                                        f"generated by fleet-demo --warehouse {opts.warehouse}")
    else:
        warehouse_file = Path(opts.warehouse) if opts.warehouse else None
        warehouse = load_warehouse(warehouse_file)
    params_file = Path(opts.params) if opts.params else config_path(DEMO_PARAMS)
    planner_params: list[Parameter] = []
    if opts.robots is not None:
        members = place_robots(warehouse, kinds, opts.robots)
        spots = [v for p in parking_spots(warehouse, members) for v in p]
        if spots:
            planner_params = [Parameter("parking", value=spots)]
            params_file = _with_parking(params_file, spots, opts.out / "planner_params_generated.yaml")
    else:
        members = load_fleet(opts.fleet, kinds, warehouse)
        spots = fleet_parking(params_file, warehouse, members) if opts.fleet else []
        if spots:
            planner_params = [Parameter("parking", value=spots)]
            params_file = _with_parking(params_file, spots, opts.out / "planner_params_generated.yaml")
    use_sim = opts.sim == "on" or opts.sim == "auto" and len(members) > SIM_ABOVE
    fleet_file = write_fleet_file(members, opts.out / "fleet_generated.yaml") if use_sim else None
    jobs = random_jobs(warehouse, kinds, members, opts.jobs, opts.seed)
    store = emptied(opts.out / DEMO_STORE)   # each run starts with no jobs (its job ids repeat)

    signal.signal(signal.SIGTERM, _interrupt)   # SIGTERM ends the demo as Ctrl-C does
    # (and Ctrl-C is heard even when a script started the demo in the background, which ignores SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    context = Context()
    procs: list[subprocess.Popen] = []
    used: list[Usage] = []
    spans: list[float] = []   # when the cost was read: wall s since the fleet came up, simulated s
    wall0 = time.monotonic()

    fleet: Fleet | None = None
    monitor: FleetMonitor | None = None
    console = None
    extras: list[Node] = []

    def stop_fleet() -> None:
        """The cost of every process of the run so far, then its processes stopped (not with a console
        lingering: it shows the fleet after the last job)."""
        if not used:
            used.extend(usage([os.getpid()] + [p.pid for p in procs]))
            spans[:] = [time.monotonic() - wall0, monitor.latest_stamp() if monitor is not None else 0.0]
        if console is None:
            _shielded(stop_processes, procs)

    # a failure while the fleet comes up shows its traceback, as it always did (errors=())
    with ros_session(argv, prog="fleet-demo", context=context, errors=(), interrupted=INTERRUPTED):
        try:
            executor: Executor
            if opts.mode == "inproc":
                fleet = bring_up(context, warehouse, kinds, members, opts.rate, planner_params, params_file=params_file,
                                 coordination=opts.coordination, sim=use_sim, job_store=store)
                executor, monitor = fleet.executor, fleet.monitor
                parking = list(fleet.planner.fleet.parking.values())
                if not opts.verbose:
                    for node in fleet.nodes:
                        node.get_logger().set_level(LoggingSeverity.WARN)
            else:
                log_dir = opts.out / "logs"
                log_dir.mkdir(exist_ok=True)
                procs = start_processes(members, opts.rate, params_file, warehouse_file, log_dir=log_dir,
                                        coordination=opts.coordination, fleet_file=fleet_file, job_store=store)
                monitor = FleetMonitor(context=context, parameter_overrides=[Parameter("use_sim_time", value=True)])
                executor, parking = SingleThreadedExecutor(context=context), parking_of(params_file)
                executor.add_node(monitor)
            if opts.console is not None:  # the web operator console, in this process
                from fleet_planner.ros.console import attach_console
                console = attach_console(executor, warehouse, parking, opts.console, context=context)
                print(f"fleet-demo: operator console at {console[1].url}", flush=True)
            extras = _extras(context, opts, warehouse, members)  # people, recorder: in this process
            for node in extras:
                executor.add_node(node)
            summary = run_jobs(executor, monitor, [m.id for m in members], jobs, interval=opts.interval,
                               timeout=opts.timeout, progress=not opts.no_progress, on_end=stop_fleet)
            if console is not None and not summary.interrupted:
                spin_until(executor, lambda: False, max(0.0, opts.linger))
            title = (f"fleet-demo ({opts.coordination}): {summary.done}/{summary.jobs} jobs, {len(members)} robots, "
                     f"closest approach {summary.min_gap:+.2f} m beyond the sum of radii")
            png = opts.out / "fleet_demo.png"
            for _ in range(20 if context.ok() else 0):   # what is still on its way to the recorder
                executor.spin_once(timeout_sec=0.02)
            plot_run(warehouse, monitor.trajectories(), png, title, parking, monitor.obstacle_trajectories())
            lines = summary.lines(monitor.radius, opts.rate)
            if spans:
                lines += usage_lines(used, *spans)
            if opts.time_use and summary.completion_s:
                from fleet_planner.ros.demo.timeuse import sites_of, time_use
                chutes = {s.name: s.pose for s in warehouse.stations_of("chute")}
                lines += time_use(monitor.modes, monitor.events, jobs, kinds, monitor.tracks, chutes, summary.start,
                                  summary.start + summary.completion_s, sites=sites_of(warehouse)).lines()
            gap, robot, person, t = monitor.obstacle_separation()
            if robot is not None and t is not None:
                lines.append(f"closest approach to an obstacle: {gap:+.3f} m beyond the sum of radii ({robot} and "
                             f"{person} at t = {t:.1f} s, {'no contact' if gap >= 0 else 'DISCS OVERLAPPED'})")
            for node in extras:
                executor.remove_node(node)
                node.destroy_node()   # the recorder closes its file
            extras = []
            if opts.record:
                lines.append(f"recording: {opts.record} (fleet-replay {opts.record} --plot out.png draws it)")
            lines.append(f"robots: {len(members)} ({'fleet-sim' if use_sim else 'one agent each'}, {opts.mode}) on "
                         f"{warehouse.name} ({warehouse.grid.size_m[0]:g} m x {warehouse.grid.size_m[1]:g} m)")
            print("\n".join(lines + [f"picture: {png}"]), flush=True)
            if summary.interrupted:
                sys.exit(INTERRUPTED)
            if summary.done < summary.jobs:
                sys.exit(1)
        finally:
            for node in extras:
                node.destroy_node()
            if console is not None:
                console[1].stop()
                executor.remove_node(console[0])
                console[0].destroy_node()
            _shielded(stop_processes, procs)
            if fleet is not None:
                fleet.destroy()
            elif monitor is not None:
                monitor.destroy_node()


def _extras(context: Context, opts: argparse.Namespace, warehouse: Warehouse,
            members: Sequence[FleetMember]) -> list[Node]:
    """The simulated people (``--people``) and the recorder (``--record``), on simulated time."""
    from fleet_planner.fleet.people import random_people
    from fleet_planner.ros.people import PeopleNode
    from fleet_planner.ros.record import RecorderNode

    sim = [Parameter("use_sim_time", value=True)]
    nodes: list[Node] = []
    if opts.record:
        nodes.append(RecorderNode(context=context, output=opts.record, parameter_overrides=sim))
    if opts.people:
        walkers = random_people(warehouse.grid, opts.people, opts.seed,
                                avoid=[(m.x, m.y) for m in members] + [s.pose for s in warehouse.stations.values()])
        nodes.append(PeopleNode(context=context, walkers=walkers, parameter_overrides=sim))
    return nodes


def fleet_parking(params_file: Path, warehouse: Warehouse, members: Sequence[FleetMember]) -> list[float]:
    """The parking spots (flat x, y, ...) for a fleet file's robots: the params file's spots and where
    the robots start (not on chargers), or [] when they all start on those spots already. With only
    the default nine's spots, 22 robots idled in the aisles ("no charger or parking spot is free")
    and blocked the jobs (fleet-22.yaml, procs: 53 of 60 done, none after t = 580 s)."""
    known = parking_of(params_file)
    extra = [p for p in parking_spots(warehouse, members) if all(math.dist(p, q) > 1e-3 for q in known)]
    return [v for p in known + extra for v in p] if extra else []


def _with_parking(params_file: Path, spots: list[float], out: Path) -> Path:
    """A copy of a planner ros__parameters file with ``parking`` replaced by ``spots``."""
    data = yaml.safe_load(Path(params_file).read_text()) or {}
    for value in data.values():
        if isinstance(value, dict) and isinstance(value.get("ros__parameters"), dict):
            value["ros__parameters"]["parking"] = spots
    out.write_text(yaml.safe_dump(data))
    return out


def run_jobs(executor: Executor, monitor: FleetMonitor, robot_ids: Sequence[str], jobs: Sequence[Task], *,
             interval: float, timeout: float, progress: bool = True,
             on_end: Callable[[], None] | None = None) -> Summary:
    """Wait for the fleet (the planner and every robot in ``robot_ids``), submit the jobs one by one
    every ``interval`` simulated seconds, show progress, summarise; ``timeout`` wall seconds in all.
    Ctrl-C or SIGTERM (the ROS context shut down) ends it early: the summary of what was done so far,
    marked ``interrupted``. ``on_end`` runs once the jobs are over, before the summary (the demo reads
    the processes' cost and stops them there, so they do not compete with the summary for CPU)."""
    # when the stream began: (simulated s of the first submission, wall s); none if interrupted before
    began: list[float] = []
    interrupted = False
    try:
        _stream(executor, monitor, robot_ids, jobs, interval, timeout, progress, began)
    except (KeyboardInterrupt, ExternalShutdownException):
        interrupted = True
    wall = time.monotonic() - began[1] if began else 0.0
    if on_end is not None:
        on_end()
    summary = summarise(monitor, jobs, began[0] if began else monitor.latest_stamp(), wall)
    summary.interrupted = interrupted
    return summary


def _stream(executor: Executor, monitor: FleetMonitor, robot_ids: Sequence[str], jobs: Sequence[Task],
            interval: float, timeout: float, progress: bool, began: list[float]) -> None:
    """run_jobs' wait for the fleet and its stream of jobs; ``began`` gets the simulated time of the
    first submission and the wall time then."""
    wall0 = time.monotonic()
    deadline = wall0 + timeout
    ids = set(robot_ids)
    if not spin_until(executor, lambda: monitor.planner_ready() and ids <= set(monitor.status), timeout):
        raise SystemExit(f"fleet-demo: the planner or some robots did not come up within {timeout:g} s "
                         f"(seen: {', '.join(sorted(monitor.status)) or 'none'})")
    # once every robot has reported, give the planner one status round before the first job
    t_ready = monitor.now()
    spin_until(executor, lambda: monitor.now() > t_ready + 0.5, 30.0)
    bar = None
    if progress:
        bar = tqdm(total=len(jobs), desc="jobs done", unit="job", file=sys.stderr, dynamic_ncols=True)
    first = monitor.now()
    submitted = 0
    began[:] = [first, time.monotonic()]

    def finished() -> int:
        return sum(j.id in monitor.last_event and monitor.last_event[j.id].event in TERMINAL for j in jobs)

    try:
        while finished() < len(jobs) and time.monotonic() < deadline:
            now = monitor.now()
            while submitted < len(jobs) and now >= first + submitted * interval:
                monitor.submit(jobs[submitted])
                submitted += 1
            executor.spin_once(timeout_sec=0.05)
            if bar is not None:
                done = sum(e.event == "done" for e in monitor.last_event.values())
                if done != bar.n:
                    bar.update(done - bar.n)
                bar.set_postfix_str(f"sim t = {now - first:6.1f} s, submitted {submitted}", refresh=False)
    finally:
        if bar is not None:
            bar.close()


#: the demo's exit status when Ctrl-C or SIGTERM ended it (128 + SIGINT, as a shell reports it)
INTERRUPTED = 130


def _interrupt(signum: int, frame: object) -> None:
    """SIGTERM handled as Ctrl-C: the run ends, its summary is printed, its processes are stopped."""
    raise KeyboardInterrupt


def _shielded(stop: Callable[[Sequence[subprocess.Popen]], None], procs: list[subprocess.Popen]) -> None:
    """``stop(procs)`` with Ctrl-C and SIGTERM ignored until it is done (it is bounded: the processes
    get SIGINT, and SIGKILL after a grace period), so a second Ctrl-C leaves no process behind;
    ``procs`` is emptied."""
    old = [signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)]
    try:
        stop(procs)
        procs.clear()
    finally:
        for s, handler in zip((signal.SIGINT, signal.SIGTERM), old):
            signal.signal(s, handler)
