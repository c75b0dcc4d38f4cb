"""The live fleet under a flood of hostile messages (issue 9, hardened inputs): a stranger node sends
random bytes (malformed CDR and bad UTF-8 too), random JSON, absurd and mutated records, statuses of
unknown robots and far-off stamps, and broken timed paths on every topic the planner and the
agents listen to; afterwards every node is still up and a good job is done without contact."""
import json
import random

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from std_msgs.msg import String
from test_records_total import GOOD_ALL
from test_ros_system import MEMBERS, ended, no_contact, running_fleet, wait_for

from fleet_planner.model import TimedPath
from msg_schemas import topics
from msg_schemas.convert import ns_to_stamp, timed_path_to_msg
from msg_schemas.records import RobotStatus, Task, TaskEvent


@pytest.fixture(scope="module")
def fleet(ros_context, tmp_path_factory):
    roster = tmp_path_factory.mktemp("roster") / "fleet.yaml"
    roster.write_text(json.dumps({"robots": [vars(m) for m in MEMBERS]}))
    yield from running_fleet(ros_context, [Parameter("fleet_file", value=str(roster))])


def hostile_texts(rng: random.Random, now: float) -> list[str]:
    out = ["[" * 50_000, '{"a":' * 5_000 + "1" + "}" * 5_000, "x" * 300_000, "\x00\x07", "null", "1e999",
           '{"schema": "fleet/task@1", "id": "\\ud800"}']
    for _ in range(150):
        out.append(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 80))).decode("utf-8", "replace"))
    for good in GOOD_ALL.values():
        for _ in range(40):
            record = dict(good)
            if "stamp" in record:
                record["stamp"] = now
            key = rng.choice([*record, "extra", "\udc80"])
            record[key] = rng.choice([None, True, -1, 2 ** 70, 1e308, "", "z" * 5000, [[[]]], {"k": []}, "r1"])
            out.append(json.dumps(record))
    for i in range(300):  # statuses of robots not on the roster, and of real ones stamped far away
        rid, stamp = (f"ghost{i}", now) if i % 3 else (MEMBERS[i % len(MEMBERS)].id, now + rng.choice([-1e5, 1e5]))
        out.append(RobotStatus(id=rid, kind="cargo", x=1.0, y=1.0, yaw=0.0, vx=0.0, vy=0.0, battery=1.0,
                               mode="idle", progress=1.0, stamp=stamp, radius=0.3).to_json())
    return out


def broken_paths(rng: random.Random) -> list[Path]:
    paths = []
    for n in range(40):
        msg = Path()
        msg.header.frame_id = "map"
        msg.header.stamp.sec = rng.choice([0, 2 ** 31 - 1, 5])
        for k in range(rng.choice([0, 1, 3, 20_001 if n == 0 else 2])):
            p = PoseStamped()
            p.header.stamp.sec = rng.choice([0, 2 ** 31 - 1, 10 - k])
            p.pose.position.x = rng.choice([float("nan"), float("inf"), -1e9, 3.0])
            p.pose.position.y = rng.choice([float("nan"), 1e9, 3.0])
            msg.poses.append(p)
        paths.append(msg)
    return paths


def test_a_flood_of_hostile_messages_leaves_every_node_up_and_a_good_job_is_done(fleet):
    rng = random.Random(9)
    mon = fleet.monitor
    stranger = mon  # any node may publish; this one sits in the same executor, which must survive
    pubs = {name: stranger.create_publisher(String, name, qos) for name, qos in [
        (topics.TASKS, topics.TASKS_QOS), (topics.ROBOT_STATUS, topics.ROBOT_STATUS_QOS),
        (topics.WAIT_MESSAGES, topics.WAIT_MESSAGES_QOS)]}
    path_pubs = [stranger.create_publisher(Path, topics.timed_path_topic(m.id), topics.TIMED_PATH_QOS)
                 for m in MEMBERS]
    garbage_cdr = [b"\x00\x01\x00\x00\xff\xff\xff\x7f", b"junk", serialize_message(String(data="x"))[:6],
                   b"\x00\x01\x00\x00\x05\x00\x00\x00\xff\xfe\xc3\x28\x00"]
    texts = hostile_texts(rng, mon.now())
    for i, text in enumerate(texts):
        for pub in pubs.values():
            pub.publish(String(data=text))
            pub.publish(garbage_cdr[i % len(garbage_cdr)])  # raw bytes: malformed CDR, bad UTF-8
        if i % 50 == 0:
            fleet.executor.spin_once(timeout_sec=0.0)
    for msg in broken_paths(rng):
        for pub in path_pubs:
            pub.publish(msg)
    forged_events = stranger.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
    r1 = fleet.agents["r1"]
    x, y = r1.agent.model.x, r1.agent.model.y
    into_racks = TimedPath("r1", 0.3, np.array([[x, y, 0.0], [x, y - 6.0, 6.0]]))
    path_pubs[0].publish(timed_path_to_msg(into_racks, ns_to_stamp(r1.get_clock().now().nanoseconds + 10**9), "map"))
    for m in MEMBERS:
        forged_events.publish(String(data=TaskEvent(task_id="X1", event="assigned", stamp=mon.now(),
                                                    robot_id=m.id).to_json()))
    assert wait_for(fleet, lambda: all(a._event_origin.refused >= 1 for a in fleet.agents.values())
                    and r1._path_origin.refused >= 1)
    assert all(a.agent.job is None for a in fleet.agents.values()) and r1.agent.model.path is None
    for pub in [*pubs.values(), *path_pubs, forged_events]:
        stranger.destroy_publisher(pub)  # the stranger leaves
    planner = fleet.planner
    assert not any(rid.startswith("ghost") for rid in planner.fleet.robots)
    mon.submit(Task(id="F1", pick="chute_1", place="B03-02"))
    assert wait_for(fleet, lambda: ended(fleet, "F1")), mon.events_of("F1")
    assert [e.event for e in mon.events_of("F1")] == ["accepted", "assigned", "picked", "placed", "done"]
    assert set(planner.fleet.robots) == {m.id for m in MEMBERS}
    assert all(planner.fleet.robots[m.id].online for m in MEMBERS)
    # contact, from the robots' own reports: the forged ones (ghosts, far-off stamps) left out
    now = mon.now()
    mon.tracks = {rid: [p for p in track if abs(p[2] - now) < 1000.0] for rid, track in mon.tracks.items()
                  if rid in planner.fleet.robots}
    no_contact(fleet)
