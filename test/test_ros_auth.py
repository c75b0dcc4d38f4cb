"""Authenticated commands on the live fleet (issue 9, deliverable 5): with keys configured, a task
signed by a client key is done; unsigned and wrongly signed tasks are rejected with the reason and
counted; forged events and timed paths (unsigned, or signed with a key the robots do not trust) are
refused and counted by the agents, even from a node that calls itself the planner; so are forged
gate records, and the operator's commands (unsigned, wrongly signed, altered, replayed; the pause
and e-stop services but for engaging the e-stop; manual drive by service, Twist or unsigned robot
command), which are obeyed only when signed by an operator key."""
import math
import os
from dataclasses import replace

import pytest
import rclpy
from geometry_msgs.msg import Twist
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import String
from test_ros_system import KINDS, MEMBERS, PARKING, RATE, WH, ended, no_contact, run_fleet_op, wait_for

from fleet_planner.auth import new_key_line
from fleet_planner.ros.demo.bringup import Fleet, agent_params
from fleet_planner.ros.demo.monitor import FleetMonitor, spin_until
from fleet_planner.ros.operate import OperatorClient
from fleet_planner.ros.operator_services import SIGN_IT, SIGN_IT_ROBOT
from fleet_planner.ros.planner_node import PlannerNode
from fleet_planner.ros.signing import Keys
from fleet_planner.ros.sim_clock import SimClock
from fleet_planner.ros.submit import Submitter
from msg_schemas import topics
from msg_schemas.records import Command, RobotCommand, Task, TaskEvent
from robot_agent.agent_node import AgentNode


def key(tmp_path, name):
    path = tmp_path / name
    path.write_text(new_key_line(name.split(".")[0]) + "\n")
    os.chmod(path, 0o600)
    return str(path)


@pytest.fixture(scope="module")
def keyed(ros_context, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("keys")
    files = {name: key(tmp, f"{name}.key") for name in ("planner", "client", "forger", "operator")}
    sim = [Parameter("use_sim_time", value=True)]
    clock = SimClock(context=ros_context, parameter_overrides=[Parameter("rate", value=RATE)])
    planner = PlannerNode(context=ros_context, warehouse=WH, kinds=KINDS, parameter_overrides=sim + [
        Parameter("parking", value=PARKING), Parameter("auth_key_file", value=files["planner"]),
        Parameter("auth_trust_file", value=files["client"]), Parameter("auth_operator_file", value=files["operator"])])
    agents = {m.id: AgentNode(f"agent_{m.id}", context=ros_context, warehouse=WH, kinds=KINDS,
                              parameter_overrides=sim + agent_params(m) + [
                                  Parameter("auth_trust_file", value=files["planner"]),
                                  Parameter("auth_operator_file", value=files["operator"])]) for m in MEMBERS[:2]}
    monitor = FleetMonitor(context=ros_context, parameter_overrides=sim)
    fleet = Fleet(clock, planner, agents, monitor, SingleThreadedExecutor(context=ros_context))
    for node in fleet.nodes:
        fleet.executor.add_node(node)
    try:
        assert spin_until(fleet.executor, lambda: monitor.planner_ready() and set(agents) <= set(monitor.status), 60)
        yield fleet, files
    finally:
        fleet.destroy()


# (the operator's tests come first: a node named "planner" that leaves, as the impostors below do, leaves
# the real planner's endpoints without a known node name in this one-process graph, and the agents then
# refuse the e-stop's release from it: failing safe)
def ask(fleet, op, service, value):
    """Call a SetBool service (bounded wait): the response."""
    future = [None]

    def answered():
        if future[0] is None:
            future[0] = op.call_set_bool(service, value)
        return future[0] is not None and future[0].done()

    assert wait_for(fleet, answered), f"{service}: no answer"
    return future[0].result()


def published(fleet, op, raw, cid):
    """Publish ``raw`` on /fleet/commands as is and wait for the reply to ``cid``."""
    assert wait_for(fleet, op.commands_heard)
    op.replies.pop(cid, None)  # (a replay: the first copy's reply is not the answer)
    op._commands.publish(String(data=raw))
    assert wait_for(fleet, lambda: cid in op.replies), f"no reply to {cid}"
    return op.replies[cid]


def test_with_operator_keys_only_signed_commands_are_obeyed_and_the_e_stop_stays_open_to_anyone(keyed, ros_context):
    """Unsigned, untrusted, altered and replayed commands on /fleet/commands are refused with the
    reason and counted, and change nothing; the pause service and the e-stop's release are refused
    (no signature); engaging the e-stop is open to anyone; signed commands are obeyed."""
    fleet, files = keyed
    planner = fleet.planner
    operator = planner.operator.operator
    op = OperatorClient("keyed_operator", keys=Keys(sign_file=files["operator"]), context=ros_context)
    fleet.executor.add_node(op)
    try:
        channel = op._commands.topic_name
        forger, signer = Keys(sign_file=files["forger"]), Keys(sign_file=files["operator"])
        refused0 = planner.operator.keys.refused
        good = signer.sign(Command(id="k_replayed", command="pause"), channel)
        assert published(fleet, op, good.to_json(), "k_replayed").ok and operator.fleet_paused
        assert published(fleet, op, signer.sign(Command(id="k_resume", command="resume"), channel).to_json(),
                         "k_resume").ok and not operator.fleet_paused
        tampered = signer.sign(Command(id="k_altered", command="resume"), channel).to_json().replace(
            '"resume"', '"pause"')
        bad = [(Command(id="k_unsigned", command="pause").to_json(), "unsigned"),
               (forger.sign(Command(id="k_forged", command="pause"), channel).to_json(), "does not accept"),
               (tampered, "wrong signature"),
               (good.to_json(), "replayed")]
        for raw, why in bad:
            cid = Command.from_json(raw).id
            reply = published(fleet, op, raw, cid)
            assert not reply.ok and reply.message.startswith("command.auth: ") and why in reply.message, reply
        assert not operator.fleet_paused  # none of them paused the fleet
        res = ask(fleet, op, topics.PAUSE_FLEET_SERVICE, True)
        assert not res.success and SIGN_IT in res.message and not operator.fleet_paused
        assert planner.operator.keys.refused == refused0 + len(bad) + 1
        res = ask(fleet, op, topics.ESTOP_SERVICE, True)     # anyone may stop the fleet
        assert res.success and operator.estopped
        res = ask(fleet, op, topics.ESTOP_SERVICE, False)    # ... but not release it unsigned
        assert not res.success and SIGN_IT in res.message and operator.estopped
        op.send_command(Command(id="k_release", command="release"))  # (signed: the operator key)
        assert wait_for(fleet, lambda: "k_release" in op.replies) and op.replies["k_release"].ok
        assert not operator.estopped
    finally:
        fleet.executor.remove_node(op)
        op.destroy_node()
    # fleet-op signs with --key; without it the planner refuses the same command

    code, text = run_fleet_op(fleet, "pause", MEMBERS[0].id)
    assert code == 1 and "command.auth: unsigned" in text and not planner.fleet.robots[MEMBERS[0].id].paused
    code, text = run_fleet_op(fleet, "--key", files["operator"], "pause", MEMBERS[0].id)
    assert code == 0 and "paused" in text and planner.fleet.robots[MEMBERS[0].id].paused, text
    code, text = run_fleet_op(fleet, "--key", files["operator"], "resume", MEMBERS[0].id)
    assert code == 0 and not planner.fleet.robots[MEMBERS[0].id].paused, text


def test_with_operator_keys_manual_drive_takes_only_signed_robot_commands(keyed, ros_context):
    """On the agent: the manual service, a Twist on cmd_vel and unsigned, untrusted or other-robot
    robot commands are refused and counted (the robot stays put, not in manual drive); signed robot
    commands switch manual drive and drive it."""
    fleet, files = keyed
    mon = fleet.monitor
    rid = next(r for r in fleet.agents if fleet.planner.fleet.robots[r].free)
    agent = fleet.agents[rid]
    op = OperatorClient("keyed_hand", keys=Keys(sign_file=files["operator"]), context=ros_context)
    fleet.executor.add_node(op)
    try:
        assert wait_for(fleet, lambda: op.robot_heard(rid))
        channel = op.robot_command_publisher(rid).topic_name
        forger = Keys(sign_file=files["forger"])
        refused0 = agent.operator.keys.refused
        res = ask(fleet, op, topics.robot_topic(rid, "manual"), True)
        assert not res.success and SIGN_IT_ROBOT in res.message and not agent.agent.hand.manual
        raw_pub = op.robot_command_publisher(rid)
        for cmd, why in ((RobotCommand(id="h_unsigned", robot_id=rid, manual=True), "unsigned"),
                         (forger.sign(RobotCommand(id="h_forged", robot_id=rid, manual=True), channel),
                          "does not accept")):
            raw_pub.publish(String(data=cmd.to_json()))
            assert wait_for(fleet, lambda c=cmd: c.id in op.replies)
            assert not op.replies[cmd.id].ok and why in op.replies[cmd.id].message
        assert not agent.agent.hand.manual and agent.operator.keys.refused == refused0 + 3
        op.send_robot_command(RobotCommand(id="h_on", robot_id=rid, manual=True))
        assert wait_for(fleet, lambda: "h_on" in op.replies) and op.replies["h_on"].ok
        assert agent.agent.hand.manual
        assert wait_for(fleet, lambda: mon.status[rid].manual)
        st0 = mon.status[rid]
        twist = op.create_publisher(Twist, topics.robot_topic(rid, "cmd_vel"), topics.CMD_VEL_QOS)
        heading = (math.cos(st0.yaw), math.sin(st0.yaw))
        sign = 1.0 if fleet.planner.fleet.warehouse.grid.disc_is_free(st0.x + heading[0], st0.y + heading[1],
                                                                      st0.radius) else -1.0
        msg = Twist()
        msg.linear.x = 0.3 * sign
        t0 = mon.now()

        def twisted():
            twist.publish(msg)
            return agent.operator.keys.refused >= refused0 + 5 and mon.now() > t0 + 1.0

        assert wait_for(fleet, twisted)
        assert math.dist((mon.status[rid].x, mon.status[rid].y), (st0.x, st0.y)) < 1e-6, "a Twist drove it"
        t0 = mon.now()

        def driven():
            op.send_robot_command(RobotCommand(id=f"h_drive_{mon.now():.2f}", robot_id=rid, linear=0.3 * sign))
            return math.dist((mon.status[rid].x, mon.status[rid].y), (st0.x, st0.y)) > 0.2 or mon.now() > t0 + 10

        assert wait_for(fleet, driven) and mon.now() <= t0 + 10, "signed robot commands did not drive it"
        op.send_robot_command(RobotCommand(id="h_off", robot_id=rid, manual=False))
        assert wait_for(fleet, lambda: "h_off" in op.replies) and op.replies["h_off"].ok
        assert wait_for(fleet, lambda: not mon.status[rid].manual and not fleet.planner.fleet.robots[rid].manual)
    finally:
        fleet.executor.remove_node(op)
        op.destroy_node()
    no_contact(fleet)


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

