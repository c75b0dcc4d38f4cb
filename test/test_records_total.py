"""Record parsing is total (issue 9, hardened inputs): whatever comes off the wire - random bytes,
random text, random JSON, valid records with one field mutated, absurd sizes and nestings - the
parsers return a record or raise RecordError, and the error's message is bounded and encodable.
The fleet manager's task path answers every such input with a rejection event, never an exception."""
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_msg_schemas import GOOD

from fleet_planner.fleet import FleetManager, RobotAgent
from fleet_planner.robots import RobotModel, load_kinds
from fleet_planner.warehouse import generate_warehouse
from msg_schemas.records import (
    MAX_DEPTH,
    MAX_NAME_CHARS,
    MAX_REASON_CHARS,
    MAX_RECORD_BYTES,
    RECORDS,
    Command,
    CommandReply,
    GateRecord,
    Heard,
    OperatorState,
    RecordError,
    RobotCommand,
    RobotStatus,
    Task,
    TaskEvent,
    WaitMessageRecord,
)

GOOD_ALL = {**{cls.SCHEMA: data for cls, data in GOOD.items()},
            WaitMessageRecord.SCHEMA: {"schema": WaitMessageRecord.SCHEMA, "sender": "r1", "receiver": "r2",
                                       "waiting": ["r1"], "stamp": 1.0},
            Command.SCHEMA: {"schema": Command.SCHEMA, "id": "c1", "command": "send", "robot_id": "r1",
                             "station": "chute_1"},
            RobotCommand.SCHEMA: {"schema": RobotCommand.SCHEMA, "id": "d1", "robot_id": "r1", "manual": True,
                                  "linear": 0.2, "angular": -0.1},
            CommandReply.SCHEMA: {"schema": CommandReply.SCHEMA, "id": "c1", "ok": False, "stamp": 1.0,
                                  "message": "robot_id: unknown robot 'r9'", "command": "send"},
            GateRecord.SCHEMA: {"schema": GateRecord.SCHEMA, "robot_id": "r1", "path_id": 7, "seq": 2, "stamp": 1.0,
                                "links": [{"robot": "r2", "path_id": 5, "exit": 3.5, "entry": 1.25}],
                                "watch": {"r2": 5}},
            Heard.SCHEMA: {"schema": Heard.SCHEMA, "stamp": 3.0, "lease_s": 1.5, "silence_s": 9.0,
                           "robots": {"r1": 2.5, "r2": 2.9}, "legs": {"r1": 7}},
            OperatorState.SCHEMA: {"schema": OperatorState.SCHEMA, "stamp": 2.0, "estop": True, "fleet_paused": False,
                                   "paused": ["r1"], "manual": []},
            "fleet/obstacle@1": {"schema": "fleet/obstacle@1", "id": "person_1", "kind": "person", "x": 3.0, "y": 4.0,
                                 "vx": 1.0, "vy": 0.0, "radius": 0.3, "stamp": 1.0}}
BY_SCHEMA = {cls.SCHEMA: cls for cls in RECORDS}

# text that includes lone surrogates and control characters (hypothesis' default text has neither)
WILD_TEXT = st.text(st.characters(min_codepoint=0, max_codepoint=0x10FFFF, blacklist_categories=()), max_size=40)
JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.integers(min_value=-10**400, max_value=10**400)
    | st.floats() | WILD_TEXT,
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(WILD_TEXT, inner, max_size=5),
    max_leaves=30)


def outcome(cls, raw, *, as_dict=False):
    """Parse ``raw``; a RecordError's message must be bounded and encodable. Returns the record or None."""
    try:
        return cls.from_dict(raw) if as_dict else cls.from_json(raw)
    except RecordError as exc:
        message = str(exc)
        message.encode("utf-8")  # no lone surrogate left in it
        assert len(message) <= MAX_REASON_CHARS and message.isprintable()
        assert message.startswith(cls.NAME)
        return None


@pytest.mark.parametrize("cls", RECORDS)
@given(raw=st.binary(max_size=300))
@settings(max_examples=60, deadline=None)
def test_random_bytes_are_a_record_or_a_record_error(cls, raw):
    outcome(cls, raw)


@pytest.mark.parametrize("cls", RECORDS)
@given(raw=WILD_TEXT)
@settings(max_examples=60, deadline=None)
def test_random_text_is_a_record_or_a_record_error(cls, raw):
    outcome(cls, raw)


@pytest.mark.parametrize("cls", RECORDS)
@given(value=JSON)
@settings(max_examples=60, deadline=None)
def test_random_json_is_a_record_or_a_record_error(cls, value):
    outcome(cls, json.dumps(value))
    outcome(cls, value, as_dict=True)


@given(schema=st.sampled_from(sorted(GOOD_ALL)), data=st.data(), value=JSON)
@settings(max_examples=200, deadline=None)
def test_mutated_valid_records_are_a_record_or_a_record_error(schema, data, value):
    record = dict(GOOD_ALL[schema])
    key = data.draw(st.sampled_from(sorted(record)) | WILD_TEXT)
    record[key] = value
    outcome(BY_SCHEMA[schema], json.dumps(record))
    outcome(BY_SCHEMA[schema], record, as_dict=True)


def good_task(**change):
    return json.dumps({**GOOD[Task], **change})


@pytest.mark.parametrize(("raw", "expected"), [
    ("[" * 100_000 + "]" * 100_000, f"task: not valid JSON (nested more than {MAX_DEPTH} levels deep)"),
    ('{"a":' * 20_000 + "1" + "}" * 20_000, "nested more than"),
    (good_task(id="x" * 1_000_000), "task: message too long"),
    (good_task(id="x" * (MAX_NAME_CHARS + 1)), f"task.id: must be at most {MAX_NAME_CHARS} characters"),
    ('{"schema": "fleet/task@1", "id": "a", "pick": "p", "place": "q", "priority": ' + "9" * 4000 + "}",
     "task: an integer of 4000 digits"),
    (good_task(priority=2 ** 63), "task.priority: must be <= 9223372036854775807"),
    (good_task(payload_kg=10 ** 400), "task: an integer of 401 digits"),
    ('{"schema": "fleet/task@1", "\\ud800": 1}', "task.\\ud800: unknown field"),
    (good_task(id="\ud800"), "task.id: must be printable text"),
    (good_task(id="a\nb"), "task.id: must be printable text"),
    (b"\xff\xfe{}", "task: not valid JSON (not UTF-8"),
    (b"x" * (MAX_RECORD_BYTES + 1), "task: message too long"),
    (12, "task: must be JSON text (got int)"),
])
def test_absurd_input_is_refused_with_a_short_reason(raw, expected):
    with pytest.raises(RecordError) as exc:
        Task.from_json(raw)
    assert expected in str(exc.value)
    assert len(str(exc.value)) <= MAX_REASON_CHARS
    str(exc.value).encode("utf-8")


def test_huge_python_numbers_in_from_dict_are_record_errors():
    with pytest.raises(RecordError, match="payload_kg: must be a finite number .got an integer of about"):
        Task.from_dict({**GOOD[Task], "payload_kg": 10 ** 5000})
    deep: list = []
    for _ in range(100_000):
        deep = [deep]
    with pytest.raises(RecordError, match="task.needs"):
        Task.from_dict({**GOOD[Task], "needs": deep})


def test_nesting_inside_strings_does_not_count():
    task = Task.from_json(good_task(id="[" * 50 + "{" * 50 + "\\\"" + "[" * 20))
    assert task.id.startswith("[[[")


# -- the manager's task path: any input, one bounded rejection ------------------------------------
KINDS = load_kinds()
WH = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)


@given(raw=st.one_of(st.binary(max_size=200), WILD_TEXT, JSON.map(json.dumps), JSON))
@settings(max_examples=150, deadline=None)
def test_manager_answers_any_task_with_an_event(raw):
    fm = FleetManager(WH, KINDS)
    events = fm.submit(raw, 1.0)
    assert len(events) == 1 and events[0].event in ("accepted", "rejected")
    line = events[0].to_json()
    assert TaskEvent.from_json(line) == events[0]
    assert len(events[0].task_id) <= MAX_NAME_CHARS
    (events[0].reason or "").encode("utf-8")


def test_manager_rejection_never_echoes_a_huge_or_unprintable_id():
    fm = FleetManager(WH, KINDS)
    (ev,) = fm.submit(good_task(id="x" * 1_000_000), 1.0)
    assert ev.event == "rejected" and ev.task_id == "?" and len(ev.reason) <= MAX_REASON_CHARS
    (ev,) = fm.submit('{"schema": "fleet/task@1", "id": "\\udc80", "\\ud800": 1}', 1.0)
    assert ev.event == "rejected" and ev.task_id == "?"
    ev.reason.encode("utf-8")
    (ev,) = fm.submit('{"schema": "fleet/task@1", "id": "T7", "pick": ' + "[" * 10_000, 1.0)
    assert ev.event == "rejected" and ev.task_id == "T7" and "nested" in ev.reason


# -- stamps far from the receiver's clock -----------------------------------------------------------
def status(rid, stamp, x=2.25, y=10.75):
    return RobotStatus(id=rid, kind="cargo", x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, battery=1.0, mode="idle",
                       progress=1.0, stamp=stamp, radius=KINDS["cargo"].radius)


def test_a_status_stamped_far_ahead_is_refused_and_does_not_lock_the_robot_out():
    fm = FleetManager(WH, KINDS, max_clock_skew_s=2.0)
    fm.on_status(status("r1", 10.0), 10.0)
    with pytest.raises(ValueError, match="stamped 1e\\+06 s ahead"):
        fm.on_status(status("r1", 1e6), 10.5)
    for t in (11.0, 12.0, 13.0, 14.0, 15.0):
        fm.on_status(status("r1", t), t)
        fm.step(t)
    assert fm.robots["r1"].online and fm.robots["r1"].status.stamp == 15.0
    fm.on_status(status("r1", 16.5), 15.0)  # within the skew allowed: taken
    assert fm.robots["r1"].status.stamp == 16.5


def test_an_agent_ignores_statuses_stamped_far_ahead():
    agent = RobotAgent(RobotModel("r1", KINDS["cargo"], 2.25, 10.75), WH)
    agent.tick(10.0)
    agent.on_status(status("r2", 1e9, x=6.25))
    agent.on_status(status("r2", 10.0, x=4.25))
    assert agent.heard["r2"].x == 4.25
