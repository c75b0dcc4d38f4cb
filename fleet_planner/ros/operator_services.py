"""The operator's ROS face: services and topics of standard types on the planner and the agents,
a thin layer over :class:`~fleet_planner.fleet.operator.Operator` (planner) and
:class:`~fleet_planner.fleet.manual.OperatorHand` (agent). docs/ARCHITECTURE.md, "Topics and QoS".

On the planner (:class:`PlannerOperator`, made once by the planner node):

* ``/fleet/pause`` (std_srvs/SetBool): true pauses the fleet, false resumes it;
* ``/robots/<id>/pause`` (std_srvs/SetBool): the same for one robot (made when the robot joins);
* ``/fleet/estop`` (std_srvs/SetBool): true engages the e-stop, false releases it; the state goes
  out at once, latched, on ``/fleet/estopped`` (std_msgs/Bool), which every agent obeys;
* ``/fleet/commands`` (std_msgs/String, ``fleet/command@1``): the commands with arguments (cancel a
  job, change its priority, send a robot to a station, and the ones above), each answered on
  ``/fleet/command_replies`` (``fleet/command_reply@1``, same ``id``). No standard service type
  carries a string request and custom ``.srv`` types cannot be built from our wheels, so a JSON
  record on a topic, correlated by id, as tasks and task events are; a topic is also recorded
  with the rest of a run.

On an agent (:class:`AgentOperator`): ``/robots/<id>/manual`` (std_srvs/SetBool) switches manual
drive, ``/robots/<id>/cmd_vel`` (geometry_msgs/Twist) drives it there, and it holds while
``/fleet/estopped`` is true (engaged by anyone, released only by the planner node: see
``fleet_planner/ros/origin.py``). Every handler is total: bad input is answered (or logged, for a topic)
with the reason naming the field.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from geometry_msgs.msg import Twist
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.service import Service
from std_msgs.msg import Bool, String
from std_srvs.srv import SetBool

from fleet_planner.fleet import Decisions, FleetManager
from fleet_planner.fleet.agent import RobotAgent
from fleet_planner.fleet.manual import DEADMAN_S
from fleet_planner.fleet.operator import Operator, Outcome
from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.origin import OriginCheck
from fleet_planner.validation import printable
from msg_schemas import topics
from msg_schemas.convert import string_to_record
from msg_schemas.records import Command, CommandReply, OperatorState, RecordError, load_json, nonempty

Publish = Callable[[Decisions, float], None]


def _now(node: Node) -> float:
    return node.get_clock().now().nanoseconds / 1e9


class PlannerOperator:
    """The operator's services and topics on the planner node ``node`` over its ``fleet``;
    ``publish`` sends a command's legs and events at once. Call :meth:`step` instead of the
    fleet's ``step``."""

    def __init__(self, node: Node, fleet: FleetManager, publish: Publish):
        self.node = node
        self.operator = Operator(fleet)
        self._publish = publish
        self._robot_services: dict[str, Service] = {}
        self._estopped = node.create_publisher(Bool, topics.ESTOPPED, topics.ESTOPPED_QOS)
        self._replies = node.create_publisher(String, topics.COMMAND_REPLIES, topics.COMMAND_REPLIES_QOS)
        self._state = node.create_publisher(String, topics.OPERATOR_STATE, topics.OPERATOR_STATE_QOS)
        self._last_state: tuple | None = None
        node.create_service(SetBool, topics.PAUSE_FLEET_SERVICE, self._on_pause_fleet)
        node.create_service(SetBool, topics.ESTOP_SERVICE, self._on_estop)
        create_draining_subscription(node, String, topics.COMMANDS, self._on_command, topics.COMMANDS_QOS)
        self._estopped.publish(Bool(data=False))

    def step(self, now: float) -> Decisions:
        """The fleet's planning step through the operator (manual drive, late jobs); robots that
        joined get their pause service."""
        for rid in self.operator.fleet.robots.keys() - self._robot_services.keys():
            self._robot_services[rid] = self.node.create_service(
                SetBool, topics.robot_topic(rid, "pause"),
                lambda req, res, rid=rid: self._on_pause_robot(rid, req, res))
        d = self.operator.step(now)
        self._publish_state(now)
        return d

    def _publish_state(self, now: float) -> None:
        """The operator's state, latched, when it changed."""
        op, robots = self.operator, self.operator.fleet.robots.values()
        state = (op.estopped, op.fleet_paused, tuple(sorted(r.id for r in robots if r.paused)),
                 tuple(sorted(r.id for r in robots if r.manual)))
        if state != self._last_state:
            self._last_state = state
            record = OperatorState(stamp=now, estop=state[0], fleet_paused=state[1], paused=state[2], manual=state[3])
            self._state.publish(String(data=record.to_json()))

    # -- handlers: none lets an exception out -----------------------------------------------------
    def _carry_out(self, action: Callable[[float], Outcome]) -> Outcome:
        now = _now(self.node)
        try:
            out = action(now)
        except Exception as exc:  # a bug must not take the planner down: answer, log, carry on
            self.node.get_logger().error(f"operator command failed: {exc!r}")
            return Outcome(False, printable(f"internal error: {exc}", 300))
        if out.ok:
            self.node.get_logger().info(f"operator: {out.message}")
        else:
            self.node.get_logger().warning(f"operator command refused: {out.message}")
        self._estopped.publish(Bool(data=self.operator.estopped))  # at once, before any leg
        self._publish(out.decisions, now)
        self._publish_state(now)
        return out

    def _answer(self, res: Any, out: Outcome) -> Any:
        res.success, res.message = out.ok, out.message
        return res

    def _on_pause_fleet(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        act = self.operator.pause if req.data else self.operator.resume
        return self._answer(res, self._carry_out(lambda now: act(None, now)))

    def _on_pause_robot(self, rid: str, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        act = self.operator.pause if req.data else self.operator.resume
        return self._answer(res, self._carry_out(lambda now: act(rid, now)))

    def _on_estop(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        act = self.operator.estop if req.data else self.operator.release
        return self._answer(res, self._carry_out(act))

    def _on_command(self, msg: String) -> None:
        try:
            command = string_to_record(msg, Command)
        except RecordError as exc:
            self.node.get_logger().warning(f"operator command refused: {exc}", throttle_duration_sec=2.0)
            self._reply(_guess_id(msg.data), False, str(exc), None)
            return
        out = self._carry_out(lambda now: self.operator.execute(command, now))
        self._reply(command.id, out.ok, out.message, command.command)

    def _reply(self, cid: str, ok: bool, message: str, command: str | None) -> None:
        try:
            reply = CommandReply(id=cid, ok=ok, message=printable(message or "-", 1000), stamp=_now(self.node),
                                 command=command)
        except RecordError as exc:
            self.node.get_logger().error(f"operator reply not sent: {exc}")
            return
        self._replies.publish(String(data=reply.to_json()))


def _guess_id(raw: str) -> str:
    """The ``id`` of a command that failed validation, when one can be made out and is itself a
    valid id ("?" if not: a reply never echoes an oversized or unprintable id)."""
    try:
        data = load_json(raw, "command")
        return nonempty(data.get("id") if isinstance(data, dict) else None, "command.id")
    except RecordError:
        return "?"


class AgentOperator:
    """The operator's services and topics on the agent node ``node`` of ``agent``."""

    def __init__(self, node: Node, agent: RobotAgent, robot_id: str, planner: str | None = None):
        self.node = node
        self.agent = agent
        node.create_service(SetBool, topics.robot_topic(robot_id, "manual"), self._on_manual)
        node.create_subscription(Twist, topics.robot_topic(robot_id, "cmd_vel"), self._on_cmd_vel,
                                 topics.CMD_VEL_QOS)
        estop = node.create_subscription(Bool, topics.ESTOPPED, self._on_estop, topics.ESTOPPED_QOS)
        # an e-stop is obeyed from anyone (fail safe); its release only from the planner node
        self.estop_origin = OriginCheck(node, estop, planner) if planner else None
        # the operator's hand keeps wall time: a command held fresh (DEADMAN_S of wall time) is given
        # again on the robot's clock, which may run faster than real time (use_sim_time)
        self._held: tuple[tuple[float, float, float], tuple[float, float, float], float] | None = None
        node.create_timer(0.05, self._keep_alive, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _keep_alive(self) -> None:
        held = self._held
        if held is None:
            return
        if time.monotonic() - held[2] > DEADMAN_S:
            self._held = None
            return
        try:
            self.agent.hand.command(held[0], held[1], _now(self.node))
        except Exception:   # (a command already passed the checks once; manual drive may be off now)
            self._held = None

    def _on_manual(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        try:
            res.message = self.agent.hand.set_manual(bool(req.data))
            res.success = True
        except ValueError as exc:
            res.success, res.message = False, str(exc)
        except Exception as exc:
            self.node.get_logger().error(f"manual drive switch failed: {exc!r}")
            res.success, res.message = False, f"internal error: {exc}"
        self.node.get_logger().info(res.message)
        return res

    def _on_cmd_vel(self, msg: Twist) -> None:
        try:
            lin, ang = msg.linear, msg.angular
            linear, angular = (lin.x, lin.y, lin.z), (ang.x, ang.y, ang.z)
            self._held = None
            self.agent.hand.command(linear, angular, _now(self.node))
            self._held = (linear, angular, time.monotonic())
        except ValueError as exc:
            self.node.get_logger().warning(f"cmd_vel refused: {exc}", throttle_duration_sec=2.0)
        except Exception as exc:
            self.node.get_logger().error(f"cmd_vel: {exc!r}", throttle_duration_sec=2.0)

    def _on_estop(self, msg: Bool) -> None:
        try:
            release = not msg.data and self.agent.hand.estopped
            if release and self.estop_origin is not None and (problem := self.estop_origin.problem()):
                self.node.get_logger().error(printable(f"e-stop release ignored: not from the planner: {problem}",
                                                       300), throttle_duration_sec=1.0)
                return
            if bool(msg.data) != self.agent.hand.estopped:
                self.node.get_logger().info(self.agent.hand.set_estop(bool(msg.data)))
        except Exception as exc:
            self.node.get_logger().error(f"e-stop: {exc!r}")

