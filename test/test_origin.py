"""Agents and fleet-submit take task events and timed paths only from the planner node, with no keys
(issue 9, deliverable 5): while another node publishes on those topics, what comes there is
refused (a forged ``cancelled`` does not make a robot drop its job, a forged timed path is not
driven, a forged gate record does not release a robot, a forged ``done`` is not success, a forged
release does not lift an e-stop); when it is gone, the planner's word counts again."""
import numpy as np
import pytest
import rclpy
from nav_msgs.msg import Path
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Bool, String
from test_records_total import KINDS, WH

from fleet_planner.fleet.gate import gate_limit
from fleet_planner.model import TimedPath
from fleet_planner.ros.demo.monitor import spin_until
from fleet_planner.ros.submit import Submitter
from msg_schemas import topics
from msg_schemas.convert import ns_to_stamp, timed_path_to_msg
from msg_schemas.records import GateRecord, Task, TaskEvent
from robot_agent.agent_node import AgentNode

START = WH.stations_of("charger")[0].pose
WAIT = 20.0


@pytest.fixture
def world(ros_context):
    agent = AgentNode("origin_agent", context=ros_context, warehouse=WH, kinds=KINDS, parameter_overrides=[
        Parameter("id", value="o1"), Parameter("x", value=START[0]), Parameter("y", value=START[1]),
        Parameter("planner", value="origin_planner")])
    planner = rclpy.create_node("origin_planner", context=ros_context)
    forger = rclpy.create_node("forger", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    for node in (agent, planner, forger):
        executor.add_node(node)
    try:
        yield agent, planner, forger, executor
    finally:
        executor.shutdown()
        for node in (agent, planner, forger):
            node.destroy_node()


def event(task_id, kind, robot_id="o1", **kw):
    return String(data=TaskEvent(task_id=task_id, event=kind, stamp=1.0, robot_id=robot_id, **kw).to_json())


def until(executor, condition):
    return spin_until(executor, condition, WAIT)


def test_events_and_paths_count_only_while_the_planner_alone_publishes_them(world):
    agent, planner, forger, executor = world
    events = planner.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
    assert until(executor, lambda: agent._event_origin.sub.get_publisher_count() == 1)
    events.publish(event("J1", "assigned"))
    assert until(executor, lambda: agent.agent.job == "J1")

    fake = forger.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
    refused = agent._event_origin.refused
    fake.publish(event("J1", "cancelled"))  # published at once: the match itself must refuse it
    assert until(executor, lambda: agent._event_origin.refused > refused)
    assert agent.agent.job == "J1"
    events.publish(event("J2", "assigned"))  # while the forger is there, nobody's events count
    assert until(executor, lambda: agent._event_origin.refused > refused + 1)
    assert agent.agent.job == "J1"

    path = TimedPath("o1", 0.3, np.array([[START[0], START[1], 0.0], [START[0] + 3.0, START[1], 3.0]]))
    forged = forger.create_publisher(Path, topics.timed_path_topic("o1"), topics.TIMED_PATH_QOS)
    forged.publish(timed_path_to_msg(path, ns_to_stamp(agent.get_clock().now().nanoseconds), "map"))
    assert until(executor, lambda: agent._path_origin.refused > 0)
    assert agent.agent.model.path is None  # never followed

    forger.destroy_publisher(fake)
    assert until(executor, lambda: agent._event_origin.sub.get_publisher_count() == 1)
    events.publish(event("J1", "cancelled"))
    assert until(executor, lambda: agent.agent.job is None)


def test_fleet_submit_takes_no_forged_done(world, ros_context):
    _, planner, forger, executor = world
    task = Task(id="S9", pick="chute_1", place="B01-01")
    submitter = Submitter(task, "origin_submit", planner="origin_planner", context=ros_context)
    executor.add_node(submitter)
    try:
        planner.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
        fake = forger.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
        assert until(executor, lambda: submitter._sub.get_publisher_count() == 2)
        fake.publish(event("S9", "done"))
        assert until(executor, lambda: submitter.origin.refused > 0)
        assert submitter.events == []
    finally:
        executor.remove_node(submitter)
        submitter.destroy_node()


def test_gate_records_count_only_while_the_planner_alone_publishes_them(world):
    """A forged gate record of a higher ``seq`` without links would release the robot into the
    regions its record holds it before: refused while another node publishes there."""
    agent, planner, forger, executor = world
    hold = ({"robot": "o2", "path_id": 3, "exit": 4.0, "entry": 1.0},)
    gates = planner.create_publisher(String, topics.gate_topic("o1"), topics.GATE_QOS)
    assert until(executor, lambda: agent._gate_origin.sub.get_publisher_count() == 1)
    gates.publish(String(data=GateRecord(robot_id="o1", path_id=5, seq=0, stamp=1.0, links=hold).to_json()))
    driver = agent.agent.driver
    assert until(executor, lambda: driver.gate is not None)
    assert gate_limit(driver.gate, 5, {}) == 1.0

    fake = forger.create_publisher(String, topics.gate_topic("o1"), topics.GATE_QOS)
    fake.publish(String(data=GateRecord(robot_id="o1", path_id=5, seq=9, stamp=2.0).to_json()))
    assert until(executor, lambda: agent._gate_origin.refused > 0)
    assert driver.gate.seq == 0 and gate_limit(driver.gate, 5, {}) == 1.0  # still held

    forger.destroy_publisher(fake)
    assert until(executor, lambda: agent._gate_origin.sub.get_publisher_count() == 1)
    gates.publish(String(data=GateRecord(robot_id="o1", path_id=5, seq=1, stamp=3.0).to_json()))
    assert until(executor, lambda: driver.gate.seq == 1)  # the planner's word counts again


def test_an_e_stop_is_obeyed_from_anyone_but_released_only_by_the_planner(world):
    agent, planner, forger, executor = world
    hand = agent.agent.hand
    stop = planner.create_publisher(Bool, topics.ESTOPPED, topics.ESTOPPED_QOS)
    assert until(executor, lambda: agent.operator.estop_origin.sub.get_publisher_count() == 1)
    stop.publish(Bool(data=True))
    assert until(executor, lambda: hand.estopped)
    fake = forger.create_publisher(Bool, topics.ESTOPPED, topics.ESTOPPED_QOS)
    fake.publish(Bool(data=False))  # a forged release
    assert until(executor, lambda: agent.operator.estop_origin.refused > 0)
    assert hand.estopped
    forger.destroy_publisher(fake)
    assert until(executor, lambda: agent.operator.estop_origin.sub.get_publisher_count() == 1)
    stop.publish(Bool(data=False))
    assert until(executor, lambda: not hand.estopped)
