"""BBMRCA behaviour layer (Sun, Kleiner & Nebel, "Behavior-based Multi-Robot Collision Avoidance",
section IV): geometry, traffic rules, docking, deadlocks, and the fleet simulation (liveness within a
time bound, and never two overlapping discs)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fleet_planner.behavior import (
    Behavior,
    BehaviorFleet,
    BehaviorParams,
    Collision,
    DockingArbiter,
    RobotView,
    WaitMessage,
    collision_type,
    front_area_check,
    in_critical_area,
    in_front_area,
    low_order,
    on_wait_message,
    select_behavior,
    virtual_wall_cells,
)
from fleet_planner.grid import GridMap
from fleet_planner.model import PlanningError, RobotSpec

B = Behavior
FWP, AVOID, EXCH, GT, DOCK = B.FOLLOW_WAYPOINT, B.AVOID, B.EXCHANGE, B.GO_THROUGH, B.DOCK
WKD, WFGT, WFD = B.WAIT_KEEP_DISTANCE, B.WAIT_FOR_GO_THROUGH, B.WAIT_FOR_DOCKING
R = 0.35  # every disc in the rule tests; default params: front area 2 x 2 m, critical half-width 0.8 m


def view(rid, pos, wp=None, behavior=FWP, remaining=10.0, partner=None, station=None, straight=math.inf):
    return RobotView(rid, pos, R, behavior, next_waypoint=wp, remaining=remaining, straight=straight,
                     station=station, partner=partner)


# "me" stands at the origin heading along +x; the other robot's place and heading give the collision
ME_POS, ME_WP = (0.0, 0.0), (10.0, 0.0)
PLACES = {
    Collision.REAR_END: ((1.2, 0.0), (11.2, 0.0)),   # ahead in my channel, same way
    Collision.HEAD_ON: ((1.5, 0.0), (-10.0, 0.0)),   # ahead in my channel, coming at me
    Collision.SIDE: ((1.5, -1.1), (1.5, 10.0)),      # beside my channel, crossing into it
    Collision.NONE: ((1.5, 1.1), (1.5, 10.0)),       # beside my channel, driving away from it
}


def me_and_other(mine, theirs, col, low, partner_is_me=False):
    pos, wp = PLACES[col]
    me = view("me", ME_POS, ME_WP, mine, remaining=10.0)
    other = view("o", pos, wp, theirs, remaining=5.0 if low else 20.0, partner="me" if partner_is_me else None)
    return me, other


# -- geometry -----------------------------------------------------------------------------------
def test_places_have_the_collision_types_the_tables_assume():
    for col, (pos, wp) in PLACES.items():
        me, other = view("me", ME_POS, ME_WP), view("o", pos, wp)
        assert in_front_area(me, other)
        assert collision_type(me, other) is col
        assert in_critical_area(me, other) == (col in (Collision.REAR_END, Collision.HEAD_ON))


def test_front_area_is_a_rectangle_towards_the_next_waypoint():
    me = view("me", (0.0, 0.0), (10.0, 0.0))
    edge = 2.0 + R  # front length + the other's radius (its disc overlaps the area)
    assert in_front_area(me, view("o", (edge - 0.01, 0.0)))
    assert not in_front_area(me, view("o", (edge + 0.01, 0.0)))
    assert in_front_area(me, view("o", (1.0, 1.0 + R - 0.01)))       # half width + radius
    assert not in_front_area(me, view("o", (1.0, 1.0 + R + 0.01)))
    assert not in_front_area(me, view("o", (-0.3, 0.0)))             # behind me
    # the orientation comes from position -> next waypoint (there is no heading to look at)
    up = view("me", (0.0, 0.0), (0.0, 10.0))
    assert in_front_area(up, view("o", (0.0, 1.5))) and not in_front_area(me, view("o", (0.0, 1.5)))
    # no next waypoint, no front area
    assert not in_front_area(view("me", (0.0, 0.0)), view("o", (1.0, 0.0)))


def test_front_area_ends_where_the_path_turns():
    other = view("o", (1.5, 0.0))
    assert in_front_area(view("me", (0, 0), (10, 0), straight=3.0), other)
    assert not in_front_area(view("me", (0, 0), (10, 0), straight=0.5), other)


def test_critical_area_is_the_drive_channel():
    me = view("me", (0.0, 0.0), (10.0, 0.0))
    half = R + 0.2 / 2 + R   # my radius + half the margin + the other's radius
    assert in_critical_area(me, view("o", (1.0, half - 0.01)))
    assert not in_critical_area(me, view("o", (1.0, half + 0.01)))
    wide = BehaviorParams(critical_margin=1.0)
    assert in_critical_area(me, view("o", (1.0, half + 0.01)), wide)


def test_front_area_check_prefers_the_critical_area_then_the_closest():
    me = view("me", (0.0, 0.0), (10.0, 0.0))
    near_side = view("a", (0.8, 1.0))     # closer, not in my channel
    far_ahead = view("b", (1.8, 0.1))     # farther, in my channel
    behind = view("c", (-0.5, 0.0))
    assert front_area_check(me, [near_side, far_ahead, behind]).id == "b"
    assert front_area_check(me, [near_side, behind]).id == "a"
    assert front_area_check(me, [view("d", (1.6, 0.0)), far_ahead]).id == "d"
    assert front_area_check(me, [behind]) is None


@pytest.mark.parametrize("angle, expected", [
    (0, Collision.REAR_END), (40, Collision.REAR_END), (50, Collision.SIDE), (90, Collision.SIDE),
    (130, Collision.SIDE), (140, Collision.HEAD_ON), (180, Collision.HEAD_ON)])
def test_collision_class_is_the_angle_between_travel_directions(angle, expected):
    me = view("me", (0.0, 0.0), (10.0, 0.0))
    a = math.radians(angle)
    other = view("o", (1.2, 0.0), (1.2 + 5 * math.cos(a), 5 * math.sin(a)))  # in my channel
    assert collision_type(me, other) is expected


def test_standing_robot_only_collides_when_in_my_channel():
    me = view("me", (0.0, 0.0), (10.0, 0.0))
    assert collision_type(me, view("o", (1.5, 0.0))) is Collision.REAR_END
    assert collision_type(me, view("o", (1.5, 1.2))) is Collision.NONE


def test_low_order_by_remaining_distance_then_id():
    a, b = view("r2", (0, 0), remaining=5.0), view("r10", (0, 0), remaining=8.0)
    assert not low_order(a, b) and low_order(b, a)
    a, b = view("r2", (0, 0), remaining=5.0), view("r10", (0, 0), remaining=5.0)
    assert not low_order(a, b) and low_order(b, a)        # natural order: r2 before r10


# -- traffic rules: tables of the paper's algorithms -----------------------------------------
# other's behaviour -> {collision: (my new behaviour if lowOrder(me), ... if not)}; None = keep.
REAR, HEAD, SIDE, NONE = Collision.REAR_END, Collision.HEAD_ON, Collision.SIDE, Collision.NONE
ALL_WKD = {REAR: (WKD, WKD), HEAD: (WKD, WKD), SIDE: (WKD, WKD), NONE: (WKD, WKD)}
DOCK_ROW = {REAR: (AVOID, AVOID), HEAD: (AVOID, AVOID), SIDE: (AVOID, AVOID), NONE: (WKD, WKD)}
# SolveActiveAndWaitCollision, nobody else around: wait for a robot in my channel, else pass it
ACTIVE_VS_WAIT = {REAR: (WKD, WKD), HEAD: (WKD, WKD), SIDE: (GT, GT), NONE: (GT, GT)}

ALGORITHM_1 = {  # I follow my waypoints
    FWP: ALL_WKD, AVOID: ALL_WKD, EXCH: ALL_WKD, GT: ALL_WKD, DOCK: DOCK_ROW,
    WKD: ACTIVE_VS_WAIT, WFGT: ACTIVE_VS_WAIT, WFD: ACTIVE_VS_WAIT,
}
ALG2_ACTIVE = {REAR: (WKD, WKD), HEAD: (WKD, None), SIDE: (WKD, None), NONE: (None, None)}
ALGORITHM_2 = {  # I avoid or exchange
    FWP: ALG2_ACTIVE, AVOID: ALG2_ACTIVE, EXCH: ALG2_ACTIVE,
    GT: {REAR: (WKD, WKD), HEAD: (WKD, WKD), SIDE: (WKD, WKD), NONE: (None, None)},
    DOCK: DOCK_ROW,
    WKD: ACTIVE_VS_WAIT, WFGT: ACTIVE_VS_WAIT, WFD: ACTIVE_VS_WAIT,
}
ALG3_ACTIVE = {REAR: (WKD, WKD), HEAD: (None, None), SIDE: (None, None), NONE: (None, None)}
ALGORITHM_3 = {  # I go through
    FWP: ALG3_ACTIVE, AVOID: ALG3_ACTIVE, EXCH: ALG3_ACTIVE,
    GT: ALG2_ACTIVE,
    DOCK: DOCK_ROW,
    WKD: ACTIVE_VS_WAIT, WFGT: ACTIVE_VS_WAIT, WFD: ACTIVE_VS_WAIT,
}
KEEP = {REAR: (None, None), HEAD: (None, None), SIDE: (None, None), NONE: (None, None)}
# a waiting robot that does not wait for me: pass it unless it is in my channel
WAIT_VS_WAIT = {REAR: (None, None), HEAD: (None, None), SIDE: (GT, GT), NONE: (GT, GT)}
ALGORITHM_4 = {  # I wait (WaitKeepDistance, WaitForGoThrough); the other's partner is not me
    FWP: KEEP, AVOID: KEEP, EXCH: KEEP, GT: KEEP,
    DOCK: {REAR: (AVOID, AVOID), HEAD: (AVOID, AVOID), SIDE: (AVOID, AVOID), NONE: (None, None)},
    WKD: WAIT_VS_WAIT, WFGT: WAIT_VS_WAIT, WFD: WAIT_VS_WAIT,
}
ALGORITHM_4_ABOUT_ME = {  # I wait; the other's partner is me
    AVOID: KEEP,                                      # it drives round me: hold still
    EXCH: {c: (EXCH, EXCH) for c in Collision},      # exchange with it
    GT: {c: (WFGT, WFGT) for c in Collision},        # let it go through
    # "wait for me": a two-robot deadlock; the low-order robot drives round with a proper behaviour
    WKD: {REAR: (AVOID, None), HEAD: (EXCH, None), SIDE: (GT, None), NONE: (GT, None)},
}


def _rows(mine_list, table, partner_is_me=False):
    for mine in mine_list:
        for theirs, by_col in table.items():
            for col, (if_low, if_high) in by_col.items():
                for low, expected in ((True, if_low), (False, if_high)):
                    yield pytest.param(mine, theirs, col, low, partner_is_me, expected,
                                       id=f"{mine.value}-vs-{theirs.value}-{col.value}-{'low' if low else 'high'}")


@pytest.mark.parametrize("mine, theirs, col, low, partner_is_me, expected", [
    *_rows([FWP], ALGORITHM_1),
    *_rows([AVOID, EXCH], ALGORITHM_2),
    *_rows([GT], ALGORITHM_3),
    *_rows([WKD, WFGT], ALGORITHM_4),
    *_rows([WKD, WFGT], ALGORITHM_4_ABOUT_ME, partner_is_me=True),
])
def test_traffic_rules(mine, theirs, col, low, partner_is_me, expected):
    me, other = me_and_other(mine, theirs, col, low, partner_is_me)
    assert low_order(me, other) == low
    assert select_behavior(me, other, [other]) is expected


def test_circumnavigation_is_delayed_by_other_active_robots_and_same_station():
    """SolveActiveAndWaitCollision and Algorithm 4: only pass a waiting robot when no other robot
    in the front area is active and it is not headed to my station."""
    pos, wp = PLACES[SIDE]
    waiting = view("o", pos, wp, WKD)
    mover = view("x", (1.0, 0.9), (1.0, 10.0), FWP)
    also_waiting = view("y", (1.0, 0.9), (1.0, 10.0), WKD)
    for mine, go, hold in ((FWP, GT, WKD), (WKD, GT, None)):
        me = view("me", ME_POS, ME_WP, mine)
        assert select_behavior(me, waiting, [waiting, also_waiting]) is go
        assert select_behavior(me, waiting, [waiting, mover]) is hold
        same = view("me", ME_POS, ME_WP, mine, station="s1")
        assert select_behavior(same, view("o", pos, wp, WKD, station="s1"), []) is hold


def test_dock_keeps_moving_and_wait_for_docking_keeps_waiting():
    for mine in (DOCK, WFD):
        me = view("me", ME_POS, ME_WP, mine)
        for theirs in Behavior:
            pos, wp = PLACES[HEAD]
            assert select_behavior(me, view("o", pos, wp, theirs), []) is None


def test_standing_robot_is_an_obstacle_to_avoid_not_to_wait_for():
    ahead, beside = view("o", (1.5, 0.0)), view("o", (1.5, 1.2))
    assert select_behavior(view("me", ME_POS, ME_WP, FWP), ahead, [ahead]) is AVOID
    assert select_behavior(view("me", ME_POS, ME_WP, AVOID), ahead, [ahead]) is None
    assert select_behavior(view("me", ME_POS, ME_WP, FWP), beside, [beside]) is None
    assert select_behavior(view("me", ME_POS, ME_WP, WKD), beside, [beside]) is FWP


def test_a_running_exchange_is_kept():
    """Algorithm 2 would make the low-order robot wait; once both exchange with each other it goes on."""
    pos, wp = PLACES[HEAD]
    me = view("me", ME_POS, ME_WP, EXCH, remaining=10.0, partner="o")
    other = view("o", pos, wp, EXCH, remaining=5.0, partner="me")
    assert select_behavior(me, other, [other]) is None
    assert select_behavior(me, view("o", pos, wp, EXCH, remaining=5.0), []) is WKD


# -- docking, deadlock messages, virtual wall -------------------------------------------------
def test_docking_first_come_first_served_ties_by_priority():
    arb = DockingArbiter()
    assert arb.request("A", "r3", 2.0) and arb.holder("A") == "r3"   # alone: docks at once
    assert not arb.request("A", "r10", 5.0)
    assert not arb.request("A", "r2", 5.0)              # same arrival time as r10
    assert not arb.request("A", "r1", 6.0)
    arb.release("A", "r3")
    assert not arb.request("A", "r10", 7.0)             # r2 has the priority at the same time
    assert arb.request("A", "r2", 7.0) and arb.holder("A") == "r2"
    assert not arb.request("A", "r10", 7.1)             # one robot at a time
    arb.release("A", "r2")
    arb.withdraw("A", "r10")                            # gave up: r1 is next
    assert arb.request("A", "r1", 8.0)
    assert arb.request("B", "r10", 8.0)                 # another station is independent


def test_wait_message_finds_a_three_robot_cycle():
    a = view("a", (0, 0), (1, 0), WKD, partner="b")
    b = view("b", (1, 0), (1, 1), WKD, partner="c")
    c = view("c", (1, 1), (0, 0), WFGT, partner="a")
    msg = WaitMessage(("a",))                     # a waits, so it tells b
    deadlock, msg = on_wait_message(b, msg)
    assert not deadlock and msg.waiting == ("a", "b")
    deadlock, msg = on_wait_message(c, msg)
    assert not deadlock and msg.waiting == ("a", "b", "c")
    deadlock, msg = on_wait_message(a, msg)
    assert deadlock and msg is None


def test_wait_message_is_ignored_by_a_robot_that_does_not_wait():
    for b in (FWP, AVOID, EXCH, GT, DOCK):
        assert on_wait_message(view("b", (0, 0), (1, 0), b, partner="a"), WaitMessage(("a",))) == (False, None)


def test_virtual_wall_blocks_the_way_ahead_without_gaps():
    grid = GridMap(np.zeros((8, 8), bool))
    cells = virtual_wall_cells(grid, [(0.5, 0.5), (6.5, 6.5)], goal=(7.5, 0.5), radius=0.35)
    assert (0, 0) not in cells                     # the robot's own cell stays open
    assert {(k, k) for k in range(1, 7)} <= set(cells)
    s = set(cells)
    for k in range(1, 6):                          # each diagonal step is closed on a side
        assert (k + 1, k) in s or (k, k + 1) in s
    wall = virtual_wall_cells(grid, [(0.5, 3.5), (7.5, 3.5)], goal=(7.5, 3.5), radius=0.35)
    assert wall == [(c, 3) for c in range(1, 7)]  # the goal cell stays open too


# -- the fleet ----------------------------------------------------------------------------------
OPEN = GridMap(np.zeros((12, 12), bool))


def run(fleet, limit_s, dt=0.1, on_step=None):
    """Step until every robot arrived or ``limit_s``; returns the smallest gap between discs seen
    (and checks at every step that every disc is in free space)."""
    radii = np.array([fleet.view(i).radius for i in fleet.ids])
    need = radii[:, None] + radii[None, :]
    np.fill_diagonal(need, -np.inf)
    smallest = np.inf
    while fleet.time < limit_s and not all(fleet.arrived(i) for i in fleet.ids):
        fleet.step(dt)
        p = fleet.positions()
        gap = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1]) - need
        np.fill_diagonal(gap, np.inf)
        smallest = min(smallest, float(gap.min()))
        assert all(fleet.grid.disc_is_free(x, y, r) for (x, y), r in zip(p, radii)), f"t={fleet.time}"
        if on_step:
            on_step(fleet)
    return smallest


def test_six_robots_crossing_reach_their_goals_without_touching():
    centre, robots = np.array([6.0, 6.0]), []
    for k in range(6):  # on a circle, each bound for the opposite point: all meet in the middle
        a = 2 * math.pi * k / 6
        start = centre + 4.5 * np.array([math.cos(a), math.sin(a)])
        robots.append(RobotSpec(f"r{k}", 0.35 + 0.02 * (k % 3), 1.0, tuple(start), tuple(2 * centre - start)))
    fleet = BehaviorFleet(OPEN, robots)
    for r in robots:
        fleet.assign(r.id, r.goal)
    smallest = run(fleet, limit_s=90.0)
    assert all(fleet.arrived(r.id) for r in robots), fleet.behaviors()
    assert smallest >= 0.0
    assert np.allclose(fleet.positions(), [r.goal for r in robots])
    assert fleet.stats().stalled == ()


def _wait_triangle(params):
    """Three robots on a triangle, each bound past the next one: each waits for the next."""
    side, centre = 1.4, np.array([6.0, 6.0])
    corners = [centre + side / math.sqrt(3) * np.array([math.cos(a), math.sin(a)])
               for a in np.radians([90, 210, 330])]
    robots = []
    for k in range(3):
        ahead = (corners[(k + 1) % 3] - corners[k]) / side
        robots.append(RobotSpec(f"r{k}", 0.35, 1.0, tuple(corners[k]), tuple(corners[k] + 4 * ahead)))
    fleet = BehaviorFleet(OPEN, robots, params)
    for r in robots:
        fleet.assign(r.id, r.goal)
    return fleet


def test_three_robot_wait_cycle_is_detected_and_broken():
    fleet = _wait_triangle(BehaviorParams(wait_msg_period=2.0))
    fleet.step(0.1)
    assert fleet.behaviors() == {"r0": WKD, "r1": WKD, "r2": WKD}
    assert {i: fleet.view(i).partner for i in fleet.ids} == {"r0": "r1", "r1": "r2", "r2": "r0"}
    seen = []
    smallest = run(fleet, limit_s=30.0, on_step=lambda f: seen.append((f.stats().deadlocks, f.stats().replans)))
    assert seen[0] == (0, 0)
    first = next(k for k, s in enumerate(seen) if s[0])
    assert seen[first] == (1, 1)              # found by one robot, which re-plans ...
    assert seen[-1][0] == 1                   # ... and that breaks the cycle for good
    assert all(fleet.arrived(i) for i in fleet.ids) and smallest >= 0.0


def test_without_wait_messages_the_cycle_stays():
    fleet = _wait_triangle(BehaviorParams(wait_msg_period=1e6))
    run(fleet, limit_s=20.0)
    assert set(fleet.behaviors().values()) == {WKD}
    assert not any(fleet.arrived(i) for i in fleet.ids)
    assert fleet.stats().deadlocks == 0


def test_one_robot_docks_at_a_station_at_a_time():
    starts = [(2.5, 8.5), (6.5, 9.5), (10.0, 8.0), (4.0, 10.5)]
    robots = [RobotSpec(f"r{k}", 0.35, 1.0, s, s) for k, s in enumerate(starts)]
    elsewhere = {"r0": (1.5, 1.5), "r1": (10.5, 1.5), "r2": (1.5, 5.5), "r3": (10.5, 5.5)}
    fleet = BehaviorFleet(OPEN, robots)
    for r in robots:
        fleet.assign(r.id, (6.0, 1.0), station="A")
    served, docking_at_once, waited = [], [], set()

    def watch(f):
        docking_at_once.append(sum(1 for i, b in f.behaviors().items() if b is DOCK))
        waited.update(i for i, b in f.behaviors().items() if b is WFD)
        for i in f.ids:
            if f.arrived(i) and i not in served:
                served.append(i)
                assert np.allclose(f.positions()[f.ids.index(i)], (6.0, 1.0))
                f.assign(i, elsewhere[i])          # unloaded: leave the station

    smallest = run(fleet, limit_s=120.0, on_step=watch)
    assert sorted(served) == ["r0", "r1", "r2", "r3"]
    assert max(docking_at_once) == 1
    assert waited                                     # the station was contended
    assert all(fleet.arrived(i) for i in fleet.ids) and smallest >= 0.0


def test_safety_layer_keeps_discs_apart_when_the_behaviours_see_nothing():
    """Front areas too short to notice anybody: only the safety layer stands between the discs."""
    blind = BehaviorParams(front_length=0.01, front_width=0.01)
    robots = [RobotSpec("a", 0.4, 1.0, (2.0, 6.0), (10.0, 6.0)),
              RobotSpec("b", 0.3, 1.0, (10.0, 6.1), (2.0, 6.1)),
              RobotSpec("c", 0.35, 1.0, (6.0, 2.0), (6.0, 10.0))]
    fleet = BehaviorFleet(OPEN, robots, blind)
    for r in robots:
        fleet.assign(r.id, r.goal)
    assert run(fleet, limit_s=15.0) >= 0.0
    assert fleet.stats().refused_moves > 0


def test_head_on_in_a_one_cell_corridor_is_solved_by_replanning():
    grid = GridMap.from_rows(["..........",
                              ".@@@@@@@@.",
                              ".@@@@@@@@.",
                              ".........."])
    robots = [RobotSpec("r0", 0.35, 1.0, (2.5, 0.5), (7.5, 0.5)),
              RobotSpec("r1", 0.35, 1.0, (7.5, 0.5), (2.5, 0.5))]
    fleet = BehaviorFleet(grid, robots)
    for r in robots:
        fleet.assign(r.id, r.goal)
    smallest = run(fleet, limit_s=60.0)
    assert all(fleet.arrived(r.id) for r in robots)
    assert fleet.stats().replans >= 1 and smallest >= 0.0


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="front_length"):
        BehaviorParams(front_length=0)
    with pytest.raises(ValueError, match="dock_give_up"):
        BehaviorParams(dock_region=3.0, dock_give_up=2.0)
    a = RobotSpec("a", 0.35, 1.0, (1.5, 1.5), (1.5, 1.5))
    with pytest.raises(ValueError, match="overlap"):
        BehaviorFleet(OPEN, [a, RobotSpec("b", 0.35, 1.0, (1.9, 1.5), (1.9, 1.5))])
    with pytest.raises(ValueError, match="duplicate"):
        BehaviorFleet(OPEN, [a, a])
    corner = RobotSpec("a", 0.35, 1.0, (0.5, 0.5), (0.5, 0.5))
    fleet = BehaviorFleet(GridMap.from_rows(["...", ".@.", "..."]), [corner])
    with pytest.raises(ValueError, match="unknown robot"):
        fleet.assign("zz", (2.5, 2.5))
    with pytest.raises(ValueError, match="not free"):
        fleet.assign("a", (1.5, 1.5))
    with pytest.raises(ValueError, match="dt"):
        fleet.step(0.0)
    walled = BehaviorFleet(GridMap.from_rows([".@.", ".@.", ".@."]), [corner])
    with pytest.raises(PlanningError, match="no path"):
        walled.assign("a", (2.5, 2.5))
