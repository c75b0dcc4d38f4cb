"""The fleet manager and the robot agent, without ROS: task checks, allocation, charging, parking,
offline handover, late robots, and a short simulated run whose legs and driven positions keep every
pair of robots apart (the independent checker is the oracle)."""
import importlib
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from fleet_planner.checker import min_separation
from fleet_planner.fleet import (
    DispatchParams,
    FleetError,
    FleetManager,
    RobotAgent,
    lag_allowance,
    load_fleet,
    samples_to_path,
)
from fleet_planner.fleet.dispatch import LEGACY
from fleet_planner.fleet.jobstore import RESENT
from fleet_planner.fleet.state import Target
from fleet_planner.grid import GridMap
from fleet_planner.model import TimedPath
from fleet_planner.robots import RobotModel, load_kinds
from fleet_planner.warehouse import Station, Warehouse, generate_warehouse, load_warehouse
from msg_schemas.records import RobotStatus, Task, TaskEvent

KINDS = load_kinds()
#: the shipped kinds with short picks and places, so that simulated runs stay short
FAST = {name: replace(k, pick_s=2.0, place_s=2.0, lift_s=1.0 if k.lift_s else 0.0) for name, k in KINDS.items()}
WH = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)  # 16 m x 13 m
PARKING = [(10.75, 11.75), (12.75, 11.75), (14.75, 11.75)]  # along the south wall, right of the chargers
CHARGERS = [s.pose for s in WH.stations_of("charger")]


def status(rid, kind, x, y, *, battery=1.0, mode="idle", stamp=0.0, path_id=None, progress=1.0, **extra):
    return RobotStatus(id=rid, kind=kind, x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, battery=battery, mode=mode,
                       progress=progress, stamp=stamp, radius=KINDS[kind].radius, path_id=path_id, **extra)


def task(tid="J1", pick="chute_1", place="B01-01", **fields):
    return Task(id=tid, pick=pick, place=place, **fields)


def manager(wh=WH, parking=PARKING, **params):
    return FleetManager(wh, FAST, DispatchParams(**params), parking)


MANAGER = importlib.import_module("fleet_planner.fleet.manager")   # (the package's name ``manager`` is another)


class Sim:
    """A fleet manager and robot agents on one simulated clock: statuses, legs and events are
    delivered at once. Agents step every ``dt``, the manager every ``period``."""

    def __init__(self, fleet, wh=WH, parking=PARKING, kinds=FAST, dt=0.1, period=0.5, **params):
        self.wh, self.dt, self.period = wh, dt, period
        self.fm = FleetManager(wh, kinds, DispatchParams(**params), parking)
        chargers = [s.pose for s in wh.stations_of("charger")]
        self.agents = {rid: RobotAgent(RobotModel(rid, kinds[k], x, y, battery=b, chargers=chargers), wh)
                       for rid, k, x, y, b in fleet}
        self.dead: set[str] = set()   # agents that stopped: no ticks, nothing in or out
        self.mute: set[str] = set()   # agents cut off: they drive on, nothing in or out
        self.t = 0.0
        self.events, self.notes = [], []
        self.legs = {rid: [] for rid in self.agents}
        self.start = {rid: (a.model.x, a.model.y) for rid, a in self.agents.items()}
        self.track = {rid: [] for rid in self.agents}
        self._ticks = 0

    def submit(self, *tasks):
        out = []
        for tk in tasks:
            for a in self.agents.values():
                a.on_task(tk)
            out += self.fm.submit(tk, self.t)
        self.events += out
        self.fm.announced()
        return out

    def run_until(self, condition, limit=600.0):
        """Step until ``condition()`` holds; False if ``limit`` simulated seconds pass first."""
        end = self.t + limit
        while not condition():
            if self.t >= end:
                return False
            self._tick()
        return True

    def _tick(self):
        self._ticks += 1
        self.t = round(self._ticks * self.dt, 9)
        for rid, a in self.agents.items():
            if rid in self.dead:
                continue
            st = a.tick(self.t)
            self.track[rid].append((st.x, st.y, self.t))
            if rid not in self.mute:
                self.fm.on_status(st, self.t)
        if self._ticks % round(self.period / self.dt) == 0:
            self.deliver(self.step(self.t))

    def step(self, now):
        """One planning step (test_operator's sim steps the operator instead)."""
        return self.fm.step(now)

    def deliver(self, d):
        """Legs, events and notes of one decision, delivered at once."""
        self.notes += d.notes
        for leg in d.legs:
            self.legs[leg.robot_id].append(leg)
            if leg.robot_id not in self.dead | self.mute:
                self.agents[leg.robot_id].on_path(leg.relative(), leg.t0, leg.path_id)
        for ev in d.events:
            self.events.append(ev)
            for rid, a in self.agents.items():
                if rid not in self.dead | self.mute:
                    a.on_event(ev)
        self.fm.announced()   # (as the planner node after publishing them)

    def last(self, task_id):
        evs = [e for e in self.events if e.task_id == task_id]
        return evs[-1].event if evs else None

    def driven(self):
        """Every robot's simulated positions as timed paths."""
        return [samples_to_path(rid, self.agents[rid].model.kind.radius, tr) for rid, tr in self.track.items()]

    def planned(self):
        """Every robot's trajectory as the manager planned it: its legs one after the other, each
        until the next one starts, standing at its start before the first."""
        out = []
        for rid, legs in self.legs.items():
            wp = [[*self.start[rid], 0.0]]
            for k, leg in enumerate(legs):
                w = leg.path.waypoints
                nxt = legs[k + 1].t0 if k + 1 < len(legs) else math.inf
                wp += [list(p) for p in w[w[:, 2] < nxt]]
                if nxt < math.inf:
                    wp.append([*leg.path.position(nxt), nxt])
            out.append(TimedPath(rid, self.agents[rid].model.kind.radius, np.array(wp)))
        return out


def four_robots(battery=0.9):
    """One robot of each kind, on the four chargers."""
    names = ["cargo", "manipulator", "cargo_forklift", "manipulator_forklift"]
    return [(f"r{i + 1}", k, *CHARGERS[i], battery) for i, k in enumerate(names)]


# -- task checks -------------------------------------------------------------------------------------
@pytest.mark.parametrize("raw, words", [
    ('{"schema": "fleet/task@1", "id": "bad1", "pick": ', ["bad1", "not valid JSON"]),
    ('{"schema": "fleet/task@1", "id": "bad2", "pick": "chute_1", "place": "B01-01", "payload_kg": NaN}',
     ["bad2", "payload_kg", "NaN"]),
    (task("bad3", pick="chute_9").to_json(), ["bad3", "task.pick", "unknown station 'chute_9'"]),
    (task("bad4", pick="B01").to_json(), ["bad4", "'B01' is a storage, not a chute"]),
    (task("bad5", place="Z99-01").to_json(), ["bad5", "unknown address tag", "'Z99-01'"]),
    (task("bad6", payload_kg=5000).to_json(), ["bad6", "no robot can do it", "5000 kg"]),
    ('{"schema": "fleet/task@1", "id": "bad7", "pick": "chute_1", "place": "B01-01", "needs": ["wings"]}',
     ["bad7", "task.needs[0]", "wings"]),
    ("[1, 2]", ["?", "must be a JSON object"]),
])
def test_bad_tasks_are_rejected_naming_the_problem(raw, words):
    fm = manager()
    [ev] = fm.submit(raw, 3.0)
    assert ev.event == "rejected" and ev.stamp == 3.0
    for w in words:
        assert w in ev.task_id + " " + ev.reason
    assert fm.jobs == {}


def test_good_tasks_are_accepted_by_tag_or_site_and_a_known_id_gets_the_jobs_state():
    fm = manager()
    assert [e.event for e in fm.submit(task("J1", place="B02-03"), 0.0)] == ["accepted"]
    assert [e.event for e in fm.submit(json.dumps(task("J2", place="B04").to_dict()), 0.0)] == ["accepted"]
    [dup] = fm.submit(task("J1", pick="chute_2"), 1.0)  # (a copy, changed or not, is not a second job)
    assert (dup.event, dup.task_id, dup.stamp) == ("accepted", "J1", 1.0) and dup.reason.startswith(RESENT)
    assert len(fm.jobs) == 2
    assert fm.jobs["J1"].place.name == "B02" and fm.jobs["J2"].place.name == "B04"
    assert fm.jobs["J1"].pick.name == "chute_1"


# -- allocation ---------------------------------------------------------------------------------------
def allocate(robots, tk, **params):
    """Robots given as (id, kind, x, y, battery); returns the id of the robot assigned ``tk``."""
    fm = manager(**params)
    for rid, kind, x, y, battery in robots:
        fm.on_status(status(rid, kind, x, y, battery=battery), 0.0)
    fm.submit(tk, 0.0)
    d = fm.step(0.5)
    assigned = [e for e in d.events if e.event == "assigned"]
    if not assigned:
        return None
    [leg] = [leg for leg in d.legs if leg.robot_id == assigned[0].robot_id]
    assert leg.purpose == "pick" and tuple(leg.path.waypoints[-1, :2]) == WH.stations["chute_1"].pose
    return assigned[0].robot_id


def test_allocation_takes_the_nearest_robot_able_to_do_the_job():
    near, far = (6.25, 3.75), (14.25, 11.75)  # chute_1 is at (4.25, 2.25)
    robots = [("cargo", "cargo", *near, 1.0), ("fork", "cargo_forklift", *far, 1.0)]
    assert allocate(robots, task()) == "cargo"
    assert allocate(robots, task(needs=("forklift",))) == "fork"
    assert allocate(robots, task(payload_kg=150.0)) == "fork"  # a cargo carries 100 kg
    assert allocate(robots[:1], task(needs=("forklift",))) is None  # waits for a forklift


def test_allocation_skips_robots_low_on_battery_and_breaks_ties_by_battery():
    a, b = (2.25, 3.75), (6.25, 3.75)  # both 2.5 m from chute_1
    assert allocate([("a", "cargo", *a, 0.5), ("b", "cargo", *b, 0.9)], task()) == "b"
    assert allocate([("a", "cargo", *a, 0.2), ("b", "cargo", *(12.25, 6.25), 0.9)], task()) == "b"
    assert allocate([("a", "cargo", *a, 0.2)], task(), min_task_battery=0.3) is None


# -- charging and parking -------------------------------------------------------------------------------
def test_a_robot_low_on_battery_goes_to_the_nearest_free_charger():
    fm = manager()
    fm.on_status(status("r1", "cargo", 5.25, 9.25, battery=0.1), 0.0)
    fm.on_status(status("r2", "cargo", *CHARGERS[1]), 0.0)  # charger_2, the nearest, is taken
    d = fm.step(0.5)
    [leg] = d.legs
    assert (leg.robot_id, leg.purpose, leg.goal) == ("r1", "charge", "charger_3")


def test_a_charger_stays_with_the_robot_bound_for_it_while_it_has_no_leg_there():
    """A robot whose leg to a charger was refused (it stands; its new leg is not planned yet) keeps
    the charger: another robot is not sent there (late messages: the second parked on it and the
    first could never get a leg there, standing in others' way for good)."""
    fm = manager()
    fm.on_status(status("r1", "cargo", 5.25, 9.25, battery=0.1), 0.0)
    fm.on_status(status("r2", "cargo", 8.25, 9.25), 0.0)
    r2 = fm.robots["r2"]
    r2.target, r2.replan, r2.leg_retry_at = Target("charge", "charger_2", CHARGERS[1]), True, 10.0
    d = fm.step(0.5)
    [leg] = d.legs
    assert (leg.robot_id, leg.purpose) == ("r1", "charge")
    assert leg.goal != "charger_2"


def test_an_idle_robot_goes_charging_and_one_at_a_station_parks_when_no_charger_is_free():
    fm = manager(idle_s=5.0)
    fm.policy = LEGACY  # the old rule: idle robots charge (staging near the chutes: test_dispatch_policy.py)

    def report(t):
        for i, pose in enumerate(CHARGERS):
            fm.on_status(status(f"c{i}", "cargo", *pose, stamp=t), t)
        fm.on_status(status("idle", "cargo", *WH.stations["B01"].pose, stamp=t), t)
    report(0.0)
    assert fm.step(1.0).legs == []  # not idle long enough yet
    report(6.0)
    [leg] = fm.step(6.0).legs
    assert (leg.robot_id, leg.purpose) == ("idle", "park")
    assert tuple(leg.path.waypoints[-1, :2]) in PARKING


def test_an_agent_charges_at_a_charger_and_stops_when_sent_off():
    agent = RobotAgent(RobotModel("r1", FAST["cargo"], *CHARGERS[0], battery=0.5, chargers=CHARGERS), WH)
    agent.tick(0.0)
    assert agent.tick(10.0).mode == "charging"
    assert agent.model.battery > 0.5


def test_an_agent_picks_only_at_its_jobs_chute_and_places_only_where_the_tag_is():
    def agent_at(station, loaded=False):
        agent = RobotAgent(RobotModel("r1", FAST["cargo"], *WH.stations[station].pose), WH)
        agent.on_task(task("J1", pick="chute_1", place="B03-02"))
        agent.on_event(TaskEvent(task_id="J1", event="assigned", stamp=0.0, robot_id="r1"))
        agent.loaded = loaded
        return agent

    assert agent_at("chute_2").tick(0.0).mode == "idle"  # a chute, but not the job's
    picker = agent_at("chute_1")
    assert picker.tick(0.0).mode == "picking"
    assert picker.tick(5.0).mode == "idle" and picker.loaded
    assert agent_at("B01", loaded=True).tick(0.0).mode == "idle"  # a storing site without the tag
    placer = agent_at(WH.station_for_tag("B03-02").name, loaded=True)
    assert placer.tick(0.0).mode == "placing"
    done = placer.tick(5.0)
    assert done.mode == "idle" and done.task_id is None and not placer.loaded


def test_an_agent_drops_a_job_given_to_another_robot():
    agent = RobotAgent(RobotModel("r1", FAST["cargo"], *CHARGERS[0]), WH)
    agent.on_event(TaskEvent(task_id="J1", event="assigned", stamp=0.0, robot_id="r1"))
    assert agent.job == "J1"
    agent.on_event(TaskEvent(task_id="J1", event="assigned", stamp=1.0, robot_id="r2"))
    assert agent.job is None


# -- whole runs ------------------------------------------------------------------------------------------
JOBS = [task("J1", "chute_1", "B01-01"), task("J2", "chute_2", "B04-02", needs=("manipulator",)),
        task("J3", "chute_1", "B02-03", needs=("forklift",)), task("J4", "chute_2", "B03-04", payload_kg=200),
        task("J5", "chute_2", "B01-02", needs=("manipulator", "forklift")), task("J6", "chute_1", "B04-01")]


def test_a_short_run_does_every_job_and_no_two_robots_ever_touch():
    sim = Sim(four_robots())
    assert [e.event for e in sim.submit(*JOBS)] == ["accepted"] * len(JOBS)
    assert sim.run_until(lambda: all(sim.last(j.id) == "done" for j in JOBS), limit=900)
    for j in JOBS:  # the lifecycle, in order, by one robot that can do the job
        evs = [e for e in sim.events if e.task_id == j.id]
        assert [e.event for e in evs] == ["accepted", "assigned", "picked", "placed", "done"]
        robot = sim.agents[evs[1].robot_id].model.kind
        assert set(j.needs) <= robot.capabilities and j.payload_kg <= robot.payload_kg
    planned_gap, *who = min_separation(sim.planned())
    assert planned_gap >= sim.fm.margin - 1e-6, who
    driven_gap, *who = min_separation(sim.driven())
    assert driven_gap >= 0.0, who
    # the margin is what the robots' lag needs: more than the driven paths ever used of it
    assert sim.fm.margin == pytest.approx(2 * max(lag_allowance(k, 0.9) for k in FAST.values()) + 0.05)


def test_an_offline_robot_becomes_an_obstacle_and_its_job_goes_to_another_robot():
    sim = Sim(four_robots(), offline_timeout_s=2.0)
    sim.submit(task("J1", "chute_2", "B04-01"))
    assert sim.run_until(lambda: sim.last("J1") == "assigned")
    first = next(e.robot_id for e in sim.events if e.event == "assigned")
    assert sim.run_until(lambda: sim.agents[first].model.speed > 0)
    sim.dead.add(first)  # its agent dies on the way
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=400)
    owners = [e.robot_id for e in sim.events if e.task_id == "J1" and e.event == "assigned"]
    assert owners[0] == first and owners[-1] != first
    assert not sim.fm.robots[first].online
    assert any(f"robot {first} offline" in n for n in sim.notes)
    gap, *who = min_separation(sim.driven())  # the dead robot's track ends where it stopped
    assert gap >= 0.0, who


@pytest.mark.parametrize("deaf_factor", [MANAGER.DEAF_FACTOR, 0.0])
def test_a_planner_that_hears_no_robot_at_all_for_a_while_takes_nobody_offline(monkeypatch, deaf_factor):
    """Statuses of the whole fleet stop at once for twice the offline timeout (a starved planner, its
    network: the offline waves of the process-mode demo) and come back: nobody is offline, the note
    says why. Control (DEAF_FACTOR 0, the old rule): every robot goes offline. One robot silent among
    others' statuses is offline at the timeout either way (the test above); the whole fleet silent
    for longer than DEAF_FACTOR timeouts goes offline too."""
    monkeypatch.setattr(MANAGER, "DEAF_FACTOR", deaf_factor)
    sim = Sim(four_robots(), offline_timeout_s=2.0)
    assert sim.run_until(lambda: len(sim.fm.robots) == 4, limit=2)
    sim.mute.update(sim.agents)
    sim.run_until(lambda: False, limit=4.0)   # 2x the timeout, nobody heard
    sim.mute.clear()
    offline = sorted(rid for rid in sim.agents if any(n.startswith(f"robot {rid} offline") for n in sim.notes))
    if deaf_factor:
        assert offline == [] and any("the planner's input is late" in n for n in sim.notes)
        sim.mute.update(sim.agents)   # silent past DEAF_FACTOR timeouts: offline after all
        assert sim.run_until(lambda: not any(r.online for r in sim.fm.robots.values()), limit=7.0)
    else:
        assert offline == sorted(sim.agents)


def test_a_robot_heard_again_after_a_silence_is_stopped_where_it_is_and_serves_again():
    sim = Sim(four_robots(), offline_timeout_s=2.0)
    sim.submit(task("J1", "chute_2", "B04-01"))
    assert sim.run_until(lambda: sim.last("J1") == "assigned")
    first = next(e.robot_id for e in sim.events if e.event == "assigned")
    assert sim.run_until(lambda: sim.agents[first].model.speed > 0)
    sim.mute.add(first)  # it drives on, unheard
    assert sim.run_until(lambda: not sim.fm.robots[first].online)
    sim.mute.clear()
    assert sim.run_until(lambda: any(f"robot {first} is back online" in n for n in sim.notes))
    assert sim.run_until(lambda: sim.legs[first][-1].purpose == "hold")
    hold = sim.legs[first][-1]
    assert sim.run_until(lambda: sim.agents[first].model.path_id == hold.path_id, limit=5)
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=400)
    assert sim.fm.robots[first].online


def test_a_robot_late_on_its_schedule_re_plans_from_where_it_is():
    slow = dict(FAST, cargo=replace(FAST["cargo"], max_speed=0.25))  # the planner thinks 1 m/s
    sim = Sim([("r1", "cargo", *CHARGERS[0], 1.0)], lateness_tolerance_s=2.0)
    sim.agents["r1"] = RobotAgent(RobotModel("r1", slow["cargo"], *CHARGERS[0], chargers=CHARGERS), WH)
    sim.submit(task("J1", "chute_2", "B04-01"))
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=600)
    assert any("late: re-planning" in n for n in sim.notes)
    replans = [leg for leg in sim.legs["r1"] if leg.purpose in ("pick", "place")]
    assert len(replans) > 2  # more legs than the two of the job


@pytest.mark.parametrize("took", [4.0, 0.0])
def test_a_robot_that_took_its_leg_late_re_plans_only_once_later_than_that_by_the_tolerance(took):
    """A leg that reached its robot late (its first status on it says so) is not re-planned for that
    lateness, which the robot cannot make up (re-planned, the new leg reached it late again: under late
    messages robots spent their time halted between legs); only for lateness beyond it."""
    from fleet_planner.fleet.legs import Decisions, Leg
    fm = manager(lateness_tolerance_s=3.0)
    fm.on_status(status("r1", "cargo", 5.25, 9.25), 0.0)
    r = fm.robots["r1"]
    path = TimedPath("r1", r.radius, np.array([[5.25, 9.25, 1.0], [12.25, 9.25, 8.0]]))
    r.leg, r.target = Leg("r1", path, 1_000_000_000, "park", "x"), Target("park", "x", (12.25, 9.25))

    def late(s, stamp):
        fm.on_status(status("r1", "cargo", 5.5, 9.25, mode="driving", stamp=stamp, path_id=1_000_000_000,
                            progress=0.1, lateness_s=s), stamp)
        fm._find_late(Decisions())
        return r.replan
    assert not late(took, 1.0 + took) and not late(took + 2.5, 2.0 + took)
    assert late(5.0, 3.0 + took) == (took == 0.0)        # 5 s late: 2 s beyond the tolerance, 2 s within it
    assert late(took + 3.5, 4.0 + took)


def test_a_free_robot_blocking_the_only_way_is_sent_off_first():
    rows = ["@@@@@@@@@@@@@@@@@@@@@@@@",
            "@.........@@@@.........@",
            "@.........@@@@.........@",
            "@.........@@@@.........@",
            "@......................@",
            "@......................@",
            "@......................@",
            "@.........@@@@.........@",
            "@.........@@@@.........@",
            "@.........@@@@.........@",
            "@@@@@@@@@@@@@@@@@@@@@@@@"]  # two rooms joined by a corridor only one robot wide
    stations = [Station("chute_1", "chute", 10.25, 1.25), Station("B01", "storage", 10.25, 4.25, ("B01-01",)),
                Station("charger_1", "charger", 1.25, 1.25)]
    wh = Warehouse(GridMap.from_rows(rows, 0.5), {s.name: s for s in stations})
    sim = Sim([("arm", "manipulator", 2.75, 2.75, 1.0), ("plug", "cargo", 6.0, 2.75, 1.0)], wh=wh,
              parking=[(1.25, 4.25)], idle_s=3600.0)
    sim.submit(task("J1", needs=("manipulator",)))
    assert sim.run_until(lambda: sim.last("J1") == "done", limit=300)
    moves = [leg for leg in sim.legs["plug"]]
    assert moves and moves[0].purpose in ("charge", "park")  # it made way; it had nothing else to do
    assert min_separation(sim.driven())[0] >= 0.0


@pytest.mark.parametrize("gap", [0.15, 0.06])
def test_two_robots_stopped_within_the_margin_of_each_other_both_get_on_their_way(gap, monkeypatch):
    """Two robots, each with somewhere to go past the other, stand ``gap`` apart beyond the sum of
    radii, inside the planner's margin (0.23 m: as test_obstacles' walkers left two robots held
    with pipelined dispatch, 0.152 m; 0.06 m is where the safety net stops one). Each gets on its way
    and neither ever comes nearer to the other than it stood. Control: planned around with their full
    discs grown by the margin, neither ever gets a leg (each "parks on its goal in the way")."""
    from fleet_planner.fleet import coordination
    from fleet_planner.fleet.state import Target

    south, north = (9.48, 7.10), (8.68, 6.57)   # in the middle aisle, where the cross aisle meets it
    away = (north[0] - south[0], north[1] - south[1])
    scale = (KINDS["cargo"].radius + KINDS["manipulator_forklift"].radius + gap) / math.hypot(*away)
    north = (south[0] + away[0] * scale, south[1] + away[1] * scale)
    goals = {"s": Target("charge", "charger_4", CHARGERS[3]), "n": Target("park", "parking_1", (12.75, 3.0))}

    def run():
        sim = Sim([("s", "cargo", *south, 1.0), ("n", "manipulator_forklift", *north, 1.0)],
                  parking=[goals["n"].pose], idle_s=3600.0)
        sim.run_until(lambda: len(sim.fm.robots) == 2, limit=2)
        for rid, target in goals.items():
            sim.fm.robots[rid].target, sim.fm.robots[rid].replan = target, True
        arrived = sim.run_until(lambda: all(math.dist((sim.agents[r].model.x, sim.agents[r].model.y), g.pose) < 0.05
                                            for r, g in goals.items()), limit=60)
        return sim, arrived

    sim, arrived = run()
    assert arrived, sim.notes
    assert min_separation(sim.driven())[0] >= gap - 0.01
    monkeypatch.setattr(coordination, "room_to_leave", lambda other, *args: other)
    sim, arrived = run()
    assert not arrived and not any(sim.legs.values())
    assert any("parks on its goal in the way" in n for n in sim.notes)


def test_robots_waiting_for_legs_are_planned_in_turn_when_a_step_holds_one_leg(monkeypatch):
    """On a fast clock a step's planning budget holds about one leg. Three robots on their legs re-plan
    in vain at every step (nobody can get past; as robots held by their gates did) and a fourth stands
    with somewhere to go (after a leg it could not take): it gets its leg once each of them was tried.
    Control (manager.py of 3a29e8b: legs to storing sites first, then by id, a driving robot tried at
    every step whatever its back-off): the first of the three took every step and the fourth never got
    a leg (100 robots on large: all the others ended up waiting for it)."""
    from fleet_planner.fleet.state import Target
    from fleet_planner.model import PlanningError
    from fleet_planner.planners import get_planner

    clock = [0.0]   # wall time as the manager sees it: each leg planned takes 1 s, the step's budget 0.5 s

    class OneLegPerStep:
        def __init__(self, margin):
            self.md, self.refuse = get_planner("md", margin=margin), set()

        def plan_incremental(self, grid, robots, fixed, t0):
            clock[0] += 1.0
            if robots[0].id in self.refuse:
                raise PlanningError({robots[0].id: "blocked by x, which parks on its goal in the way"})
            return self.md.plan_incremental(grid, robots, fixed, t0)

    monkeypatch.setattr(MANAGER, "time", type("Clock", (), {"monotonic": staticmethod(lambda: clock[0])}))

    def run():
        fm = manager()
        fm.planner = OneLegPerStep(fm.margin)
        starts = {"a": (2.25, 6.5), "b": (5.25, 6.5), "c": (8.25, 6.5), "d": (13.25, 6.5)}
        for rid, (x, y) in starts.items():
            fm.on_status(status(rid, "cargo", x, y), 0.0)
        sites = {rid: WH.stations["B0" + str(k + 1)] for k, rid in enumerate("abc")}
        for rid, site in sites.items():
            fm.robots[rid].target, fm.robots[rid].replan = Target("place", site.name, site.pose), True
        t, legs = 0.0, {}
        while len(legs) < 3:   # each of them gets its leg to its storing site, one per step
            t += 0.5
            legs.update({leg.robot_id: leg for leg in fm.step(t).legs})
        fm.planner.refuse = set("abc")
        for rid, leg in legs.items():  # on their legs, late: they re-plan (and are refused at every step)
            fm.on_status(status(rid, "cargo", *starts[rid], mode="driving", path_id=leg.path_id, progress=0.3,
                                stamp=t), t)
            fm.robots[rid].replan = True
        fm.on_status(status("d", "cargo", *starts["d"], stamp=t), t)
        fm.robots["d"].target, fm.robots["d"].replan = Target("park", "parking_1", PARKING[0]), True
        tried = []   # who was refused at each step
        for _ in range(12):
            t += 0.5
            d = fm.step(t)
            if any(leg.robot_id == "d" for leg in d.legs):
                return tried
            tried.append({n.split()[1].rstrip(":") for n in d.notes if "no leg" in n})
            for rid, leg in legs.items():
                fm.on_status(status(rid, "cargo", *starts[rid], mode="driving", path_id=leg.path_id, progress=0.3,
                                    stamp=t), t)
            fm.on_status(status("d", "cargo", *starts["d"], stamp=t), t)
        return None

    assert run() == [{"a"}, {"b"}, {"c"}]   # each of them once, then the fourth gets its leg


@pytest.mark.parametrize("told", [True, False])
def test_on_a_fast_clock_a_standing_robots_leg_starts_after_its_step_can_have_reached_it(told):
    """On a clock 10x real time where a step takes 0.3 s of wall time, its legs reach the robots 3 s of
    clock time after the ``now`` they were planned at: a standing robot's leg starts that much later
    than ``lead_s`` (else it is 2 s late on arrival, re-plans as late, and its legs keep arriving late);
    the estimate fades with quicker steps. Control (the manager not told the pace): lead_s only."""
    fm = manager()
    fm.on_status(status("r1", "cargo", *CHARGERS[0]), 0.0)
    if told:
        fm.note_pace(10.0, 0.3)
    fm.submit(task("J1"), 0.0)
    [leg] = fm.step(0.5).legs
    lag = 3.0 if told else 0.0
    assert leg.path.waypoints[0, 2] == pytest.approx(0.5 + fm.params.lead_s + lag)
    if told:
        fm.note_pace(10.0, 0.01)
        assert fm.decision_lag_s == pytest.approx(2.7)


# -- fleet files ------------------------------------------------------------------------------------------
def test_the_shipped_demo_fleet_is_mixed_and_fits_the_default_warehouse():
    fleet = load_fleet(None, KINDS, load_warehouse())
    assert len(fleet) >= 8 and {m.kind for m in fleet} == set(KINDS)


@pytest.mark.parametrize("robots, expected", [
    ([{"id": "r1", "kind": "cargo", "x": 2.25}], "robots[0].y: missing"),
    ([{"id": "1r", "kind": "cargo", "x": 2.25, "y": 10.75}], "robots[0].id: must be letters"),
    ([{"id": "r1", "kind": "drone", "x": 2.25, "y": 10.75}], "robot 'r1'.kind: 'drone' is not one of"),
    ([{"id": "r1", "kind": "cargo", "x": 2.25, "y": 10.75, "battery": 2}], "robot 'r1'.battery: must be in [0, 1]"),
    ([{"id": "r1", "kind": "cargo", "x": 0.1, "y": 10.75}], "robot 'r1': (0.1, 10.75) is not free"),
    ([{"id": "r1", "kind": "cargo", "x": 2.25, "y": 10.75}, {"id": "r2", "kind": "cargo", "x": 2.5, "y": 10.75}],
     "robot 'r2': overlaps robot 'r1'"),
])
def test_a_bad_fleet_file_names_the_robot_and_field(tmp_path, robots, expected):
    path = tmp_path / "fleet.yaml"
    path.write_text(json.dumps({"robots": robots}))
    with pytest.raises(FleetError) as err:
        load_fleet(path, KINDS, WH)
    assert expected in str(err.value)
