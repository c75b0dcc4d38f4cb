"""Whose messages these are: :class:`OriginCheck`, how an agent and ``fleet-submit`` accept task
events and timed paths only from the planner node, with or without keys (issue 9, deliverable 5).

rclpy of ROS 2 Jazzy cannot tell which publisher sent a message: its ``MessageInfo`` has the
timestamps and sequence numbers but no publisher gid (rclpy gained ``publisher_gid`` after
Jazzy, ros2/rclpy issue 1465), so a message cannot be attributed one by one. What the graph API
does tell is who publishes on a topic, by node name (``Node.get_publishers_info_by_topic``), and
the subscription tells how many publishers it is matched with (``Subscription.get_publisher_count``,
counted by the middleware as writers match, before their node names are known). A message is taken
as the planner's when, as it is handled, every publisher of the topic is the planner node (by fully
qualified name) and the subscription is matched with no more publishers than the graph names:
then nobody else can have sent it. While any other node publishes there, every message on the
topic is refused (a robot stops taking new paths and jobs: it fails safe) and the refusal names
the intruder.

What it cannot do: a node that takes the planner's name passes (names are not authenticated in
plain DDS); configure keys (``fleet_planner/auth.py``), or SROS2 on a full ROS install, for that.

Right after the planner creates a publisher (its first timed path or gate record to a robot) the
subscriber may be matched with it before the graph knows its node name: the message is refused as
"not known by name yet". For a latched gate record that would hold the robot at its leg's start
until the next record, so the agent keeps such a record and asks :meth:`OriginCheck.settled` again
for a few seconds: taken once only the planner is named, dropped if anyone else is.
"""
from __future__ import annotations

from rclpy.node import Node
from rclpy.subscription import Subscription

from fleet_planner.validation import printable

#: the node name the graph gives an endpoint whose node it does not know (yet)
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


def qualified(namespace: str, name: str) -> str:
    """``/ns/name`` of a node (``name`` alone if it is already absolute)."""
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}"


class OriginCheck:
    """Whether the messages arriving on ``sub`` can only come from the node ``trusted`` (a fully
    qualified node name, or a name relative to ``node``'s namespace)."""

    def __init__(self, node: Node, sub: Subscription, trusted: str):
        self.node = node
        self.sub = sub
        self.trusted = self.qualify(node, trusted)
        self.refused = 0
        #: the last refusal was only for publishers the graph does not know by name yet (nobody else
        #: named): the sender is likely the trusted node itself, just discovered (see :meth:`settled`)
        self.unnamed_only = False

    @staticmethod
    def qualify(node: Node, name: str) -> str:
        """``name`` as a fully qualified node name, relative to ``node``'s namespace unless absolute."""
        return qualified(node.get_namespace(), name)

    def problem(self) -> str | None:
        """None if a message handled now can only be the trusted node's, else why not (one
        bounded, printable line); counts the refusals."""
        self.unnamed_only = False
        why = self._why()
        if why is not None:
            self.refused += 1
        return why

    def settled(self) -> bool | None:
        """For a message refused with ``unnamed_only``, asked again a moment later: True once the
        graph names only the trusted node here (take the message now), False if another node is
        named (drop it), None while it still cannot tell."""
        self.unnamed_only = False
        why = self._why()
        if why is None:
            return True
        return None if self.unnamed_only else False

    def _why(self) -> str | None:
        topic = self.sub.topic_name
        infos = self.node.get_publishers_info_by_topic(topic)
        named = [i for i in infos if i.node_name != UNKNOWN_NODE]
        others = sorted({qualified(i.node_namespace, i.node_name) for i in named} - {self.trusted})
        if others:
            shown = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
            return printable(f"{topic} has publishers besides {self.trusted}: {shown}", 300)
        unnamed = max(len(infos) - len(named), self.sub.get_publisher_count() - len(named))
        if unnamed > 0:
            self.unnamed_only = True
            return f"{topic}: {unnamed} publisher(s) not known by name yet"
        if not named:
            return f"{topic}: {self.trusted} does not publish here (the sender is unknown)"
        return None


__all__ = ["UNKNOWN_NODE", "OriginCheck", "qualified"]
