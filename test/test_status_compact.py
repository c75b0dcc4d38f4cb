"""The compact robot status (``fleet/robot_status@2``, issue 10): the same record in about half the
bytes, read by the same parser as the old form, validated field by field; and the status's fast
construction (floats in range skip their checks) accepts and refuses exactly what the checks do."""
import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleet_planner.fleet.inbox import StatusInbox
from fleet_planner.validation import check_fields
from msg_schemas.records import (
    _STATUS_FLOATS,
    COMPACT_FIELDS,
    COMPACT_ROUNDING,
    INT_MAX,
    Neighbours,
    RecordError,
    RobotStatus,
    _status_checks,
)

BEHAVIOR = {"name": "FollowWayPoint", "next": [2.0, 3.0], "remaining": 4.5, "straight": 1.0, "station": None,
            "partner": "r2", "no_space": False, "docked_at": None, "dock_since": None}


def status(**over) -> RobotStatus:
    fields = dict(id="r12", kind="cargo", x=12.345678901, y=-3.45678912, yaw=1.5707963, vx=0.4999999,
                  vy=-0.0001234, battery=0.912345678, mode="driving", progress=0.51234567, stamp=123.456789,
                  radius=0.35, task_id='t "12"', path_id=1796182134055028518, lateness_s=0.1234567,
                  travelled_m=3.2123456, loaded=True)
    fields.update(over)
    return RobotStatus(**fields)


def same_up_to_rounding(a: RobotStatus, b: RobotStatus) -> None:
    for name in ("id", *COMPACT_FIELDS):
        x, y = getattr(a, name), getattr(b, name)
        if name in COMPACT_ROUNDING and x is not None:
            tol = 10 ** -COMPACT_ROUNDING[name]
            assert abs(x - y) <= tol * 0.5 + 1e-12 if name not in ("progress", "travelled_m") \
                else 0.0 <= x - y < tol + 1e-12, name
        else:
            assert x == y, name


@pytest.mark.parametrize("over", [{}, {"task_id": None, "path_id": None, "travelled_m": None, "loaded": None},
                                  {"behavior": BEHAVIOR, "manual": True, "estop": False, "rejected_path_id": 4,
                                   "placed_task_id": 't "11"'},
                                  {"progress": 1.0, "x": -0.0, "battery": 0.0, "lateness_s": 0.0}])
def test_compact_round_trip(over):
    s = status(**over)
    text = s.to_compact_json()
    back = RobotStatus.from_json(text)
    same_up_to_rounding(s, back)
    assert back.to_compact_json() == text            # rounding once is rounding for good
    assert RobotStatus.from_json(s.to_json()) == s    # the old form is still read
    assert len(text) < 0.7 * len(s.to_json())


def test_rounding_never_reports_a_robot_further_along():
    below_one = math.nextafter(1.0, 0.0)
    back = RobotStatus.from_json(status(progress=below_one, travelled_m=2.99999999).to_compact_json())
    assert back.progress < 1.0 and back.travelled_m < 2.99999999
    assert RobotStatus.from_json(status(progress=1.0).to_compact_json()).progress == 1.0


def test_trailing_nulls_left_out_and_optional_values_may_be_left_out():
    s = status(task_id=None, path_id=None, travelled_m=None, loaded=None, lateness_s=0.0)
    v = json.loads(s.to_compact_json())["v"]
    assert len(v) == 14 and v[-1] == 0.0
    minimal = {"schema": RobotStatus.COMPACT_SCHEMA, "id": "r1", "v": v[:11]}
    assert RobotStatus.from_dict(minimal).lateness_s == 0.0


@pytest.mark.parametrize("change, error", [
    (lambda d: d["v"].__setitem__(1, "NaN"), "robot_status.x: must be a finite number"),
    (lambda d: d["v"].__setitem__(6, 1.5), "robot_status.battery: must be in [0, 1] (got 1.5)"),
    (lambda d: d["v"].__setitem__(0, "drone"), "robot_status.kind: must be one of"),
    (lambda d: d["v"].__setitem__(7, None), "robot_status.mode: must be one of"),
    (lambda d: d["v"].__setitem__(12, -1), "robot_status.path_id: must be >= 0"),
    (lambda d: d["v"].__setitem__(19, 1), "robot_status.loaded: must be true or false"),
    (lambda d: d["v"].__setitem__(20, ""), "robot_status.placed_task_id: must be a non-empty string"),
    (lambda d: d.__setitem__("id", "r-1"), "robot_status.id: must be letters, digits and '_'"),
    (lambda d: d.__setitem__("v", d["v"][:10]), "robot_status.v: must be a list of 11 to 21 values"),
    (lambda d: d.__setitem__("v", d["v"] + [None]), "robot_status.v: must be a list of 11 to 21 values"),
    (lambda d: d.__setitem__("v", {"x": 1}), "robot_status.v: must be a list"),
    (lambda d: d.pop("id"), "robot_status.id: required field missing"),
    (lambda d: d.__setitem__("x", 1.0), "robot_status.x: unknown field"),
])
def test_compact_errors_name_the_field(change, error):
    data = json.loads(status(rejected_path_id=2, loaded=False, placed_task_id="t9").to_compact_json())
    assert len(data["v"]) == 21
    change(data)
    with pytest.raises(RecordError) as exc:
        RobotStatus.from_json(json.dumps(data).replace('"NaN"', "NaN"))
    assert str(exc.value).startswith(error), str(exc.value)


def test_neighbours_carry_compact_statuses_and_the_inbox_finds_their_id():
    a, b = status(id="r1"), status(id="r2", behavior=BEHAVIOR)
    text = (f'{{"schema":"{Neighbours.SCHEMA}","id":"r3","stamp":1.0,'
            f'"robots":[{a.to_compact_json()},{b.to_json()}]}}')
    rec = Neighbours.from_json(text)
    assert [r.id for r in rec.robots] == ["r1", "r2"] and rec.robots[1] == b
    inbox = StatusInbox()
    assert inbox.offer(a.to_compact_json(), 0.0) is None and len(inbox) == 1


def test_fast_path_bounds_are_the_checks_bounds():
    checks = {name: (check, path) for name, check, path, *_ in _status_checks()}
    for name, (lo, hi) in _STATUS_FLOATS.items():
        check, path = checks[name]
        for edge, outside in ((lo, math.nextafter(lo, -math.inf)), (hi, math.nextafter(hi, math.inf))):
            if math.isfinite(edge):
                assert check(edge, path) == edge
                with pytest.raises(RecordError):
                    check(outside, path)
        with pytest.raises(RecordError):
            check(math.inf, path)
    for name, _, _, _, _, _, fast in _status_checks():   # the typed fast paths
        check, path = checks[name]
        if fast == "path_id":
            assert check(0, path) == 0 and check(INT_MAX, path) == INT_MAX
            for bad in (-1, INT_MAX + 1):
                with pytest.raises(RecordError):
                    check(bad, path)
        elif fast == "bool":
            assert check(True, path) is True and check(False, path) is False


_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 3), st.booleans(), st.none(),
                    st.sampled_from([0.0, 1.0, -0.0, 1.0000001, -1e-300, 5e-324, 2 ** 63 - 1, 2 ** 63, "r1", " t1 ",
                                     "cargo", "idle", "1r", "", "a\x00", {}]), st.text(max_size=3))
_FIELDS = sorted(f for f in RobotStatus.__dataclass_fields__ if f not in ("SCHEMA", "NAME", "COMPACT_SCHEMA"))


@settings(max_examples=400, deadline=None)
@given(st.dictionaries(st.sampled_from(_FIELDS), _VALUES, max_size=4))
def test_fast_construction_equals_the_checks(changes):
    """Whatever the values, the status accepts (normalised alike) or refuses (same message) exactly
    as check_fields over its declared checks does (twice: the second time strings come from the
    memo of checked strings)."""
    for _ in range(2):
        fast_equals_slow(status().__dict__ | changes)


def fast_equals_slow(base):
    try:
        fast = RobotStatus(**base)
    except RecordError as exc:
        fast = str(exc)
    slow = object.__new__(RobotStatus)
    for k, v in base.items():
        object.__setattr__(slow, k, v)
    try:
        check_fields(slow, RobotStatus.NAME)
    except RecordError as exc:
        slow = str(exc)
    if isinstance(fast, str) or isinstance(slow, str):
        assert fast == slow
    else:
        assert fast.__dict__ == slow.__dict__
        assert all(type(getattr(fast, k)) is type(getattr(slow, k)) for k in base)
