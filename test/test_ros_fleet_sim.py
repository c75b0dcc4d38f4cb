"""30 simulated robots in one ``fleet-sim`` process and the planner in another (and the sim clock in
a third), talking over DDS as a real fleet does: every job submitted is done, and the positions the
robots report never come closer than the sum of their radii (checked here from the statuses, not
by the planner)."""
import time

import rclpy
import yaml
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from fleet_planner.fleet.placement import parking_spots, place_robots, warehouse_for
from fleet_planner.robots import load_kinds
from fleet_planner.ros.demo import TERMINAL, FleetMonitor, random_jobs, start_processes, stop_processes
from fleet_planner.ros.demo.bringup import write_fleet_file
from fleet_planner.warehouse import config_path, save_warehouse

ROBOTS, JOBS, RATE = 30, 10, 3.0


def write_config(tmp_path):
    """Kinds with short picks and places, the demo's planner parameters with a patient offline
    timeout (a loaded machine), and a fleet file of ROBOTS robots on free spots."""
    kinds = yaml.safe_load(config_path("robot_kinds.yaml").read_text())
    for spec in kinds.values():
        spec.update(pick_s=2, place_s=2)
        if "lift_s" in spec:
            spec["lift_s"] = 1
    (tmp_path / "kinds.yaml").write_text(yaml.safe_dump(kinds))
    loaded = load_kinds(tmp_path / "kinds.yaml")
    warehouse = warehouse_for(ROBOTS)
    save_warehouse(warehouse, tmp_path / "warehouse.yaml")
    members = place_robots(warehouse, loaded, ROBOTS)
    params = yaml.safe_load(config_path("planner_params.yaml").read_text())
    params["/**"]["ros__parameters"]["offline_timeout_s"] = 10.0
    params["/**"]["ros__parameters"]["parking"] = [v for p in parking_spots(warehouse, members) for v in p]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    return (tmp_path / "params.yaml", tmp_path / "kinds.yaml", tmp_path / "warehouse.yaml",
            write_fleet_file(members, tmp_path / "fleet.yaml"), members, loaded, warehouse)


def test_thirty_simulated_robots_in_one_process_do_every_job_without_contact(tmp_path):
    params, kinds_file, warehouse_file, fleet_file, members, kinds, warehouse = write_config(tmp_path)
    jobs = random_jobs(warehouse, kinds, members, JOBS, seed=3)
    procs = start_processes(members, RATE, params, warehouse_file, kinds_file, log_dir=tmp_path, fleet_file=fleet_file)
    context = Context()
    rclpy.init(context=context)
    monitor = FleetMonitor(context=context, parameter_overrides=[Parameter("use_sim_time", value=True)])
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(monitor)

    def logs():
        return "\n".join(f"--- {p.name}\n{p.read_text()[-3000:]}" for p in sorted(tmp_path.glob("*.log")))

    try:
        deadline = time.monotonic() + 30
        while not (monitor.planner_ready() and len(monitor.status) == ROBOTS) and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert len(monitor.status) == ROBOTS, f"robots heard: {sorted(monitor.status)}\n{logs()}"
        for job in jobs:
            monitor.submit(job)
        deadline = time.monotonic() + 150
        while time.monotonic() < deadline and not all(
                monitor.last_event.get(j.id) is not None and monitor.last_event[j.id].event in TERMINAL for j in jobs):
            executor.spin_once(timeout_sec=0.1)
        states = {j.id: (monitor.last_event[j.id].event if j.id in monitor.last_event else None) for j in jobs}
        assert all(s == "done" for s in states.values()), f"{states}\n{logs()}"
        gap, a, b, t = monitor.min_separation()
        assert gap >= 0.0, f"robots {a} and {b} overlapped by {-gap:.3f} m at t = {t}"
        assert all(p.poll() is None for p in procs), f"a process died\n{logs()}"
    finally:
        executor.shutdown()
        monitor.destroy_node()
        rclpy.try_shutdown(context=context)
        stop_processes(procs)
