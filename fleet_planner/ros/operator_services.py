"""The operator's ROS face: services and topics of standard types on the planner and the agents,
a thin layer over :class:`~fleet_planner.fleet.operator.Operator` (planner) and
:class:`~fleet_planner.fleet.manual.OperatorHand` (agent). docs/ARCHITECTURE.md, "Topics and QoS".

On the planner (:class:`PlannerOperator`, made once by the planner node):

* ``/fleet/pause`` (std_srvs/SetBool): true pauses the fleet, false resumes it;
* ``/fleet/estop`` (std_srvs/SetBool): true engages the e-stop, false releases it; the state goes
  out at once, latched, on ``/fleet/estopped`` (std_msgs/Bool), which every agent obeys;
* ``/fleet/commands`` (std_msgs/String, ``fleet/command@1``): the commands with arguments (pause or
  resume one robot, cancel a job, change its priority, send a robot to a station, and the ones
  above), each answered on ``/fleet/command_replies`` (``fleet/command_reply@1``, same ``id``). No
  standard service type carries a string request and custom ``.srv`` types cannot be built from our
  wheels, so a JSON record on a topic, correlated by id, as tasks and task events are; a topic is
  also recorded with the rest of a run. One robot is paused by a command, not by a service of its
  own: 500 robots' services were 500 more entities in every wait of the planner's executor (2.8 ms
  of CPU per wake-up, measured, against 0.13 ms without).

On an agent (:class:`AgentOperator`): ``/robots/<id>/manual`` (std_srvs/SetBool) switches manual
drive, ``/robots/<id>/cmd_vel`` (geometry_msgs/Twist) drives it there, ``/robots/<id>/command``
(``fleet/robot_command@1``) does either, and it holds while ``/fleet/estopped`` is true (engaged by
anyone, released only by the planner node: see ``fleet_planner/ros/origin.py``).

**With operator keys** (``fleet_planner/auth.py``; the planner's ``auth_operator_file``, by default
the keys of ``auth_trust_file``; the agent's likewise): a ``fleet/command@1`` or
``fleet/robot_command@1`` is obeyed only when signed by one of those keys for its topic (``auth``:
fresh, not replayed); an unsigned or wrongly signed one is refused with the reason and counted. A
std_srvs service or a Twist carries no signature, so then they are refused and counted too (answer:
"sign it: fleet-op --key FILE"), with one exception: **engaging the e-stop** over ``/fleet/estop``
stays open to anyone (stopping is always safe, as the agents obey ``/fleet/estopped`` from anyone);
its release, a pause, a resume and manual drive need a signed command. ``fleet-op --key FILE``
sends every command signed on the topics. Every handler is total: bad input is answered (or logged,
for a topic) with the reason naming the field.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from geometry_msgs.msg import Twist
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from std_msgs.msg import Bool, String
from std_srvs.srv import SetBool

from fleet_planner.fleet import Decisions, FleetManager
from fleet_planner.fleet.agent import RobotAgent
from fleet_planner.fleet.manual import DEADMAN_S
from fleet_planner.fleet.operator import Operator, Outcome
from fleet_planner.ros.drain import create_draining_subscription
from fleet_planner.ros.origin import OriginCheck
from fleet_planner.ros.signing import Keys
from fleet_planner.validation import printable
from msg_schemas import topics
from msg_schemas.convert import string_to_record
from msg_schemas.records import (
    Command,
    CommandReply,
    OperatorState,
    RecordError,
    RobotCommand,
    load_json,
    nonempty,
)

#: the answer of a service or a Twist where operator keys are configured
SIGN_IT = "operator keys are configured: send it signed (fleet-op --key FILE; fleet/command@1 on /fleet/commands)"
SIGN_IT_ROBOT = ("operator keys are configured: send it signed (fleet-op --key FILE; fleet/robot_command@1 on "
                 "/robots/<id>/command)")

Publish = Callable[[Decisions, float], None]
#: wall seconds between two repeats of the e-stop's state on /fleet/estopped (latched; see step)
ESTOP_REPEAT_S = 2.0


def _now(node: Node) -> float:
    return node.get_clock().now().nanoseconds / 1e9


class PlannerOperator:
    """The operator's services and topics on the planner node ``node`` over its ``fleet``;
    ``publish`` sends a command's legs and events at once. Call :meth:`step` instead of the
    fleet's ``step``."""

    def __init__(self, node: Node, fleet: FleetManager, publish: Publish, keys: Keys | None = None):
        self.node = node
        self.operator = Operator(fleet)
        self._publish = publish
        #: the operators' keys: with them, only signed commands are obeyed (see the module's docstring)
        self.keys = keys or Keys()
        self._estopped = node.create_publisher(Bool, topics.ESTOPPED, topics.ESTOPPED_QOS)
        self._replies = node.create_publisher(String, topics.COMMAND_REPLIES, topics.COMMAND_REPLIES_QOS)
        self._state = node.create_publisher(String, topics.OPERATOR_STATE, topics.OPERATOR_STATE_QOS)
        self._last_state: tuple | None = None
        node.create_service(SetBool, topics.PAUSE_FLEET_SERVICE, self._on_pause_fleet)
        node.create_service(SetBool, topics.ESTOP_SERVICE, self._on_estop)
        self._commands = create_draining_subscription(node, String, topics.COMMANDS, self._on_command,
                                                      topics.COMMANDS_QOS)
        self._estopped.publish(Bool(data=False))
        self._estop_said = time.monotonic()

    def step(self, now: float) -> Decisions:
        """The fleet's planning step through the operator (manual drive, late jobs). The e-stop's
        state is said again every ESTOP_REPEAT_S wall seconds: an agent that refused a release
        (another publisher on the topic, or one the graph does not yet know by name: it cannot tell
        who sent it) takes the next one once only the planner publishes there, instead of holding for good."""
        d = self.operator.step(now)
        if time.monotonic() - self._estop_said >= ESTOP_REPEAT_S:
            self._estopped.publish(Bool(data=self.operator.estopped))
            self._estop_said = time.monotonic()
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
        self._estop_said = time.monotonic()
        self._publish(out.decisions, now)
        self._publish_state(now)
        return out

    def _answer(self, res: Any, out: Outcome) -> Any:
        res.success, res.message = out.ok, out.message
        return res

    def _unsigned(self, service: str) -> Outcome | None:
        """With operator keys, a service call (no signature) is refused and counted."""
        if not self.keys.checks:
            return None
        refused = self.keys.verifier.refused  # type: ignore[union-attr]  # (checks: it has one)
        refused["unsigned service"] = refused.get("unsigned service", 0) + 1
        self.node.get_logger().warning(f"operator service {service} refused: {SIGN_IT}", throttle_duration_sec=2.0)
        return Outcome(False, f"{service}: {SIGN_IT}")

    def _on_pause_fleet(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        refused = self._unsigned(topics.PAUSE_FLEET_SERVICE)
        if refused is not None:
            return self._answer(res, refused)
        act = self.operator.pause if req.data else self.operator.resume
        return self._answer(res, self._carry_out(lambda now: act(None, now)))

    def _on_estop(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        refused = None if req.data else self._unsigned(topics.ESTOP_SERVICE)  # engaging it: anyone, always
        if refused is not None:
            return self._answer(res, refused)
        act = self.operator.estop if req.data else self.operator.release
        return self._answer(res, self._carry_out(act))

    def _on_command(self, msg: String) -> None:
        try:
            command = string_to_record(msg, Command)
        except RecordError as exc:
            self.node.get_logger().warning(f"operator command refused: {exc}", throttle_duration_sec=2.0)
            self._reply(_guess_id(msg.data), False, str(exc), None)
            return
        problem = self.keys.problem(command, self._commands.topic_name)
        if problem:
            why = f"command.auth: {problem} ({self.keys.refused} refused so far)"
            self.node.get_logger().warning(f"operator command {command.command} refused: {why}",
                                           throttle_duration_sec=2.0)
            self._reply(command.id, False, why, command.command)
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

    def __init__(self, node: Node, agent: RobotAgent, robot_id: str, planner: str | None = None,
                 keys: Keys | None = None):
        self.node = node
        self.agent = agent
        self.robot_id = robot_id
        #: the operators' keys: with them, manual drive only by signed robot commands
        self.keys = keys or Keys()
        self._replies: Any = None   # (made at the first switch: most robots never get one)
        node.create_service(SetBool, topics.robot_topic(robot_id, "manual"), self._on_manual)
        node.create_subscription(Twist, topics.robot_topic(robot_id, "cmd_vel"), self._on_cmd_vel,
                                 topics.CMD_VEL_QOS)
        self._commands = create_draining_subscription(node, String, topics.robot_topic(robot_id, "command"),
                                                      self._on_robot_command, topics.ROBOT_COMMAND_QOS)
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

    def _count_unsigned(self, what: str) -> bool:
        """With operator keys, ``what`` (a service call, a Twist: no signature) is refused and counted."""
        if not self.keys.checks:
            return False
        refused = self.keys.verifier.refused  # type: ignore[union-attr]  # (checks: it has one)
        refused[what] = refused.get(what, 0) + 1
        self.node.get_logger().warning(f"{what} refused: {SIGN_IT_ROBOT}", throttle_duration_sec=2.0)
        return True

    def _switch(self, on: bool) -> tuple[bool, str]:
        try:
            message = self.agent.hand.set_manual(on)
            ok = True
        except ValueError as exc:
            ok, message = False, str(exc)
        except Exception as exc:
            self.node.get_logger().error(f"manual drive switch failed: {exc!r}")
            ok, message = False, f"internal error: {exc}"
        self.node.get_logger().info(message)
        return ok, message

    def _on_manual(self, req: SetBool.Request, res: SetBool.Response) -> SetBool.Response:
        if self._count_unsigned("manual service"):
            res.success, res.message = False, f"manual: {SIGN_IT_ROBOT}"
            return res
        res.success, res.message = self._switch(bool(req.data))
        return res

    def _drive(self, linear: tuple[float, float, float], angular: tuple[float, float, float], what: str) -> None:
        try:
            self._held = None
            self.agent.hand.command(linear, angular, _now(self.node))
            self._held = (linear, angular, time.monotonic())
        except ValueError as exc:
            self.node.get_logger().warning(f"{what} refused: {exc}", throttle_duration_sec=2.0)
        except Exception as exc:
            self.node.get_logger().error(f"{what}: {exc!r}", throttle_duration_sec=2.0)

    def _on_cmd_vel(self, msg: Twist) -> None:
        try:
            if self._count_unsigned("cmd_vel"):
                return
            lin, ang = msg.linear, msg.angular
        except Exception as exc:
            self.node.get_logger().error(f"cmd_vel: {exc!r}", throttle_duration_sec=2.0)
            return
        self._drive((lin.x, lin.y, lin.z), (ang.x, ang.y, ang.z), "cmd_vel")

    def _on_robot_command(self, msg: String) -> None:
        """A ``fleet/robot_command@1``: checked (this robot's, signed where keys are configured), then
        the switch (answered on /fleet/command_replies) and the velocity command."""
        try:
            cmd = string_to_record(msg, RobotCommand)
        except RecordError as exc:
            self.node.get_logger().warning(f"robot command refused: {exc}", throttle_duration_sec=2.0)
            return
        try:
            if cmd.robot_id != self.robot_id:
                self._reply(cmd.id, False, f"robot_command.robot_id: {cmd.robot_id!r} is not this robot "
                                           f"({self.robot_id!r})")
                return
            problem = self.keys.problem(cmd, self._commands.topic_name)
            if problem:
                why = f"robot_command.auth: {problem} ({self.keys.refused} refused so far)"
                self.node.get_logger().warning(f"robot command refused: {why}", throttle_duration_sec=2.0)
                self._reply(cmd.id, False, why)
                return
            if cmd.manual is not None:
                self._reply(cmd.id, *self._switch(cmd.manual))
            if cmd.linear is not None or cmd.angular is not None:
                self._drive((cmd.linear or 0.0, 0.0, 0.0), (0.0, 0.0, cmd.angular or 0.0), "robot command")
        except Exception as exc:
            self.node.get_logger().error(f"robot command: {exc!r}", throttle_duration_sec=2.0)

    def _reply(self, cid: str, ok: bool, message: str) -> None:
        if self._replies is None:
            self._replies = self.node.create_publisher(String, topics.COMMAND_REPLIES, topics.COMMAND_REPLIES_QOS)
        reply = CommandReply(id=cid, ok=ok, message=printable(message or "-", 1000), stamp=_now(self.node))
        self._replies.publish(String(data=reply.to_json()))

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

