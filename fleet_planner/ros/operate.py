"""``fleet-op``: the operator's commands from a shell (a sibling of ``fleet-submit``).

    fleet-op pause [r3]            # the fleet (std_srvs/SetBool /fleet/pause) or one robot (a command)
    fleet-op resume [r3]
    fleet-op estop                 # every robot stops at once, latched (SetBool /fleet/estop)
    fleet-op release
    fleet-op cancel J1 [--reason "wrong chute"]   # fleet/command@1 on /fleet/commands
    fleet-op priority J1 5
    fleet-op send r3 charger_2
    fleet-op manual r3 on|off      # SetBool /robots/r3/manual (the robot's agent)
    fleet-op drive r3 --linear 0.3 --angular 0 --seconds 2   # Twist on /robots/r3/cmd_vel at 10 Hz
    fleet-op --key op.key estop    # signed (fleet_planner/auth.py): every command as a record on a topic

With ``--key FILE`` (where the planner and agents have operator keys) every command is a signed
record: ``fleet/command@1`` on ``/fleet/commands`` for the planner's (pause, resume, e-stop,
release too), ``fleet/robot_command@1`` on ``/robots/<id>/command`` for manual drive and driving
(answered on ``/fleet/command_replies``); services and Twists carry no signature.

Prints the answer and exits 0 when the command was carried out, 1 when it was refused or nobody
answered within ``--timeout`` wall seconds. :class:`OperatorClient` is the same hand for other
tools (the web console).
"""
from __future__ import annotations

import argparse
import sys
import time
import uuid
from typing import Any

import rclpy
from geometry_msgs.msg import Twist
from rclpy.client import Client
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import String
from std_srvs.srv import SetBool

from fleet_planner.ros.entry import run_node
from fleet_planner.ros.signing import Keys
from msg_schemas import topics
from msg_schemas.convert import string_to_record
from msg_schemas.records import Command, CommandReply, RecordError, RobotCommand


class OperatorClient(Node):
    """Calls the operator's services, publishes commands and velocity commands, and collects the
    replies (non-blocking: the caller spins; :func:`wait` is a bounded wait)."""

    def __init__(self, name: str = "fleet_op", *, keys: Keys | None = None, **kwargs: Any):
        super().__init__(name, **kwargs)
        #: with a signing key, commands go out signed
        self.keys = keys or Keys()
        self.replies: dict[str, CommandReply] = {}
        self._set_bools: dict[str, Client] = {}
        self._cmd_vels: dict[str, Any] = {}
        self._robot_commands: dict[str, Any] = {}
        self._commands = self.create_publisher(String, topics.COMMANDS, topics.COMMANDS_QOS)
        self._replies = self.create_subscription(String, topics.COMMAND_REPLIES, self._on_reply,
                                                 topics.COMMAND_REPLIES_QOS)

    # -- std_srvs/SetBool ---------------------------------------------------------------------------
    def set_bool_client(self, service: str) -> Client:
        if service not in self._set_bools:
            self._set_bools[service] = self.create_client(SetBool, service)
        return self._set_bools[service]

    def call_set_bool(self, service: str, value: bool) -> Future | None:
        """Call ``service`` with ``data=value``; None if no server is there (yet)."""
        client = self.set_bool_client(service)
        if not client.service_is_ready():
            return None
        return client.call_async(SetBool.Request(data=bool(value)))

    # -- fleet/command@1 ------------------------------------------------------------------------------
    def commands_heard(self) -> bool:
        """The planner takes our commands and we hear its replies."""
        return self._commands.get_subscription_count() > 0 and self._replies.get_publisher_count() > 0

    def send_command(self, command: Command) -> None:
        self._commands.publish(String(data=self.keys.sign(command, self._commands.topic_name).to_json()))

    # -- fleet/robot_command@1 (an agent) -------------------------------------------------------------
    def robot_command_publisher(self, robot_id: str) -> Any:
        if robot_id not in self._robot_commands:
            self._robot_commands[robot_id] = self.create_publisher(
                String, topics.robot_topic(robot_id, "command"), topics.ROBOT_COMMAND_QOS)
        return self._robot_commands[robot_id]

    def robot_heard(self, robot_id: str) -> bool:
        """The robot's agent takes our robot commands and we hear the replies."""
        return self.robot_command_publisher(robot_id).get_subscription_count() > 0 \
            and self._replies.get_publisher_count() > 0

    def send_robot_command(self, command: RobotCommand) -> None:
        pub = self.robot_command_publisher(command.robot_id)
        pub.publish(String(data=self.keys.sign(command, pub.topic_name).to_json()))

    def _on_reply(self, msg: String) -> None:
        try:
            reply = string_to_record(msg, CommandReply)
        except RecordError as exc:
            self.get_logger().warning(f"command reply ignored: {exc}", throttle_duration_sec=5.0)
            return
        self.replies[reply.id] = reply
        while len(self.replies) > 1000:
            self.replies.pop(next(iter(self.replies)))

    # -- geometry_msgs/Twist ----------------------------------------------------------------------------
    def drive(self, robot_id: str, linear: float, angular: float) -> None:
        """One velocity command to ``robot_id`` (ValueError for a bad id)."""
        if robot_id not in self._cmd_vels:
            self._cmd_vels[robot_id] = self.create_publisher(Twist, topics.robot_topic(robot_id, "cmd_vel"),
                                                           topics.CMD_VEL_QOS)
        msg = Twist()
        msg.linear.x, msg.angular.z = float(linear), float(angular)
        self._cmd_vels[robot_id].publish(msg)


def wait(executor: Executor, condition: Any, timeout: float) -> bool:
    """Spin until ``condition()`` or ``timeout`` wall seconds; returns it."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.05)
    return True


def set_bool(node: OperatorClient, executor: Executor, service: str, value: bool, timeout: float) -> tuple[bool, str]:
    """Call a SetBool service and wait for its answer: (success, message)."""
    future: list[Future | None] = [None]

    def called() -> bool:
        if future[0] is None:
            future[0] = node.call_set_bool(service, value)
        return future[0] is not None and future[0].done()

    if not wait(executor, called, timeout):
        return False, f"{service}: no answer within {timeout:g} s" if future[0] else f"{service}: no such service"
    res = future[0].result() if future[0] is not None else None
    return (bool(res.success), str(res.message)) if res is not None else (False, f"{service}: the call failed")


def command(node: OperatorClient, executor: Executor, cmd: Command, timeout: float) -> tuple[bool, str]:
    """Publish a command once the planner hears us and wait for its reply: (ok, message)."""
    return _send_and_wait(node, executor, cmd.id, node.commands_heard, lambda: node.send_command(cmd),
                          f"no planner on {topics.COMMANDS}", f"no reply to {cmd.command}", timeout)


def robot_command(node: OperatorClient, executor: Executor, cmd: RobotCommand, timeout: float) -> tuple[bool, str]:
    """Publish a manual drive switch once the robot's agent hears us and wait for its reply."""
    return _send_and_wait(node, executor, cmd.id, lambda: node.robot_heard(cmd.robot_id),
                          lambda: node.send_robot_command(cmd),
                          f"no agent on {topics.robot_topic(cmd.robot_id, 'command')}",
                          f"no reply from robot {cmd.robot_id}", timeout)


def _send_and_wait(node: OperatorClient, executor: Executor, cmd_id: str, heard: Any, send: Any,
                   not_heard: str, no_reply: str, timeout: float) -> tuple[bool, str]:
    """Send once ``heard()`` holds, then wait for the reply to ``cmd_id``; each wait bounded by ``timeout``."""
    if not wait(executor, heard, timeout):
        return False, f"{not_heard} within {timeout:g} s"
    send()
    if not wait(executor, lambda: cmd_id in node.replies, timeout):
        return False, f"{no_reply} within {timeout:g} s"
    reply = node.replies[cmd_id]
    return reply.ok, reply.message


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fleet-op", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("--timeout", type=float, default=10.0, help="wall seconds to wait for an answer (default 10)")
    p.add_argument("--key", default="", metavar="FILE",
                   help="operator key file (fleet_planner/auth.py): send every command signed with its first key")
    sub = p.add_subparsers(dest="what", required=True)
    for name, words in (("pause", "pause the fleet or one robot"), ("resume", "resume the fleet or one robot")):
        sp = sub.add_parser(name, help=words)
        sp.add_argument("robot", nargs="?", help="robot id (default: the whole fleet)")
    sub.add_parser("estop", help="engage the e-stop: every robot stops, latched")
    sub.add_parser("release", help="release the e-stop")
    sp = sub.add_parser("cancel", help="cancel a job")
    sp.add_argument("job")
    sp.add_argument("--reason")
    sp = sub.add_parser("priority", help="change a job's priority (higher goes first)")
    sp.add_argument("job")
    sp.add_argument("priority", type=int)
    sp = sub.add_parser("send", help="send a free robot to a station or parking spot")
    sp.add_argument("robot")
    sp.add_argument("station")
    sp = sub.add_parser("manual", help="switch a robot's manual drive on or off")
    sp.add_argument("robot")
    sp.add_argument("state", choices=("on", "off"))
    sp = sub.add_parser("drive", help="drive a robot in manual drive (Twist at 10 Hz)")
    sp.add_argument("robot")
    sp.add_argument("--linear", type=float, default=0.0, help="m/s forward (negative: backwards)")
    sp.add_argument("--angular", type=float, default=0.0, help="rad/s, counter-clockwise")
    sp.add_argument("--seconds", type=float, default=1.0, help="how long (wall seconds, default 1)")
    return p


def command_of(opts: argparse.Namespace, signed: bool = False) -> Command | None:
    """The ``fleet/command@1`` record of a command for the planner that goes on the topic: those
    with arguments, one robot's pause or resume, and (``signed``) every one; None for the others."""
    cid = f"op_{uuid.uuid4().hex[:8]}"
    if opts.what in ("pause", "resume") and (opts.robot or signed):
        return Command(id=cid, command=opts.what, robot_id=opts.robot)
    if opts.what in ("estop", "release") and signed:
        return Command(id=cid, command=opts.what)
    if opts.what == "cancel":
        return Command(id=cid, command="cancel", task_id=opts.job, reason=opts.reason)
    if opts.what == "priority":
        return Command(id=cid, command="priority", task_id=opts.job, priority=opts.priority)
    if opts.what == "send":
        return Command(id=cid, command="send", robot_id=opts.robot, station=opts.station)
    return None


def run(node: OperatorClient, opts: argparse.Namespace, cmd: Command | None) -> int:
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    t = opts.timeout
    signed = node.keys.signer is not None
    try:
        if cmd is not None:
            ok, message = command(node, executor, cmd, t)
        elif opts.what == "pause" or opts.what == "resume":
            ok, message = set_bool(node, executor, topics.PAUSE_FLEET_SERVICE, opts.what == "pause", t)
        elif opts.what in ("estop", "release"):
            ok, message = set_bool(node, executor, topics.ESTOP_SERVICE, opts.what == "estop", t)
        elif opts.what == "manual" and signed:
            ok, message = robot_command(node, executor, RobotCommand(
                id=f"op_{uuid.uuid4().hex[:8]}", robot_id=opts.robot, manual=opts.state == "on"), t)
        elif opts.what == "manual":
            ok, message = set_bool(node, executor, topics.robot_topic(opts.robot, "manual"), opts.state == "on", t)
        else:  # drive
            if signed and not wait(executor, lambda: node.robot_heard(opts.robot), t):
                ok, message = False, f"no agent on {topics.robot_topic(opts.robot, 'command')} within {t:g} s"
            else:
                _drive(node, executor, opts, signed)
                ok, message = True, f"sent {opts.seconds:g} s of {'signed commands' if signed else 'cmd_vel'} " \
                                    f"to {opts.robot}"
    finally:
        executor.remove_node(node)
    print(message, file=sys.stdout if ok else sys.stderr, flush=True)
    return 0 if ok else 1


def _drive(node: OperatorClient, executor: Executor, opts: argparse.Namespace, signed: bool) -> None:
    """Velocity commands at 10 Hz for ``opts.seconds``, then a stop."""
    def send(linear: float, angular: float) -> None:
        if signed:
            node.send_robot_command(RobotCommand(id=f"op_{uuid.uuid4().hex[:8]}", robot_id=opts.robot,
                                                 linear=linear, angular=angular))
        else:
            node.drive(opts.robot, linear, angular)

    end = time.monotonic() + max(0.0, opts.seconds)
    while time.monotonic() < end:
        send(opts.linear, opts.angular)
        executor.spin_once(timeout_sec=0.1)
    send(0.0, 0.0)


def main(args: list[str] | None = None) -> None:
    argv = sys.argv if args is None else args
    parser = _parser()
    opts = parser.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    try:  # bad ids and records are usage errors, said before ROS starts
        if getattr(opts, "robot", None) is not None:
            topics.robot_topic(opts.robot, "pause")
        keys = Keys(sign_file=opts.key)
        cmd = command_of(opts, signed=keys.signer is not None)
    except (ValueError, RecordError) as exc:
        parser.error(str(exc))
    run_node(lambda: OperatorClient(keys=keys), argv, prog="fleet-op", spin=lambda node: run(node, opts, cmd),
             errors=(), interrupted=1)


if __name__ == "__main__":
    main()
