"""The fleet as separate processes talking over DDS: the simulated clock, the planner and two agents
started as console scripts (configured by files, as a user would), and ``fleet-submit`` as a process
too: one job goes in and must come back ``done`` with exit code 0."""
import subprocess

import yaml

from fleet_planner.fleet import FleetMember
from fleet_planner.ros.demo.bringup import node_command, start_processes, stop_processes
from fleet_planner.warehouse import config_path, generate_warehouse, save_warehouse

WH = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)
CHARGERS = [s.pose for s in WH.stations_of("charger")]
MEMBERS = [FleetMember("p1", "cargo", *CHARGERS[0]), FleetMember("p2", "manipulator_forklift", *CHARGERS[2])]


def write_config(tmp_path):
    """A small warehouse, kinds with short picks and places, and a planner params file (/** wildcard)."""
    save_warehouse(WH, tmp_path / "warehouse.yaml")
    kinds = yaml.safe_load(config_path("robot_kinds.yaml").read_text())
    for spec in kinds.values():
        spec.update(pick_s=2, place_s=2)
        if "lift_s" in spec:
            spec["lift_s"] = 1
    (tmp_path / "kinds.yaml").write_text(yaml.safe_dump(kinds))
    params = {"/**": {"ros__parameters": {"step_period_s": 0.5, "offline_timeout_s": 10.0,
                                          "parking": [10.75, 11.75, 12.75, 11.75]}}}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    return tmp_path / "params.yaml", tmp_path / "warehouse.yaml", tmp_path / "kinds.yaml"


def test_a_job_submitted_from_the_command_line_is_done_by_robots_in_other_processes(tmp_path):
    params, warehouse, kinds = write_config(tmp_path)
    procs = start_processes(MEMBERS, 5.0, params, warehouse, kinds, log_dir=tmp_path)
    try:
        submit = subprocess.run(
            node_command("fleet-submit", "fleet_planner.ros.submit")
            + ["--pick", "chute_2", "--place", "B03-02", "--needs", "forklift", "--id", "P1", "--timeout", "75"],
            capture_output=True, text=True, timeout=100)
        logs = "\n".join(f"--- {p.name}\n{p.read_text()[-2000:]}" for p in sorted(tmp_path.glob("*.log")))
        assert submit.returncode == 0, f"{submit.stdout}\n{submit.stderr}\n{logs}"
        lines = submit.stdout.splitlines()
        seen = [ln.split("] ", 1)[1].split()[1] for ln in lines]
        # every event in order; "accepted" may be missed when the planner's writer matches our reader a
        # moment after our reader matched it (DDS discovery is not symmetric; noted in the issue 9 note)
        full = ["accepted", "assigned", "picked", "placed", "done"]
        assert seen in (full, full[1:]), submit.stdout + submit.stderr
        assert "P1 assigned to p2" in submit.stdout  # the only robot with a forklift
        assert all(p.poll() is None for p in procs), "a node died during the run"
    finally:
        stop_processes(procs)
