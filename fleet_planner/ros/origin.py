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
"""
from __future__ import annotations

from rclpy.node import Node
from rclpy.subscription import Subscription

from fleet_planner.validation import printable


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

    @staticmethod
    def qualify(node: Node, name: str) -> str:
        """``name`` as a fully qualified node name, relative to ``node``'s namespace unless absolute."""
        return qualified(node.get_namespace(), name)

    def problem(self) -> str | None:
        """None if a message handled now can only be the trusted node's, else why not (one
        bounded, printable line); counts the refusals."""
        why = self._why()
        if why is not None:
            self.refused += 1
        return why

    def _why(self) -> str | None:
        topic = self.sub.topic_name
        named = self.node.get_publishers_info_by_topic(topic)
        others = sorted({qualified(i.node_namespace, i.node_name) for i in named} - {self.trusted})
        if others:
            shown = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
            return printable(f"{topic} has publishers besides {self.trusted}: {shown}", 300)
        if not named:
            return f"{topic}: {self.trusted} does not publish here (the sender is unknown)"
        matched = self.sub.get_publisher_count()
        if matched > len(named):
            return f"{topic}: {matched - len(named)} publisher(s) not known by name yet"
        return None


__all__ = ["OriginCheck", "qualified"]
