"""The validation vocabulary: one error class for every loader and record, paths, wordings, YAML files."""
import math

import pytest

from fleet_planner.fleet.fleet_file import FleetError
from fleet_planner.robots import KindsError
from fleet_planner.scenario import ScenarioError, parse_scenario
from fleet_planner.validation import ValidationError, Vocabulary, all_of, anything, in_file, optional, read_yaml
from fleet_planner.warehouse import WarehouseError, load_warehouse
from msg_schemas.records import RecordError, Task

V = Vocabulary()


@pytest.mark.parametrize("cls", [RecordError, ScenarioError, WarehouseError, KindsError, FleetError])
def test_every_loader_and_record_error_is_a_validation_error(cls):
    assert issubclass(cls, ValidationError) and issubclass(cls, ValueError)


def test_errors_carry_the_field_path():
    with pytest.raises(RecordError) as err:
        Task(id="t", pick="c", place="p", payload_kg=math.nan)
    assert (err.value.path, err.value.reason) == ("task.payload_kg", "must be a finite number (got NaN)")
    data = {"map": {"rows": ["...."]}, "robots": [{"id": "r1", "radius": -1, "max_speed": 1, "start": [0.5, 0.5],
                                                  "goal": [3.5, 0.5]}]}
    with pytest.raises(ScenarioError) as err:
        parse_scenario(data, ".")
    assert err.value.path == "robots[0].radius" and str(err.value).startswith("robots[0].radius: ")


def test_the_file_goes_in_front_and_the_path_stays(tmp_path):
    (tmp_path / "w.yaml").write_text("map: {rows: ['....'], size: 3}\nstations: []\n")
    with pytest.raises(WarehouseError) as err:
        load_warehouse(tmp_path / "w.yaml")
    assert str(err.value) == f"{tmp_path / 'w.yaml'}: map.size: unknown key (allowed: file, rows, resolution)"
    assert err.value.path == "map.size"
    with pytest.raises(ValidationError, match=r"^f\.yaml: x: must be"), in_file("f.yaml", ValidationError):
        V.number()("1", "x")


@pytest.mark.parametrize("check, value, message", [
    (V.number(), True, "v: must be a finite number (got True)"),
    (V.number(), math.inf, "v: must be a finite number (got inf)"),
    (V.number(0, 1), 2, "v: must be in [0, 1] (got 2)"),
    (V.number(above=0), 0, "v: must be > 0 (got 0)"),
    (V.integer(lo=1), 0, "v: must be >= 1 (got 0)"),
    (V.string(min_len=1, strip=True), " ", "v: must be a non-empty string (got ' ')"),
    (V.choice(("a", "b")), "c", "v: must be one of a, b (got 'c')"),
    (V.point, [1, "x"], "v[1]: must be a finite number (got 'x')"),
    (V.list_of(V.integer(), unique=True), [1, 1], "v: 1 appears more than once"),
    (V.list_of(anything), (1,), "v: must be a list (got (1,))"),
    (V.worded(V.list_of(V.integer()), "must be a list of integers (got {got})"), [1, "2"],
     "v: must be a list of integers (got [1, '2'])"),
    (V.mapping({"a": V.integer()}, defaults={"a": 0}), {"b": 1}, "v.b: unknown key (allowed: a)"),
    (V.mapping({"a": V.integer()}), {}, "v.a: missing"),
    (V.mapping({"a": V.integer()}), [], "v: must be a mapping (got list)"),
])
def test_checks_name_the_path_and_show_the_value(check, value, message):
    with pytest.raises(ValidationError) as err:
        check(value, "v")
    assert str(err.value) == message


def test_checks_normalise():
    assert V.number()(3, "v") == 3.0 and isinstance(V.number()(3, "v"), float)
    assert V.number(above=0, infinite=True)(math.inf, "v") == math.inf
    assert V.list_of(V.point)([[1, 2]], "v") == ((1.0, 2.0),)
    assert V.mapping({"a": V.integer(), "b": V.number()}, defaults={"b": 1})({"a": 2}, "v") == {"a": 2, "b": 1.0}
    assert optional(V.integer())(None, "v") is None
    with pytest.raises(ValidationError, match=r"^v: must be > 0 \(got 0\.0\)"):
        all_of(V.number(), V.number(above=0))(0, "v")  # the second check sees the float


def test_wordings_of_a_family():
    kinds_like = Vocabulary(unknown="unknown field(s) {keys} (known: {known})", unknown_in="mapping",
                            unknown_sorted=True, missing="{key} is missing", missing_in="mapping")
    with pytest.raises(ValidationError, match=r"^k: unknown field\(s\) a, z \(known: x\)$"):
        kinds_like.keys({"z": 1, "a": 2}, "k", ["x"])
    with pytest.raises(ValidationError, match=r"^k: x is missing$"):
        kinds_like.keys({}, "k", ["x"], ["x"])
    with pytest.raises(ValidationError, match=r"^top: must be a mapping \(got int\)$"):
        Vocabulary(root="top").keys(3, "", ["x"])


def test_read_yaml(tmp_path):
    with pytest.raises(ScenarioError, match=r"nope\.yaml: cannot read thing file \("):
        read_yaml(tmp_path / "nope.yaml", ScenarioError, what="thing file")
    (tmp_path / "bad.yaml").write_text("a: [unclosed\n")
    with pytest.raises(ScenarioError, match=r"bad\.yaml: not valid YAML \("):
        read_yaml(tmp_path / "bad.yaml", ScenarioError, what="thing file")
    with pytest.raises(ScenarioError, match=r"bad\.yaml: cannot read thing file \("):
        read_yaml(tmp_path / "bad.yaml", ScenarioError, what="thing file", invalid=None)
    (tmp_path / "twice.yaml").write_text("a: 1\nb:\n  c: 1\n  c: 2\n")
    assert read_yaml(tmp_path / "twice.yaml", ScenarioError, what="thing file") == {"a": 1, "b": {"c": 2}}
    with pytest.raises(ScenarioError, match=r"twice\.yaml: line 4: duplicate key 'c'$"):
        read_yaml(tmp_path / "twice.yaml", ScenarioError, what="thing file", unique_keys=True)
