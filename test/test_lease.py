"""Leases (fleet/lease.py): a robot the planner cannot hear stops, and the planner keeps its way
reserved until it must have stopped, then counts it as anywhere on the stretch it could reach."""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_dispatch import FAST, MANAGER, PARKING, WH, status

from fleet_planner.fleet import DispatchParams, FleetManager, RobotAgent
from fleet_planner.fleet.gate import links_of
from fleet_planner.fleet.lease import Lease, braking_s, heard_record, reachable
from fleet_planner.fleet.state import Target
from fleet_planner.geometry import polyline_passes_near
from fleet_planner.model import TimedPath
from fleet_planner.robots import RobotModel
from msg_schemas.records import Heard, RecordError

CARGO = FAST["cargo"]
R = CARGO.radius


def heard(now, mine=None, legs=None, rid="me", lease_s=1.5, silence_s=4.5):
    """The planner's record at ``now``: it took in ``rid``'s status stamped ``mine`` (default ``now``; False:
    left out) and another robot's stamped ``now``."""
    robots = {"other": now} if mine is False else {rid: now if mine is None else mine, "other": now}
    return Heard(stamp=now, lease_s=lease_s, silence_s=silence_s, robots=robots,
                 legs=None if legs is None or mine is False else {rid: legs})


# -- the robot's end ------------------------------------------------------------------------------------
def agent_on_a_leg():
    """An agent at (2, 6.25) on a 12 m leg east along the aisle at 1 m/s, from t = 0 (leg 10)."""
    a = RobotAgent(RobotModel("me", CARGO, 2.0, 6.25), WH)
    a.tick(0.0)
    a.on_path(TimedPath("me", R, np.array([[2.0, 6.25, 0.0], [14.0, 6.25, 12.0]])), 0.0, 10)
    return a


def run(a, t0, t1, echo=None, dt=0.1):
    """Tick ``a`` from t0 to t1; ``echo(t, status)`` is called after each tick (the planner's side)."""
    out = []
    for k in range(round(t0 / dt) + 1, round(t1 / dt) + 1):
        st = a.tick(k * dt)
        out.append(st)
        if echo is not None:
            echo(k * dt, st)
    return out


def test_an_agent_unheard_past_its_lease_brakes_to_a_stop_and_drives_on_once_heard_on_its_leg():
    a = agent_on_a_leg()
    last, cut = [], [math.inf]

    def planner(t, st):   # every 0.5 s the planner says whom it heard: this robot's statuses until cut[0]
        if st.stamp <= cut[0]:
            last.append(st.stamp)
        if round(t * 10) % 5 == 0:
            a.on_heard(heard(t, last[-1], legs=10), t)

    run(a, 0.0, 3.0, planner)
    assert a.lease.heard == pytest.approx(3.0) and a.model.speed > 0.9
    cut[0] = 3.0   # the planner hears it no more (it hears the other robot): its lease runs out at 4.5
    sts = run(a, 3.0, 9.0, planner)
    speeds = [s.vx for s in sts]
    assert all(b >= a_ - CARGO.max_accel * 0.1 - 1e-9 for a_, b in zip(speeds, speeds[1:]))  # brakes at <= max_accel
    stopped = next(s.stamp for s in sts if s.vx == 0.0)
    assert 3.0 + 1.5 < stopped <= 3.0 + 1.5 + 0.5 + braking_s(CARGO) + 0.2
    assert sts[-1].vx == 0.0 and sts[-1].x == sts[-10].x and a.lease.stopped
    x = sts[-1].x
    a.on_heard(heard(9.0, legs=None), 9.0)   # heard again, but its leg is no longer kept: it stays
    assert run(a, 9.0, 10.0)[-1].x == x
    cut[0] = math.inf   # heard on its leg: it drives on
    assert run(a, 10.0, 12.0, planner)[-1].x > x + 0.5 and not a.lease.stopped
    # control: the same agent never named by a planner (no lease) drives on unheard
    b = agent_on_a_leg()
    b.on_heard(heard(0.0, mine=False), 0.0)
    assert run(b, 0.0, 9.0)[-1].x > 10.0


def test_an_agent_that_hears_no_planner_for_its_silence_stops_and_one_the_planner_leaves_out_too():
    a = agent_on_a_leg()
    a.on_heard(heard(0.0, legs=10), 0.0)
    sts = run(a, 0.0, 8.0)   # no record after t = 0: it drives on up to its silence (4.5 s), then brakes
    moving = [s.stamp for s in sts if s.vx > 0.0]
    assert 4.5 < moving[-1] <= 4.5 + braking_s(CARGO) + 0.2 and a.lease.stopped
    b = agent_on_a_leg()
    b.on_heard(heard(0.0, legs=10), 0.0)
    run(b, 0.0, 1.0)
    b.on_heard(heard(1.0, mine=False), 1.0)   # marked offline: left out of the record
    assert run(b, 1.0, 1.2)[-1].vx < b.model.kind.max_speed and b.lease.stopped


def test_a_planner_whose_input_runs_late_for_every_robot_stops_nobody():
    """Its record names every robot 3 s stale against its clock (a loaded planner's input), but none more
    than the lease behind the newest: the robot drives on (measured against the clock, all stopped)."""
    a = agent_on_a_leg()
    for k in range(1, 41):
        t = k * 0.1
        a.tick(t)
        if k % 5 == 0:
            a.on_heard(Heard(stamp=t, lease_s=1.5, silence_s=4.5, robots={"me": t - 3.0, "other": t - 3.0},
                             legs={"me": 10}), t)
    assert not a.lease.stopped and a.model.speed > 0.9


def test_a_stopped_agent_drives_on_a_new_leg_and_a_heard_record_from_the_future_is_refused():
    a = agent_on_a_leg()
    a.on_heard(heard(0.0, legs=10), 0.0)
    run(a, 0.0, 7.0)
    assert a.lease.stopped
    x = a.model.x
    a.on_heard(heard(7.0, legs=11), 7.0)   # the planner keeps a new leg for it (a hold), not the old one
    assert run(a, 7.0, 8.0)[-1].x == x
    a.on_path(TimedPath("me", R, np.array([[x, 6.25, 0.0], [x + 3.0, 6.25, 3.0]])), 8.0, 11)

    def planner(t, st):
        a.on_heard(heard(t, st.stamp, legs=11), t)

    assert run(a, 8.0, 11.5, planner)[-1].x > x + 2.0
    with pytest.raises(ValueError, match=r"heard.robots.me: stamped 100 s ahead"):
        a.on_heard(heard(11.5, 111.5), 11.5)
    with pytest.raises(ValueError, match=r"heard.stamp: stamped 100 s ahead"):
        a.on_heard(heard(111.5, 11.5), 11.5)
    assert a.lease.heard == pytest.approx(11.5)   # (unchanged by them)


def test_heard_records_are_checked_field_by_field():
    with pytest.raises(RecordError, match=r"heard.lease_s"):
        Heard.from_json('{"schema": "fleet/heard@1", "stamp": 1, "lease_s": -1, "silence_s": 1, "robots": {}}')
    with pytest.raises(RecordError, match=r"heard.robots\['r1'\]"):
        Heard.from_json('{"schema": "fleet/heard@1", "stamp": 1, "lease_s": 1, "silence_s": 1, "robots": {"r1": null}}')
    with pytest.raises(RecordError, match=r"heard.legs.r2: a leg kept for a robot not heard"):
        Heard.from_json('{"schema": "fleet/heard@1", "stamp": 1, "lease_s": 1, "silence_s": 1, '
                        '"robots": {"r1": 0.5}, "legs": {"r2": 3}}')
    lease = Lease("r1")
    lease.on_heard(Heard(stamp=1.0, lease_s=1.0, silence_s=1.0, robots={"r2": 1.0}))   # not naming r1: no lease
    assert not lease.holds(100.0, None)


# -- the planner's end --------------------------------------------------------------------------------
AISLE_Y = 6.25


def _scene(monkeypatch, reserve=True):
    """r1 drives east along the aisle at y = 6.25 and is last heard at t = 3 (x ~ 5); r2 stands north
    of the aisle at (7.5, 3.5). Returns the manager, r1's leg and r1's last status."""
    if not reserve:   # the control: the planner as it was (an unheard robot is an obstacle where last heard)
        monkeypatch.setattr(MANAGER, "stopped_by", lambda r, now, silence_s: -math.inf)
    fm = FleetManager(WH, FAST, DispatchParams(idle_s=3600.0), PARKING)
    fm.on_status(status("r1", "cargo", 4.0, AISLE_Y), 0.0)
    fm.on_status(status("r2", "cargo", 7.5, 3.5), 0.0)
    r1 = fm.robots["r1"]
    r1.target, r1.replan = Target("park", "east", (14.5, AISLE_Y)), True
    d = fm.step(0.0)
    (leg,) = d.legs
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(leg.path.waypoints[:, :2], axis=0).T))])
    for k in range(1, 61):   # statuses every 0.1 s; r1 on its leg until t = 3, r2 throughout
        t = k * 0.1
        if t <= 3.0 + 1e-9:
            x, y = leg.path.position(t)
            s = float(np.interp(t, leg.path.waypoints[:, 2], arc))
            fm.on_status(status("r1", "cargo", x, y, stamp=t, path_id=leg.path_id, progress=s / arc[-1],
                                mode="driving", travelled_m=s), t)
        fm.on_status(status("r2", "cargo", 7.5, 3.5, stamp=t), t)
        if k % 5 == 0:
            fm.step(t)
            fm.heard(t)   # (as the node publishes them)
    return fm, leg


def _way_in(points, path: TimedPath, clear):
    """The first travelled length (m) along ``path`` at which its disc comes within ``clear`` of a point."""
    wp = path.waypoints
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(wp[:, :2], axis=0).T))])
    for s in np.arange(0.0, arc[-1], 0.02):
        p = (np.interp(s, arc, wp[:, 0]), np.interp(s, arc, wp[:, 1]))
        if np.min(np.hypot(points[:, 0] - p[0], points[:, 1] - p[1])) < clear:
            return float(s)
    return None


@pytest.mark.parametrize("reserve", [True, pytest.param(False, marks=pytest.mark.xfail(strict=True,
                                                                                       reason="control"))])
def test_the_planner_keeps_an_unheard_robots_way_until_it_must_have_stopped(monkeypatch, reserve):
    """r1 is marked offline at t ~ 6.5 (3 s silent) but may drive on until it must have stopped: the first
    heard record showing it unheard (t = 5) + its silence (9 s, had it missed every record since) + braking
    (2 s) + slack (0.5 s). Until then its leg is kept and the others' links on it hold: r2, sent across the
    aisle, either keeps off every point r1 could reach or waits for r1 before it; then r1 is an obstacle on
    that whole stretch and r2's legs keep off it. The control (the planner as it was: an obstacle at its
    last heard point at once) sends r2 through the stretch with no link on r1."""
    fm, leg = _scene(monkeypatch, reserve)
    r1, r2 = fm.robots["r1"], fm.robots["r2"]
    clear = 2 * R
    sent, until, could = [], None, None
    r2.target, r2.replan = Target("park", "south", (7.5, 9.5)), True
    for k in range(61, 260):
        t = k * 0.1
        fm.on_status(status("r2", "cargo", 7.5, 3.5, stamp=t), t)
        if k % 5 == 0:
            d = fm.step(t)
            fm.heard(t)
            if until is None and not r1.online:
                until = r1.unheard[0] if r1.unheard is not None else t
                # where r1 may be by then, unheard (the stretch as the planner reserves it)
                could = reachable(r1, {leg.path_id: leg.path}, r1.status.stamp + fm.params.lease + braking_s(CARGO))
                assert np.ptp(could[:, 0]) > 3.0   # (a stretch of the aisle, not a point)
            sent += [(t, lg) for lg in d.legs if lg.robot_id == "r2"]
            for lg in d.legs:   # r2 takes each leg at once (it stands at its start)
                if lg.robot_id == "r2":
                    r2.status = status("r2", "cargo", 7.5, 3.5, stamp=t, path_id=lg.path_id, progress=0.0,
                                       travelled_m=0.0)
    assert sent, "r2 got no leg"
    assert until is not None and could is not None
    for t, lg in sent:
        enters = _way_in(could, lg.path, clear)
        if enters is None:
            continue
        # it may pass only while r1's leg is kept, and only behind a link on r1 short of where it enters
        rec = fm.gates.records.get("r2") if fm.gates is not None else None
        assert t < until and rec is not None and rec.path_id == lg.path_id
        assert any(lk.robot == "r1" and lk.entry <= enters for lk in links_of(rec)), \
            f"r2's leg at t = {t:.1f} enters r1's reach at {enters:.2f} m with no link on r1"
    assert r1.immobile and r1.reach is not None and len(r1.reach) > 10
    assert all(not polyline_passes_near(lg.path.waypoints[:, :2], p, clear) for t, lg in sent if t >= until
               for p in r1.reach[::3])


def test_the_heard_record_names_the_online_robots_and_the_legs_kept_for_them():
    fm = FleetManager(WH, FAST, DispatchParams(offline_timeout_s=2.0), PARKING)
    fm.on_status(status("r1", "cargo", 2.0, AISLE_Y, stamp=0.12345), 0.2)
    fm.on_status(status("r2", "cargo", 7.5, 3.5), 0.0)
    fm.robots["r2"].online = False
    rec = heard_record(fm.robots.values(), 1.0, fm.params.lease, fm.params.silence)
    assert rec.robots == {"r1": 0.123} and rec.legs is None and (rec.lease_s, rec.silence_s) == (1.0, 6.0)
    assert fm.robots["r2"].stale_since == 1.0 and fm.robots["r1"].stale_since is None
    assert fm.heard(1.0) == rec


@pytest.mark.parametrize("net", [True, pytest.param(False, marks=pytest.mark.xfail(strict=True, reason="control"))])
def test_braking_never_takes_a_robot_past_where_its_gate_holds_it(monkeypatch, net):
    """Its lease runs out 0.5 m before the entry of a region it must wait at, at 1 m/s (1 m to stop):
    it holds at the entry as driving would. Control: braking by the model alone passes the entry."""
    from fleet_planner.fleet.coordination import CentralDriver, Driver
    from fleet_planner.fleet.gate import Link
    from msg_schemas.records import GateRecord
    if not net:
        monkeypatch.setattr(CentralDriver, "brake", Driver.brake)
    a = RobotAgent(RobotModel("me", CARGO, 2.0, 6.25), WH, gated=True)
    a.tick(0.0)
    a.on_gate(GateRecord(robot_id="me", path_id=10, seq=0, stamp=0.0, links=(Link("other", 5, 4.0, 2.0).to_dict(),),
                         watch={"other": 5}))
    a.on_path(TimedPath("me", R, np.array([[2.0, 6.25, 0.0], [14.0, 6.25, 12.0]])), 0.0, 10)
    a.on_heard(heard(0.0, legs=10), 0.0)
    sts = run(a, 0.0, 2.5)
    assert 1.3 < sts[-1].travelled_m < 1.6 and a.model.speed > 0.9 and not a.lease.stopped   # not yet run out
    a.on_heard(heard(2.5, 0.9, legs=10), 2.5)   # the planner says: last heard at 0.9 (the other at 2.5)
    sts = run(a, 2.5, 7.0)
    assert a.lease.stopped and sts[-1].vx == 0.0
    assert max(s.travelled_m for s in sts) <= 2.0 + 1e-6


def _unheard_before_a_crossing(o_stamp, o_travelled, third=False):
    """r drives east along y = 5 from x = 0 at 1 m/s; o, northbound across x = 10, passes the crossing first, so r's
    first record holds r short of it until o is out. r is last heard at 2 m (t = 2); the stretch it can have reached
    by t = 30 (its leg is due at 28 m), with o last heard at ``o_stamp`` ``o_travelled`` m along its way (late: by
    plan it left the crossing at t ~ 6). ``third``: q then gets a leg that crosses r's way at x = 16 first (r's
    record grows a link r may never have had; q is heard at t = 30 at its start)."""
    from fleet_planner.fleet.gate import GateBook
    from fleet_planner.fleet.state import FleetRobot

    def robot(rid, x, y):
        return FleetRobot(CARGO, status(rid, "cargo", x, y), 0.0, 0.0)

    def straight(rid, a, b, t0):
        return TimedPath(rid, R, np.array([[*a, t0], [*b, t0 + math.dist(a, b)]]))

    book, r, o, q = GateBook(), robot("r", 0.0, 5.0), robot("o", 10.0, 0.0), robot("q", 16.0, 9.0)
    book.on_leg(o, 1, straight("o", (10.0, 0.0), (10.0, 10.0), 0.0), [r, o, q], 0.0)
    path = straight("r", (0.0, 5.0), (30.0, 5.0), 0.0)
    book.on_leg(r, 2, path, [r, o, q], 0.0)
    entry = min(lk.entry for lk in links_of(book.records["r"]))
    if third:
        book.on_leg(q, 3, straight("q", (16.0, 9.0), (16.0, 1.0), 0.0), [r, o, q], 0.0)
        assert any(lk.robot == "q" for lk in links_of(book.records["r"]))
    r.status = status("r", "cargo", 2.0, 5.0, stamp=2.0, path_id=2, progress=0.1, travelled_m=2.0)
    o.status = status("o", "cargo", 10.0, o_travelled, stamp=o_stamp, path_id=1, progress=0.1, travelled_m=o_travelled)
    q.status = status("q", "cargo", 16.0, 9.0, stamp=30.0, path_id=3, progress=0.0, travelled_m=0.0)
    limits = book.reach_limits(r, [r, o, q], 30.0)
    return reachable(r, {2: path}, 30.0, limits), entry, limits


def test_an_unheard_robots_reserved_stretch_ends_where_its_gate_must_have_held_it():
    """An unheard robot's reserve (fleet/lease.py) ends at the entry where its gate holds it for a robot that cannot
    have left the region by the reserve's time (last heard short of the exit, too near it in time to get out at
    its top speed): it cannot have driven past (it was 26 m, the whole leg as due). Controls: with that robot last
    heard long before (it may be out by then) or beyond its exit, the stretch is the leg as due; a link the record
    only got later (it may never have reached the robot) does not cap it."""
    could, entry, limits = _unheard_before_a_crossing(29.9, 1.0)
    assert limits == {2: entry} and 6.0 < entry < 10.0
    assert could[:, 0].max() <= entry + 1e-9 and could[:, 0].max() > entry - 0.2
    for o_stamp, o_travelled in ((20.0, 1.0), (29.9, 9.0)):
        could, entry, limits = _unheard_before_a_crossing(o_stamp, o_travelled)
        assert limits == {} and could[:, 0].max() > 27.0
    could, entry, limits = _unheard_before_a_crossing(20.0, 1.0, third=True)   # (q's link came later: no cap)
    assert limits == {} and could[:, 0].max() > 27.0
