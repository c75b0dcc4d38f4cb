"""The fleet file in the validation vocabulary (fleet_planner.fleet.fleet_file): the messages of load_fleet."""
import json

import pytest

from fleet_planner.fleet.fleet_file import MEMBER_FIELDS, FleetError, read_fleet_file
from fleet_planner.robots import load_kinds
from fleet_planner.validation import ValidationError
from fleet_planner.warehouse import config_path, generate_warehouse, load_warehouse

KINDS = load_kinds()
WH = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)  # 16 m x 13 m, as test_dispatch


def test_the_shipped_fleet_reads_as_member_fields():
    members = read_fleet_file(config_path("fleet.yaml"), KINDS, load_warehouse())
    assert len(members) >= 8 and {m["kind"] for m in members} == set(KINDS)
    assert all(set(m) <= set(MEMBER_FIELDS) and isinstance(m["x"], float) for m in members)


@pytest.mark.parametrize("data, expected", [
    ({"robots": [{"id": "r1", "kind": "cargo", "x": 2.25}]}, "robots[0].y: missing"),
    ({"robots": [{"id": "r1", "kind": "cargo", "x": 2, "y": 3, "z": 1, "a": 2}]},
     "robots[0].a: unknown field (known: id, kind, x, y, yaw, battery)"),
    ({"robots": ["r1"]}, "robots[0]: expected a mapping with id, kind, x, y, yaw, battery (got 'r1')"),
    ({"robots": [{"id": "1r", "kind": "cargo", "x": 2.25, "y": 10.75}]}, "robots[0].id: must be letters"),
    ({"robots": [{"id": "r1", "kind": "drone", "x": 2.25, "y": 10.75}]},
     "robot 'r1'.kind: 'drone' is not one of cargo"),
    ({"robots": [{"id": "r1", "kind": "cargo", "x": True, "y": 10.75}]},
     "robot 'r1'.x: must be a finite number (got True)"),
    ({"robots": [{"id": "r1", "kind": "cargo", "x": 2.25, "y": 10.75, "battery": 2}]},
     "robot 'r1'.battery: must be in [0, 1] (got 2)"),
    ({"robots": [{"id": "r1", "kind": "cargo", "x": 0.1, "y": 10.75}]}, "robot 'r1': (0.1, 10.75) is not free"),
    ({"robots": [{"id": "r1", "kind": "cargo", "x": 2.25, "y": 10.75},
                 {"id": "r1", "kind": "cargo", "x": 6.25, "y": 10.75}]}, "robot 'r1'.id: used twice"),
    ({"robots": [{"id": "r1", "kind": "cargo", "x": 2.25, "y": 10.75},
                 {"id": "r2", "kind": "cargo", "x": 2.5, "y": 10.75}]}, "robot 'r2': overlaps robot 'r1'"),
    ({"robots": []}, "expected a mapping with a non-empty list 'robots'"),
    ({"robots": [{"id": "r1", "kind": "cargo", "x": 2.25, "y": 10.75}], "b": 1, "a": 2},
     "unknown key(s) a, b (known: robots)"),
])
def test_a_bad_fleet_file_names_the_file_robot_and_field(tmp_path, data, expected):
    path = tmp_path / "fleet.yaml"
    path.write_text(json.dumps(data))
    with pytest.raises(FleetError) as err:
        read_fleet_file(path, KINDS, WH)
    assert str(err.value).startswith(f"{path}: {expected}"), str(err.value)
    assert isinstance(err.value, ValidationError)


def test_unreadable_fleet_files(tmp_path):
    with pytest.raises(FleetError, match="cannot read fleet file"):
        read_fleet_file(tmp_path / "missing.yaml")
    (tmp_path / "broken.yaml").write_text("robots: [unclosed\n")
    with pytest.raises(FleetError, match="cannot read fleet file"):
        read_fleet_file(tmp_path / "broken.yaml")
