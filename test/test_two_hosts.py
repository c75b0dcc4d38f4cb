"""The fleet across two hosts (issue 9, deliverable 7): two network namespaces joined by a veth
pair stand for two machines. The simulated clock, the planner and ``fleet-submit`` run in one,
the agents in the other, with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` and only the UDPv4
transport (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``: no shared memory, so every byte crosses the
veth); a job goes in and must come back done. The namespaces see nothing but each other (no
route leaves them), and they are removed whatever happens. Needs root and ``ip`` (iproute2);
skipped otherwise."""
import os
import shutil
import subprocess
import uuid

import pytest
from test_ros_processes import MEMBERS, write_config

from fleet_planner.ros.demo.bringup import node_command, stop_processes

SUBNET = "10.213.77"


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=10)


@pytest.fixture
def two_hosts():
    if shutil.which("ip") is None:
        pytest.skip("needs iproute2's ip to make network namespaces")
    if os.geteuid() != 0:
        pytest.skip("needs root to make network namespaces and a veth pair")
    tag = uuid.uuid4().hex[:6]
    hosts = [f"fleet_a_{tag}", f"fleet_b_{tag}"]
    links = [f"vfa{tag}", f"vfb{tag}"]
    made: list[str] = []
    try:
        for ns in hosts:
            try:
                ip("netns", "add", ns)
            except subprocess.CalledProcessError as exc:
                pytest.skip(f"cannot make a network namespace here: {exc.stderr.strip()}")
            made.append(ns)
        ip("link", "add", links[0], "type", "veth", "peer", "name", links[1])
        for k, (ns, link) in enumerate(zip(hosts, links)):
            ip("link", "set", link, "netns", ns)
            ip("-n", ns, "addr", "add", f"{SUBNET}.{k + 1}/24", "dev", link)
            ip("-n", ns, "link", "set", link, "up", "multicast", "on")
            ip("-n", ns, "link", "set", "lo", "up")
            ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", link)  # discovery multicast over the veth
        yield list(zip(hosts, links))
    finally:
        for ns in made:  # deleting a namespace deletes its end of the veth, and so the pair
            subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=10)
        # a pair never moved into the namespaces (set-up failed half way) is still here: remove it
        subprocess.run(["ip", "link", "del", links[0]], capture_output=True, timeout=10)


def test_a_job_is_done_by_agents_on_another_host(two_hosts, tmp_path):
    (planner_host, planner_link), (robot_host, robot_link) = two_hosts
    params, warehouse, kinds = write_config(tmp_path)
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4",
           "ROS_DOMAIN_ID": os.environ.get("ROS_DOMAIN_ID", "13")}
    env.pop("ROS_STATIC_PEERS", None)
    common = ["-p", f"warehouse_file:={warehouse}", "-p", f"kinds_file:={kinds}", "-p", "use_sim_time:=true"]

    def on(host: str, cmd: list[str]) -> list[str]:
        return ["ip", "netns", "exec", host, *cmd]

    commands = {"sim_clock": on(planner_host, node_command("sim_clock", "fleet_planner.ros.sim_clock")
                                + ["--rate", "5"]),
                "planner": on(planner_host, node_command("planner", "fleet_planner.ros.planner_node")
                              + ["--ros-args", "--params-file", str(params), *common])}
    for m in MEMBERS:
        commands[f"agent_{m.id}"] = on(robot_host, node_command("robot_agent", "robot_agent.agent_node") + [
            "--ros-args", "-r", f"__node:=agent_{m.id}", "-p", f"id:={m.id}", "-p", f"kind:={m.kind}",
            "-p", f"x:={m.x!r}", "-p", f"y:={m.y!r}", *common])
    procs = []
    try:
        for name, cmd in commands.items():
            with open(tmp_path / f"{name}.log", "w") as log:
                procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env))
        submit = subprocess.run(
            on(planner_host, node_command("fleet-submit", "fleet_planner.ros.submit")
               + ["--pick", "chute_2", "--place", "B03-02", "--needs", "forklift", "--id", "H1", "--timeout", "90"]),
            capture_output=True, text=True, timeout=120, env=env)
        logs = "\n".join(f"--- {p.name}\n{p.read_text()[-1500:]}" for p in sorted(tmp_path.glob("*.log")))
        assert submit.returncode == 0, f"{submit.stdout}\n{submit.stderr}\n{logs}"
        assert "H1 assigned to p2" in submit.stdout and "H1 done" in submit.stdout
        assert all(p.poll() is None for p in procs), f"a node died during the run\n{logs}"
        for host, link in two_hosts:  # it all went over the veth pair
            stats = subprocess.run(["ip", "netns", "exec", host, "cat", f"/sys/class/net/{link}/statistics/rx_bytes"],
                                   capture_output=True, text=True, timeout=10)
            assert int(stats.stdout) > 100_000, (host, stats.stdout)
    finally:
        stop_processes(procs)
