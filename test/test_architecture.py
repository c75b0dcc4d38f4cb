"""The layering of docs/ARCHITECTURE.md, checked on the code's own imports (read as text, nothing run).

* no import cycle between any two of our modules (imports inside functions count too: a lazy
  import hides a cycle, it does not remove it);
* the vocabulary floor (model, geometry, validation) imports nothing of ours;
* the wire records depend only on the floor;
* the pure core never imports rclpy or ROS message packages.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("fleet_planner", "msg_schemas", "robot_agent")
FLOOR = {"fleet_planner.model", "fleet_planner.geometry", "fleet_planner.validation"}
#: modules that may talk ROS; everything else of ours is the pure core
ROS_GLUE_PREFIXES = ("fleet_planner.ros", "robot_agent", "msg_schemas.topics", "msg_schemas.convert")
ROS_PACKAGES = {"rclpy", "std_msgs", "geometry_msgs", "nav_msgs", "visualization_msgs", "builtin_interfaces",
                "rcl_interfaces", "rosgraph_msgs", "std_srvs", "sensor_msgs", "action_msgs"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((REPO / pkg).rglob("*.py")):
            out[_module_name(path)] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> tuple[set[str], set[str]]:
    """(our modules that ``name`` imports, top-level names of the other packages it imports)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    ours, others = set(), set()

    def add(target: str) -> None:
        if target.split(".")[0] in PACKAGES:
            while target and target not in MODULES:   # "pkg.mod.Name" -> "pkg.mod"
                target = target.rpartition(".")[0]
            if target and target != name:
                ours.add(target)
        else:
            others.add(target.split(".")[0])

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            for alias in node.names:
                sub = f"{module}.{alias.name}"
                add(sub if sub in MODULES else module)
    return ours, others


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _cycle() -> list[str] | None:
    """One import cycle among our modules, or None (iterative DFS with colours)."""
    colour = dict.fromkeys(GRAPH, 0)
    for root in sorted(GRAPH):
        if colour[root]:
            continue
        stack = [(root, iter(sorted(GRAPH[root][0])))]
        trail = [root]
        colour[root] = 1
        while stack:
            node, children = stack[-1]
            child = next(children, None)
            if child is None:
                colour[node] = 2
                stack.pop()
                trail.pop()
            elif colour.get(child) == 1:
                return trail[trail.index(child):] + [child]
            elif colour.get(child) == 0:
                colour[child] = 1
                stack.append((child, iter(sorted(GRAPH[child][0]))))
                trail.append(child)
    return None


def test_the_walk_sees_the_code():
    assert len(MODULES) > 20
    assert "fleet_planner.model" in GRAPH["fleet_planner.checker"][0]
    assert "rclpy" in GRAPH["fleet_planner.ros.planner_node"][1]


def test_no_import_cycle():
    cycle = _cycle()
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


@pytest.mark.parametrize("floor", sorted(FLOOR & set(MODULES)))
def test_the_vocabulary_floor_imports_nothing_of_ours(floor):
    assert GRAPH[floor][0] == set(), f"{floor} imports {sorted(GRAPH[floor][0])}"


def test_wire_records_depend_only_on_the_floor():
    assert GRAPH["msg_schemas.records"][0] <= FLOOR, sorted(GRAPH["msg_schemas.records"][0] - FLOOR)


@pytest.mark.parametrize("name", sorted(n for n in MODULES if not n.startswith(ROS_GLUE_PREFIXES)))
def test_the_pure_core_imports_no_ros(name):
    ros = GRAPH[name][1] & ROS_PACKAGES
    assert not ros, f"{name} imports {sorted(ros)}"
    glue = {m for m in GRAPH[name][0] if m.startswith(ROS_GLUE_PREFIXES)}
    assert not glue, f"{name} imports the ROS glue {sorted(glue)}"
