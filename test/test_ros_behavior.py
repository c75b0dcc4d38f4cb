"""The fleet on ROS in behaviour coordination (BBMRCA): the planner only allocates and hands out
goals, the agents find their own ways and avoid each other from the statuses they hear. The same
small warehouse and mixed fleet as test_ros_system.py; contact is checked on the robots' own status
reports, not by asking the planner."""
import pytest
from test_ros_system import WAIT, ended, no_contact, running_fleet

from fleet_planner.ros.demo.monitor import spin_until
from msg_schemas.records import Task


@pytest.fixture(scope="module")
def fleet(ros_context):
    yield from running_fleet(ros_context, coordination="behavior")


def test_robots_coordinating_by_behaviours_do_their_jobs_without_contact(fleet):
    mon = fleet.monitor
    assert fleet.planner.fleet.coordination == "behavior"
    assert all(a.agent.coordination == "behavior" for a in fleet.agents.values())
    # two jobs per chute: robots meet at the chutes, in the aisles and at the chargers
    jobs = [Task(id="H1", pick="chute_1", place="B02-01"),
            Task(id="H2", pick="chute_1", place="B03-02", needs=("manipulator",)),
            Task(id="H3", pick="chute_2", place="B01-02", needs=("forklift",), payload_kg=250.0),
            Task(id="H4", pick="chute_2", place="B04-01", needs=("manipulator", "forklift"))]
    for job in jobs:
        mon.submit(job)
    assert spin_until(fleet.executor, lambda: all(ended(fleet, j.id) for j in jobs), 2 * WAIT), mon.last_event
    for job in jobs:
        evs = mon.events_of(job.id)
        assert [e.event for e in evs] == ["accepted", "assigned", "picked", "placed", "done"]
        assert len({e.robot_id for e in evs[1:]}) == 1
    # the robots broadcast their BBMRCA state; the planner's legs carry no (M,D) delays
    assert all(st.behavior is not None for st in mon.status.values())
    schedule = fleet.planner.fleet.schedule(mon.now())
    assert all(node["delay"] == 0.0 for node in schedule.nodes.values())
    no_contact(fleet)
