"""Authenticated commands on the live fleet (issue 9, deliverable 5): with keys configured, a task
signed by a client key is done; unsigned and wrongly signed tasks are rejected with the reason and
counted; forged events and timed paths (unsigned, or signed with a key the robots do not trust) are
refused and counted by the agents, even from a node that calls itself the planner; so are forged
gate records."""
import os
from dataclasses import replace

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import String
from test_ros_system import KINDS, MEMBERS, PARKING, RATE, WH, ended, no_contact, wait_for

from fleet_planner.auth import new_key_line
from fleet_planner.ros.demo.bringup import Fleet, agent_params
from fleet_planner.ros.demo.monitor import FleetMonitor, spin_until
from fleet_planner.ros.planner_node import PlannerNode
from fleet_planner.ros.signing import Keys
from fleet_planner.ros.sim_clock import SimClock
from fleet_planner.ros.submit import Submitter
from msg_schemas import topics
from msg_schemas.records import Task, TaskEvent
from robot_agent.agent_node import AgentNode


def key(tmp_path, name):
    path = tmp_path / name
    path.write_text(new_key_line(name.split(".")[0]) + "\n")
    os.chmod(path, 0o600)
    return str(path)


@pytest.fixture(scope="module")
def keyed(ros_context, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("keys")
    files = {name: key(tmp, f"{name}.key") for name in ("planner", "client", "forger")}
    sim = [Parameter("use_sim_time", value=True)]
    clock = SimClock(context=ros_context, parameter_overrides=[Parameter("rate", value=RATE)])
    planner = PlannerNode(context=ros_context, warehouse=WH, kinds=KINDS, parameter_overrides=sim + [
        Parameter("parking", value=PARKING), Parameter("auth_key_file", value=files["planner"]),
        Parameter("auth_trust_file", value=files["client"])])
    agents = {m.id: AgentNode(f"agent_{m.id}", context=ros_context, warehouse=WH, kinds=KINDS,
                              parameter_overrides=sim + agent_params(m) + [
                                  Parameter("auth_trust_file", value=files["planner"])]) for m in MEMBERS[:2]}
    monitor = FleetMonitor(context=ros_context, parameter_overrides=sim)
    fleet = Fleet(clock, planner, agents, monitor, SingleThreadedExecutor(context=ros_context))
    for node in fleet.nodes:
        fleet.executor.add_node(node)
    try:
        assert spin_until(fleet.executor, lambda: monitor.planner_ready() and set(agents) <= set(monitor.status), 60)
        yield fleet, files
    finally:
        fleet.destroy()


def test_only_signed_tasks_are_taken_and_only_signed_commands_obeyed(keyed, ros_context):
    fleet, files = keyed
    mon, planner = fleet.monitor, fleet.planner
    client, forger = Keys(sign_file=files["client"]), Keys(sign_file=files["forger"])
    channel = mon._tasks.topic_name  # the full name: "/fleet/tasks"
    mon.submit(Task(id="U1", pick="chute_1", place="B01-01"))                               # unsigned
    mon.submit(forger.sign(Task(id="U2", pick="chute_1", place="B01-01"), channel))        # untrusted key
    tampered = client.sign(Task(id="U3", pick="chute_1", place="B01-01"), channel)
    mon.submit(tampered.to_json().replace('"B01-01"', '"B02-01"'))                          # altered after signing
    assert wait_for(fleet, lambda: all(ended(fleet, t, "rejected") for t in ("U1", "U2", "U3")))
    reasons = {t: mon.last_event[t].reason for t in ("U1", "U2", "U3")}
    assert "task.auth: unsigned" in reasons["U1"] and "does not accept" in reasons["U2"]
    assert "wrong signature" in reasons["U3"] and planner.keys.refused == 3
    assert mon.last_event["U1"].auth["key"] == "planner"  # the planner signs what it says

    # a node that calls itself the planner: names are not proof, signatures are
    impostor = rclpy.create_node("planner", namespace="/", context=ros_context)
    fleet.executor.add_node(impostor)
    try:
        fake = impostor.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
        good = client.sign(Task(id="K1", pick="chute_2", place="B03-02"), channel)
        mon.submit(good)
        assert wait_for(fleet, lambda: any(e.event == "assigned" for e in mon.events_of("K1")))
        robot = next(e.robot_id for e in mon.events_of("K1") if e.event == "assigned")
        agent = fleet.agents[robot]
        refused = agent.keys.refused
        for ev in (TaskEvent(task_id="K1", event="cancelled", stamp=mon.now(), robot_id=robot),
                   forger.sign(TaskEvent(task_id="K1", event="cancelled", stamp=mon.now(), robot_id=robot),
                               fake.topic_name)):
            fake.publish(String(data=ev.to_json()))
        assert wait_for(fleet, lambda: agent.keys.refused >= refused + 2)
        assert agent.agent.job == "K1"
        assert wait_for(fleet, lambda: ended(fleet, "K1") and mon.last_event["K1"].auth is not None)
    finally:
        fleet.executor.remove_node(impostor)
        impostor.destroy_node()
    said = [e.event for e in mon.events_of("K1") if e.auth and e.auth["key"] == "planner"]  # (the monitor has no keys)
    assert said == ["accepted", "assigned", "picked", "placed", "done"]
    no_contact(fleet)


def test_fleet_submit_signs_its_task_and_believes_only_signed_events(keyed, ros_context):
    fleet, files = keyed
    task = Task(id="K2", pick="chute_1", place="B02-02")
    submitter = Submitter(task, "keyed_submit", keys=Keys(files["client"], files["planner"]), context=ros_context)
    forger = Keys(sign_file=files["forger"])
    fake = fleet.monitor.create_publisher(String, topics.TASK_EVENTS, topics.TASK_EVENTS_QOS)
    fleet.executor.add_node(submitter)
    try:
        assert wait_for(fleet, submitter.planner_ready)
        for ev in (TaskEvent(task_id="K2", event="done", stamp=1.0),
                   forger.sign(TaskEvent(task_id="K2", event="done", stamp=1.0), fake.topic_name)):
            fake.publish(String(data=ev.to_json()))
        submitter.send()
        assert wait_for(fleet, lambda: any(e.event == "done" for e in submitter.events)), submitter.events
        assert [e.event for e in submitter.events] == ["accepted", "assigned", "picked", "placed", "done"]
        assert submitter.keys.refused >= 2
    finally:
        fleet.monitor.destroy_publisher(fake)
        fleet.executor.remove_node(submitter)
        submitter.destroy_node()


def test_gate_records_count_only_signed_by_the_planner_fresh_and_for_this_robot(keyed, ros_context):
    """A gate record releases a robot into a collision region: with keys, an unsigned one, one signed
    with a key the robots do not trust, one re-signed for another robot's topic and a replay of the
    planner's own record are refused and counted, whoever publishes them; the robot keeps the
    planner's record (the forged ones, of a higher ``seq`` and with no links, would release it)."""
    fleet, files = keyed
    mon = fleet.monitor
    client, forger = Keys(sign_file=files["client"]), Keys(sign_file=files["forger"])
    mon.submit(client.sign(Task(id="K3", pick="chute_1", place="B04-01"), mon._tasks.topic_name))
    assert wait_for(fleet, lambda: any(e.event == "assigned" for e in mon.events_of("K3")))
    robot = next(e.robot_id for e in mon.events_of("K3") if e.event == "assigned")
    agent = fleet.agents[robot]
    driver = agent.agent.driver
    assert wait_for(fleet, lambda: driver.gate is not None and driver.gate.path_id == agent.agent.model.path_id)
    genuine = driver.gate
    assert genuine.auth is not None and genuine.auth["key"] == "planner"  # the planner signs its gate records
    impostor = rclpy.create_node("planner", namespace="/", context=ros_context)
    fleet.executor.add_node(impostor)
    try:
        fake = impostor.create_publisher(String, topics.gate_topic(robot), topics.GATE_QOS)
        other = next(r for r in fleet.agents if r != robot)
        release = replace(genuine, seq=genuine.seq + 50, links=(), watch=None, auth=None)
        refused = agent.keys.refused
        for rec in (release,                                                          # unsigned
                    forger.sign(release, fake.topic_name),                            # untrusted key
                    Keys(sign_file=files["planner"]).sign(release, topics.gate_topic(other)),  # another channel
                    genuine):                                                         # replayed
            fake.publish(String(data=rec.to_json()))
            assert wait_for(fleet, lambda n=refused: agent.keys.refused > n), rec
            refused = agent.keys.refused
        assert driver.gate.seq < release.seq and driver.gate.auth is not None
        assert driver.gate.auth["key"] == "planner"
    finally:
        fleet.executor.remove_node(impostor)
        impostor.destroy_node()
    assert wait_for(fleet, lambda: ended(fleet, "K3"))
    no_contact(fleet)
