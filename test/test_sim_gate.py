"""fleet-sim's robots are gated like agents (issue 9, deliverable 4; the demo drives more than 15
robots with one fleet-sim): a robot waits at the start of a leg until its gate record comes, stops
at the entry of a region until the robot ranked above reports leaving it, and hears that robot
however far it is (the gate's watch, as the planner's relay does for agents); and a jump of the
clock is driven in short steps, so the robots' safety nets act as often as in real time."""
import math

import numpy as np
import pytest

from fleet_planner.fleet.placement import place_robots
from fleet_planner.fleet.sim import MAX_STEP_S, SimFleet
from fleet_planner.model import TimedPath
from fleet_planner.robots import load_kinds
from fleet_planner.warehouse import load_warehouse
from msg_schemas.records import GateRecord, RobotStatus

KINDS = load_kinds()


def test_simulated_robots_wait_for_their_gate_and_hear_the_robots_it_names():
    warehouse = load_warehouse()
    members = place_robots(warehouse, KINDS, 12)
    sim = SimFleet(members, KINDS, warehouse, gated=True)
    me, far = members[0], members[-1]
    sim.step(0.0)
    a = sim.agents[me.id]
    start = (a.model.x, a.model.y)
    path = TimedPath(me.id, a.model.kind.radius, np.array([[*start, 0.1], [start[0], start[1] + 3.0, 4.0]]))
    sim.on_path(me.id, path, 0.1, 100)
    t = 0.0
    for _ in range(10):
        t += 0.1
        sim.step(t)
    assert a.model.travelled == 0.0                       # no gate record for its leg yet: it waits
    link = {"robot": far.id, "path_id": 7, "exit": 1.0, "entry": 1.0}
    sim.on_gate(GateRecord(robot_id=me.id, path_id=100, seq=0, stamp=t, links=(link,), watch={far.id: 7}))
    for _ in range(40):
        t += 0.1
        sim.step(t)
    assert 0.5 < a.model.travelled <= 1.0                 # up to the entry, not beyond
    assert far.id in a.heard                              # the robot its gate names, 20 m away
    sim.hear([RobotStatus.from_dict({**sim.last[far.id].to_dict(), "id": "elsewhere"})])  # another process's
    sim.step(t + 0.05)
    sim.on_gate(GateRecord(robot_id=me.id, path_id=100, seq=1, stamp=t))
    for _ in range(10):
        t += 0.1
        sim.step(t)
    assert a.model.travelled > 1.0


def test_ungated_simulated_robots_drive_by_the_clock():
    warehouse = load_warehouse()
    members = place_robots(warehouse, KINDS, 3)
    sim = SimFleet(members, KINDS, warehouse)
    sim.step(0.0)
    a = sim.agents[members[0].id]
    start = (a.model.x, a.model.y)
    sim.on_path(a.model.id, TimedPath(a.model.id, a.model.kind.radius,
                                      np.array([[*start, 0.1], [start[0], start[1] + 3.0, 4.0]])), 0.1, 100)
    for k in range(1, 11):
        sim.step(0.1 * k)
    assert a.model.travelled > 0.0


def _crossing_gaps(max_step_s: float, jump_s: float) -> list[float]:
    """Two simulated robots on legs that cross at (20, 3) at the same moment (no gate: only their
    safety nets keep them apart), the clock jumping ``jump_s`` between two steps of fleet-sim (a
    loaded machine); the gap between their discs after every step."""
    warehouse = load_warehouse()
    members = place_robots(warehouse, KINDS, 2)
    sim = SimFleet(members, KINDS, warehouse, max_step_s=max_step_s)
    a, b = (sim.agents[m.id] for m in members)
    v = 0.9 * min(a.model.kind.max_speed, b.model.kind.max_speed)
    for agent, (x, y) in ((a, (14.0, 3.0)), (b, (20.0, 9.0))):
        agent.model.x, agent.model.y = x, y
    sim.step(0.0)
    t0 = 0.5
    sim.on_path(a.model.id, TimedPath(a.model.id, a.model.kind.radius,
                                      np.array([[14.0, 3.0, t0], [26.0, 3.0, t0 + 12.0 / v]])), t0, 1)
    sim.on_path(b.model.id, TimedPath(b.model.id, b.model.kind.radius,
                                      np.array([[20.0, 9.0, t0], [20.0, 3.0, t0 + 6.0 / v],
                                                [20.0, 1.8, t0 + 7.2 / v]])), t0, 1)
    gaps, t = [], 0.0
    while t < t0 + 20.0 / v:
        t += jump_s
        sim.step(t)
        gaps.append(math.dist((a.model.x, a.model.y), (b.model.x, b.model.y))
                    - a.model.kind.radius - b.model.kind.radius)
    return gaps


@pytest.mark.parametrize("jump_s", [1.0, 3.0])
def test_a_clock_jump_is_driven_in_short_steps(jump_s):
    # the safety nets stop the robots short of each other at the crossing: never an overlap
    gaps = _crossing_gaps(MAX_STEP_S, jump_s)
    assert min(gaps) >= 0.0 and min(gaps) < 1.0   # (they did come close)
    # control: the whole jump driven in one step, the two robots meet on the crossing
    assert min(_crossing_gaps(math.inf, jump_s)) < 0.0
