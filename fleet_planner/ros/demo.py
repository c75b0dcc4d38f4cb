"""The fleet demo: the planner and a mixed fleet on the default warehouse, fed a stream of jobs.

``fleet-demo`` brings up a simulated clock (``--rate`` x real time), the planner node and one agent
per robot of ``config/fleet.yaml``, then submits ``--jobs`` random pick-and-place jobs on
``/fleet/tasks`` and shows progress until all are done. Nodes share one process and one executor
(``--mode inproc``, the default) or run as separate processes (``--mode procs``: the console
scripts, or ``python -m`` where a script is not installed, in the same ROS environment).
``--coordination behavior`` runs the same fleet with the robots avoiding each other by the BBMRCA
behaviours instead of timed paths (the planner only allocates and gives goals).

At the end it prints a summary (jobs done, completion time, average speed, and the smallest
distance ever seen between two robots against the sum of their radii, computed here from the
robots' own status reports, not by the planner) and draws the robots' trajectories over the map
to ``out/fleet_demo.png``.

:class:`FleetMonitor` (the demo's eyes and hands on the topics), :func:`bring_up` (the nodes of an
in-process fleet) and :func:`start_processes` are also what the system tests use.
"""
from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import rclpy
import yaml
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import LoggingSeverity
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import String
from tqdm import tqdm

from fleet_planner.checker import min_separation
from fleet_planner.dispatch import COORDINATION, FleetMember, load_fleet, samples_to_path
from fleet_planner.model import TimedPath
from fleet_planner.robots import load_kinds
from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.planner_node import PlannerNode
from fleet_planner.ros.sim_clock import SimClock
from fleet_planner.ros.submit import planner_matched
from fleet_planner.warehouse import config_path, load_warehouse
from msg_schemas import topics
from msg_schemas.records import RecordError, RobotStatus, Task, TaskEvent
from robot_agent.agent_node import AgentNode

DEMO_PARAMS = "planner_params.yaml"
NEEDS = ((), ("manipulator",), ("forklift",), ("manipulator", "forklift"))
TERMINAL = ("done", "failed", "rejected", "cancelled")


# -------------------------------------------------------------------------------------------------
# watching the fleet
# -------------------------------------------------------------------------------------------------
class FleetMonitor(Node):
    """Submits tasks and records what the fleet reports: every task event, and every robot's
    positions (x, y, stamp) from its status messages."""

    def __init__(self, name: str = "fleet_monitor", **kwargs):
        super().__init__(name, **kwargs)
        self.events: list[TaskEvent] = []
        self.last_event: dict[str, TaskEvent] = {}
        self.tracks: dict[str, list[tuple[float, float, float]]] = {}
        self.radius: dict[str, float] = {}
        self.status: dict[str, RobotStatus] = {}
        self._tasks = self.create_publisher(String, topics.TASKS, topics.TASKS_QOS)
        self._events = create_draining_subscription(self, String, topics.TASK_EVENTS, self._on_event,
                                                    topics.TASK_EVENTS_QOS)
        create_draining_subscription(self, String, topics.ROBOT_STATUS, self._on_status, topics.ROBOT_STATUS_QOS)

    def now(self) -> float:
        return self.get_clock().now().nanoseconds / 1e9

    def submit(self, task: Task | str) -> None:
        self._tasks.publish(String(data=task if isinstance(task, str) else task.to_json()))

    def planner_ready(self) -> bool:
        return planner_matched(self, self._tasks, self._events)

    def _on_event(self, msg: String) -> None:
        try:
            ev = TaskEvent.from_json(msg.data)
        except RecordError as exc:
            self.get_logger().warning(f"task event ignored: {exc}")
            return
        self.events.append(ev)
        self.last_event[ev.task_id] = ev

    def _on_status(self, msg: String) -> None:
        try:
            st = RobotStatus.from_json(msg.data)
        except RecordError as exc:
            self.get_logger().warning(f"robot status ignored: {exc}", throttle_duration_sec=5.0)
            return
        self.status[st.id] = st
        self.radius[st.id] = st.radius
        self.tracks.setdefault(st.id, []).append((st.x, st.y, st.stamp))

    def events_of(self, task_id: str) -> list[TaskEvent]:
        return [e for e in self.events if e.task_id == task_id]

    def trajectories(self) -> list[TimedPath]:
        """Each robot's reported positions as a timed path (straight between reports)."""
        return [samples_to_path(rid, self.radius[rid], track) for rid, track in self.tracks.items()]

    def min_separation(self) -> tuple[float, str | None, str | None, float | None]:
        """Smallest distance minus the sum of radii over all pairs and all reported times."""
        return min_separation(self.trajectories())


def spin_until(executor, condition, timeout: float, step: float = 0.05) -> bool:
    """Spin ``executor`` until ``condition()`` holds or ``timeout`` wall seconds pass; returns it."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=step)
    return True


# -------------------------------------------------------------------------------------------------
# bring-up
# -------------------------------------------------------------------------------------------------
@dataclass
class Fleet:
    """The nodes of an in-process fleet, all on one executor."""

    clock: SimClock
    planner: PlannerNode
    agents: dict[str, AgentNode]
    monitor: FleetMonitor
    executor: SingleThreadedExecutor

    @property
    def nodes(self) -> list[Node]:
        return [self.clock, self.planner, *self.agents.values(), self.monitor]

    def destroy(self) -> None:
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()


def bring_up(context: Context, warehouse, kinds: Mapping, members: Sequence[FleetMember], rate: float,
             planner_params: Sequence[Parameter] = (), params_file: str | Path | None = None,
             coordination: str = "central") -> Fleet:
    """Sim clock, planner, one agent per fleet member and a monitor, all on simulated time in
    ``context`` and on one executor. ``planner_params`` and ``params_file`` (a ros__parameters
    YAML) configure the planner; ``coordination`` goes to the planner and every agent."""
    sim = [Parameter("use_sim_time", value=True)]
    mode = [Parameter("coordination", value=coordination)]
    clock = SimClock(context=context, parameter_overrides=[Parameter("rate", value=float(rate))])
    cli = ["--ros-args", "--params-file", str(params_file)] if params_file else None
    planner = PlannerNode(context=context, warehouse=warehouse, kinds=kinds, cli_args=cli,
                          parameter_overrides=sim + mode + list(planner_params))
    agents = {m.id: AgentNode(f"agent_{m.id}", context=context, warehouse=warehouse, kinds=kinds,
                              parameter_overrides=sim + mode + _agent_params(m)) for m in members}
    monitor = FleetMonitor(context=context, parameter_overrides=sim)
    fleet = Fleet(clock, planner, agents, monitor, SingleThreadedExecutor(context=context))
    for node in fleet.nodes:
        fleet.executor.add_node(node)
    return fleet


def _agent_params(m: FleetMember) -> list[Parameter]:
    return [Parameter("id", value=m.id), Parameter("kind", value=m.kind), Parameter("x", value=m.x),
            Parameter("y", value=m.y), Parameter("yaw", value=m.yaw), Parameter("battery", value=m.battery)]


def node_command(script: str, module: str) -> list[str]:
    """How to start a node as a process: the console script beside this Python, else ``-m module``."""
    exe = Path(sys.executable).parent / script
    return [str(exe)] if exe.is_file() and os.access(exe, os.X_OK) else [sys.executable, "-m", module]


def start_processes(members: Sequence, rate: float, params_file: Path, warehouse_file: Path | None,
                    kinds_file: Path | None = None, log_dir: Path | None = None,
                    coordination: str = "central") -> list[subprocess.Popen]:
    """Sim clock, planner and agents as processes in this environment (stop them with stop_processes)."""
    common = ["-p", f"coordination:={coordination}"]
    if warehouse_file:
        common += ["-p", f"warehouse_file:={warehouse_file}"]
    if kinds_file:
        common += ["-p", f"kinds_file:={kinds_file}"]
    sim = ["-p", "use_sim_time:=true"]
    commands = {"sim_clock": [sys.executable, "-m", "fleet_planner.ros.sim_clock", "--rate", str(rate)],
                "planner": node_command("planner", "fleet_planner.ros.planner_node")
                + ["--ros-args", "--params-file", str(params_file)] + sim + common}
    for m in members:
        commands[f"agent_{m.id}"] = node_command("robot_agent", "robot_agent.agent_node") + [
            "--ros-args", "-r", f"__node:=agent_{m.id}", "-p", f"id:={m.id}", "-p", f"kind:={m.kind}",
            "-p", f"x:={m.x!r}", "-p", f"y:={m.y!r}", "-p", f"yaw:={m.yaw!r}", "-p", f"battery:={m.battery!r}"] \
            + sim + common
    procs = []
    try:
        for name, cmd in commands.items():
            if log_dir is None:
                procs.append(subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT))
                continue
            with open(log_dir / f"{name}.log", "w") as log:  # the child keeps its own copy open
                procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT))
    except BaseException:
        stop_processes(procs)
        raise
    return procs


def stop_processes(procs: Sequence[subprocess.Popen], grace: float = 5.0) -> None:
    """SIGINT (the nodes shut down cleanly), then kill what is still running after ``grace`` s."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)
    deadline = time.monotonic() + grace
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


# -------------------------------------------------------------------------------------------------
# jobs, summary, picture
# -------------------------------------------------------------------------------------------------
def random_jobs(warehouse, kinds: Mapping, members: Sequence, count: int, seed: int) -> list:
    """``count`` jobs between random chutes and address tags, each doable by some robot of the fleet:
    its needs are those of a random member's kind, its payload within that kind's."""
    rng = random.Random(seed)
    chutes = [s.name for s in warehouse.stations_of("chute")]
    tags = [t for s in warehouse.stations_of("storage") for t in s.tags]
    jobs = []
    for i in range(count):
        kind = kinds[rng.choice(members).kind]
        needs = tuple(sorted(c for c in kind.capabilities if rng.random() < 0.7))
        jobs.append(Task(id=f"job_{i + 1:03d}", pick=rng.choice(chutes), place=rng.choice(tags), needs=needs,
                         payload_kg=round(rng.uniform(0.0, min(25.0, kind.payload_kg)), 1)))
    return jobs


@dataclass
class Summary:
    jobs: int
    done: int
    failed: int
    rejected: int
    completion_s: float | None     # from the first submission to the last job done (simulated)
    distance_m: float               # driven by the whole fleet
    average_speed: float            # fleet distance / (robots x completion time)
    moving_speed: float             # fleet distance / time spent moving
    min_gap: float                  # smallest distance minus the sum of radii
    closest: tuple[str | None, str | None, float | None]
    wall_s: float

    def lines(self, radius: Mapping[str, float]) -> list[str]:
        out = [f"jobs: {self.done} done, {self.failed} failed, {self.rejected} rejected of {self.jobs}"]
        if self.completion_s is not None:
            out.append(f"completion time: {self.completion_s:.1f} s simulated ({self.wall_s:.1f} s wall, "
                       f"{self.completion_s / max(self.wall_s, 1e-9):.1f}x real time)")
        out.append(f"average speed: {self.average_speed:.2f} m/s per robot over the run, {self.moving_speed:.2f} m/s "
                   f"while moving ({self.distance_m:.0f} m driven)")
        a, b, t = self.closest
        if a is not None:
            reach = radius[a] + radius[b]
            verdict = "no contact" if self.min_gap >= 0 else "DISCS OVERLAPPED"
            out.append(f"closest approach: {reach + self.min_gap:.3f} m between {a} and {b} at t = {t:.1f} s; "
                       f"sum of radii {reach:.3f} m ({verdict}, clearance {self.min_gap:+.3f} m)")
        return out


def summarise(monitor, jobs: Sequence, first_submit: float, wall_s: float) -> Summary:
    states = [monitor.last_event.get(j.id) for j in jobs]
    done_times = [e.stamp for e in states if e is not None and e.event == "done"]
    distance = moving_time = 0.0
    span = (max(done_times) - first_submit) if done_times else None
    for path in monitor.trajectories():
        wp = path.waypoints
        seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
        dt = np.diff(wp[:, 2])
        distance += float(seg.sum())
        moving_time += float(dt[seg > 1e-6].sum())
    gap, a, b, t = monitor.min_separation()
    robots = max(1, len(monitor.tracks))
    return Summary(len(jobs), len(done_times), sum(e is not None and e.event == "failed" for e in states),
                   sum(e is not None and e.event == "rejected" for e in states), span, distance,
                   distance / (robots * span) if span else 0.0, distance / moving_time if moving_time else 0.0,
                   gap, (a, b, t), wall_s)


def plot_run(warehouse, trajectories: Sequence, path_png: str | Path, title: str, parking: Sequence = ()) -> None:
    """The robots' reported trajectories over the map (drawn like the map file, y downwards)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    grid = warehouse.grid
    w, h = grid.size_m
    fig, ax = plt.subplots(figsize=(10, max(3.5, 10 * h / w)), layout="constrained")
    ax.imshow(np.where(grid.blocked, 0.25, 0.97), cmap="gray", vmin=0, vmax=1, extent=(0, w, h, 0),
              origin="upper", interpolation="nearest")
    marks = {"chute": ("v", "tab:red"), "storage": ("s", "tab:blue"), "charger": ("P", "tab:green")}
    for kind, (marker, colour) in marks.items():
        pts = np.array([s.pose for s in warehouse.stations_of(kind)]).reshape(-1, 2)
        ax.scatter(pts[:, 0], pts[:, 1], marker=marker, c=colour, s=30, label=kind, zorder=3)
    if len(parking):
        pts = np.asarray(parking, dtype=float).reshape(-1, 2)
        ax.scatter(pts[:, 0], pts[:, 1], marker="x", c="grey", s=25, label="parking", zorder=3)
    cmap = matplotlib.colormaps["tab10" if len(trajectories) <= 10 else "turbo"]
    for i, path in enumerate(sorted(trajectories, key=lambda p: p.robot_id)):
        c = cmap(i % 10 if len(trajectories) <= 10 else i / max(1, len(trajectories) - 1))
        wp = path.waypoints
        ax.plot(wp[:, 0], wp[:, 1], "-", color=c, lw=1.1, alpha=0.8, zorder=4)
        ax.add_patch(Circle(tuple(wp[0, :2]), path.radius, fill=False, ec=c, lw=1.2, zorder=5))
        ax.add_patch(Circle(tuple(wp[-1, :2]), path.radius, fc=c, ec="black", lw=0.5, zorder=5))
        ax.annotate(path.robot_id, tuple(wp[0, :2]), ha="center", va="center", fontsize=6, zorder=6)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m] (downwards, as in the map file)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper right", fontsize=7, framealpha=0.8)
    fig.savefig(path_png, dpi=120)
    plt.close(fig)


# -------------------------------------------------------------------------------------------------
# the command
# -------------------------------------------------------------------------------------------------
def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fleet-demo", description=__doc__.split("\n\n")[0])
    p.add_argument("--mode", choices=("inproc", "procs"), default="inproc",
                   help="nodes in this process on one executor (default), or one process each")
    p.add_argument("--coordination", choices=COORDINATION, default="central",
                   help="central: timed paths planned around each other (default); behavior: the robots "
                        "get only goals and avoid each other by BBMRCA behaviours")
    p.add_argument("--jobs", type=int, default=20, help="how many jobs to submit (default 20)")
    p.add_argument("--interval", type=float, default=4.0, help="simulated seconds between jobs (default 4)")
    p.add_argument("--rate", type=float, default=10.0, help="simulated seconds per wall second, at most (default 10)")
    p.add_argument("--fleet", type=Path, help="fleet file (default: config/fleet.yaml)")
    p.add_argument("--warehouse", type=Path, help="warehouse YAML (default: config/warehouse.yaml)")
    p.add_argument("--params", type=Path, help="planner ros__parameters YAML (default: config/planner_params.yaml)")
    p.add_argument("--seed", type=int, default=1, help="seed of the random jobs (default 1)")
    p.add_argument("--out", type=Path, default=Path("out"), help="where the picture goes (default out/)")
    p.add_argument("--timeout", type=float, default=600.0, help="give up after this many wall seconds (default 600)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--verbose", action="store_true", help="show the nodes' info messages (in-process mode)")
    return p


def main(args: list[str] | None = None) -> None:
    argv = sys.argv if args is None else args
    # DDS stays on this machine and on a domain of its own unless the caller chose one (before
    # rclpy.init, which reads them)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    opts = _parser().parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    if opts.jobs < 1 or not opts.rate > 0 or not opts.interval >= 0:
        _parser().error("--jobs must be >= 1, --rate > 0 and --interval >= 0")

    warehouse = load_warehouse(opts.warehouse)
    kinds = load_kinds()
    members = load_fleet(opts.fleet, kinds, warehouse)
    params_file = opts.params or config_path(DEMO_PARAMS)
    jobs = random_jobs(warehouse, kinds, members, opts.jobs, opts.seed)
    opts.out.mkdir(parents=True, exist_ok=True)

    context = Context()
    rclpy.init(args=argv, context=context)
    procs: list[subprocess.Popen] = []
    fleet = monitor = None
    try:
        if opts.mode == "inproc":
            fleet = bring_up(context, warehouse, kinds, members, opts.rate, params_file=params_file,
                             coordination=opts.coordination)
            executor, monitor, parking = fleet.executor, fleet.monitor, list(fleet.planner.fleet.parking.values())
            if not opts.verbose:
                for node in fleet.nodes:
                    node.get_logger().set_level(LoggingSeverity.WARN)
        else:
            log_dir = opts.out / "logs"
            log_dir.mkdir(exist_ok=True)
            procs = start_processes(members, opts.rate, params_file, opts.warehouse, log_dir=log_dir,
                                    coordination=opts.coordination)
            monitor = FleetMonitor(context=context, parameter_overrides=[Parameter("use_sim_time", value=True)])
            executor, parking = SingleThreadedExecutor(context=context), _parking_of(params_file)
            executor.add_node(monitor)
        summary = _run(executor, monitor, members, jobs, opts)
        title = (f"fleet-demo ({opts.coordination}): {summary.done}/{summary.jobs} jobs, {len(members)} robots, "
                 f"closest approach {summary.min_gap:+.2f} m beyond the sum of radii")
        png = opts.out / "fleet_demo.png"
        plot_run(warehouse, monitor.trajectories(), png, title, parking)
        print("\n".join(summary.lines(monitor.radius) + [f"picture: {png}"]))
        if summary.done < summary.jobs:
            sys.exit(1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        stop_processes(procs)
        if fleet is not None:
            fleet.destroy()
        elif monitor is not None:
            monitor.destroy_node()
        rclpy.try_shutdown(context=context)


def _parking_of(params_file: Path) -> list:
    data = yaml.safe_load(Path(params_file).read_text()) or {}
    flat = next((v["ros__parameters"].get("parking", []) for v in data.values()
                 if isinstance(v, dict) and isinstance(v.get("ros__parameters"), dict)), [])
    return [(flat[i], flat[i + 1]) for i in range(0, len(flat) - 1, 2)]


def _run(executor, monitor, members: Sequence, jobs: Sequence, opts) -> Summary:
    """Wait for the fleet, submit the jobs one by one on simulated time, show progress, summarise."""
    wall0 = time.monotonic()
    deadline = wall0 + opts.timeout
    ids = {m.id for m in members}
    if not spin_until(executor, lambda: monitor.planner_ready() and ids <= set(monitor.status), opts.timeout):
        raise SystemExit(f"fleet-demo: the planner or some robots did not come up within {opts.timeout:g} s "
                         f"(seen: {', '.join(sorted(monitor.status)) or 'none'})")
    # once every robot has reported, give the planner one status round before the first job
    t_ready = monitor.now()
    spin_until(executor, lambda: monitor.now() > t_ready + 0.5, 30.0)
    bar = None
    if not opts.no_progress:
        bar = tqdm(total=len(jobs), desc="jobs done", unit="job", file=sys.stderr, dynamic_ncols=True)
    first = monitor.now()
    submitted = 0
    wall_start = time.monotonic()

    def finished() -> int:
        return sum(j.id in monitor.last_event and monitor.last_event[j.id].event in TERMINAL for j in jobs)

    try:
        while finished() < len(jobs) and time.monotonic() < deadline:
            now = monitor.now()
            while submitted < len(jobs) and now >= first + submitted * opts.interval:
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
    return summarise(monitor, jobs, first, time.monotonic() - wall_start)


if __name__ == "__main__":
    main()
