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


def heard(stamp, lease_s=1.5, legs=None, rid="me"):
    return Heard(stamp=stamp, lease_s=lease_s, robots={rid: stamp}, legs=None if legs is None else {rid: legs})


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
    last = []

    def planner_hears(t, st):   # every 0.5 s the planner says it heard the latest status
        last.append(st.stamp)
        if round(t * 10) % 5 == 0:
            a.on_heard(heard(last[-1], legs=10), t)

    run(a, 0.0, 3.0, planner_hears)
    heard_at = a.lease.heard
    assert heard_at == pytest.approx(3.0) and a.model.speed > 0.9
    sts = run(a, 3.0, 9.0)   # the planner hears it no more: nothing renews its lease
    speeds = [s.vx for s in sts]
    assert all(b >= a_ - CARGO.max_accel * 0.1 - 1e-9 for a_, b in zip(speeds, speeds[1:]))  # brakes at <= max_accel
    stopped = next(s.stamp for s in sts if s.vx == 0.0)
    assert heard_at + 1.5 < stopped <= heard_at + 1.5 + braking_s(CARGO) + 0.2
    assert sts[-1].vx == 0.0 and sts[-1].x == sts[-10].x and a.lease.stopped
    x = sts[-1].x
    a.on_heard(heard(9.0, legs=None), 9.0)   # heard again, but its leg is no longer kept: it stays
    assert run(a, 9.0, 10.0)[-1].x == x
    a.on_heard(heard(10.0, legs=10), 10.0)   # heard on its leg: it drives on
    assert run(a, 10.0, 12.0, planner_hears)[-1].x > x + 0.5 and not a.lease.stopped
    # control: the same agent never named by a planner (no lease) drives on unheard
    b = agent_on_a_leg()
    assert run(b, 0.0, 9.0)[-1].x > 10.0


def test_a_stopped_agent_drives_on_a_new_leg_and_a_heard_record_from_the_future_is_refused():
    a = agent_on_a_leg()
    a.on_heard(heard(0.0, legs=10), 0.0)
    run(a, 0.0, 4.0)
    assert a.lease.stopped
    x = a.model.x
    a.on_heard(heard(4.0, legs=11), 4.0)   # the planner keeps a new leg for it (a hold), not the old one
    assert run(a, 4.0, 5.0)[-1].x == x
    a.on_path(TimedPath("me", R, np.array([[x, 6.25, 0.0], [x + 3.0, 6.25, 3.0]])), 5.0, 11)

    def planner_hears(t, st):
        a.on_heard(heard(st.stamp, legs=11), t)

    assert run(a, 5.0, 8.5, planner_hears)[-1].x > x + 2.0
    with pytest.raises(ValueError, match=r"heard.robots.me: stamped 100 s ahead"):
        a.on_heard(heard(108.5), 8.5)
    assert a.lease.heard == pytest.approx(8.5)   # (unchanged by it)


def test_heard_records_are_checked_field_by_field():
    with pytest.raises(RecordError, match=r"heard.lease_s"):
        Heard.from_json('{"schema": "fleet/heard@1", "stamp": 1, "lease_s": -1, "robots": {}}')
    with pytest.raises(RecordError, match=r"heard.robots\['r1'\]"):
        Heard.from_json('{"schema": "fleet/heard@1", "stamp": 1, "lease_s": 1, "robots": {"r1": null}}')
    with pytest.raises(RecordError, match=r"heard.legs.r2: a leg kept for a robot not heard"):
        Heard.from_json('{"schema": "fleet/heard@1", "stamp": 1, "lease_s": 1, "robots": {"r1": 0.5}, '
                        '"legs": {"r2": 3}}')
    lease = Lease("r1")
    lease.on_heard(Heard(stamp=1.0, lease_s=1.0, robots={"r2": 1.0}))   # another robot's: no lease for r1
    assert not lease.holds(100.0, None)


# -- the planner's end --------------------------------------------------------------------------------
AISLE_Y = 6.25


def _scene(monkeypatch, reserve=True):
    """r1 drives east along the aisle at y = 6.25 and is last heard at t = 3 (x ~ 5); r2 stands north
    of the aisle at (7.5, 3.5). Returns the manager, r1's leg and r1's last status."""
    if not reserve:   # the control: the planner as it was (an unheard robot is an obstacle where last heard)
        monkeypatch.setattr(MANAGER, "stopped_by", lambda r, lease_s: -math.inf)
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
    """r1 is marked offline at t ~ 6 (3 s silent) but may drive on until its lease (1.5 s), its braking
    (2 s) and the slack (0.5 s) have surely run out: until t = 7 its leg is kept and the others' links on
    it hold; r2, sent across the aisle, either keeps off every point r1 could reach or waits for r1 before
    it; after t = 7 r1 is an obstacle on that whole stretch and r2's legs keep off it. The control (the
    planner as it was: an obstacle at its last heard point at once) sends r2 through the stretch."""
    fm, leg = _scene(monkeypatch, reserve)
    r1, r2 = fm.robots["r1"], fm.robots["r2"]
    until = r1.status.stamp + fm.params.lease + braking_s(CARGO) + 0.5
    could = reachable(r1, {leg.path_id: leg.path}, until)   # where r1 may be by then, unheard
    assert np.ptp(could[:, 0]) > 3.0                          # (a stretch of the aisle, not a point)
    clear = 2 * R
    sent = []
    r2.target, r2.replan = Target("park", "south", (7.5, 9.5)), True
    for k in range(61, 120):
        t = k * 0.1
        fm.on_status(status("r2", "cargo", 7.5, 3.5, stamp=t), t)
        if k % 5 == 0:
            d = fm.step(t)
            sent += [(t, lg) for lg in d.legs if lg.robot_id == "r2"]
            for lg in d.legs:   # r2 takes each leg at once (it stands at its start)
                if lg.robot_id == "r2":
                    r2.status = status("r2", "cargo", 7.5, 3.5, stamp=t, path_id=lg.path_id, progress=0.0,
                                       travelled_m=0.0)
    assert sent, "r2 got no leg"
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
    rec = heard_record(fm.robots.values(), 1.0, fm.params.lease)
    assert rec.robots == {"r1": 0.123} and rec.legs is None and rec.lease_s == 1.0
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
    a.on_heard(heard(1.0, legs=10), 1.0)
    sts = run(a, 0.0, 2.5)
    assert 1.3 < sts[-1].travelled_m < 1.6 and a.model.speed > 0.9 and not a.lease.stopped   # not yet run out
    sts = run(a, 2.5, 7.0)
    assert a.lease.stopped and sts[-1].vx == 0.0
    assert max(s.travelled_m for s in sts) <= 2.0 + 1e-6
