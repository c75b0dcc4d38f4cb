"""Two fleets side by side under two namespaces (issue 12, ROS conventions): the topic names are
relative, so a planner, its agents and its monitor in ``/site_a`` talk on ``/site_a/fleet/...``
and never hear ``/site_b``'s; one simulated clock (``/clock``) drives both. A job in each fleet is
done by that fleet's robot, and neither planner ever heard of the other's."""
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from test_ros_system import KINDS, PARKING, RATE, WH

from fleet_planner.fleet import FleetMember
from fleet_planner.ros.demo.bringup import agent_params
from fleet_planner.ros.demo.monitor import FleetMonitor, spin_until
from fleet_planner.ros.planner_node import PlannerNode
from fleet_planner.ros.sim_clock import SimClock
from msg_schemas.records import Task
from robot_agent.agent_node import AgentNode

CHARGERS = [s.pose for s in WH.stations_of("charger")]
SITES = {"/site_a": FleetMember("a1", "cargo", *CHARGERS[0]), "/site_b": FleetMember("b1", "cargo", *CHARGERS[1])}


@pytest.fixture(scope="module")
def sites(ros_context):
    sim = [Parameter("use_sim_time", value=True)]
    nodes = [SimClock(context=ros_context, parameter_overrides=[Parameter("rate", value=RATE)])]
    fleets = {}
    for ns, member in SITES.items():
        planner = PlannerNode(context=ros_context, namespace=ns, warehouse=WH, kinds=KINDS,
                              parameter_overrides=sim + [Parameter("parking", value=PARKING)])
        agent = AgentNode(f"agent_{member.id}", context=ros_context, namespace=ns, warehouse=WH, kinds=KINDS,
                          parameter_overrides=sim + agent_params(member))
        monitor = FleetMonitor(context=ros_context, namespace=ns, parameter_overrides=sim)
        fleets[ns] = (planner, agent, monitor)
        nodes += [planner, agent, monitor]
    executor = SingleThreadedExecutor(context=ros_context)
    for node in nodes:
        executor.add_node(node)
    try:
        assert spin_until(executor, lambda: all(m.planner_ready() and a.robot_id in m.status
                                                for _, a, m in fleets.values()), 60)
        yield fleets, executor
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()


def test_two_namespaced_fleets_run_side_by_side_without_hearing_each_other(sites):
    fleets, executor = sites
    (pa, aa, ma), (pb, ab, mb) = fleets["/site_a"], fleets["/site_b"]
    assert pa._events.topic_name == "/site_a/fleet/task_events" and aa.robot_id == "a1"
    ma.submit(Task(id="J1", pick="chute_1", place="B01-01"))
    mb.submit(Task(id="J1", pick="chute_2", place="B04-02"))  # the same id: another fleet's business
    done = lambda m: m.last_event.get("J1") is not None and m.last_event["J1"].event == "done"  # noqa: E731
    assert spin_until(executor, lambda: done(ma) and done(mb), 90), (ma.events_of("J1"), mb.events_of("J1"))
    assert [e.robot_id for e in ma.events_of("J1") if e.event == "assigned"] == ["a1"]
    assert [e.robot_id for e in mb.events_of("J1") if e.event == "assigned"] == ["b1"]
    assert set(pa.fleet.robots) == {"a1"} and set(pb.fleet.robots) == {"b1"}
    assert set(ma.status) == {"a1"} and set(mb.status) == {"b1"}
    assert set(aa.agent.heard) == set() and set(ab.agent.heard) == set()
