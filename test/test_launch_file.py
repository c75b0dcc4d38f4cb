"""launch/fleet.launch.py, checked without running it (the ``launch`` package is not on our
registry): it is valid Python that setup.py installs, every executable it starts is one of our
console scripts, every parameter it sets is one its node declares, every launch argument it reads
is declared, and every config file it names is shipped."""
import ast
import re
from pathlib import Path

import pytest
from test_packaging import ENTRY_POINT, setup_kwargs  # noqa: F401 - the fixture

ROOT = Path(__file__).resolve().parent.parent
LAUNCH = ROOT / "launch" / "fleet.launch.py"
TREE = ast.parse(LAUNCH.read_text(encoding="utf-8"), str(LAUNCH))
#: the node each executable runs, and so the parameters it may be given
SOURCES = {"planner": "fleet_planner/ros/planner_node.py", "robot_agent": "robot_agent/agent_node.py",
           "sim_clock": "fleet_planner/ros/sim_clock.py", "fleet-console": "fleet_planner/ros/console/__init__.py"}
#: parameters every rclpy node has
BUILT_IN = {"use_sim_time"}


def node_calls():
    return [n for n in ast.walk(TREE) if isinstance(n, ast.Call) and getattr(n.func, "id", None) == "Node"]


def keyword(call, name):
    return next((k.value for k in call.keywords if k.arg == name), None)


def declared(source: str) -> set[str] | None:
    """The parameters a node's source declares (None if the module is not on this branch yet)."""
    path = ROOT / source
    if not path.is_file():
        return None
    text = "".join(p.read_text(encoding="utf-8") for p in sorted(path.parent.glob("*.py"))) \
        if path.name == "__init__.py" else path.read_text(encoding="utf-8")
    names = set(re.findall(r"declare_parameter\(\s*\"(\w+)\"", text))
    if "fields(DispatchParams)" in text:  # the planner declares one parameter per dispatch parameter
        from fleet_planner.fleet import DispatchParams
        names |= set(DispatchParams.RANGES)
    return names


def test_the_launch_file_is_installed(setup_kwargs):  # noqa: F811
    data = dict(setup_kwargs["data_files"])
    assert "launch/fleet.launch.py" in data["share/fleet_planner/launch"]


def test_every_executable_is_one_of_our_console_scripts(setup_kwargs):  # noqa: F811
    scripts = {ENTRY_POINT.match(e)["name"] for e in setup_kwargs["entry_points"]["console_scripts"]}
    calls = node_calls()
    executables = {keyword(c, "executable").value for c in calls}
    assert executables == {"sim_clock", "planner", "robot_agent", "fleet-console"}
    assert executables <= scripts
    assert all(keyword(c, "package").id == "PACKAGE" for c in calls)
    assert 'PACKAGE = "fleet_planner"' in LAUNCH.read_text()


@pytest.mark.parametrize("executable", ["planner", "robot_agent", "fleet-console"])
def test_every_parameter_it_sets_is_declared_by_its_node(executable):
    call = next(c for c in node_calls() if keyword(c, "executable").value == executable)
    given = set()
    for item in ast.walk(keyword(call, "parameters")):
        if isinstance(item, ast.Dict):
            given |= {k.value for k in item.keys if isinstance(k, ast.Constant)}
            given |= {"use_sim_time", "warehouse_file", "kinds_file"} if any(k is None for k in item.keys) else set()
    names = declared(SOURCES[executable])
    if names is None:
        pytest.skip(f"{SOURCES[executable]} is not on this branch")
    assert given - BUILT_IN <= names, given - BUILT_IN - names


def test_every_launch_argument_read_is_declared_and_the_config_files_are_shipped(setup_kwargs):  # noqa: F811
    text = LAUNCH.read_text()
    arguments = next(n for n in ast.walk(TREE) if isinstance(n, ast.Assign)
                     and getattr(n.targets[0], "id", None) == "ARGUMENTS")
    declared_args = {k.value for k in arguments.value.keys}
    read = set(re.findall(r'arg\["(\w+)"\]', text))
    assert read <= declared_args, read - declared_args
    assert all(text.count(f'"{name}"') >= 2 for name in declared_args)  # each declared one is used
    shipped = dict(setup_kwargs["data_files"])["share/fleet_planner/config"]
    for name in re.findall(r'"config", "([\w.]+)"', text):
        assert f"config/{name}" in shipped, name
    assert {"fleet.yaml", "planner_params.yaml"} <= set(re.findall(r'"config", "([\w.]+)"', text))
