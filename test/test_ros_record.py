"""Recorded runs (issue 12, deliverable 5): a short run of the test fleet with one simulated person,
recorded by the recorder node into an MCAP file of ROS 2 messages, then read back from the file
alone (its own schemas, no ROS graph) and drawn by fleet-replay."""
import numpy as np
import pytest
from mcap.reader import make_reader
from rclpy.parameter import Parameter
from test_ros_system import KINDS, MEMBERS, PARKING, RATE, WAIT, WH

from fleet_planner.fleet.people import Walker
from fleet_planner.ros import replay
from fleet_planner.ros.demo.bringup import bring_up
from fleet_planner.ros.demo.monitor import spin_until
from fleet_planner.ros.people import PeopleNode
from fleet_planner.ros.record import RecorderNode, message_definition
from msg_schemas import topics
from msg_schemas.records import Task


def test_a_recorded_run_reads_back_with_its_robots_people_jobs_and_paths(ros_context, tmp_path):
    out = tmp_path / "run.mcap"
    fleet = bring_up(ros_context, WH, KINDS, MEMBERS, RATE, planner_params=[Parameter("parking", value=PARKING)])
    sim = [Parameter("use_sim_time", value=True)]
    recorder = RecorderNode(context=ros_context, output=out, parameter_overrides=sim)
    walker = Walker("p1", np.array([(13.0, 5.75), (13.0, 10.25)]), once=True)   # down the right aisle
    people = PeopleNode(context=ros_context, walkers=[walker], parameter_overrides=sim)
    extra = [recorder, people]
    try:
        mon, ex = fleet.monitor, fleet.executor
        for node in extra:
            ex.add_node(node)
        ids = {m.id for m in MEMBERS}
        assert spin_until(ex, lambda: mon.planner_ready() and ids <= set(mon.status), WAIT)
        mon.submit(Task(id="R1", pick="chute_1", place="B01-01"))
        assert spin_until(ex, lambda: mon.last_event.get("R1") is not None and mon.last_event["R1"].event == "done"
                          and walker.gone, 3 * WAIT)
        events = "/" + topics.TASK_EVENTS   # every event the monitor heard is in the file too
        assert spin_until(ex, lambda: recorder.recorder.written(events) >= len(mon.events), WAIT)
        seen = dict(mon.tracks)
    finally:
        for node in extra:
            fleet.executor.remove_node(node)
            node.destroy_node()   # the recorder closes its file
        fleet.destroy()

    with open(out, "rb") as f:   # the ros2 profile, as ros2 bag -s mcap writes it
        summary = make_reader(f).get_summary()
        f.seek(0)
        assert make_reader(f).get_header().profile == "ros2"
    channels = {c.topic: c for c in summary.channels.values()}
    assert {"/" + t for t in (topics.ROBOT_STATUS, topics.TASK_EVENTS, topics.OBSTACLES, topics.MAP)} <= set(channels)
    assert any(t.startswith("/robots/") and t.endswith("/timed_path") for t in channels)
    for c in channels.values():
        schema = summary.schemas[c.schema_id]
        assert c.message_encoding == "cdr" and schema.encoding == "ros2msg" and "/msg/" in schema.name
        assert "history:" in c.metadata["offered_qos_profiles"]

    run = replay.read_run(out)
    assert set(run.robots) == set(seen) == ids
    assert run.done() == ["R1"], (run.messages, run.skipped, run.events)
    assert [e.event for e in run.events if e.task_id == "R1"][-1] == "done"
    assert set(run.obstacles) == {"p1"}
    ys = [y for _, y, _ in run.obstacles["p1"]]
    assert max(ys) - min(ys) > 4.0                       # it walked down the aisle
    assert run.closest_robots()[0] >= 0.0 and run.closest_obstacle()[0] >= 0.0
    # the tracks read back are the ones the monitor heard live (best effort: the file may hold fewer)
    for rid, track in run.robots.items():
        assert len(track) >= 0.9 * len(seen[rid]) or len(track) > 100, rid

    png = tmp_path / "run.png"
    replay.main([str(out), "--plot", str(png)])
    assert png.stat().st_size > 10_000


def test_the_schema_of_a_timed_path_names_every_type_it_uses():
    from nav_msgs.msg import Path

    text = message_definition(Path)
    assert text.startswith("# An array of poses")
    deps = [line[5:] for line in text.splitlines() if line.startswith("MSG: ")]
    assert deps == ["std_msgs/Header", "builtin_interfaces/Time", "geometry_msgs/PoseStamped", "geometry_msgs/Pose",
                    "geometry_msgs/Point", "geometry_msgs/Quaternion"]


def test_replay_refuses_a_file_that_is_not_a_run(tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(SystemExit) as exc:
        replay.main([str(bad)])
    assert exc.value.code == 2 and "not a readable MCAP file" in capsys.readouterr().err
