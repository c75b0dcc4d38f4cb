"""The ways the BBMRCA fleet stalled in the delivery benchmark (issue 13), each on a constructed
scene that stays stuck without its fix and completes with it (paper 002, Sun, Kleiner & Nebel,
"Behavior-based Multi-Robot Collision Avoidance", sections IV.A-IV.C; the fixes are ours where
the paper leaves the case open, see the "Interpretation" notes in fleet_planner/behavior)."""
from __future__ import annotations

import numpy as np
from test_behavior import run as _drive  # steps a fleet, checks walls, returns the smallest gap

from fleet_planner.behavior import Behavior, BehaviorFleet, BehaviorParams
from fleet_planner.grid import GridMap
from fleet_planner.model import RobotSpec


def _leaving(fleet: BehaviorFleet, station: tuple[float, float], at: tuple[float, float],
             path: list[tuple[float, float]]) -> None:
    """Robot d docks at ``station`` (it holds it), then stands at ``at``, leaving the station for the
    end of ``path`` along it (a scene as measured in a run)."""
    fleet.assign("d", station, station="chute")
    for _ in range(10):
        fleet.step(0.1)
    d = fleet.controller("d")
    assert d.holds is not None
    d.pos = np.array(at)
    fleet.assign("d", path[-1])
    d._set_path(np.array(path))


def test_a_docking_robot_pushed_behind_a_wall_corner_replans():
    """Dock keeps moving (IV.B.5) but its straight way to the next waypoint may graze a wall
    corner once it was pushed off its path (WaitForDocking backs off): it must re-plan from where
    it is, not press against the corner for ever."""
    grid = GridMap.from_rows([".....",
                              ".@@..",
                              "....."])
    params = BehaviorParams(dock_region=3.0, dock_give_up=3.0)
    fleet = BehaviorFleet(grid, [RobotSpec("r0", 0.35, 1.0, (0.5, 2.5), (0.5, 2.5))], params)
    fleet.assign("r0", (2.5, 0.5), station="S")
    fleet.step(0.1)
    robot = fleet.controller("r0")
    assert robot.behavior is Behavior.DOCK and robot.holds is not None
    assert robot.path is not None and np.allclose(robot.path[robot.wp], (0.5, 0.5))
    robot.pos = np.array([2.5, 2.5])   # pushed off its path: the way to (0.5, 0.5) crosses the wall
    assert not grid.disc_is_free(1.5, 1.5, 0.35)
    _drive(fleet, limit_s=20.0)
    assert fleet.arrived("r0")
    assert np.allclose(fleet.positions()[0], (2.5, 0.5))


def _aisle_chains(n: int, params: BehaviorParams | None = None) -> BehaviorFleet:
    """A one-cell aisle (row 1) between two halls: n robots queued eastwards in it face n queued
    westwards, each bound for the hall behind the other queue (the first ones of each queue park
    in the halls, some of them in the way of the later ones)."""
    grid = GridMap.from_rows(["......@@@@@@@@@@......",
                              "......................",
                              "......@@@@@@@@@@......",
                              "......@@@@@@@@@@......",
                              "......................"])
    robots = []
    for k in range(n):
        robots.append(RobotSpec(f"e{k}", 0.354, 0.8, (10.5 - k, 1.5), (17.5 + 2 * (k % 3), 0.5 + 3 * (k // 3))))
        robots.append(RobotSpec(f"w{k}", 0.354, 0.8, (11.5 + k, 1.5), (4.5 - 2 * (k % 3), 0.5 + 3 * (k // 3))))
    fleet = BehaviorFleet(grid, robots, params or BehaviorParams())
    for r in robots:
        fleet.assign(r.id, r.goal)
    return fleet


def test_a_robot_behind_a_parked_robot_finds_a_detour():
    """When no detour is found behind the virtual wall of a re-plan (IV.C), the wall is cut a front
    length ahead (ours): running to the next waypoint of the straightened path, right across the
    hall, it left the robot queued behind a parked one without a detour for ever (three robots
    left waiting)."""
    fleet = _aisle_chains(5)
    smallest = _drive(fleet, limit_s=120.0)
    assert all(fleet.arrived(i) for i in fleet.ids), fleet.behaviors()
    assert smallest >= 0.0


def test_head_on_chains_in_a_one_cell_aisle_back_out_in_a_retreat_wave():
    """Five robots facing five in a one-cell aisle: the robot that re-plans backs out and the robots
    queued behind it give way in turn (retreat waves, ours), so no wait cycle is left for the
    WaitMessages to find; without the waves (control) the chain re-plans back and forth through
    wait cycles and finishes later."""
    fleet = _aisle_chains(5)
    assert _drive(fleet, limit_s=120.0) >= 0.0
    assert all(fleet.arrived(i) for i in fleet.ids), fleet.behaviors()
    waves = fleet.stats()
    assert waves.deadlocks == 0
    assert sum(fleet.controller(i).yields for i in fleet.ids) >= 2   # the wave went down the queue

    control = _aisle_chains(5, BehaviorParams(retreat_timeout=0.0))
    assert _drive(control, limit_s=120.0) >= 0.0
    assert control.stats().deadlocks > 0
    assert sum(control.controller(i).yields for i in control.ids) == 0
    assert control.time > waves.time   # and the waves finish sooner


def _niche_corridor(params: BehaviorParams) -> BehaviorFleet:
    """A one-cell corridor, the only way between its ends, with a one-cell niche above it: two
    robots meet head-on in it. No re-plan finds a way round (there is none), so a virtual wall
    does not help."""
    grid = GridMap.from_rows(["@@@@.@@@@@@@@@",
                              "..............",
                              "@@@@@@@@@@@@@@"])
    robots = [RobotSpec("a", 0.35, 0.8, (2.5, 1.5), (13.5, 1.5)), RobotSpec("b", 0.35, 0.8, (12.5, 1.5), (0.5, 1.5))]
    fleet = BehaviorFleet(grid, robots, params)
    for r in robots:
        fleet.assign(r.id, r.goal)
    return fleet


def test_a_robot_whose_replan_finds_no_way_escapes_into_a_less_crowded_place():
    """Head-on in a one-cell corridor without another way: the re-plan behind a virtual wall (IV.C)
    finds no path; the robot drives into the niche (a less crowded place off the other's way,
    ours after IV.B.8) and both reach their goals. Without escapes (control) they stay stuck."""
    control = _niche_corridor(BehaviorParams(escape_after=0.0))
    _drive(control, limit_s=90.0)
    assert not (control.arrived("a") and control.arrived("b"))

    fleet = _niche_corridor(BehaviorParams())
    assert _drive(fleet, limit_s=90.0) >= 0.0
    assert fleet.arrived("a") and fleet.arrived("b"), fleet.behaviors()
    assert sum(fleet.controller(i).escapes for i in fleet.ids) >= 1


def _waiting_in_a_docking_robots_way(params: BehaviorParams):
    """A robot waiting (for some robot behind it) stands in the drive channel of a robot that
    drives to its station (Dock: it keeps moving, the others give way, IV.B.5)."""
    from fleet_planner.behavior import BehaviorController, RobotView

    grid = GridMap.from_rows(["........", "........", "........"])
    w = BehaviorController(grid, "w", 0.35, 0.8, (3.0, 1.5), params)
    w.assign((0.5, 1.5))
    w.behavior, w.partner = Behavior.WAIT_KEEP_DISTANCE, "x"
    dock = RobotView("d", (4.2, 1.5), 0.35, Behavior.DOCK, next_waypoint=(0.5, 1.5), station="S")
    return w, dock


def test_a_waiting_robot_gives_way_to_a_docking_robot():
    """Without giving way (control) the waiting robot holds in the Dock robot's channel for good;
    with it, it leaves the channel."""
    from fleet_planner.behavior import in_critical_area

    for params, gives_way in ((BehaviorParams(give_way_reach=0.0), False), (BehaviorParams(), True)):
        w, dock = _waiting_in_a_docking_robots_way(params)
        for k in range(30):
            w.move(0.1 * k, 0.1, [dock])
        assert in_critical_area(dock, w.view(), params) is not gives_way


def _leaving_blocked_by_the_queue() -> BehaviorFleet:
    """The default `large` warehouse's chute_6 (the scene of ARMO at 20 robots): r6 leaves the
    station it still holds, three robots queue for it; on a road map paths are not straightened,
    and r6's first step out (a diagonal staircase) runs at r19, pinned against the wall."""
    from fleet_planner.delivery import ROBOT_RADIUS
    from fleet_planner.roadmap import RoadMap, with_lanes
    from fleet_planner.warehouse import generate_warehouse

    grid = generate_warehouse(5, 10, 24, 2, 3, 0.5, "large").grid
    allowed = RoadMap.open(grid).allowed.copy()
    allowed[0, 0] = 0                       # a road map (it restricts one corner cell)
    grid = with_lanes(grid, RoadMap(allowed, grid.resolution))
    station = (37.25, 2.25)
    starts = {"r6": (37.25, 2.55), "r19": (36.05, 3.63), "r1": (35.85, 1.74), "r10": (38.33, 2.84)}
    fleet = BehaviorFleet(grid, [RobotSpec(k, ROBOT_RADIUS, 1.0, p, p) for k, p in starts.items()])
    fleet.assign("r6", station, station="chute_6")
    for _ in range(20):
        fleet.step(0.1)
    assert fleet.controller("r6").holds is not None
    fleet.assign("r6", (5.25, 20.75))
    for k in ("r19", "r1", "r10"):
        fleet.assign(k, station, station="chute_6")
    return fleet


def _until_r6_arrives(fleet: BehaviorFleet, limit_s: float) -> None:
    while fleet.time < limit_s and not fleet.arrived("r6"):
        fleet.step(0.1)


def test_a_robot_leaving_its_station_replans_round_a_waiting_robot_pinned_in_its_way(monkeypatch):
    """IV.C.1 re-plans round a *standing* robot in the way; a robot queued for the station that is
    pinned between the leaving robot and a wall cannot give way either (ours): the leaving robot
    re-plans round it. Control (the paper's rule only): r6 stays blocked."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _leaving_blocked_by_the_queue()
    _until_r6_arrives(fleet, 120.0)
    assert fleet.arrived("r6") and fleet.controller("r6").replans >= 1
    monkeypatch.setattr(BehaviorController, "_does_not_give_way", staticmethod(lambda o: not o.travelling))
    monkeypatch.setattr(BehaviorController, "_given_up_on", lambda self, other: False)   # the later breaker too
    control = _leaving_blocked_by_the_queue()
    _until_r6_arrives(control, 120.0)
    assert not control.arrived("r6") and control.controller("r6").blocked_since is not None


def _one_wave_face_to_face() -> BehaviorFleet:
    """Two robots of one retreat wave face each other in a one-cell aisle (a parallel aisle is the
    way round): each waits for the other to give way, as retreating robots do. Retreats that do
    not time out and no escapes, so only the wait cycle's re-plan can break it."""
    grid = GridMap.from_rows(["@@@@@@@@@@@@", "............", ".@@@@@@@@@@.", "............", "@@@@@@@@@@@@"])
    robots = [RobotSpec("a", 0.35, 0.8, (4.5, 1.5), (11.5, 1.5)), RobotSpec("b", 0.35, 0.8, (6.5, 1.5), (0.5, 1.5))]
    fleet = BehaviorFleet(grid, robots, BehaviorParams(retreat_timeout=600.0, escape_after=0.0))
    for r in robots:
        fleet.assign(r.id, r.goal)
        robot = fleet.controller(r.id)
        robot.retreat, robot.retreat_at = (0.0, "a"), 0.0
    return fleet


def test_a_wait_cycle_of_retreating_robots_turns_one_of_them(monkeypatch):
    """A retreating robot does not re-plan on a wait cycle (the others give way to it); when every
    robot of the cycle retreats, the one of the youngest wave (ties: larger id) re-plans behind a
    virtual wall (ours, ``BehaviorController._turns_in_retreat_cycle``): b turns, both arrive.
    Control: the cycle is found again and again and nobody turns."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _one_wave_face_to_face()
    assert _drive(fleet, limit_s=60.0) >= 0.0
    assert fleet.arrived("a") and fleet.arrived("b"), fleet.behaviors()
    assert fleet.controller("b").replans == 1 and fleet.controller("a").replans == 0

    monkeypatch.setattr(BehaviorController, "_turns_in_retreat_cycle", lambda self, msg, sensed: False)
    control = _one_wave_face_to_face()
    _drive(control, limit_s=120.0)
    assert not control.arrived("a") and not control.arrived("b")
    assert control.stats().deadlocks > 10 and control.stats().replans == 0


def _blocked_short_way() -> BehaviorFleet:
    """Two ways from a to its goal: the short one along the bottom row, shut near the goal by a
    robot parked there (p: a one-cell row, no way past it), and a long one over the top row, 8 m
    up, where a comes no closer to its goal for longer than ``escape_after``. (The scene of ARMO on
    the default warehouse at 50 robots: the last robot among robots parked at their homes.)"""
    grid = GridMap.from_rows(["." * 30] + ["." + "@" * 28 + "."] * 7 + ["." * 30])
    robots = [RobotSpec("a", 0.354, 0.8, (2.5, 8.5), (28.5, 8.5)), RobotSpec("p", 0.354, 0.8, (25.5, 8.5), (25.5, 8.5))]
    fleet = BehaviorFleet(grid, robots)
    fleet.assign("a", (28.5, 8.5))
    return fleet


def _until_a_arrives(fleet: BehaviorFleet, limit_s: float) -> None:
    while fleet.time < limit_s and not fleet.arrived("a"):
        fleet.step(0.1)


def test_an_escaped_robot_plans_round_a_parked_robot_it_saw_out_of_range_now(monkeypatch):
    """a fails at the parked robot and re-plans over the top (IV.C), escapes on the way (no
    progress for 30 s), and then plans its way back from where it stands: round the parked robot it
    remembers (ours, ``BehaviorController._remember``), so it takes the top and arrives. Control
    (forgetting it once out of range): back along the bottom row into p, again and again."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _blocked_short_way()
    _until_a_arrives(fleet, 200.0)
    assert fleet.arrived("a")
    monkeypatch.setattr(BehaviorController, "_remember", lambda self, sensed: None)
    control = _blocked_short_way()
    _until_a_arrives(control, 600.0)
    assert not control.arrived("a") and control.controller("a").escapes >= 10


def test_a_robot_standing_where_it_escaped_to_has_its_way_to_the_goal_left():
    """The delivery run measures a leg's progress by ``remaining()``; a robot standing in its
    escape place (no path, still bound for its goal) reported 0 (the leg as good as done), so no
    later progress counted and the run declared a stall (ARMO, default warehouse, 50 robots:
    149/150, "1 deadlocked", while the robot was still on its way)."""
    import math

    fleet = _niche_corridor(BehaviorParams())
    standing = None
    while fleet.time < 90.0 and standing is None:
        fleet.step(0.1)
        standing = next((c for c in map(fleet.controller, fleet.ids) if c.escape_to is not None and c.path is None),
                        None)
    assert standing is not None and standing.goal is not None
    assert standing.remaining() == math.dist(standing.position, standing.goal) > 1.0


def _pinned_in_a_one_way_aisle() -> BehaviorFleet:
    """A 2 m aisle whose lanes run east only (the two rows of centres a robot fits in), a station
    in a niche below it (the scene of ARMO on `large`, 100 robots, chute_5): d leaves the station
    it still holds, its path climbing to the upper row and on east; p stands pressed against the
    top wall 0.73 m from it, its way running down into d (it drives round d in Avoid, finds no
    side, waits, tries again). Escapes off: only a re-plan can break it."""
    from fleet_planner.roadmap import _BIT, RoadMap, with_lanes

    rows = ["@" * 40] + ["." * 40] * 4 + ["@" * 9 + "..." + "@" * 28] * 3 + ["@" * 40]
    grid = GridMap.from_rows(rows, resolution=0.5)
    allowed = RoadMap.open(grid).allowed.copy()
    allowed[1:5, :] &= ~np.uint8(_BIT[(-1, 0)])      # the aisle: eastbound only
    grid = with_lanes(grid, RoadMap(allowed, 0.5))
    d0, p0 = (5.25, 2.95), (4.93, 0.87)
    fleet = BehaviorFleet(grid, [RobotSpec("d", 0.354, 0.8, d0, d0), RobotSpec("p", 0.354, 0.8, p0, p0)],
                          BehaviorParams(escape_after=0.0))
    _leaving(fleet, (5.25, 3.0), (5.05, 1.59), [(5.39, 1.25), (19.25, 1.25)])
    fleet.assign("p", (19.25, 1.75))
    fleet.controller("p")._set_path(np.array([[4.6, 1.5], [19.25, 1.75]]))
    return fleet


def _until_d_arrives(fleet: BehaviorFleet, limit_s: float) -> None:
    while fleet.time < limit_s and not fleet.arrived("d"):
        fleet.step(0.1)


def test_a_robot_leaving_its_station_replans_round_a_driving_robot_pinned_in_its_way(monkeypatch):
    """The paper's re-plan behind a virtual wall (IV.C) cuts both eastbound rows (the wall and the
    disc's clearance), and p, driving, is no obstacle the leaving robot re-plans round: d stood
    (control: 200 s, dozens of failed re-plans; the measured lock lasted 1044 s). Ours
    (``BehaviorController._given_up_on``): a robot in a leaving Dock robot's way that has not
    given way in ``avoid_timeout`` cannot, and d re-plans round it, without a wall, keeping only
    the discs apart; it arrives."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _pinned_in_a_one_way_aisle()
    _until_d_arrives(fleet, 120.0)
    assert fleet.arrived("d") and fleet.controller("d").holds is None
    monkeypatch.setattr(BehaviorController, "_given_up_on", lambda self, other: False)
    control = _pinned_in_a_one_way_aisle()
    _until_d_arrives(control, 200.0)
    d = control.controller("d")
    assert not control.arrived("d") and d.holds is not None and d.replan_failures >= 10


def _shut_in_a_junction_pocket() -> BehaviorFleet:
    """The east end of `large`'s rack aisles (x 66-74 m, y 0-9.5 m of the map, shifted to the
    origin) on one-way lanes as ARMO laid them: the side aisle x = 6.75 southbound (one robot
    wide), the rack aisle y = 5.75 westbound out of it, y = 8.25 eastbound into it, a way back
    north at x = 0.75. p stands in the corner cell (6.25, 5.25) of the junction of y = 5.75 with
    the side aisle, whose only way out the lanes allow runs north past q; q, in the side aisle
    above it, is bound south past p; b queues behind q."""
    from fleet_planner.roadmap import _BIT, RoadMap, with_lanes

    rows = ["@" * 16,                               # y = 0 (row 0) first
            "." * 7 + "@@@" + "." * 5 + "@",
            "." * 7 + "@@@" + "." * 5 + "@",
            "." * 15 + "@",
            *(["." * 15 + "@"] * 4),
            *(["..." + "@" * 9 + "...@"] * 2),
            *(["." * 15 + "@"] * 3),
            *(["..." + "@" * 9 + "...@"] * 2),
            *(["." * 15 + "@"] * 3),
            "@" * 12 + "...@"]
    grid = GridMap.from_rows(rows, resolution=0.5)
    n, s, e, w = (np.uint8(_BIT[d]) for d in ((0, 1), (0, -1), (1, 0), (-1, 0)))
    allowed = RoadMap.open(grid).allowed.copy()
    allowed[:, 13] &= ~n                     # the side aisle x = 6.75: southbound
    allowed[:, 1] &= ~s                      # x = 0.75: northbound
    allowed[11, :13] &= ~e                   # y = 5.75: westbound
    allowed[16, :13] &= ~w                   # y = 8.25: eastbound
    allowed[10, 12] &= ~e                    # the pocket: out north only
    grid = with_lanes(grid, RoadMap(allowed, 0.5))
    radius = 0.5 ** 1.5                      # the robots of `large`
    robots = [RobotSpec("p", radius, 0.8, (6.25, 5.25), (1.25, 5.75)),
              RobotSpec("q", radius, 0.8, (6.75, 6.25), (6.75, 2.25)),
              RobotSpec("b", radius, 0.8, (6.75, 8.25), (3.25, 2.25))]
    fleet = BehaviorFleet(grid, robots, BehaviorParams())
    for r in robots:
        fleet.assign(r.id, r.goal)
    return fleet


def _until_all_arrive(fleet: BehaviorFleet, limit_s: float) -> None:
    while fleet.time < limit_s and not all(fleet.arrived(i) for i in fleet.ids):
        fleet.step(0.1)


def test_a_robot_shut_in_a_junction_pocket_by_one_way_lanes_steps_out_against_them(monkeypatch):
    """p and q wait for each other; the wait cycle is found (IV.C) but every re-plan and escape
    of either keeps to the lanes, which leave p one way out, past q (control: stuck 300 s, over
    40 failed re-plans, the cycle found 200 times and more; the measured lock on `large`, ARMO,
    100 robots, lasted 2900 s). Ours (``BehaviorController._step_out``): p re-plans from a
    neighbouring cell, its first move against the lanes, and all three arrive."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _shut_in_a_junction_pocket()
    gap = _drive(fleet, limit_s=120.0)   # checks the walls at every step
    assert all(fleet.arrived(i) for i in fleet.ids) and gap > 0
    assert fleet.controller("p").steps_out >= 1
    monkeypatch.setattr(BehaviorController, "_step_out", lambda self, sensed: False)
    control = _shut_in_a_junction_pocket()
    _until_all_arrive(control, 300.0)
    p, q = control.controller("p"), control.controller("q")
    assert not control.arrived("p") and not control.arrived("q")
    assert p.replan_failures + q.replan_failures >= 40 and p.deadlocks + q.deadlocks >= 200


def _escaped_in_the_way() -> BehaviorFleet:
    """A one-cell corridor with a niche above it (x = 4.5): e escaped (ours, after IV.B.8) and stands
    where its escape took it, at x = 8.5 in the corridor, still bound for the corridor's east end;
    b drives east along the corridor 2 m behind it, e in its way."""
    grid = GridMap.from_rows(["@@@@.@@@@@@@@@@@",
                              "................",
                              "@@@@@@@@@@@@@@@@"])
    robots = [RobotSpec("e", 0.35, 0.8, (8.5, 1.5), (15.5, 1.5)), RobotSpec("b", 0.35, 0.8, (6.5, 1.5), (13.5, 1.5))]
    fleet = BehaviorFleet(grid, robots, BehaviorParams(escape_after=0.0))   # b does not escape itself
    for r in robots:
        fleet.assign(r.id, r.goal)
    e = fleet.controller("e")   # standing in the place it escaped to, as _advance leaves it
    e.path = e.tail = e.run = None
    e.escape_to = e.pos.copy()
    e.escape_hold, e.escape_end = 3.0, 15.0
    return fleet


def _until_b_arrives(fleet: BehaviorFleet, limit_s: float) -> None:
    while fleet.time < limit_s and not fleet.arrived("b"):
        fleet.step(0.1)


def test_an_escaped_robot_standing_in_a_drivers_way_moves_on(monkeypatch):
    """An escaped robot standing in the way of a driving robot leaves its place at once (ours,
    ``BehaviorController._end_escape``): into another less crowded place off the way or on to its
    goal, so b passes. Control (the old condition: in someone's way it stood until its escape
    ended, 15 s; in nobody's way it left after 3 s): b stands behind e until then."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _escaped_in_the_way()
    _until_b_arrives(fleet, 60.0)
    assert fleet.arrived("b")
    fixed_s = fleet.time

    def old(self, sensed):
        if self.time >= self.escape_end or (
                self.path is None and self.time >= self.escape_hold and not self._in_the_way(sensed)):
            self._resume(sensed)

    monkeypatch.setattr(BehaviorController, "_end_escape", old)
    control = _escaped_in_the_way()
    stood = 0.0
    while control.time < 60.0 and not control.arrived("b"):
        control.step(0.1)
        e = control.controller("e")
        if e.escape_to is not None and e.path is None:
            stood = control.time
    assert control.arrived("b")
    assert stood >= 14.0                 # e stood in b's way until its escape ended
    assert fixed_s < control.time - 5.0, (fixed_s, control.time)


def _going_through_a_waiting_robot() -> BehaviorFleet:
    """A one-cell corridor with a niche above it (x = 5.5): g goes through (GoThrough) eastwards
    while its partner w, bound westwards, waits for it (WaitForGoThrough) standing right in g's
    channel with no room to leave it sideways (the pair that held 39 of 62 stuck robots on
    ``large`` at 200 robots, t = 500 s)."""
    grid = GridMap.from_rows(["@@@@@.@@@@@@@@@@", "." * 16, "@" * 16])
    robots = [RobotSpec("g", 0.35, 0.8, (2.5, 1.5), (14.5, 1.5)), RobotSpec("w", 0.35, 0.8, (3.4, 1.5), (0.5, 1.5))]
    fleet = BehaviorFleet(grid, robots)
    for r in robots:
        fleet.assign(r.id, r.goal)
    g, w = fleet.controller("g"), fleet.controller("w")
    g._set(Behavior.GO_THROUGH, "w")
    w._set(Behavior.WAIT_FOR_GO_THROUGH, "g")
    return fleet


def test_a_going_through_robot_blocked_by_its_waiting_partner_fails(monkeypatch):
    """GoThrough fails (IV.C.4) once the safety layer refused its motion for ``blocked_timeout``, as
    Avoid and Exchange do (ours): g re-plans, and the pair gets past each other by the niche.
    Control (IV.C.4's timeout only): they stand until the GoThrough has lasted
    ``go_through_timeout`` (30 s)."""
    from fleet_planner.behavior.controller import BehaviorController

    def until_g_arrives(fleet: BehaviorFleet) -> float:
        while fleet.time < 120.0 and not (fleet.arrived("g") and fleet.arrived("w")):
            fleet.step(0.1)
        assert fleet.arrived("g") and fleet.arrived("w")
        return fleet.time

    fixed_s = until_g_arrives(_going_through_a_waiting_robot())
    failed = BehaviorController._failed

    def timeout_only(self, me, sensed, in_front):
        if self.behavior is Behavior.GO_THROUGH:
            return self.time - self.since > self.params.go_through_timeout
        return failed(self, me, sensed, in_front)

    monkeypatch.setattr(BehaviorController, "_failed", timeout_only)
    control_s = until_g_arrives(_going_through_a_waiting_robot())
    assert fixed_s < control_s - 15.0, (fixed_s, control_s)



def _short_of_diagonal_waypoints(params: BehaviorParams) -> BehaviorFleet:
    """The scene of ARMO on `large`, 100 robots, at chute_3 (shifted): d leaves the station it still
    holds (Dock), 2.7 cm short of its waypoint (3.25, 1.75), its path turning west there; f, 2.6
    cm short of its waypoint (2.75, 2.25), the next diagonal cell on the road map, its path turning
    east. The discs are 0.76 m apart and the waypoints 0.71 m (the sum of radii): each move is
    refused by the other's disc plus the safety margin. Three robots parked round f stand for the
    crowd that left its re-plans no other first move."""
    from fleet_planner.roadmap import RoadMap, with_lanes

    grid = GridMap.from_rows(["." * 16] * 8, resolution=0.5)
    allowed = RoadMap.open(grid).allowed.copy()
    allowed[0, 0] = 0                       # a road map: paths are not straightened
    grid = with_lanes(grid, RoadMap(allowed, 0.5))
    radius, station, crowd = 0.5 ** 1.5, (3.75, 1.25), [(2.75, 3.0), (2.0, 2.4), (3.5, 3.0)]
    robots = [RobotSpec("d", radius, 0.8, (3.75, 1.5), station),
              RobotSpec("f", radius, 0.8, (2.732, 2.268), (7.25, 2.25))]
    robots += [RobotSpec(f"c{k}", radius, 0.8, p, p) for k, p in enumerate(crowd)]
    fleet = BehaviorFleet(grid, robots, params)
    for k, p in enumerate(crowd):
        fleet.assign(f"c{k}", p)            # parked: arrived where they stand
    _leaving(fleet, station, (3.269, 1.731), [(3.25, 1.75), (0.75, 1.75)])
    fleet.assign("f", (7.25, 2.25))
    fleet.controller("f")._set_path(np.array([[2.75, 2.25], [3.75, 2.25], [7.25, 2.25]]))
    return fleet


def test_two_robots_refused_a_few_cm_short_of_diagonal_waypoints_head_on():
    """Neither front area (a few cm long: the paths turn at the waypoints) holds the other, so no
    rule applies and both stand, their moves refused (control: 120 s, not a cm moved; measured on
    `large`: 1800 s, 65 robots queued behind). Ours (``BehaviorController._reached_nearly``): a
    waypoint a refused move is this close to counts as reached; each heads for its next one, the
    rules see the other ahead, and both arrive, their discs never closer than the sum of radii."""
    fleet = _short_of_diagonal_waypoints(BehaviorParams())
    assert _drive(fleet, limit_s=60.0) >= 0.0   # checks the walls at every step
    assert fleet.arrived("d") and fleet.arrived("f"), fleet.behaviors()
    assert fleet.controller("d").nearly_reached + fleet.controller("f").nearly_reached >= 1
    control = _short_of_diagonal_waypoints(BehaviorParams(waypoint_reach=0.0))
    _drive(control, limit_s=120.0)
    assert not control.arrived("d") and not control.arrived("f")
    assert np.allclose(control.positions()[:2], [(3.269, 1.731), (2.732, 2.268)])


def test_a_robot_parked_inside_the_docking_region_of_the_station_it_left_releases_it():
    """A robot that docked at S and then parks 1.2 m from it (inside the 1.5 m docking region) used
    to hold S for good: IV.A releases a station when its robot leaves the region, and this one never
    does (measured: 200 robots on `large`, r77 parked 1.5 m from B098, two robots waiting 1200 s).
    Arrived at a goal that is not S, it has left S (ours): the robot waiting for S docks there."""
    grid = GridMap.from_rows(["." * 10] * 4)
    fleet = BehaviorFleet(grid, [RobotSpec("a", 0.35, 1.0, (1.5, 1.5), (1.5, 1.5)),
                                 RobotSpec("b", 0.35, 1.0, (8.5, 1.5), (8.5, 1.5))])
    fleet.assign("a", (4.5, 1.5), station="S")
    _drive(fleet, limit_s=20.0)
    assert fleet.arrived("a") and fleet.controller("a").holds is not None
    fleet.assign("a", (4.5, 2.7))              # park 1.2 m from S
    _drive(fleet, limit_s=40.0)
    assert fleet.arrived("a")
    fleet.assign("b", (4.5, 1.5), station="S")
    _drive(fleet, limit_s=80.0)
    assert fleet.arrived("b"), fleet.behaviors()
    assert fleet.controller("b").holds is not None and fleet.controller("a").holds is None


def _escaping_past_its_partner() -> BehaviorFleet:
    """The west end of `large`'s rack aisles (x 0-7 m, y 22.5-30 m of the map, shifted up by 22 m,
    and a side aisle x = 7-8.5 m added) on one-way lanes as ARMO laid them: the side aisle x = 1.25
    southbound (one robot wide), the cross aisle y = 3.75 eastbound out of it, the corner cells of
    their junction pockets (1.75, 3.25) (out west into the side aisle) and (1.75, 4.25) (out north).
    p stands in the lower pocket, bound for the lower main aisle; its shortest way runs north into
    the upper pocket and down the side aisle, where q, bound down that aisle, stands waiting for it
    (p's disc is 0.5 m from q's way south). p has just escaped (ours, after IV.B.8) east along the
    cross aisle: its path turns away from q 0.83 m from it, clear of the disc but inside the
    critical area (0.91 m wide). (Scene by session 25, from the run's snapshot at t = 2750 s.)"""
    from fleet_planner.roadmap import _BIT, RoadMap, with_lanes

    racks = "@..." + "@" * 10 + "...@"
    aisle = "@" + "." * 16 + "@"
    rows = ["@" * 18,                                   # y = 0 (row 0) first
            *([aisle] * 3), *([racks] * 2), *([aisle] * 3), *([racks] * 2), *([aisle] * 5), "@" * 18]
    grid = GridMap.from_rows(rows, resolution=0.5)
    n, s, e, w = (np.uint8(_BIT[d]) for d in ((0, -1), (0, 1), (1, 0), (-1, 0)))
    allowed = RoadMap.open(grid).allowed.copy()
    allowed[:8, 2] &= ~n                     # the side aisle x = 1.25: southbound
    allowed[7, 3:15] &= ~w                   # the cross aisle y = 3.75: eastbound
    allowed[:, 15] &= ~n                     # the side aisle x = 7.75: southbound
    allowed[6, 3] &= ~(s | e)                # the upper pocket: out west (or north)
    allowed[7, 3] &= ~s                      # no way down into the lower pocket ...
    allowed[8, 3] &= ~(s | e | w)            # ... whose way out is north
    grid = with_lanes(grid, RoadMap(allowed, 0.5))
    radius = 0.5 ** 1.5                      # the robots of `large`
    robots = [RobotSpec("p", radius, 0.8, (1.75, 4.25), (6.25, 6.25)),
              RobotSpec("q", radius, 0.8, (1.08, 3.26), (1.25, 7.25))]
    fleet = BehaviorFleet(grid, robots, BehaviorParams())
    for r in robots:
        fleet.assign(r.id, r.goal)
    p = fleet.controller("p")                # escaping, as _escape leaves it
    p._set_path(np.array([[1.75, 3.75], [3.75, 3.75]]))
    p.escape_to = np.array([3.75, 3.75])
    p.escape_end = p.escape_ready = 15.0
    fleet.controller("q")._set_path(np.array([[1.25, 7.25]]))   # straight down the aisle, as it stood
    return fleet


def test_a_robot_whose_escape_was_in_vain_steps_out_against_the_lanes(monkeypatch):
    """p and q wait for each other: q stands in p's critical area, p's disc is in q's way. The
    escape found a place but no way clear of q, so the paper's rules stop p at once (Exchange
    finds no side in the pocket, its re-plan (IV.C) leads north past q, q's re-plans fail on the
    lanes); the step against the lanes was tried only when an escape found no place, and every
    escape (one per 30 s) found this one again (control: neither arrives in 200 s, as measured on
    `large`, ARMO, 100 robots: 600 s, the run's one stall). Ours (``STEP_OUT_AFTER_VAIN_ESCAPE``):
    after one escape in vain p steps out instead of escaping again, and both arrive."""
    from fleet_planner.behavior import controller

    fleet = _escaping_past_its_partner()
    gap = _drive(fleet, limit_s=120.0)   # checks the walls at every step
    assert all(fleet.arrived(i) for i in fleet.ids) and gap > 0, fleet.behaviors()
    p = fleet.controller("p")
    assert p.steps_out == 1 and p.escapes == 1     # one escape in vain, then the step out
    monkeypatch.setattr(controller, "STEP_OUT_AFTER_VAIN_ESCAPE", False)
    control = _escaping_past_its_partner()
    _until_all_arrive(control, 200.0)
    p, q = control.controller("p"), control.controller("q")
    assert not control.arrived("p") and not control.arrived("q")
    assert p.escapes >= 5 and p.steps_out == 0 and q.replan_failures >= 20

def _docking_across_a_pinned_robot() -> BehaviorFleet:
    """The north-east corner of warehouse-10-20-10-2-1 at S4 on ARMO's road map (shifted by
    (-129, -56) m): a top aisle y = 5.5 under the wall, eastbound only, racks below it west of x = 6,
    the side aisles x = 6.5 and 7.5 northbound, x = 8.5 southbound. d holds station S at (7.5, 5.5)
    and docks diagonally from the side aisle; b, bound east along the top aisle, stands 0.73 m from
    it against the wall; q1 queues behind b, q2 (bound for S too) behind d. Positions as measured
    (100 robots, t = 1000 s: r12, r19, r45, r16); d and b have passed their cells' centres."""
    from fleet_planner.roadmap import _BIT, RoadMap, with_lanes

    rows = ["@" * 14, "." * 14, "." * 14, "@" * 6 + "." * 8, "@" * 6 + "." * 8, "." * 14, "@" * 14]
    grid = GridMap.from_rows(rows)
    n, s, w = (np.uint8(_BIT[d]) for d in ((0, 1), (0, -1), (-1, 0)))
    allowed = RoadMap.open(grid).allowed.copy()
    allowed[5, :] &= ~w                      # the top aisle: eastbound
    allowed[1:6, 6:8] &= ~s                  # x = 6.5, 7.5: northbound
    allowed[1:6, 8] &= ~n                    # x = 8.5: southbound
    grid = with_lanes(grid, RoadMap(allowed, grid.resolution))
    radius = 0.5 ** 1.5
    robots = [RobotSpec("d", radius, 1.0, (6.92, 4.92), (7.5, 5.5)),
              RobotSpec("b", radius, 1.0, (6.79, 5.64), (12.5, 1.5)),
              RobotSpec("q1", radius, 1.0, (5.58, 5.5), (12.5, 2.5)),
              RobotSpec("q2", radius, 1.0, (6.82, 3.62), (7.5, 5.5))]
    fleet = BehaviorFleet(grid, robots, BehaviorParams())
    for r in robots:
        fleet.assign(r.id, r.goal, station="S" if r.id in ("d", "q2") else None)
    for k in ("d", "b"):
        fleet.controller(k).wp = 1           # past the centre of its cell, the path's first waypoint
    return fleet


def test_a_docking_robot_makes_way_for_a_robot_pinned_in_its_approach(monkeypatch):
    """Dock keeps moving, the others give way (IV.B.5); b cannot (the wall beside it, q1 behind
    it, q2 where its Avoid would pass d) and waits for d, which the safety layer stops 0.73 m from
    b: a wait cycle of two that no WaitMessage finds (d does not wait). Control: both stand 120 s
    (the measured lock: 1477 s, 16 robots behind). Ours (``BehaviorController._dock_make_way``):
    after ``avoid_timeout`` d backs off from b, still in its docking region, b passes, d docks."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _docking_across_a_pinned_robot()
    assert _drive(fleet, limit_s=60.0) >= 0.0   # checks the walls at every step
    d = fleet.controller("d")
    assert fleet.arrived("d") and fleet.arrived("b"), fleet.behaviors()
    assert d.holds is not None and np.allclose(d.position, (7.5, 5.5))
    monkeypatch.setattr(BehaviorController, "_dock_make_way", lambda self, me, sensed: None)
    control = _docking_across_a_pinned_robot()
    _drive(control, limit_s=120.0)
    d = control.controller("d")
    assert not control.arrived("d") and not control.arrived("b")
    assert d.holds is not None and d.blocked_since is not None and control.time - d.blocked_since > 100.0


def _leaving_past_a_parked_robot() -> BehaviorFleet:
    """BBMRCA on `large`, 40 robots, at chute_7 (x 40-62 m of the map, shifted by -40 m): d leaves
    the station it still holds (Dock) north through the 2.5 m gap between two racks, where p is
    parked at its home (4.75, 4.25); d's path to (8.75, 5.75) runs through p's disc, and the safety
    layer stopped d 0.74 m from p (the sum of radii is 0.71 m). Its re-plan (the virtual wall
    closes the gap) runs east round the racks, its first step again bearing towards p. Positions
    as measured (r14, r20, t = 548 s)."""
    rack, aisle = "@@@@@@.....@@@@@@@@@@@@@@@@@@@@@@@@.....@@@@", "." * 44   # y from 0 up, 0.5 m rows
    rows = ["@" * 44] + ["......@@@..........@@@..........@@@........."] * 2 + [aisle] * 5 + [rack] * 2 \
        + [aisle] * 3 + [rack] * 2 + [aisle] * 3
    grid = GridMap.from_rows(rows, resolution=0.5)
    radius, station = 0.5 ** 1.5, (3.75, 2.25)
    fleet = BehaviorFleet(grid, [RobotSpec("d", radius, 1.0, station, station),
                                 RobotSpec("p", radius, 1.0, (4.75, 4.25), (4.75, 4.25))])
    fleet.assign("p", (4.75, 4.25))            # parked: arrived where it stands
    _leaving(fleet, station, (4.373, 3.609), [(5.25, 5.75), (8.75, 5.75)])
    return fleet


def test_a_robot_leaving_its_station_slides_past_a_parked_robot_its_path_grazes(monkeypatch):
    """Every motion of d along its path brings it closer to p inside the safety margin, so the
    safety layer refuses it, and d's re-plans cannot keep out of p's disc, which d stands in
    already: control, d stands 120 s (measured: 600 s, 130 re-plans, the run's last delivery
    never made). Ours (``BehaviorController._slide_past_standing``): after half
    ``blocked_timeout`` d drops the part of its step that points at p and slides round it."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _leaving_past_a_parked_robot()
    assert _drive(fleet, limit_s=60.0) >= 0.0   # checks the walls at every step
    assert fleet.arrived("d") and fleet.controller("d").slides >= 1
    assert np.allclose(fleet.positions()[1], (4.75, 4.25))   # p never moved
    monkeypatch.setattr(BehaviorController, "_slide_past_standing", lambda self, wanted, sensed: None)
    control = _leaving_past_a_parked_robot()
    _drive(control, limit_s=120.0)
    assert not control.arrived("d")
    assert np.linalg.norm(control.positions()[0] - (4.373, 3.609)) < 0.05


def _between_two_rows_of_parked_robots() -> BehaviorFleet:
    """The 200-robot stress run on `large` (x 56-74 m of the map, shifted by -56 m; t = 5300 s):
    16 robots parked in the corridor south of the racks, among them two rows 2 m apart (y = 1.25
    and 3.25 at x = 9.75-12.25) and two at the west gap to the aisle y = 5.75, where d's station
    is. d drives east along the path it planned when those were out of range: at a slant through
    the two rows to the east gap, round the racks and back west."""
    rows = ["@" * 36, "@@@...........@@@..........@@@.....@", "@@@...........@@@..........@@@.....@"] \
        + ["." * 35 + "@"] * 5 + ["@@@.....@@@@@@@@@@@@@@@@@@@@@@@@...@"] * 2 + ["." * 35 + "@"] * 3 + ["@" * 36]
    grid = GridMap.from_rows(rows, resolution=0.5)   # y from 0 up
    parked = [(15.75, 1.25), (3.75, 3.75), (4.75, 3.25), (6.25, 1.25), (2.25, 1.25), (9.75, 1.25), (12.25, 3.25),
              (11.25, 3.25), (12.25, 1.25), (5.25, 1.25), (10.75, 1.25), (3.75, 1.25), (3.25, 4.75), (5.75, 3.25),
              (16.75, 2.25), (10.25, 3.25)]
    radius = 0.5 ** 1.5
    robots = [RobotSpec(f"p{k}", radius, 0.8, p, p) for k, p in enumerate(parked)]
    robots.append(RobotSpec("d", radius, 0.8, (2.75, 2.75), (7.25, 5.75)))
    fleet = BehaviorFleet(grid, robots, BehaviorParams())
    for r in robots:
        fleet.assign(r.id, r.goal)
    fleet.controller("d")._set_path(np.array([[6.25, 2.25], [16.75, 3.75], [16.25, 5.75], [7.25, 5.75]]))
    return fleet


def test_a_robot_escaping_from_robots_it_cannot_pass_keeps_out_of_them_on_its_way_back(monkeypatch):
    """d's Avoid switches between the two rows (the robot closest in its critical area changes as
    it steps aside), it makes no progress and escapes west; its way back, planned out of range of
    the rows, runs through them as before: control, 9 escapes in 300 s and d never arrives. Ours
    (``BehaviorController._escape_for_no_progress``): escaping, it remembers the robots standing
    in range, and its way back keeps out of them: straight through the middle of the two rows."""
    from fleet_planner.behavior.controller import BehaviorController

    fleet = _between_two_rows_of_parked_robots()
    assert _drive(fleet, limit_s=150.0) >= 0.0   # checks the walls at every step
    assert fleet.arrived("d") and fleet.controller("d").escapes >= 1
    monkeypatch.setattr(BehaviorController, "_escape_for_no_progress",
                        lambda self, sensed: self._escape_or_step_out(sensed))
    control = _between_two_rows_of_parked_robots()
    _drive(control, limit_s=300.0)
    assert not control.arrived("d") and control.controller("d").escapes >= 5
