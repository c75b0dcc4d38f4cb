"""The wait-for graph of gated execution and its cycles (fleet/waits.py), and the manager's breaker of
wait cycles (FleetManager._break_waits)."""
from __future__ import annotations

import math

from fleet_planner.checker import min_separation
from fleet_planner.fleet.legs import Decisions
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
