"""Bringing a fleet up: in one process on one executor (:func:`bring_up`, the demo's ``--mode inproc``
and the system tests), or as one process per node (:func:`start_processes`, ``--mode procs``: the
console scripts, or ``python -m`` where a script is not installed, in the same ROS environment).

Everything a fleet needs is handed in (context, warehouse, kinds, members, rate, configuration);
nothing is read from globals.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import yaml
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from fleet_planner.fleet import DispatchParams, FleetMember
from fleet_planner.robots import RobotKind
from fleet_planner.ros.demo.monitor import FleetMonitor
from fleet_planner.ros.fleet_sim import FleetSimNode
from fleet_planner.ros.planner_node import PlannerNode
from fleet_planner.ros.sim_clock import SimClock
from fleet_planner.warehouse import Warehouse
from robot_agent.agent_node import AgentNode


# -------------------------------------------------------------------------------------------------
# in one process
# -------------------------------------------------------------------------------------------------
@dataclass
class Fleet:
    """The nodes of an in-process fleet, all on one executor."""

    clock: SimClock
    planner: PlannerNode
    agents: dict[str, AgentNode]
    monitor: FleetMonitor
    executor: SingleThreadedExecutor
    sim: FleetSimNode | None = None   # the robots, when fleet-sim drives them

    @property
    def nodes(self) -> list[Node]:
        return [self.clock, self.planner, *self.agents.values(), *([self.sim] if self.sim else []), self.monitor]

    def destroy(self) -> None:
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()


def bring_up(context: Context, warehouse: Warehouse, kinds: Mapping[str, RobotKind], members: Sequence[FleetMember],
             rate: float, planner_params: Sequence[Parameter] = (), params_file: str | Path | None = None,
             coordination: str = "central", agent_overrides: Sequence[Parameter] = (), sim: bool = False,
             job_store: str | Path | None = None) -> Fleet:
    """Sim clock, planner, one agent per fleet member (``sim``: one fleet-sim node driving them all)
    and a monitor, all on simulated time in ``context`` and on one executor. ``planner_params`` and
    ``params_file`` (a ros__parameters YAML) configure the planner; ``coordination`` goes to the
    planner and every agent, and ``agent_overrides`` to every agent; ``job_store`` is the planner's
    (None: its parameter's, by default under the ROS home)."""
    use_sim = [Parameter("use_sim_time", value=True)]
    mode = [Parameter("coordination", value=coordination)]
    store = [] if job_store is None else [Parameter("job_store", value=str(job_store))]
    clock = SimClock(context=context, parameter_overrides=[Parameter("rate", value=float(rate))])
    cli = ["--ros-args", "--params-file", str(params_file)] if params_file else None
    planner = PlannerNode(context=context, warehouse=warehouse, kinds=kinds, cli_args=cli,
                          parameter_overrides=use_sim + mode + store + list(planner_params))
    agents = {} if sim else {
        m.id: AgentNode(f"agent_{m.id}", context=context, warehouse=warehouse, kinds=kinds,
                        parameter_overrides=use_sim + mode + agent_params(m) + list(agent_overrides))
        for m in members}
    robots = FleetSimNode(context=context, warehouse=warehouse, kinds=kinds, members=members,
                          parameter_overrides=use_sim + mode) if sim else None
    monitor = FleetMonitor(context=context, parameter_overrides=use_sim)
    fleet = Fleet(clock, planner, agents, monitor, SingleThreadedExecutor(context=context), robots)
    for node in fleet.nodes:
        fleet.executor.add_node(node)
    return fleet


def agent_params(m: FleetMember) -> list[Parameter]:
    """The parameters of one fleet member's agent node."""
    return [Parameter("id", value=m.id), Parameter("kind", value=m.kind), Parameter("x", value=m.x),
            Parameter("y", value=m.y), Parameter("yaw", value=m.yaw), Parameter("battery", value=m.battery)]


# -------------------------------------------------------------------------------------------------
# one process per node
#: the process fleet's clock: simulated s of lost ticks made up, and how far it may run ahead of the
#: newest robot status (a starved fleet-sim holds it; 5 status periods)
CLOCK_CATCH_UP_S, CLOCK_MAX_LEAD_S = 1.0, 0.5
#: wall seconds at least that the process fleet's clock waits for a starved fleet-sim before it runs on
#: unheld (a loaded machine starves it for seconds; the clock's own default, 1 s, was 3 simulated s at 3x:
#: the planner's offline timeout, and a whole fleet went offline at once)
CLOCK_LEAD_GRACE_S = 10.0


def clock_lead_grace(offline_timeout_s: float) -> float:
    """Wall seconds the process fleet's clock waits for a starved robot simulator: at least the
    planner's ``offline_timeout_s`` (simulated s), so that holding the clock never makes a robot look
    offline sooner than on a real-time clock (while held no simulated time passes; after the wait it
    runs at the rate, and the planner counts the silence from there), and at least
    :data:`CLOCK_LEAD_GRACE_S`."""
    return max(CLOCK_LEAD_GRACE_S, float(offline_timeout_s))


def _ros_parameters(params_file: Path) -> dict:
    """The first ros__parameters table of a planner parameters file (empty if none)."""
    data = yaml.safe_load(Path(params_file).read_text()) or {}
    return next((v["ros__parameters"] for v in data.values()
                 if isinstance(v, dict) and isinstance(v.get("ros__parameters"), dict)), {})


def planner_param(params_file: Path, name: str, default: float) -> float:
    """A number of a planner ros__parameters file (``default`` when it is not there)."""
    value = _ros_parameters(params_file).get(name)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else default
# -------------------------------------------------------------------------------------------------
def node_command(script: str, module: str) -> list[str]:
    """How to start a node as a process: the console script beside this Python, else ``-m module``."""
    exe = Path(sys.executable).parent / script
    return [str(exe)] if exe.is_file() and os.access(exe, os.X_OK) else [sys.executable, "-m", module]


def start_processes(members: Sequence[FleetMember], rate: float, params_file: Path, warehouse_file: Path | None,
                    kinds_file: Path | None = None, log_dir: Path | None = None,
                    coordination: str = "central", fleet_file: Path | None = None,
                    job_store: str | Path | None = None) -> list[subprocess.Popen]:
    """Sim clock, planner and agents as processes in this environment (stop them with stop_processes).
    With ``fleet_file`` (holding ``members``) one ``fleet-sim`` process drives all the robots
    instead of one agent process each; ``job_store`` is the planner's (None: the params file's, by
    default under the ROS home)."""
    common = ["-p", f"coordination:={coordination}"]
    if warehouse_file:
        common += ["-p", f"warehouse_file:={warehouse_file}"]
    if kinds_file:
        common += ["-p", f"kinds_file:={kinds_file}"]
    sim = ["-p", "use_sim_time:=true"]
    # the clock makes up ticks lost to a busy machine and waits for a starved robot simulator (sim_clock.py)
    clock = ["--catch-up", str(CLOCK_CATCH_UP_S), "--max-lead", str(CLOCK_MAX_LEAD_S),
             "--lead-grace", str(clock_lead_grace(planner_param(params_file, "offline_timeout_s",
                                                                DispatchParams().offline_timeout_s)))]
    commands = {"sim_clock": [sys.executable, "-m", "fleet_planner.ros.sim_clock", "--rate", str(rate)] + clock,
                "planner": _profiled("planner", node_command("planner", "fleet_planner.ros.planner_node"))
                + ["--ros-args", "--params-file", str(params_file)] + sim + common
                + ([] if job_store is None else ["-p", f"job_store:={job_store}"])}
    if fleet_file is not None:
        commands["fleet_sim"] = _profiled("fleet_sim", node_command("fleet-sim", "fleet_planner.ros.fleet_sim")) + [
            "--ros-args", "-p", f"fleet_file:={fleet_file}"] + sim + common
    for m in members if fleet_file is None else ():
        commands[f"agent_{m.id}"] = node_command("robot_agent", "robot_agent.agent_node") + [
            "--ros-args", "-r", f"__node:=agent_{m.id}", "-p", f"id:={m.id}", "-p", f"kind:={m.kind}",
            "-p", f"x:={m.x!r}", "-p", f"y:={m.y!r}", "-p", f"yaw:={m.yaw!r}", "-p", f"battery:={m.battery!r}"] \
            + sim + common
    procs: list[subprocess.Popen] = []
    env = {**os.environ, "RCUTILS_LOGGING_BUFFERED_STREAM": "1"}  # a log line reaches the file when written
    try:
        for name, cmd in commands.items():
            if log_dir is None:
                procs.append(subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, env=env,
                                              preexec_fn=_end_with_parent))
                continue
            with open(log_dir / f"{name}.log", "w") as log:  # the child keeps its own copy open
                procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env,
                                              preexec_fn=_end_with_parent))
    except BaseException:
        stop_processes(procs)
        raise
    return procs


#: a directory: the planner and fleet-sim processes run under cProfile, their profiles written there
PROFILE_ENV = "FLEET_DEMO_PROFILE"


def _profiled(name: str, cmd: list[str]) -> list[str]:
    """``cmd`` under cProfile (profile in $FLEET_DEMO_PROFILE/<name>.prof) when that variable is set."""
    where = os.environ.get(PROFILE_ENV)
    if not where:
        return cmd
    module = {"planner": "fleet_planner.ros.planner_node", "fleet_sim": "fleet_planner.ros.fleet_sim"}[name]
    return [sys.executable, "-m", "cProfile", "-o", str(Path(where) / f"{name}.prof"), "-m", module]


def _end_with_parent() -> None:
    """In a child before it runs its node (Linux): SIGTERM to it when the process that started it
    dies, however it dies (even by SIGKILL), so no node outlives its fleet; the nodes end cleanly on
    SIGTERM (rclpy's handler shuts their context down). Elsewhere nothing."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


#: prctl(2) option: the signal a process gets when its parent dies
_PR_SET_PDEATHSIG = 1


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


def parking_of(params_file: Path) -> list[tuple[float, float]]:
    """The parking spots of a planner ros__parameters file (what the planner of a process fleet uses)."""
    flat: list[float] = _ros_parameters(params_file).get("parking", [])
    return [(flat[i], flat[i + 1]) for i in range(0, len(flat) - 1, 2)]


def write_fleet_file(members: Sequence[FleetMember], path: Path) -> Path:
    """``members`` as a fleet file (config/fleet.yaml's format) at ``path``."""
    robots = [{"id": m.id, "kind": m.kind, "x": m.x, "y": m.y, "yaw": m.yaw, "battery": m.battery} for m in members]
    Path(path).write_text(yaml.safe_dump({"robots": robots}, sort_keys=False))
    return Path(path)
