"""The wire contracts: records (validation, round trips), topic names and QoS, message conversions."""
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleet_planner.grid import GridMap, MapError
from fleet_planner.model import TimedPath, timed_path_from_polyline
from msg_schemas.records import RecordError, RobotStatus, Schedule, Task, TaskEvent

GOOD = {
    Task: {"schema": "fleet/task@1", "id": "t1", "pick": "chute_1", "place": "A-03-2",
           "needs": ["forklift"], "payload_kg": 12.5, "priority": 2, "created": 3.25},
    TaskEvent: {"schema": "fleet/task_event@1", "task_id": "t1", "event": "rejected", "stamp": 4.0,
                "robot_id": "r1", "reason": "no robot can lift 900 kg"},
    RobotStatus: {"schema": "fleet/robot_status@1", "id": "r1", "kind": "cargo_forklift", "x": 1.5,
                  "y": 2.5, "yaw": 0.5, "vx": 0.1, "vy": 0.0, "battery": 0.8, "mode": "driving",
                  "progress": 0.25, "stamp": 10.0, "radius": 0.45, "task_id": "t1", "path_id": 3,
                  "lateness_s": 0.4},
    Schedule: {"schema": "fleet/schedule@1", "plan_id": 7, "stamp": 1.0, "priority": ["r1", "r2"],
               "nodes": {"r1": {"delay": 0.0, "travel": 5.0}, "r2": {"delay": 2.5, "travel": 4.0}},
               "links": [{"i": "r2", "j": "r1", "k": 1, "M": -1.5, "D": 2.5,
                          "ks": 1.0, "ke": 3.0, "ls": 0.5, "le": 1.7}]},
}


def with_change(cls, path, value):
    """GOOD[cls] as JSON with one field (dotted path, list indices as ints) set or deleted."""
    data = json.loads(json.dumps(GOOD[cls]))
    *parents, last = path
    node = data
    for key in parents:
        node = node[key]
    if value is DELETE:
        del node[last]
    else:
        node[last] = value
    return json.dumps(data)


DELETE = object()


@pytest.mark.parametrize("cls", list(GOOD))
def test_record_round_trips_through_json(cls):
    rec = cls.from_json(json.dumps(GOOD[cls]))
    assert json.loads(rec.to_json()) == GOOD[cls]
    assert cls.from_json(rec.to_json()) == rec


# ids are printable text of at most MAX_NAME_CHARS characters (issue 9: a lone surrogate in a task
# killed the planner's logger), so the names drawn here are printable and bounded
_PRINTABLE = st.characters(blacklist_categories=("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp", "Zs")) | st.just(" ")


@given(st.text(_PRINTABLE, min_size=1, max_size=128).filter(str.strip),
       st.lists(st.sampled_from(["manipulator", "forklift"]), unique=True),
       st.floats(min_value=0, max_value=1e6), st.integers(-10**6, 10**6),
       st.one_of(st.none(), st.floats(allow_nan=False, allow_infinity=False)))
@settings(max_examples=60, deadline=None)
def test_any_valid_task_round_trips(name, needs, payload, priority, created):
    task = Task(id=name, pick=name, place="A1", needs=needs, payload_kg=payload, priority=priority,
                created=created)
    assert Task.from_json(task.to_json()) == task


def test_optional_fields_default_and_may_be_null():
    task = Task.from_json('{"schema": "fleet/task@1", "id": "t", "pick": "c", "place": "p", "created": null}')
    assert (task.needs, task.payload_kg, task.priority, task.created) == ((), 0.0, 0, None)
    assert "created" not in json.loads(task.to_json())


def test_construction_in_code_is_validated_too():
    with pytest.raises(RecordError, match=r"^task\.pick: must be a non-empty string"):
        Task(id="t", pick="  ", place="p")


@pytest.mark.parametrize("cls, path, value, expected", [
    (Task, ["id"], DELETE, "task.id: required field missing"),
    (Task, ["id"], None, "task.id: must be a non-empty string (got null)"),
    (Task, ["due"], 3, "task.due: unknown field"),
    (Task, ["payload_kg"], math.nan, "task.payload_kg: must be a finite number (got NaN)"),
    (Task, ["payload_kg"], math.inf, "task.payload_kg: must be a finite number (got Infinity)"),
    (Task, ["payload_kg"], True, "task.payload_kg: must be a finite number (got true)"),
    (Task, ["payload_kg"], "12", "task.payload_kg: must be a finite number (got '12')"),
    (Task, ["payload_kg"], -1, "task.payload_kg: must be >= 0"),
    (Task, ["priority"], 1.5, "task.priority: must be an integer (got 1.5)"),
    (Task, ["priority"], False, "task.priority: must be an integer (got false)"),
    (Task, ["needs"], "forklift", "task.needs: must be a list"),
    (Task, ["needs", 0], "wings", "task.needs[0]: must be one of manipulator, forklift (got 'wings')"),
    (Task, ["needs"], ["forklift", "forklift"], "task.needs: 'forklift' appears more than once"),
    (Task, ["schema"], "fleet/task@2", "task.schema: expected 'fleet/task@1' (got 'fleet/task@2')"),
    (Task, ["schema"], DELETE, "task.schema: required field missing"),
    (TaskEvent, ["event"], "exploded", "task_event.event: must be one of"),
    (TaskEvent, ["reason"], DELETE, "task_event.reason: required when event is 'rejected'"),
    (TaskEvent, ["robot_id"], "9lives", "task_event.robot_id: must be letters, digits and '_'"),
    (RobotStatus, ["battery"], 1.5, "robot_status.battery: must be in [0, 1] (got 1.5)"),
    (RobotStatus, ["kind"], "drone", "robot_status.kind: must be one of cargo, manipulator"),
    (RobotStatus, ["mode"], "dancing", "robot_status.mode: must be one of"),
    (RobotStatus, ["id"], "r-1", "robot_status.id: must be letters, digits and '_'"),
    (RobotStatus, ["path_id"], -1, "robot_status.path_id: must be >= 0"),
    (RobotStatus, ["x"], DELETE, "robot_status.x: required field missing"),
    (Schedule, ["priority"], ["r1"], "schedule.priority: must list every node exactly once"),
    (Schedule, ["nodes", "r2", "delay"], -1, "schedule.nodes['r2'].delay: must be >= 0"),
    (Schedule, ["nodes", "r2", "speed"], 1, "schedule.nodes['r2'].speed: unknown field"),
    (Schedule, ["nodes", "r2"], 3, "schedule.nodes['r2']: must be a JSON object"),
    (Schedule, ["links", 0, "M"], math.nan, "schedule.links[0].M: must be a finite number (got NaN)"),
    (Schedule, ["links", 0, "k"], 0, "schedule.links[0].k: must be >= 1"),
    (Schedule, ["links", 0, "D"], DELETE, "schedule.links[0].D: required field missing"),
    (Schedule, ["links", 0, "i"], "r9", "schedule.links[0].i: 'r9' is not a node"),
    (Schedule, ["links", 0, "i"], "r1", "schedule.links[0].j: a link joins two different robots"),
    (Schedule, ["links", 0, "ke"], 0.5, "schedule.links[0].ke: must be >= ks"),
])
def test_invalid_field_is_named(cls, path, value, expected):
    with pytest.raises(RecordError) as err:
        cls.from_json(with_change(cls, path, value))
    assert str(err.value).startswith(expected), str(err.value)


@pytest.mark.parametrize("text, expected", [
    ("{not json", "task: not valid JSON ("),
    ("[1, 2]", "task: must be a JSON object (got list)"),
    ('{"schema": "fleet/task@1", "id": "a", "id": "b", "pick": "c", "place": "p"}',
     "task: duplicate key 'id'"),
])
def test_malformed_json_is_named(text, expected):
    with pytest.raises(RecordError) as err:
        Task.from_json(text)
    assert str(err.value).startswith(expected)


def test_record_error_is_a_value_error():
    assert issubclass(RecordError, ValueError)


# -- topics ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot_id", ["r1", "robot_3", "_x", "A", "1r", "r-1", "r/1", "", "r 1", "ü"])
def test_timed_path_topic_accepts_exactly_the_ids_ros_accepts(robot_id):
    from rclpy.exceptions import InvalidTopicNameException
    from rclpy.validate_full_topic_name import validate_full_topic_name

    from msg_schemas.topics import timed_path_topic

    try:
        validate_full_topic_name(f"/robots/{robot_id}/timed_path")
        ros_ok = True
    except InvalidTopicNameException:
        ros_ok = False
    if ros_ok:
        assert timed_path_topic(robot_id) == f"robots/{robot_id}/timed_path"  # relative: namespaces work
    else:
        with pytest.raises(ValueError, match="robot id must be"):
            timed_path_topic(robot_id)


def test_topic_names_are_valid_and_the_qos_pairs_match():
    from rclpy.qos import QoSCompatibility, qos_check_compatible
    from rclpy.validate_full_topic_name import validate_full_topic_name

    from msg_schemas import topics as T

    for name in (T.TASKS, T.TASK_EVENTS, T.ROBOT_STATUS, T.SCHEDULE, T.MARKERS, T.MAP, T.WAIT_MESSAGES):
        assert not name.startswith("/")  # relative, so that a namespace moves the whole fleet
        validate_full_topic_name("/" + name)
    for qos in (T.TASKS_QOS, T.TASK_EVENTS_QOS, T.ROBOT_STATUS_QOS, T.TIMED_PATH_QOS, T.SCHEDULE_QOS,
                T.MARKERS_QOS, T.MAP_QOS):
        assert qos_check_compatible(qos, qos)[0] != QoSCompatibility.ERROR
    # a status subscriber also hears an agent that publishes reliably
    assert qos_check_compatible(T.TASKS_QOS, T.ROBOT_STATUS_QOS)[0] != QoSCompatibility.ERROR


# -- conversions -----------------------------------------------------------------------------------
def stamp_ns(stamp):
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def test_timed_path_round_trips_with_exact_stamps():
    from builtin_interfaces.msg import Time

    from msg_schemas.convert import msg_to_timed_path, timed_path_to_msg

    t0 = Time(sec=1_700_000_000, nanosec=999_999_999)
    wp = [(0.5, 0.5, 0.0), (0.5, 0.5, 1.5), (3.5, 0.5, 4.5), (3.5, 2.5, 6.000000001), (3.5, 2.5, 7.25)]
    tp = TimedPath("r1", 0.35, wp)
    msg = timed_path_to_msg(tp, t0, frame_id="map")
    assert msg.header.stamp == t0 and msg.header.frame_id == "map"
    assert [stamp_ns(p.header.stamp) - stamp_ns(t0) for p in msg.poses] == \
        [0, 1_500_000_000, 4_500_000_000, 6_000_000_001, 7_250_000_000]
    yaws = [2 * math.atan2(p.pose.orientation.z, p.pose.orientation.w) for p in msg.poses]
    # the hold faces its coming move (east), then north, and the goal keeps the last heading
    assert yaws == pytest.approx([0, 0, math.pi / 2, math.pi / 2, math.pi / 2])

    back, back_t0 = msg_to_timed_path(msg, "r1", 0.35)
    assert back_t0 == t0 and back.robot_id == "r1" and back.radius == 0.35
    np.testing.assert_allclose(back.waypoints, tp.waypoints, rtol=0, atol=1e-12)
    again = timed_path_to_msg(back, back_t0)
    assert [p.header.stamp for p in again.poses] == [p.header.stamp for p in msg.poses]


def test_timed_path_accepts_float_seconds_for_t0():
    from msg_schemas.convert import timed_path_to_msg

    msg = timed_path_to_msg(timed_path_from_polyline("r1", 0.3, [(0, 0), (2, 0)], 1.0), 12.5)
    assert [stamp_ns(p.header.stamp) for p in msg.poses] == [12_500_000_000, 14_500_000_000]


def test_bad_timed_paths_are_refused_with_the_field():
    from msg_schemas.convert import msg_to_timed_path, timed_path_to_msg

    with pytest.raises(ValueError, match="waypoint 2 is earlier than waypoint 1"):
        timed_path_to_msg(TimedPath("r1", 0.3, [(0, 0, 0), (1, 0, 2), (2, 0, 1)]), 0.0)
    msg = timed_path_to_msg(TimedPath("r1", 0.3, [(0, 0, 0), (1, 0, 1), (2, 0, 2)]), 5.0)
    msg.poses[2].header.stamp = msg.poses[0].header.stamp
    with pytest.raises(RecordError, match=r"^timed_path\.poses\[2\]\.header\.stamp: earlier than poses\[1\]"):
        msg_to_timed_path(msg, "r1", 0.3)
    msg.poses[2].header.stamp = msg.poses[1].header.stamp
    msg.poses[1].pose.position.x = math.nan
    with pytest.raises(RecordError, match=r"^timed_path\.poses\[1\]\.pose\.position: must be finite"):
        msg_to_timed_path(msg, "r1", 0.3)
    msg.poses = []
    with pytest.raises(RecordError, match=r"^timed_path\.poses:"):
        msg_to_timed_path(msg, "r1", 0.3)


def test_grid_round_trips_and_rows_are_not_flipped():
    from msg_schemas.convert import grid_to_msg, msg_to_grid

    blocked = np.random.default_rng(1).random((7, 11)) < 0.3
    grid = GridMap(blocked, resolution=0.5, name="map")
    msg = grid_to_msg(grid)
    assert (msg.info.width, msg.info.height, msg.info.resolution) == (11, 7, 0.5)
    assert list(msg.data) == [100 if b else 0 for b in blocked.ravel()]
    back = msg_to_grid(msg)
    assert back.resolution == 0.5 and np.array_equal(back.blocked, blocked)
    # the first row of a .map file is the first row of the message data
    assert list(grid_to_msg(GridMap.from_rows(["..@", "@.."])).data) == [0, 0, 100, 100, 0, 0]


def test_occupancy_values_unknown_is_blocked():
    from msg_schemas.convert import grid_to_msg, msg_to_grid

    msg = grid_to_msg(GridMap(np.zeros((1, 4), bool)))
    msg.data = [0, 30, 70, -1]
    assert msg_to_grid(msg).blocked.tolist() == [[False, False, True, True]]


def test_unsupported_occupancy_grids_are_refused_with_the_field():
    from msg_schemas.convert import grid_to_msg, msg_to_grid

    msg = grid_to_msg(GridMap(np.zeros((2, 3), bool)))
    msg.info.origin.position.x = -10.0
    with pytest.raises(MapError, match=r"^map\.info\.origin: must be \(0, 0\)"):
        msg_to_grid(msg)
    msg = grid_to_msg(GridMap(np.zeros((2, 3), bool)))
    msg.data = [0] * 5
    with pytest.raises(MapError, match=r"^map\.data: expected width\*height = 6"):
        msg_to_grid(msg)


def test_plan_markers_clear_then_draw_each_robot_in_its_namespace():
    from visualization_msgs.msg import Marker

    from msg_schemas.convert import plan_markers

    paths = [timed_path_from_polyline("r1", 0.35, [(0.5, 0.5), (3.5, 0.5), (3.5, 2.5)], 1.0),
             TimedPath("r2", 0.4, [(5.5, 5.5, 0.0)])]
    status = RobotStatus(id="r1", kind="cargo", x=2.0, y=0.5, yaw=0.0, vx=1.0, vy=0.0, battery=0.9,
                         mode="driving", progress=0.3, stamp=1.0, radius=0.35)
    spare = RobotStatus(**{**status.__dict__, "id": "r3", "x": 9.0, "y": 9.0, "radius": 0.45})
    arr = plan_markers(paths, [status, spare], stamp=3.0)
    assert arr.markers[0].action == Marker.DELETEALL
    drawn = {(m.ns, m.type): m for m in arr.markers[1:]}
    assert len(drawn) == len(arr.markers) - 1  # one marker per (robot, type)
    line = drawn["r1", Marker.LINE_STRIP]
    assert [(p.x, p.y) for p in line.points] == [(0.5, 0.5), (3.5, 0.5), (3.5, 2.5)]
    disc = drawn["r1", Marker.CYLINDER]
    assert (disc.pose.position.x, disc.pose.position.y, disc.scale.x) == (2.0, 0.5, 0.7)
    assert drawn["r2", Marker.CYLINDER].pose.position.x == 5.5  # no status: drawn at its start
    assert ("r2", Marker.LINE_STRIP) not in drawn  # a parked robot has no line
    assert drawn["r3", Marker.TEXT_VIEW_FACING].text == "r3"
    assert all(m.header.frame_id == "map" for m in arr.markers)


def test_records_travel_in_strings():
    from std_msgs.msg import String

    from msg_schemas.convert import record_to_string, string_to_record

    event = TaskEvent(task_id="t1", event="done", stamp=2.0, robot_id="r1")
    msg = record_to_string(event)
    assert isinstance(msg, String) and string_to_record(msg, TaskEvent) == event
    with pytest.raises(RecordError, match=r"^task\.schema: expected"):
        string_to_record(msg, Task)
