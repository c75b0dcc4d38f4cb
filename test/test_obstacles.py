"""Obstacles from the intelligent space (issue 12, deliverable 1), without ROS: the ``fleet/obstacle@1``
record, the obstacle map (supersede, clear, expire, predict), the planner planning legs around a
predicted person, the manager re-planning or holding legs an obstacle threatens, the agents' safety
net, and whole simulated runs with a person crossing in front of robots and a pallet dropped in an
aisle: no contact with the person or between robots (the independent checker on the driven tracks),
every job done."""
import json

import numpy as np
import pytest
from test_dispatch import CHARGERS, FAST, WH, Sim, status, task

from fleet_planner.checker import min_separation
from fleet_planner.fleet import RobotAgent, samples_to_path
from fleet_planner.fleet.obstacles import PREFIX, ObstacleMap, ObstacleParams
from fleet_planner.fleet.people import Walker, random_people
from fleet_planner.model import RobotSpec, TimedPath
from fleet_planner.planners import get_planner
from fleet_planner.robots import RobotModel
from msg_schemas.records import ObstacleRecord, RecordError


def person(oid="p1", x=8.0, y=3.5, vx=0.0, vy=0.0, stamp=0.0, **extra):
    return ObstacleRecord(id=oid, kind="person", x=x, y=y, vx=vx, vy=vy, radius=0.3, stamp=stamp, **extra)


# -- the record --------------------------------------------------------------------------------------
def test_an_obstacle_record_round_trips_and_bad_fields_are_named():
    ob = person(vx=1.0, persistent=False)
    assert ObstacleRecord.from_json(ob.to_json()) == ob
    good = json.loads(ob.to_json())
    for key, value, words in [("radius", -0.5, "obstacle.radius: must be > 0 (got -0.5)"),
                              ("radius", 0, "obstacle.radius"), ("x", float("nan"), "obstacle.x"),
                              ("kind", "ghost", "obstacle.kind"), ("vx", 400.0, "obstacle.vx"),
                              ("stamp", True, "obstacle.stamp"), ("colour", "red", "obstacle.colour: unknown field")]:
        with pytest.raises(RecordError, match="^" + words.replace("(", r"\(").replace(")", r"\)")):
            ObstacleRecord.from_json(json.dumps({**good, key: value}))
    with pytest.raises(RecordError, match="^obstacle.vx: speed"):
        ObstacleRecord.from_dict({**good, "vx": 15.0, "vy": 15.0})  # each within bounds, together too fast


# -- the map ----------------------------------------------------------------------------------------
def test_records_supersede_by_id_and_clear_and_stale_ones_expire_but_persistent_ones_stay():
    obs = ObstacleMap(ObstacleParams(stale_s=1.0))
    assert "obstacle p1 (person" in obs.update(person(stamp=1.0), now=1.0)
    assert obs.update(person(x=9.0, stamp=1.5), now=1.5) is None       # an update
    assert obs.update(person(x=2.0, stamp=1.2), now=1.6) is None       # older: ignored
    assert obs.obstacles["p1"].x == 9.0
    pallet = ObstacleRecord(id="pal", kind="pallet", x=4.0, y=6.0, radius=0.6, stamp=1.0, persistent=True)
    obs.update(pallet, now=1.0)
    with pytest.raises(ValueError, match="obstacle.stamp"):
        obs.update(person("p2", stamp=10.0), now=1.0)                 # stamped ahead of the clock
    assert [o.id for o in obs.expire(now=2.0)] == []
    assert [o.id for o in obs.expire(now=2.6)] == ["p1"]               # no record for 1.1 s
    assert list(obs.obstacles) == ["pal"]
    assert [o.id for o in obs.expire(now=500.0)] == []                 # a pallet stays until cleared
    assert "cleared" in obs.update(ObstacleRecord(id="pal", kind="pallet", x=4.0, y=6.0, radius=0.6, stamp=501.0,
                                                  cleared=True), now=501.0)
    assert [o.id for o in obs.expire(now=501.0)] == ["pal"] and len(obs) == 0


def test_a_moving_obstacle_is_predicted_at_constant_velocity_with_a_growing_disc():
    obs = ObstacleMap(ObstacleParams(horizon_s=4.0, growth=0.1))
    obs.update(person(x=1.0, y=3.0, vx=1.0, stamp=10.0), now=10.5)
    obs.update(ObstacleRecord(id="pal", kind="pallet", x=4.0, y=6.0, radius=0.6, stamp=10.0), now=10.5)
    walk, pallet = obs.trajectories(now=10.5)
    assert walk.robot_id == PREFIX + "p1" and pallet.robot_id == PREFIX + "pal"
    np.testing.assert_allclose(walk.waypoints, [[1.5, 3.0, 10.5], [5.5, 3.0, 14.5]])
    assert walk.radius == pytest.approx(0.3 + 0.1 * 4.5)   # the disc at the horizon, 4.5 s after the record
    np.testing.assert_allclose(pallet.waypoints, [[4.0, 6.0, 10.5]])
    assert pallet.radius == 0.6


def test_a_leg_is_threatened_when_it_meets_the_predicted_disc_not_when_it_passes_after_it():
    obs = ObstacleMap(ObstacleParams(horizon_s=4.0, growth=0.1))
    obs.update(person(x=4.0, y=3.5, vx=1.0, stamp=0.0), now=0.0)   # walks east along y = 3.5
    # a robot going north across y = 3.5 at x = 6, there at t = 2 when the person is too
    crossing = TimedPath("r1", 0.35, np.array([[6.0, 5.5, 0.0], [6.0, 1.5, 4.0]]))
    # the same crossing 6 s later: the person passed long ago (and beyond the horizon, it is not predicted)
    later = TimedPath("r2", 0.35, np.array([[6.0, 5.5, 6.0], [6.0, 1.5, 10.0]]))
    # a robot going west on y = 5.5, always 2 m from the person's line
    beside = TimedPath("r3", 0.35, np.array([[14.0, 5.5, 0.0], [2.0, 5.5, 12.0]]))
    assert obs.threats([("r1", crossing, 0.35), ("r2", later, 0.35), ("r3", beside, 0.35)], 0.0, 0.2) == {"r1": "p1"}
    assert obs.take_affected("p1") == {"r1"}
    # a static obstacle threatens every leg that passes near it, whenever
    obs.update(ObstacleRecord(id="pal", kind="pallet", x=6.0, y=7.5, radius=0.5, stamp=0.0, persistent=True), 0.0)
    far_later = TimedPath("r4", 0.35, np.array([[6.0, 5.5, 50.0], [6.0, 9.5, 54.0]]))
    assert obs.threats([("r4", far_later, 0.35)], 0.0, 0.2) == {"r4": "pal"}


def test_the_planner_plans_a_leg_around_a_predicted_person_as_a_participant_above_the_robot():
    """The md planner gets the person as a fixed trajectory: the robot's leg keeps the sum of radii
    plus the margin from the predicted disc at every instant (the independent checker measures)."""
    obs = ObstacleMap(ObstacleParams(horizon_s=6.0, growth=0.05))
    obs.update(person(x=4.0, y=3.5, vx=1.0, stamp=0.0), now=0.0)
    [walk] = obs.trajectories(now=0.0)
    planner = get_planner("md", margin=0.1)
    spec = RobotSpec("r1", 0.35, 1.0, (6.75, 6.25), (6.75, 1.75))   # straight north across the person's line
    [leg] = planner.plan_incremental(WH.grid, [spec], [walk], 0.0)
    gap, *_ = min_separation([leg, walk])
    assert gap >= 0.1 - 1e-6
    alone = planner.plan_incremental(WH.grid, [spec], [], 0.0)[0]
    assert min_separation([alone, walk])[0] < 0.0   # planned without the person, it would walk into it
    assert leg.arrival_time > alone.arrival_time    # it gave way: delayed (or re-routed)


# -- the agents' safety net -------------------------------------------------------------------------
def test_an_agent_stops_for_a_person_in_its_critical_area_and_drives_on_when_the_way_is_clear():
    agent = RobotAgent(RobotModel("r1", FAST["cargo"], 2.0, 6.25, chargers=CHARGERS), WH)
    leg = TimedPath("r1", 0.35, np.array([[2.0, 6.25, 0.0], [14.0, 6.25, 12.0]]))
    agent.on_path(leg, 0.0, 0)
    t = 0.0
    for _ in range(20):   # 2 s of driving: about 0.75 m with its ramp
        t = round(t + 0.1, 9)
        agent.tick(t)
    x_before = agent.model.x
    agent.on_obstacle(person(x=x_before + 0.35 + 0.3 + 0.05, y=6.25, stamp=t), t)   # just ahead of it
    for _ in range(10):
        t = round(t + 0.1, 9)
        agent.on_obstacle(person(x=x_before + 0.7, y=6.25, stamp=t), t)
        agent.tick(t)
    assert agent.waits_for == PREFIX + "p1"
    assert agent.model.x - x_before < 0.1 and agent.model.speed == pytest.approx(0.0, abs=1e-9)
    for _ in range(30):   # nothing heard of the person: it expires, the robot drives on
        t = round(t + 0.1, 9)
        agent.tick(t)
    assert agent.waits_for is None and agent.model.x > x_before + 0.3


# -- whole runs ---------------------------------------------------------------------------------------
class PeopleSim(Sim):
    """The manager and agents of ``Sim`` with people walking: each tick every walker steps, and its
    record goes to the manager and to every agent (the intelligent space sees them all)."""

    def __init__(self, fleet, people, **params):
        super().__init__(fleet, **params)
        self.people = people
        self.people_track = {w.id: [] for w in people}
        self.statics: list[ObstacleRecord] = []

    def _tick(self):
        t = round((self._ticks + 1) * self.dt, 9)
        robots = [(a.model.x, a.model.y, a.model.kind.radius, a.model.speed) for a in self.agents.values()]
        for w in self.people:
            w.step(self.t, t - self.t, robots)
            if w.present:
                self.people_track[w.id].append((w.x, w.y, t))
        for rec in [w.record(t) for w in self.people if w.present] + self.statics:
            self.fm.on_obstacle(rec, t)
            for a in self.agents.values():
                a.on_obstacle(rec, t)
        self.statics = []
        super()._tick()

    def tracks(self):
        people = [samples_to_path(pid, w.radius, self.people_track[pid]) for pid, w in
                  zip(self.people_track, self.people) if self.people_track[pid]]
        return self.driven(), people


def closest(robots, people):
    """Smallest gap between two robots, and between a robot and a person (the checker on driven tracks)."""
    between, *who = min_separation(robots)
    near = min((min_separation([r, p])[0] for r in robots for p in people), default=np.inf)
    return between, near, who


JOBS = [task("X1", "chute_1", "B02-01"), task("X2", "chute_2", "B01-01"),
        task("X3", "chute_1", "B01-02"), task("X4", "chute_2", "B02-02")]


def four_on_chargers():
    names = ["cargo", "manipulator", "cargo_forklift", "manipulator_forklift"]
    return [(f"r{i + 1}", k, *CHARGERS[i], 0.9) for i, k in enumerate(names)]


CROSSING = [((0.75, 3.5), (15.25, 3.5), 6.0), ((15.25, 3.75), (0.75, 3.75), 24.0)]


def crossers():
    """Two people crossing the open area in front of the chutes once each (west to east, then east
    to west), never stopping for a robot: robots going to or from a chute cross their way."""
    return [Walker(f"p{i + 1}", np.array([a, b]), speed=1.0, yields=False, once=True, start_s=t0)
            for i, (a, b, t0) in enumerate(CROSSING)]


def test_robots_give_way_to_blind_people_walking_across_their_way_and_do_every_job():
    """The planner plans around the people's predictions and re-plans or holds the legs they
    threaten; the safety net stops for them."""
    sim = PeopleSim(four_on_chargers(), crossers())
    sim.submit(*JOBS)
    assert sim.run_until(lambda: all(sim.last(j.id) == "done" for j in JOBS), limit=900)
    robots, people = sim.tracks()
    between, near, who = closest(robots, people)
    assert between >= 0.0, who
    assert near >= 0.0, f"a robot touched the person ({near:.3f} m)"
    assert any("re-plans around obstacle p" in n for n in sim.notes)
    assert all(w.gone for w in sim.people)


def test_a_dropped_pallet_blocks_its_cells_until_cleared_and_legs_re_plan_round_it():
    sim = PeopleSim([("r1", "cargo", *CHARGERS[0], 0.9)], [])
    sim.submit(task("P1", "chute_2", "B04-01"))
    assert sim.run_until(lambda: sim.agents["r1"].model.speed > 0.3)
    leg = sim.fm.robots["r1"].leg.path
    # a pallet falls on the robot's way, ahead of it in the middle of its leg
    x, y = leg.position(leg.start_time + 0.5 * (leg.arrival_time - leg.start_time))
    pallet = ObstacleRecord(id="pal", kind="pallet", x=float(x), y=float(y), radius=0.4, stamp=sim.t, persistent=True)
    sim.statics = [pallet]
    assert sim.run_until(lambda: any("re-plans around obstacle pal" in n for n in sim.notes), limit=5)
    assert sim.run_until(lambda: sim.last("P1") == "done", limit=400)
    robots, _ = sim.tracks()
    parked = TimedPath("pal", 0.4, np.array([[x, y, 0.0]]))
    gap, *_ = min_separation([robots[0], parked])
    assert gap >= 0.0, f"the robot drove into the pallet ({gap:.3f} m)"
    assert len(sim.fm.obstacles) == 1          # persistent: still there
    sim.statics = [ObstacleRecord(id="pal", kind="pallet", x=float(x), y=float(y), radius=0.4, stamp=sim.t,
                                  cleared=True)]
    assert sim.run_until(lambda: len(sim.fm.obstacles) == 0, limit=2)


def test_yielding_random_walkers_and_a_fleet_share_the_warehouse_without_contact():
    people = random_people(WH.grid, 2, seed=3, avoid=CHARGERS)
    sim = PeopleSim(four_on_chargers(), people)
    sim.submit(*JOBS)
    assert sim.run_until(lambda: all(sim.last(j.id) == "done" for j in JOBS), limit=900)
    robots, tracks = sim.tracks()
    between, near, who = closest(robots, tracks)
    assert between >= 0.0 and near >= 0.0, (between, near, who)
    assert all(len({(round(x, 1), round(y, 1)) for x, y, _ in sim.people_track[w.id]}) > 20 for w in people)


def test_a_status_of_a_robot_near_an_obstacle_still_counts_and_bad_stamps_are_refused():
    from fleet_planner.fleet import FleetManager

    fm = FleetManager(WH, FAST)
    fm.on_status(status("r1", "cargo", *CHARGERS[0]), 0.0)
    with pytest.raises(ValueError, match="obstacle.stamp"):
        fm.on_obstacle(person(stamp=100.0), 0.0)
    fm.on_obstacle(person(stamp=0.0), 0.0)
    d = fm.step(0.5)
    assert any("obstacle p1 (person" in n for n in d.notes)


@pytest.mark.parametrize("at", [(2.0, 3.5), (4.0, 4.0), (8.0, 3.0), (10.0, 4.0)])
def test_a_standing_robot_steps_aside_from_a_blind_person_walking_at_it(at, monkeypatch):
    """A robot standing (idle, no job) on a person's way: the person, blind to robots that move and
    stopping only for one that stands, would stop in front of it for good; the robot steps aside to
    a refuge off the person's way (not across it) and the person walks the whole width. Control:
    without the step aside the person is stopped."""
    def run():
        walker = Walker("p2", np.array([(15.25, 3.75), (0.75, 3.75)]), speed=1.0, yields=False, once=True,
                        start_s=1.0)
        sim = PeopleSim([("r2", "manipulator", *at, 0.9)], [walker], idle_s=3600.0)
        assert sim.run_until(lambda: walker.gone, limit=60)
        robots, people = sim.tracks()
        xs = [x for x, _, _ in sim.people_track["p2"]]
        return sim, min_separation([robots[0], people[0]])[0], max(xs) - min(xs)

    sim, gap, walked = run()
    assert gap >= 0.0 and walked > 14.0, (gap, walked)
    steps = [n for n in sim.notes if "r2 steps aside from obstacle p2" in n]
    assert len(steps) == 1, sim.notes
    x, y = (float(v) for v in steps[0].split(" to (")[1].rstrip(")").split(", "))
    assert (y - 3.75) * (at[1] - 3.75) > 0.0       # on its own side of the person's way
    assert abs(y - 3.75) >= 0.3 + 0.3 + 0.4         # the person's grown disc plus its own radius
    from fleet_planner.fleet.manager import FleetManager
    monkeypatch.setattr(FleetManager, "_evade", lambda *args: False)
    _, gap, walked = run()
    assert gap >= 0.0 and walked < 14.0, (gap, walked)   # stopped in front of the robot
