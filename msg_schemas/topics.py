"""Every fleet topic name and its QoS profile, in one place (docs/ARCHITECTURE.md, "Topics and QoS").

Nodes create publishers and subscriptions with the pair from here, e.g.
``node.create_subscription(String, TASKS, cb, TASKS_QOS)``, so both ends always match.

The names are relative (issue 12, ROS conventions): a node in the root namespace talks on
``/fleet/tasks``, ``/robots/r1/timed_path``, ``/map``, as always; a fleet brought up in a namespace
(``/site_a``: its planner, agents and tools alike) talks on ``/site_a/fleet/tasks`` and so on, so
two fleets run side by side without hearing each other. (A robot's namespace is therefore its
fleet's; give each agent its ``id``.) Nodes that need a topic's full name, as a signature's channel,
take it from their publisher or subscription (``topic_name``).

QoS choices:

* Commands and events (``TASKS``, ``TASK_EVENTS``): reliable, volatile, deep queue (1000) so a
  burst of tasks is not dropped. Volatile on purpose: a restarted planner must not receive old
  tasks again as if they were new.
* ``ROBOT_STATUS``: best effort, depth 1000 (a fleet-sim process publishes its whole fleet at once,
  and a queue shorter than that burst drops the same robots' statuses every time: bench_load
  showed 90 false offline events at 200 robots with depth 100). Each robot repeats its status at
  10 Hz and each message
  supersedes the last, so a lost one costs nothing, and a slow planner never holds the agents
  back. A best-effort subscription also matches reliable publishers (``ros2 topic pub`` defaults).
  Tests must wait for a status that satisfies a condition, not count messages. Every subscriber
  takes all waiting statuses at each wake-up (``fleet_planner/ros/drain.py``).
* ``/robots/<id>/neighbours``: best effort, depth 10, as the statuses it relays: each record
  supersedes the last, a few times a second.
* ``WAIT_MESSAGES`` (behaviour coordination): reliable, volatile, depth 100. A waiting robot
  repeats its message every couple of seconds, but a wait cycle is only found when a message
  gets all the way round it, so none should be lost on the way.
* Latched state (``/robots/<id>/timed_path``, ``/robots/<id>/gate``, ``SCHEDULE``, ``MARKERS``, ``MAP``): reliable,
  transient local, depth 1: a late subscriber gets the current value at once.
"""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .records import robot_id_problem

TASKS = "fleet/tasks"
TASK_EVENTS = "fleet/task_events"
ROBOT_STATUS = "fleet/robot_status"
SCHEDULE = "fleet/schedule"
MARKERS = "fleet/markers"
MAP = "map"
WAIT_MESSAGES = "fleet/wait_messages"
OBSTACLES = "fleet/obstacles"  # fleet/obstacle@1: people, vehicles, pallets (fleet_planner/fleet/obstacles.py)
#: fleet/heard@1: whom the planner hears (each robot's latest status stamp it took in, the leg it keeps clear
#: for it), at every step and between (fleet_planner/fleet/lease.py); best effort: each supersedes the last
HEARD = "fleet/heard"


def timed_path_topic(robot_id: str) -> str:
    """``robots/<robot_id>/timed_path``; ValueError if the id cannot be part of a topic name."""
    problem = robot_id_problem(robot_id)
    if problem:
        raise ValueError(f"robot id {problem}")
    return f"robots/{robot_id}/timed_path"


def timed_path_auth_topic(robot_id: str) -> str:
    """``robots/<robot_id>/timed_path_auth``: the signatures of its timed paths (where keys are configured)."""
    return timed_path_topic(robot_id) + "_auth"


def neighbours_topic(robot_id: str) -> str:
    """``robots/<robot_id>/neighbours`` (the planner's relay of the statuses a robot must hear);
    ValueError if the id cannot be part of a topic name."""
    problem = robot_id_problem(robot_id)
    if problem:
        raise ValueError(f"robot id {problem}")
    return f"robots/{robot_id}/neighbours"


def gate_topic(robot_id: str) -> str:
    """``robots/<robot_id>/gate``: the robot's precedence links (``fleet/gate@1``, latched)."""
    return timed_path_topic(robot_id).rsplit("/", 1)[0] + "/gate"


def _qos(depth: int, reliable: bool = True, latched: bool = False) -> QoSProfile:
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


TASKS_QOS = _qos(1000)
TASK_EVENTS_QOS = _qos(1000)
ROBOT_STATUS_QOS = _qos(1000, reliable=False)
LATCHED_QOS = _qos(1, latched=True)
TIMED_PATH_QOS = LATCHED_QOS
TIMED_PATH_AUTH_QOS = LATCHED_QOS
GATE_QOS = LATCHED_QOS
SCHEDULE_QOS = LATCHED_QOS
MARKERS_QOS = LATCHED_QOS
MAP_QOS = LATCHED_QOS
WAIT_MESSAGES_QOS = _qos(100)
NEIGHBOURS_QOS = _qos(10, reliable=False)
HEARD_QOS = _qos(5, reliable=False)

# -- the operator (fleet_planner/fleet/operator.py; docs/ARCHITECTURE.md, "Topics and QoS") ------------
#: ``fleet/command@1`` (commands with arguments) in, ``fleet/command_reply@1`` (same ``id``) out:
#: reliable and volatile like the tasks and their events
COMMANDS = "fleet/commands"
COMMAND_REPLIES = "fleet/command_replies"
COMMANDS_QOS = _qos(100)
COMMAND_REPLIES_QOS = _qos(100)
#: std_msgs/Bool, latched: whether the e-stop is engaged (the planner publishes it, every agent holds)
ESTOPPED = "fleet/estopped"
ESTOPPED_QOS = LATCHED_QOS
#: ``fleet/operator_state@1``, latched: the e-stop, a paused fleet, paused and manual robots (for consoles)
OPERATOR_STATE = "fleet/operator_state"
OPERATOR_STATE_QOS = LATCHED_QOS
#: std_srvs/SetBool services of the planner: pause (true) / resume the fleet; engage (true) / release the e-stop
PAUSE_FLEET_SERVICE = "fleet/pause"
ESTOP_SERVICE = "fleet/estop"
#: geometry_msgs/Twist to a robot in manual drive: best effort, so any teleop publisher matches
CMD_VEL_QOS = _qos(10, reliable=False)
#: ``fleet/robot_command@1`` to one agent (``robot_topic(id, "command")``): manual drive, signed with operator keys
ROBOT_COMMAND_QOS = _qos(10)


def robot_topic(robot_id: str, name: str) -> str:
    """``/robots/<robot_id>/<name>``: ``manual`` (SetBool, agent), ``cmd_vel`` (Twist, agent),
    ``command`` (``fleet/robot_command@1``, agent); ValueError if the id cannot be part of a topic name."""
    problem = robot_id_problem(robot_id)
    if problem:
        raise ValueError(f"robot id {problem}")
    return f"robots/{robot_id}/{name}"
OBSTACLES_QOS = _qos(100)  # reliable: a pallet reported once must arrive; a tracker repeats the rest
