"""The whole fleet on a full ROS 2 install (issue 12, ROS conventions): the simulated clock, the
planner, one robot agent per robot of the fleet file and the web operator console.

    ros2 launch fleet_planner fleet.launch.py
    ros2 launch fleet_planner fleet.launch.py namespace:=site_a fleet_file:=/path/fleet.yaml rate:=5.0
    ros2 launch fleet_planner fleet.launch.py use_sim_time:=false console:=false

The fleet file's robot ids are also the planner's roster (statuses of other ids are ignored).
Topic names are relative: with ``namespace:=site_a`` every node runs in ``/site_a`` and the fleet
talks on ``/site_a/fleet/...``, so two fleets run side by side (launch the second with
``sim_clock:=false``: ``/clock`` is one for all). Keys (fleet_planner/auth.py): ``planner_key``
(the planner signs with it, the agents trust it) and ``client_keys`` (tasks must be signed with
one of them). Not run in our tests (the ``launch`` package is not on PyPI):
test/test_launch_file.py checks statically that every executable, parameter and file named here
exists.
"""
import os

import yaml
from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, GroupAction, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node, PushRosNamespace

from launch import LaunchDescription

PACKAGE = "fleet_planner"
ARGUMENTS = {
    "namespace": ("", "namespace of the whole fleet (empty: the root)"),
    "fleet_file": ("", "fleet YAML: the robots to start and the planner's roster (empty: config/fleet.yaml)"),
    "params_file": ("", "planner ros__parameters YAML (empty: config/planner_params.yaml)"),
    "warehouse_file": ("", "warehouse YAML (empty: the shipped config/warehouse.yaml)"),
    "kinds_file": ("", "robot kinds YAML (empty: the shipped config/robot_kinds.yaml)"),
    "use_sim_time": ("true", "run the fleet on the simulated clock"),
    "sim_clock": ("true", "start the simulated clock (with use_sim_time)"),
    "rate": ("10.0", "simulated seconds per wall second"),
    "console": ("true", "start the web operator console (fleet-console)"),
    "planner_key": ("", "key file the planner signs with and the agents trust (empty: no signatures)"),
    "client_keys": ("", "key file of the clients whose signed tasks the planner takes (empty: any task)"),
}


def _nodes(context, *args, **kwargs):
    arg = {name: LaunchConfiguration(name).perform(context) for name in ARGUMENTS}
    share = get_package_share_directory(PACKAGE)
    fleet_file = arg["fleet_file"] or os.path.join(share, "config", "fleet.yaml")
    params_file = arg["params_file"] or os.path.join(share, "config", "planner_params.yaml")
    sim = arg["use_sim_time"].lower() == "true"
    common = {"use_sim_time": sim}
    for name in ("warehouse_file", "kinds_file"):
        if arg[name]:
            common[name] = arg[name]
    with open(fleet_file, encoding="utf-8") as f:
        robots = yaml.safe_load(f)["robots"]

    nodes = []
    if sim and arg["sim_clock"].lower() == "true":
        nodes.append(Node(package=PACKAGE, executable="sim_clock", name="sim_clock",
                          arguments=["--rate", arg["rate"]], output="screen"))
    nodes.append(Node(package=PACKAGE, executable="planner", name="planner", output="screen", parameters=[
        params_file, {**common, "fleet_file": fleet_file, "auth_key_file": arg["planner_key"],
                      "auth_trust_file": arg["client_keys"]}]))
    for r in robots:
        nodes.append(Node(package=PACKAGE, executable="robot_agent", name=f"agent_{r['id']}", output="screen",
                          parameters=[{**common, "id": r["id"], "kind": r["kind"], "x": float(r["x"]),
                                       "y": float(r["y"]), "yaw": float(r.get("yaw", 0.0)),
                                       "battery": float(r.get("battery", 1.0)), "planner": "planner",
                                       "fleet_file": fleet_file,
                                       "auth_trust_file": arg["planner_key"]}]))
    if arg["console"].lower() == "true":
        nodes.append(Node(package=PACKAGE, executable="fleet-console", name="fleet_console", output="screen",
                          parameters=[common]))
    if arg["namespace"]:
        return [GroupAction([PushRosNamespace(arg["namespace"]), *nodes])]
    return nodes


def generate_launch_description():
    return LaunchDescription([
        *(DeclareLaunchArgument(name, default_value=default, description=text)
          for name, (default, text) in ARGUMENTS.items()),
        OpaqueFunction(function=_nodes),
    ])
