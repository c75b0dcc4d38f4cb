"""Packaging as ROS users expect it: package.xml, setup.py's entry points and data files, setup.cfg's
script directories (for `ros2 run`), and the test run's ROS environment."""
from __future__ import annotations

import configparser
import importlib
import importlib.util
import os
import re
import runpy
import xml.etree.ElementTree as ET
from pathlib import Path
from unittest import mock

import pytest

import fleet_planner

ROOT = Path(__file__).resolve().parent.parent
EXEC_DEPENDS = {"rclpy", "std_msgs", "geometry_msgs", "nav_msgs", "visualization_msgs", "python3-numpy",
                "python3-shapely", "python3-yaml", "python3-matplotlib", "python3-scipy", "python3-tqdm"}
CONSOLE_SCRIPTS = {"fleet-plan", "planner", "robot_agent", "fleet-demo", "fleet-submit", "fleet-op", "sim_clock",
                   "fleet-console", "fleet-people", "fleet-record", "fleet-replay", "fleet-sim"}
ENTRY_POINT = re.compile(r"^(?P<name>[\w-]+) = (?P<module>\w+(\.\w+)*):(?P<func>\w+)$")


@pytest.fixture(scope="module")
def setup_kwargs() -> dict:
    """What setup.py hands to setuptools.setup, evaluated from the repo root as colcon and pip do."""
    captured: dict = {}
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        with mock.patch("setuptools.setup", lambda **kw: captured.update(kw)):
            runpy.run_path(str(ROOT / "setup.py"), run_name="__main__")
    finally:
        os.chdir(cwd)
    return captured


def test_package_xml_is_format_3_with_the_dependencies():
    root = ET.parse(ROOT / "package.xml").getroot()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == "fleet_planner"
    assert root.findtext("version") == fleet_planner.__version__
    assert EXEC_DEPENDS <= {e.text for e in root.findall("exec_depend")}
    assert {"python3-pytest", "python3-hypothesis"} <= {e.text for e in root.findall("test_depend")}
    assert root.findtext("export/build_type") == "ament_python"


def test_setup_py_packages_and_data_files(setup_kwargs):
    assert setup_kwargs["name"] == "fleet_planner" and setup_kwargs["version"] == fleet_planner.__version__
    packages = set(setup_kwargs["packages"])
    assert {"fleet_planner", "fleet_planner.planners", "fleet_planner.ros", "robot_agent", "msg_schemas"} <= packages
    data = dict(setup_kwargs["data_files"])
    assert data["share/ament_index/resource_index/packages"] == ["resource/fleet_planner"]
    assert data["share/fleet_planner"] == ["package.xml"]
    assert {"config/warehouse.yaml", "config/warehouse.map", "config/default_scenario.yaml"} <= set(
        data["share/fleet_planner/config"])
    for files in data.values():
        assert all((ROOT / f).is_file() for f in files), files


def test_console_scripts_are_well_formed_and_point_at_main(setup_kwargs):
    entries = setup_kwargs["entry_points"]["console_scripts"]
    parsed = [ENTRY_POINT.match(e) for e in entries]
    assert all(parsed), [e for e, m in zip(entries, parsed) if not m]
    assert {m["name"] for m in parsed} == CONSOLE_SCRIPTS
    for m in parsed:
        # modules still being written are skipped; those that exist must have the function
        spec = importlib.util.find_spec(m["module"])
        if spec is not None and spec.origin and Path(spec.origin).is_relative_to(ROOT):  # (not another checkout's)
            assert callable(getattr(importlib.import_module(m["module"]), m["func"], None)), m.group(0)


def test_setup_cfg_installs_scripts_where_ros2_run_looks():
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / "setup.cfg")
    assert cfg["develop"]["script_dir"] == "$base/lib/fleet_planner"
    assert cfg["install"]["install_scripts"] == "$base/lib/fleet_planner"


def test_ros_stays_on_this_machine_in_a_domain_of_its_own():
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert 0 <= int(os.environ["ROS_DOMAIN_ID"]) <= 232


def test_ros_context_fixture_gives_a_live_context(ros_context):
    import rclpy

    assert rclpy.ok(context=ros_context)
    node = rclpy.create_node("packaging_probe", context=ros_context)
    try:
        assert node.get_name() == "packaging_probe"
    finally:
        node.destroy_node()
