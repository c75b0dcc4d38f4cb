"""The operator's commands over ROS (fleet_planner/ros/operator_services.py): std_srvs SetBool
services, the fleet/command@1 topic and its replies, Twist on cmd_vel, on the in-process test
fleet of test_ros_system (real rclpy nodes, real DDS), and ``fleet-op`` as a process. Each wait
is bounded; the robots' own status reports are checked for contact."""
import math

import pytest
from rclpy.parameter import Parameter
from std_msgs.msg import String
from test_ros_system import MEMBERS, ended, no_contact, run_fleet_op, running_fleet, wait_for

from fleet_planner.ros.operate import OperatorClient
from msg_schemas import topics
from msg_schemas.records import Command, Task


@pytest.fixture(scope="module")
def fleet(ros_context):
    for f in running_fleet(ros_context, [Parameter("offline_timeout_s", value=3.0)]):
        f.op = OperatorClient("test_operator", context=ros_context)
        f.executor.add_node(f.op)
        try:
            yield f
        finally:
            f.executor.remove_node(f.op)
            f.op.destroy_node()


def call(fleet, service, value):
    """Call a SetBool service and wait for the answer (bounded): the response."""
    future = [None]

    def answered():
        if future[0] is None:
            future[0] = fleet.op.call_set_bool(service, value)
        return future[0] is not None and future[0].done()

    assert wait_for(fleet, answered), f"{service}: no answer"
    return future[0].result()


def command(fleet, **fields):
    cmd = Command(id=f"c{len(fleet.op.replies)}_{fields['command']}", **fields)
    assert wait_for(fleet, fleet.op.commands_heard)
    fleet.op.send_command(cmd)
    assert wait_for(fleet, lambda: cmd.id in fleet.op.replies), f"no reply to {cmd}"
    return fleet.op.replies[cmd.id]


def status(fleet, rid):
    return fleet.monitor.status[rid]


def still(fleet, rid, seconds):
    """``rid`` does not move for ``seconds`` of simulated time (bounded)."""
    mon = fleet.monitor
    st0, t0 = status(fleet, rid), mon.now()
    moved = wait_for(fleet, lambda: math.dist((status(fleet, rid).x, status(fleet, rid).y), (st0.x, st0.y)) > 1e-6
                     or mon.now() > t0 + seconds)
    assert moved
    return math.dist((status(fleet, rid).x, status(fleet, rid).y), (st0.x, st0.y)) <= 1e-6


def test_pausing_a_robot_by_command_holds_it_and_resuming_lets_it_finish(fleet):
    mon = fleet.monitor
    mon.submit(Task(id="OP1", pick="chute_1", place="B01-02"))
    assert wait_for(fleet, lambda: any(e.event == "assigned" for e in mon.events_of("OP1")))
    rid = next(e.robot_id for e in mon.events_of("OP1") if e.event == "assigned")
    assert wait_for(fleet, lambda: status(fleet, rid).mode == "driving")
    res = command(fleet, command="pause", robot_id=rid)
    assert res.ok and "paused" in res.message
    wait_for(fleet, lambda: status(fleet, rid).mode != "driving")
    assert still(fleet, rid, 3.0), "a paused robot moved"
    assert command(fleet, command="resume", robot_id=rid).ok
    assert wait_for(fleet, lambda: ended(fleet, "OP1"))
    no_contact(fleet)


def test_a_paused_fleet_assigns_nothing_until_resumed(fleet):
    mon = fleet.monitor
    res = call(fleet, topics.PAUSE_FLEET_SERVICE, True)
    assert res.success and res.message.startswith("fleet paused")
    mon.submit(Task(id="OP2", pick="chute_2", place="B02-01"))
    t0 = mon.now()
    assert wait_for(fleet, lambda: mon.now() > t0 + 3.0)
    assert [e.event for e in mon.events_of("OP2")] == ["accepted"]
    assert call(fleet, topics.PAUSE_FLEET_SERVICE, False).success
    assert wait_for(fleet, lambda: ended(fleet, "OP2"))


def test_the_e_stop_stops_every_robot_at_once_latched_until_released(fleet):
    mon = fleet.monitor
    mon.submit(Task(id="OP3", pick="chute_1", place="B03-02"))
    assert wait_for(fleet, lambda: any(st.mode == "driving" for st in mon.status.values()))
    res = call(fleet, topics.ESTOP_SERVICE, True)
    assert res.success and res.message == "e-stop engaged"
    assert wait_for(fleet, lambda: all(mon.status[m.id].estop for m in MEMBERS)), "every agent reports the e-stop"
    assert wait_for(fleet, lambda: all(mon.status[m.id].mode != "driving" for m in MEMBERS))
    for m in MEMBERS:
        assert still(fleet, m.id, 1.0), f"{m.id} moved during the e-stop"
    assert command(fleet, command="estop").message == "the e-stop was already engaged"
    assert call(fleet, topics.ESTOP_SERVICE, False).success
    assert wait_for(fleet, lambda: not any(mon.status[m.id].estop for m in MEMBERS))
    assert wait_for(fleet, lambda: ended(fleet, "OP3"))
    no_contact(fleet)


def test_cancel_priority_and_send_go_as_json_commands_and_bad_ones_are_refused_naming_the_field(fleet):
    mon = fleet.monitor
    assert call(fleet, topics.PAUSE_FLEET_SERVICE, True).success
    mon.submit(Task(id="OP4", pick="chute_1", place="B04-01"))
    mon.submit(Task(id="OP5", pick="chute_2", place="B04-02"))
    assert wait_for(fleet, lambda: "OP5" in mon.last_event)
    reply = command(fleet, command="priority", task_id="OP5", priority=9)
    assert reply.ok and reply.message == "job OP5: priority 0 -> 9" and reply.command == "priority"
    reply = command(fleet, command="cancel", task_id="OP4", reason="not needed")
    assert reply.ok and wait_for(fleet, lambda: ended(fleet, "OP4", "cancelled"))
    assert "not needed" in mon.last_event["OP4"].reason
    reply = command(fleet, command="cancel", task_id="OP4")
    assert not reply.ok and reply.message == "task_id: job OP4 is already cancelled; nothing to cancel"
    reply = command(fleet, command="send", robot_id="r9", station="chute_1")
    assert not reply.ok and reply.message.startswith("robot_id: unknown robot 'r9'")
    fleet.monitor.create_publisher(String, topics.COMMANDS, topics.COMMANDS_QOS).publish(
        String(data='{"schema": "fleet/command@1", "id": "bad1", "command": "priority", "task_id": "OP5"}'))
    assert wait_for(fleet, lambda: "bad1" in fleet.op.replies)
    assert fleet.op.replies["bad1"].message == "command.priority: required for 'priority'"
    assert call(fleet, topics.PAUSE_FLEET_SERVICE, False).success
    assert wait_for(fleet, lambda: ended(fleet, "OP5"))
    free = next(m.id for m in MEMBERS if fleet.planner.fleet.robots[m.id].free)
    reply = command(fleet, command="send", robot_id=free, station="parking_1")
    assert reply.ok, reply.message
    spot = fleet.planner.fleet.parking["parking_1"]
    assert wait_for(fleet, lambda: math.dist((status(fleet, free).x, status(fleet, free).y), spot) < 0.05)
    no_contact(fleet)


def test_manual_drive_over_its_service_and_cmd_vel_then_the_robot_re_joins_the_plan(fleet):
    mon = fleet.monitor
    mon.submit(Task(id="OP6", pick="chute_1", place="B02-03"))
    assert wait_for(fleet, lambda: any(e.event == "assigned" for e in mon.events_of("OP6")))
    rid = next(e.robot_id for e in mon.events_of("OP6") if e.event == "assigned")
    assert wait_for(fleet, lambda: status(fleet, rid).mode == "driving")
    res = call(fleet, topics.robot_topic(rid, "manual"), True)
    assert res.success and "manual drive on" in res.message
    assert wait_for(fleet, lambda: status(fleet, rid).manual and fleet.planner.fleet.robots[rid].manual)
    assert wait_for(fleet, lambda: status(fleet, rid).mode != "driving")
    st0 = status(fleet, rid)
    bad = [(math.nan, 0.0), (50.0, 0.0)]  # refused, logged by the agent naming the field; the robot stays
    for v, w in bad:
        fleet.op.drive(rid, v, w)
    assert still(fleet, rid, 1.0)
    heading = (math.cos(st0.yaw), math.sin(st0.yaw))
    # drive forwards or backwards, whichever has room
    sign = 1.0 if fleet.planner.fleet.warehouse.grid.disc_is_free(st0.x + heading[0], st0.y + heading[1],
                                                                  st0.radius) else -1.0
    t0 = mon.now()

    def driven():
        fleet.op.drive(rid, 0.3 * sign, 0.0)
        return math.dist((status(fleet, rid).x, status(fleet, rid).y), (st0.x, st0.y)) > 0.2 or mon.now() > t0 + 10

    assert wait_for(fleet, driven) and mon.now() <= t0 + 10, "the robot did not drive by cmd_vel"
    assert call(fleet, topics.robot_topic(rid, "manual"), False).success
    assert wait_for(fleet, lambda: not status(fleet, rid).manual and not fleet.planner.fleet.robots[rid].manual)
    assert wait_for(fleet, lambda: ended(fleet, "OP6")), "it re-joins the plan and does its job"
    assert all(e.robot_id == rid for e in mon.events_of("OP6") if e.event in ("picked", "done"))
    no_contact(fleet)


def test_fleet_op_on_the_command_line(fleet):

    code, text = run_fleet_op(fleet, "pause", MEMBERS[0].id)
    assert code == 0 and "paused" in text, text
    code, text = run_fleet_op(fleet, "resume", MEMBERS[0].id)
    assert code == 0 and "resumed" in text, text
    code, text = run_fleet_op(fleet, "cancel", "no_such_job")
    assert code == 1 and "task_id: unknown job 'no_such_job'" in text, text
