"""Station admission of the behaviour fleet (ours, issue 13; see fleet_planner/delivery/stations.py):
a station admits ``admit`` robots at a time, the others wait on parking spots out of the crowd round
the loading stations. Paper 002 (Sun, Kleiner & Nebel, IV.A) has robots wait for a docking robot
"at a certain distance" from the station; in a one-robot passage to a station those waiting robots
shut the loaded one in."""
from __future__ import annotations

import pytest

from fleet_planner.delivery.behavior_run import simulate_behavior
from fleet_planner.delivery.problem import Delivery, DeliveryProblem
from fleet_planner.delivery.result import RunLimits
from fleet_planner.delivery.stations import WAIT_AWAY, _DeliveryRules, _StationAdmission
from fleet_planner.grid import GridMap


def _dead_end(n: int) -> DeliveryProblem:
    """A 6 m x 5 m room and, east of it, a one-robot corridor 8 m long (1.5 m wide, radius 0.354)
    with loading station A at its dead end; n robots parked in the room, each loading at A and
    unloading at B in the room's corner."""
    rows = ["." * 12 + ("." * 16 if r in (3, 4, 5) else "@" * 16) for r in range(10)]
    grid = GridMap.from_rows(rows, 0.5, "dead-end")
    homes = [(0.75 + 1.0 * (k % 5), 4.25 - 1.0 * (k // 5)) for k in range(n)]
    spots = homes + [(4.25, 0.75), (3.25, 0.75)]
    return DeliveryProblem("dead-end", grid, {"A": (13.25, 2.25), "B": (0.75, 0.75)},
                           [Delivery("A", "B")] * n, spots, n)


def _limits(cap_s: float) -> RunLimits:
    return RunLimits(cap_s=cap_s, stall_s=cap_s, no_progress_s=60.0, retry_s=2.0, wall_cap_s=3600.0)


def test_robots_wait_out_of_a_dead_end_until_the_station_admits_them():
    """Control (no admission, the paper's fleet): four robots drive into the corridor, the first
    loads at A and the three queued behind it (WaitForDocking, WaitKeepDistance) leave it no way
    out: no delivery in 300 s (none in 600 s either, measured). With one robot admitted at a time
    the others wait in the room and all four deliveries are done (in 155 s), without a collision."""
    problem = _dead_end(4)
    control = simulate_behavior(problem, _limits(300.0), admit=None)
    assert control.completed == 0 and control.stop == "cap"
    admitted = simulate_behavior(problem, _limits(300.0), admit=1)
    assert admitted.stop == "done" and admitted.completed == 4
    assert admitted.collisions == 0 and admitted.deadlocks == 0


def test_waiting_places_keep_away_from_the_loading_stations():
    rules = _DeliveryRules(_dead_end(4), claims=False, admit=1)
    for spot, waits in zip(rules.problem.spots, rules.waiting_place):
        far = ((spot[0] - 13.25) ** 2 + (spot[1] - 2.25) ** 2) ** 0.5 >= WAIT_AWAY
        assert bool(waits) == far
    assert rules.waiting_place.any()
    assert _DeliveryRules(_dead_end(4), claims=False).admission is None   # the paper's fleet: no admission


def test_admission_is_first_come_first_served_and_hands_over_on_docking():
    admission = _StationAdmission(["A"], cap=2)
    assert admission.admit("A", 0) and admission.admit("A", 1)
    assert admission.admit("A", 0)                       # asked again: still admitted
    assert not admission.admit("A", 2)
    admission.join("A", 2)
    admission.join("A", 3)
    assert not admission.admit("A", 4)                   # the queue goes first
    admission.docked("A", 1)
    assert admission.take_handed_over() == [2] and admission.take_handed_over() == []
    admission.docked("A", 0)
    assert admission.take_handed_over() == [3]
    assert admission.admitted["A"] == {2, 3} and admission.waiting["A"] == []
    with pytest.raises(ValueError, match="admit"):
        _StationAdmission(["A"], cap=0)


def test_a_robot_admitted_while_it_drives_to_its_waiting_place_goes_on_to_the_station():
    """b queues for A (admit=1, a admitted) away from any parking spot, so it books a waiting place
    and drives there; a docks and hands A over to b while b is still driving: b's leg goes to A now.
    (Skipping it - a rule of the central methods' `near` queue - left b, on arrival, queued for a
    station that had admitted it, and every robot after it waiting for ever: the 200-robot stress
    run on `large` stopped at 575/600 with 25 robots queued.)"""
    rules = _DeliveryRules(_dead_end(4), claims=False, admit=1)
    assert rules.admission is not None
    a, b = rules.robots[0], rules.robots[1]
    assert rules.admission.admit("A", a.idx)
    rules.left(b, 0.0)                                   # b drove off its home spot
    b.pos = (6.25, 2.25)
    rules._admit_or_wait(b, "A", "pick", 0.0)
    assert b.target_kind == "hold" and b.booked_spot is not None and rules.admission.waiting["A"] == [b.idx]
    rules.left(b, 0.0)
    rules.enter(b, "drive", 0.0)                         # on its way to the waiting place
    rules.admission.docked("A", a.idx)
    assert rules.take_handed_over(1.0) == [b]
    assert b.phase == "need" and b.target == rules.problem.stations["A"] and b.target_kind == "pick"
    assert rules.admission.admitted["A"] == {b.idx}
