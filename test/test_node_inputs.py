"""Every message callback of the real planner and agent nodes is total (issue 9, hardened inputs):
random bytes (as DDS hands a string with bad UTF-8 to rclpy: replacement characters), random text
(lone surrogates and control characters too), random JSON and valid records with one field
mutated go into the callbacks of live node objects; nothing escapes, every task is answered by
exactly one event whose reason is short and printable, statuses from off the roster or stamped far
from the clock are refused, and afterwards both nodes still do their work."""
import json

import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from nav_msgs.msg import Path
from rclpy.parameter import Parameter
from std_msgs.msg import String
from test_records_total import GOOD_ALL, JSON, KINDS, WH, WILD_TEXT

from fleet_planner.fleet import FleetMember
from fleet_planner.ros.planner_node import PlannerNode
from msg_schemas.records import MAX_NAME_CHARS, MAX_REASON_CHARS, RobotStatus, Task, TaskEvent
from robot_agent.agent_node import AgentNode

CHARGERS = [s.pose for s in WH.stations_of("charger")]
ROSTER = [FleetMember("r1", "cargo", *CHARGERS[0]), FleetMember("r2", "manipulator", *CHARGERS[1])]
FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def nodes(ros_context, tmp_path_factory):
    fleet_file = tmp_path_factory.mktemp("fleet") / "fleet.yaml"
    fleet_file.write_text(json.dumps({"robots": [vars(m) for m in ROSTER]}))  # JSON is YAML
    planner = PlannerNode("fuzz_planner", context=ros_context, warehouse=WH, kinds=KINDS,
                          parameter_overrides=[Parameter("fleet_file", value=str(fleet_file))])
    agent = AgentNode("fuzz_agent", context=ros_context, warehouse=WH, kinds=KINDS,
                      parameter_overrides=[Parameter("id", value="r1"), Parameter("x", value=CHARGERS[0][0]),
                                           Parameter("y", value=CHARGERS[0][1]),
                                           Parameter("fleet_file", value=str(fleet_file))])
    sent: list[String] = []
    publish = planner._events.publish
    planner._events.publish = lambda msg: (sent.append(msg), publish(msg))  # spy: still published
    try:
        yield planner, agent, sent
    finally:
        planner.destroy_node()
        agent.destroy_node()


def wire_bytes(raw: bytes) -> str:
    """What a subscriber gets for a std_msgs/String whose bytes are ``raw`` (bad UTF-8 replaced)."""
    return raw.decode("utf-8", "replace")


def mutated(schema: str, data, value, now: float) -> str:
    record = dict(GOOD_ALL[schema])
    if "stamp" in record:
        record["stamp"] = now
    key = data.draw(st.sampled_from(sorted(record)) | WILD_TEXT)
    record[key] = value
    return json.dumps(record)


HOSTILE = st.one_of(st.binary(max_size=300).map(wire_bytes), WILD_TEXT, JSON.map(json.dumps))


def check_answer(sent: list[String]) -> TaskEvent:
    assert len(sent) == 1, f"one event per task, got {len(sent)}"
    ev = TaskEvent.from_json(sent.pop().data)
    assert ev.event in ("accepted", "rejected") and len(ev.task_id) <= MAX_NAME_CHARS
    if ev.reason is not None:
        assert len(ev.reason) <= MAX_REASON_CHARS and ev.reason.isprintable()
    return ev


def feed_everywhere(planner, agent, sent, text: str) -> None:
    msg = String(data=text)
    planner._on_task(msg)
    check_answer(sent)
    planner._on_status(msg)
    planner._take_statuses()  # (a status may wait in the inbox for the next step: parse it now)
    for callback in (agent._on_task, agent._on_event, agent._on_status, agent._on_wait_message):
        callback(msg)


@given(text=HOSTILE)
@FUZZ
def test_hostile_text_goes_through_every_callback_of_both_nodes(nodes, text):
    feed_everywhere(*nodes, text)


@given(schema=st.sampled_from(sorted(GOOD_ALL)), data=st.data(), value=JSON)
@FUZZ
def test_mutated_valid_records_go_through_every_callback_of_both_nodes(nodes, schema, data, value):
    planner, agent, sent = nodes
    feed_everywhere(planner, agent, sent, mutated(schema, data, value, planner._now()))


FLOATS = st.floats(allow_nan=True, allow_infinity=True) | st.floats(-100, 100)
STAMP = st.builds(Time, sec=st.integers(-2**31, 2**31 - 1), nanosec=st.integers(0, 2**32 - 1))


def pose(stamp: Time, x: float, y: float, frame: str) -> PoseStamped:
    p = PoseStamped()
    p.header.stamp, p.header.frame_id = stamp, frame
    p.pose.position.x, p.pose.position.y = x, y
    return p


@given(stamp=STAMP, frame=WILD_TEXT, poses=st.lists(st.tuples(STAMP, FLOATS, FLOATS, WILD_TEXT), max_size=8))
@FUZZ
def test_hostile_timed_paths_are_refused_or_followed_never_raised(nodes, stamp, frame, poses):
    _, agent, _ = nodes
    msg = Path()
    msg.header.stamp, msg.header.frame_id = stamp, frame
    msg.poses = [pose(*p) for p in poses]
    agent._on_path(msg)
    agent._on_timer()


def status(rid: str, stamp: float, kind="cargo", xy=CHARGERS[0]) -> String:
    return String(data=RobotStatus(id=rid, kind=kind, x=xy[0], y=xy[1], yaw=0.0, vx=0.0, vy=0.0, battery=1.0,
                                   mode="idle", progress=1.0, stamp=stamp, radius=KINDS[kind].radius).to_json())


def test_strangers_stale_and_future_statuses_are_refused_and_the_roster_is_served(nodes):
    planner, agent, sent = nodes
    now = planner._now()
    for i in range(3000):  # a flood of made-up ids: each refused, the warnings bounded
        planner._on_status(status(f"intruder{i}", now))
    planner._on_status(status("r2", now - 3600.0, "manipulator", CHARGERS[1]))  # stale
    planner._on_status(status("r2", now + 3600.0, "manipulator", CHARGERS[1]))  # far ahead
    planner._take_statuses()  # (statuses wait in the inbox until the next step or relay tick)
    assert not any(rid.startswith("intruder") for rid in planner.fleet.robots)
    assert "r2" not in planner.fleet.robots
    assert len(planner.fleet.roster.strangers) <= 1001
    planner._on_status(status("r1", planner._now()))
    planner._take_statuses()
    assert "r1" in planner.fleet.robots
    planner._on_task(String(data=Task(id="after_the_flood", pick="chute_1", place="B01-01").to_json()))
    assert check_answer(sent).event == "accepted"
    planner._on_timer()
    assigned = [TaskEvent.from_json(m.data) for m in sent]
    sent.clear()
    assert any(e.event == "assigned" and e.robot_id == "r1" and e.task_id == "after_the_flood" for e in assigned)
    # the agent hears no stranger, ignores stale statuses of others and keeps its own going
    for i in range(3000):
        agent._on_status(status(f"intruder{i}", agent._now()))
    assert not any(rid.startswith("intruder") for rid in agent.agent.heard)
    assert len(agent._roster.strangers) <= 1001
    agent._on_status(status("r2", agent._now() - 3600.0, "manipulator", CHARGERS[1]))
    assert "r2" not in agent.agent.heard
    agent._on_timer()  # (the core refuses statuses stamped ahead of its last tick)
    agent._on_status(status("r2", agent._now(), "manipulator", CHARGERS[1]))
    assert "r2" in agent.agent.heard
    agent._on_timer()



@pytest.fixture(scope="module")
def keyed_agent(ros_context, tmp_path_factory):
    import os

    from fleet_planner.auth import new_key_line
    key = tmp_path_factory.mktemp("keys") / "planner.key"
    key.write_text(new_key_line("planner") + "\n")
    os.chmod(key, 0o600)
    agent = AgentNode("fuzz_keyed_agent", context=ros_context, warehouse=WH, kinds=KINDS, parameter_overrides=[
        Parameter("id", value="r2"), Parameter("auth_trust_file", value=str(key))])
    try:
        yield agent
    finally:
        agent.destroy_node()


@given(text=HOSTILE, stamp=STAMP, poses=st.lists(st.tuples(STAMP, FLOATS, FLOATS, WILD_TEXT), max_size=4))
@FUZZ
def test_an_agent_with_keys_refuses_whatever_is_not_signed_and_never_raises(keyed_agent, text, stamp, poses):
    msg = Path()
    msg.header.stamp = stamp
    msg.poses = [pose(*p) for p in poses]
    keyed_agent._on_path(msg)
    for callback in (keyed_agent._on_path_auth, keyed_agent._on_event, keyed_agent._on_task):
        callback(String(data=text))
    keyed_agent._on_event(String(data=TaskEvent(task_id="J1", event="assigned", stamp=1.0, robot_id="r2").to_json()))
    assert keyed_agent.agent.job is None and keyed_agent.agent.model.path is None
