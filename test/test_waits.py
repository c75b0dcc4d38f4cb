"""The wait-for graph of gated execution and its cycles (fleet/waits.py), and the manager's breaker of
wait cycles (FleetManager._break_waits)."""
from __future__ import annotations

import math

from fleet_planner.checker import min_separation
from fleet_planner.fleet.legs import Decisions
from fleet_planner.fleet.manager import CYCLE_LASTS_S
from fleet_planner.fleet.waits import cycles


def test_cycles_are_the_strongly_connected_pieces_of_two_robots_or_more():
    graph = {"a": {"b": "gate"}, "b": {"a": "leg", "c": "gate"}, "c": {"d": "leg"}, "d": {},
             "x": {"y": "gate"}, "y": {"z": "leg"}, "z": {"x": "gate"}, "s": {"s": "leg"}}
    assert sorted(cycles(graph)) == [["a", "b"], ["x", "y", "z"]]
    assert cycles({"a": {"b": "gate"}, "b": {"c": "leg"}}) == []


def _standing_pair(gap, then=lambda: None):
    """Two gated robots, each with somewhere to go past the other, standing on hold legs ``gap`` beyond the
    sum of radii apart (inside the gate's pad): the knot of 100 robots on large (r85 held at (138.25, 6.49),
    r97 0.755 m from it, every new leg of either refused "a new leg would start in a region r97 / r85 may be
    in" for 1300 s)."""
    from gated_sim import GatedSim
    from test_dispatch import CHARGERS, KINDS

    from fleet_planner.fleet.state import Target

    south, north = (9.48, 7.10), (8.68, 6.57)   # (test_dispatch's pair stopped within the planner's margin)
    away = (north[0] - south[0], north[1] - south[1])
    scale = (KINDS["cargo"].radius + KINDS["manipulator_forklift"].radius + gap) / math.hypot(*away)
    north = (south[0] + away[0] * scale, south[1] + away[1] * scale)
    goals = {"s": Target("charge", "charger_4", CHARGERS[3]), "n": Target("park", "parking_1", (12.75, 3.0))}
    sim = GatedSim([("s", "cargo", *south, 1.0), ("n", "manipulator_forklift", *north, 1.0)],
                   parking=[goals["n"].pose], idle_s=3600.0)
    sim.run_until(lambda: len(sim.fm.robots) == 2, limit=2)
    for rid in goals:   # both stand on hold legs (the gate book knows them), one after the other
        d = Decisions()
        sim.fm._hold(sim.fm.robots[rid], sim.t, d)
        assert len(d.legs) == 1
        for rec in d.gates:
            sim.agents[rec.robot_id].on_gate(rec)
        for leg in d.legs:
            sim.legs[leg.robot_id].append(leg)
            sim.agents[leg.robot_id].on_path(leg.relative(), leg.t0, leg.path_id)
        sim.run_until(lambda: False, limit=1.0)
    then()
    for rid, target in goals.items():
        sim.fm.robots[rid].target, sim.fm.robots[rid].replan = target, True
    arrived = sim.run_until(lambda: all(math.dist((sim.agents[r].model.x, sim.agents[r].model.y), g.pose) < 0.05
                                        for r, g in goals.items()), limit=90)
    return sim, arrived


def test_two_gated_robots_standing_within_the_pad_of_each_other_both_get_on_their_way(monkeypatch):
    """A new leg that starts in a region with a robot standing for good at the end of its latest path passes
    first (it was refused: the other "may be in" the region; the other's legs likewise: neither ever moved).
    Both get where they go, and the discs as driven (the independent checker) never come nearer than they
    stood. Control: with the standing robot taken as one that may be in the region, neither gets a leg."""
    from fleet_planner.fleet import gate

    sim, arrived = _standing_pair(0.04)
    assert arrived, sim.notes[-10:]
    assert min_separation(sim.driven())[0] >= 0.04 - 0.01
    sim, arrived = _standing_pair(0.04, lambda: monkeypatch.setattr(gate, "STILL_MPS", -1.0))  # (nobody stands)
    assert not arrived
    assert any("a new leg would start in a region" in n for n in sim.notes)


def _cycle(break_waits):
    """b stands (a hold leg) 0.5 m off a's way; a's leg passes it, so a's gate holds a short of b until b
    has a later path; b's last leg search failed, blocked by a (a's leg drives through b's start disc).
    Then a step of the manager."""
    import numpy as np
    from test_dispatch import manager, status

    from fleet_planner.fleet.gate import gate_limit
    from fleet_planner.fleet.legs import Leg
    from fleet_planner.fleet.state import Target
    from fleet_planner.fleet.waits import wait_for_graph
    from fleet_planner.model import TimedPath

    fm = manager()
    fm.break_waits = break_waits
    fm.on_status(status("a", "cargo", 0.0, 5.0), 0.0)
    fm.on_status(status("b", "cargo", 5.0, 5.5), 0.0)
    a, b = fm.robots["a"], fm.robots["b"]
    assert fm._give(b, Leg("b", TimedPath("b", b.radius, np.array([[5.0, 5.5, 0.0]])), 1, "hold", ""), Decisions(), 0.0)
    fm.on_status(status("b", "cargo", 5.0, 5.5, path_id=1, progress=1.0, travelled_m=0.0, stamp=0.5), 0.5)
    way = TimedPath("a", a.radius, np.array([[0.0, 5.0, 1.0], [10.0, 5.0, 11.0]]))
    assert fm._give(a, Leg("a", way, 2, "park", "x"), Decisions(), 1.0)
    entry = gate_limit(fm.gates.records["a"], 2, {o.id: o.status for o in fm.robots.values()})
    assert 3.0 < entry < 5.0   # a waits for b short of it
    a.target = Target("park", "x", (10.0, 5.0))
    for now in (9.0, 9.0 + CYCLE_LASTS_S):   # the cycle is seen, and is still there when it has lasted
        fm.on_status(status("a", "cargo", entry - 0.05, 5.0, path_id=2, progress=0.4, travelled_m=entry - 0.05,
                            mode="waiting", stamp=now), now)
        fm.on_status(status("b", "cargo", 5.0, 5.5, path_id=1, progress=1.0, travelled_m=0.0, stamp=now), now)
        b.waits_on, b.waits_since = ("a",), now
        assert wait_for_graph(fm.gates, fm.robots.values(), now) == {"a": {"b": "gate"}, "b": {"a": "leg"}}
        d = fm.step(now + 0.5)
        if now == 9.0:
            assert not any("wait cycle" in n for n in d.notes)   # (not at once: most resolve themselves)
    return fm, d


def test_a_robot_its_gate_holds_in_a_wait_cycle_holds_where_it_stands_and_the_other_is_planned_next():
    """The breaker of a wait cycle that lasted gives the robot its gate holds a hold leg where it stands (a new record
    for a new path: the old one's links are not changed), so that the robot whose leg it blocked is planned
    around it standing, next. Control: without the breaker, nothing changes."""
    fm, d = _cycle(True)
    a = fm.robots["a"]
    assert [(leg.robot_id, leg.purpose) for leg in d.legs if leg.robot_id == "a"] == [("a", "hold")]
    assert any(n.startswith("wait cycle a -> b: robot a holds") for n in d.notes), d.notes
    hold = next(leg for leg in d.legs if leg.robot_id == "a").path.waypoints
    assert len(hold) == 1 and math.dist(hold[0, :2], a.pos) < 1e-6   # where it stands, not a step further
    assert fm.gates.records["a"].path_id == a.leg.path_id > 2 and a.leg.purpose == "hold"
    assert a.replan and a.leg_retry_at > 9.5 + CYCLE_LASTS_S and a.target is not None   # it goes on later, from there
    fm, d = _cycle(False)
    assert not [leg for leg in d.legs if leg.robot_id == "a"] and not any("wait cycle" in n for n in d.notes)
