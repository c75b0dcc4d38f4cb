"""The safety net of a central robot stops it before it touches another robot, whatever its plan
and its gate say (issue 9, deliverable 4; issue 10: the 100-robot run on `large` overlapped by
0.109 m): the net looks at the whole of the step the robot drives (however densely its path has
vertices), at robots that move during a long step, and at the jump onto the start of a new leg."""
import math

import numpy as np
import pytest

from fleet_planner.fleet.coordination import CentralDriver
from fleet_planner.model import TimedPath
from fleet_planner.robots import RobotModel, load_kinds
from msg_schemas.records import GateRecord, RobotStatus

KINDS = load_kinds()
KIND = KINDS[next(iter(KINDS))]


def _status(m: RobotModel, stamp: float) -> RobotStatus:
    return RobotStatus(**m.status(stamp))


def _driver(rid: str, x: float, y: float, path_pts: np.ndarray, t0: float = 0.0, gated: bool = True) -> CentralDriver:
    m = RobotModel(rid, KIND, x, y)
    d = CentralDriver(m, gated=gated)
    times = t0 + np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path_pts, axis=0).T))]) / KIND.max_speed
    d.follow(TimedPath(rid, KIND.radius, np.column_stack([path_pts, times])), 0.0, 1, None)
    d.on_gate(GateRecord(robot_id=rid, path_id=1, seq=0, stamp=0.0))   # no links: the gate lets it go
    return d


def _closest(drivers: list[CentralDriver], seconds: float, dt: float) -> float:
    """Step the robots together (each hears the others' statuses of the step before, as fleet-sim's
    robots do); the smallest gap between two discs at the end of a step."""
    t, gap = 0.0, math.inf
    while t < seconds:
        heard = {d.model.id: _status(d.model, t) for d in drivers}
        for d in drivers:
            d.drive(t, dt, {k: v for k, v in heard.items() if k != d.model.id})
        t += dt
        for i, d in enumerate(drivers):
            for e in drivers[i + 1:]:
                a, b = d.model, e.model
                gap = min(gap, math.dist((a.x, a.y), (b.x, b.y)) - a.kind.radius - b.kind.radius)
    return gap


def _standing(robot_id: str, x: float, y: float) -> CentralDriver:
    return CentralDriver(RobotModel(robot_id, KIND, x, y), gated=True)


@pytest.mark.parametrize("gated", [True, False])
def test_net_stops_before_a_standing_robot_on_a_path_with_dense_vertices(gated):
    # a path with a vertex every 5 mm (a re-planned leg's holds): the step reaches far beyond the next one
    pts = np.column_stack([np.linspace(0.0, 6.0, 1201), np.zeros(1201)])
    d = _driver("a", 0.0, 0.0, pts, gated=gated)
    assert _closest([d, _standing("b", 3.0, 0.0)], 12.0, dt=0.3) >= 0.0


@pytest.mark.parametrize("dt", [0.1, 0.3, 1.5])
def test_nets_stop_two_robots_driving_head_on(dt):
    # both plans drive through the other; with steps of 1.5 s (a loaded simulator) each report is
    # one step old, not silent
    a = _driver("a", 0.0, 0.0, np.array([[0.0, 0.0], [12.0, 0.0]]))
    b = _driver("b", 9.0, 0.0, np.array([[9.0, 0.0], [-3.0, 0.0]]))
    assert _closest([a, b], 12.0, dt) >= 0.0


def test_a_new_leg_whose_start_jumps_onto_another_robot_is_refused():
    m = RobotModel("a", KIND, 0.0, 0.0)
    d = CentralDriver(m, gated=True)
    b = RobotModel("b", KIND, 2 * KIND.radius + 0.1, 0.0)
    start = (0.8 * KIND.radius, 0.0)  # within its radius, but the jump would put it into b
    path = TimedPath("a", KIND.radius, np.array([[*start, 0.0], [start[0] + 3, 0.0, 5.0]]))
    with pytest.raises(ValueError, match="b"):
        d.follow(path, 0.0, 1, 0.0, {"b": _status(b, 0.0)})
    assert (m.x, m.y) == (0.0, 0.0)
    d.follow(path, 0.0, 1, 0.0, {"b": _status(RobotModel("b", KIND, 0.0, 3.0), 0.0)})   # clear: taken
    assert (m.x, m.y) == start


@pytest.mark.parametrize("off", [5e-5, 0.02])
def test_a_leg_planned_from_a_rounded_position_is_taken_beside_a_robot_within_the_nets_reach(off):
    """The planner plans from reported positions rounded to 0.1 mm: a robot standing within the net's
    reach of another takes a leg whose start is that far off towards it (it is where it stands; it
    refused every such leg before, and stood in four robots' ways for good); a start 2 cm towards it
    is still a jump the net refuses. Control (``JUMP_TOL_M`` 1e-6, as before): both refused."""
    m = RobotModel("a", KIND, 0.0, 0.0)
    d = CentralDriver(m, gated=True)
    b = RobotModel("b", KIND, 2 * KIND.radius + 0.03, 0.0)   # within the sum of radii + NET_MARGIN_M
    path = TimedPath("a", KIND.radius, np.array([[off, 0.0, 0.0], [off, 3.0, 5.0]]))
    if off > 1e-3:
        with pytest.raises(ValueError, match="towards robot 'b'"):
            d.follow(path, 0.0, 1, 0.0, {"b": _status(b, 0.0)})
    else:
        d.follow(path, 0.0, 1, 0.0, {"b": _status(b, 0.0)})
        assert m.x == pytest.approx(off)


def test_a_robot_that_drove_on_past_a_legs_start_joins_the_leg_where_it_is():
    # the leg was planned from where the robot was 1 s ago (the planner was busy): it starts 1 m behind it
    m = RobotModel("a", KIND, 3.0, 0.0)
    d = CentralDriver(m)   # not gated: the clock decides
    v = KIND.max_speed
    leg = TimedPath("a", KIND.radius, np.array([[3.0 - v, 0.0, 0.0], [9.0, 0.0, (6.0 + v) / v]]))
    d.follow(leg, 10.0, 1, 11.0)                      # due at 3.0 by now (t = 11)
    assert (m.x, m.y) == (3.0, 0.0) and m.travelled == pytest.approx(v)
    # ... but not if the leg's schedule is not there yet (it waits at its start first), nor off its way
    waits = TimedPath("a", KIND.radius, np.array([[3.0 - v, 0.0, 0.0], [3.0 - v, 0.0, 5.0], [9.0, 0.0, 12.0]]))
    away = TimedPath("a", KIND.radius, np.array([[3.0 - v, 0.0, 0.0], [3.0 - v, 5.0, 5.0]]))
    for path in (waits, away):
        m2 = RobotModel("b", KIND, 3.0, 0.0)
        with pytest.raises(ValueError, match="starts"):
            CentralDriver(m2).follow(path, 10.0, 1, 11.0)
        assert (m2.x, m2.y) == (3.0, 0.0)


def test_a_gated_robot_joins_a_leg_behind_it_short_of_its_gate_not_by_the_clock():
    v = KIND.max_speed
    # planned from standstill at its start 1 m behind: the clock is due behind the robot; the gate decides
    leg = TimedPath("a", KIND.radius, np.array([[2.0, 0.0, 0.0], [2.0, 0.0, 3.0], [9.0, 0.0, 3.0 + 7.0 / v]]))
    for entry, joins in ((5.0, True), (0.5, False)):
        m = RobotModel("a", KIND, 3.0, 0.0)
        d = CentralDriver(m, gated=True)
        link = {"robot": "b", "path_id": 7, "exit": 1.0, "entry": entry}
        d.on_gate(GateRecord(robot_id="a", path_id=1, seq=0, stamp=0.0, links=(link,), watch={"b": 7}))
        if joins:
            d.follow(leg, 10.0, 1, 11.0, {})
            assert m.travelled == pytest.approx(1.0) and (m.x, m.y) == (3.0, 0.0)
        else:  # already beyond where its gate holds it on the new leg: refused
            with pytest.raises(ValueError, match="starts"):
                d.follow(leg, 10.0, 1, 11.0, {})
