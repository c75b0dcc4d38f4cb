"""The origin check's third answer (issue 9, deliverable 5; fleet_planner/ros/origin.py): a
publisher the graph does not know by name yet (just created, or shown as ``_NODE_NAME_UNKNOWN_``)
is refused, but flagged ``unnamed_only``; asked again with :meth:`OriginCheck.settled`, it is taken
once the graph names only the planner and dropped as soon as another node is named. And an agent
keeps a gate record refused only so and takes it once the planner is known (a refused first record
would hold the robot at its leg's start until the next one). Stubs stand in for the graph."""
from types import SimpleNamespace

from test_records_total import KINDS, WH

from fleet_planner.ros.origin import UNKNOWN_NODE, OriginCheck
from msg_schemas.records import GateRecord


class Graph:
    def __init__(self):
        self.names: list[str] = []   # node names publishing, as the graph gives them
        self.matched = 0             # publishers the subscription is matched with

    def get_namespace(self):
        return "/"

    def get_publishers_info_by_topic(self, topic):
        return [SimpleNamespace(node_name=n, node_namespace="/") for n in self.names]


def check():
    graph = Graph()
    sub = SimpleNamespace(topic_name="/robots/o1/gate", get_publisher_count=lambda: graph.matched)
    return graph, OriginCheck(graph, sub, "planner")  # type: ignore[arg-type]


def test_a_publisher_without_a_known_name_is_refused_then_taken_or_dropped_as_the_graph_learns():
    graph, origin = check()
    graph.names, graph.matched = ["planner"], 1
    assert origin.problem() is None and not origin.unnamed_only
    for names, matched in (([], 1), (["planner"], 2), ([UNKNOWN_NODE], 1), (["planner", UNKNOWN_NODE], 2)):
        graph.names, graph.matched = names, matched
        why = origin.problem()
        assert why is not None and "not known by name yet" in why and origin.unnamed_only, (names, why)
        assert origin.settled() is None                        # still cannot tell
    graph.names, graph.matched = ["planner"], 1
    assert origin.settled() is True                            # only the planner: take it
    graph.names, graph.matched = ["planner", UNKNOWN_NODE], 2
    origin.problem()
    graph.names = ["planner", "forger"]
    assert origin.settled() is False                           # someone else is named: drop it
    assert "besides /planner: /forger" in origin.problem() and not origin.unnamed_only
    graph.names, graph.matched = [], 0
    assert "does not publish here" in origin.problem() and not origin.unnamed_only


def test_an_agent_takes_a_gate_record_refused_only_for_an_unnamed_publisher_once_the_planner_is_known(ros_context):
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from robot_agent.agent_node import AgentNode
    start = WH.stations_of("charger")[0].pose
    agent = AgentNode("unnamed_agent", context=ros_context, warehouse=WH, kinds=KINDS, parameter_overrides=[
        Parameter("id", value="o1"), Parameter("x", value=start[0]), Parameter("y", value=start[1]),
        Parameter("planner", value="planner")])
    try:
        graph, origin = check()
        agent._gate_origin = origin
        record = GateRecord(robot_id="o1", path_id=7, seq=1, stamp=1.0)
        graph.names, graph.matched = [UNKNOWN_NODE], 1
        agent._on_gate(String(data=record.to_json()))
        assert agent.agent.driver.gate is None and agent._gate_pending is not None
        agent._on_timer()                                      # still unnamed: kept
        assert agent.agent.driver.gate is None and agent._gate_pending is not None
        graph.names = ["planner"]
        agent._on_timer()
        assert agent.agent.driver.gate == record and agent._gate_pending is None
        forged = GateRecord(robot_id="o1", path_id=7, seq=2, stamp=1.0)
        graph.names, graph.matched = [UNKNOWN_NODE], 1
        agent._on_gate(String(data=forged.to_json()))
        graph.names = ["planner", "forger"]
        agent._on_timer()                                      # another node is named: dropped
        assert agent.agent.driver.gate == record and agent._gate_pending is None
    finally:
        agent.destroy_node()
