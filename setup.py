"""ament_python package definition (colcon build, and `pip install -e .` in a virtualenv).

Dependencies are not listed here, following ROS habit: on a ROS install they come from apt via
package.xml (rosdep), in a virtualenv from requirements.txt (scripts/setup.sh).
"""
from glob import glob

from setuptools import find_packages, setup

package_name = "fleet_planner"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["fleet_planner", "fleet_planner.*", "robot_agent", "robot_agent.*",
                                    "msg_schemas", "msg_schemas.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", sorted(glob("config/*.yaml") + glob("config/*.map"))),
        ("share/" + package_name + "/launch", sorted(glob("launch/*.launch.py"))),
    ],
    package_data={"fleet_planner.ros.console": ["static/*"]},  # the web console's page
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="fleet_planner maintainers",
    maintainer_email="fleet-planner@example.com",
    description="Central (M,D) collision-model fleet planner for warehouse mobile robots (ROS 2 Jazzy)",
    license="Apache-2.0",
    python_requires=">=3.10",
    entry_points={
        "console_scripts": [
            "fleet-plan = fleet_planner.cli:main",
            "planner = fleet_planner.ros.planner_node:main",
            "robot_agent = robot_agent.agent_node:main",
            "fleet-demo = fleet_planner.ros.demo:main",
            "fleet-submit = fleet_planner.ros.submit:main",
            "fleet-op = fleet_planner.ros.operate:main",
            "sim_clock = fleet_planner.ros.sim_clock:main",
            "fleet-console = fleet_planner.ros.console:main",
            "fleet-people = fleet_planner.ros.people:main",
            "fleet-record = fleet_planner.ros.record:main",
            "fleet-replay = fleet_planner.ros.replay:main",
            "fleet-sim = fleet_planner.ros.fleet_sim:main",
        ],
    },
)
