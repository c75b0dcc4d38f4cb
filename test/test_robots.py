"""Robot kinds and the simulated robot: schedule tracking, lateness, actions, battery."""
import math
from dataclasses import replace

import numpy as np
import pytest
import yaml

from fleet_planner.model import TimedPath, timed_path_from_polyline
from fleet_planner.robots import KINDS_FILE, KindsError, RobotModel, load_kinds
from fleet_planner.warehouse import config_path
from msg_schemas.records import RobotStatus

KINDS = load_kinds()
DT = 0.05


def kind(name="cargo", **changes):
    return replace(KINDS[name], **changes)


def run(robot, t_start, t_end, dt=DT):
    """Step the robot from t_start to t_end; yields the time after each step."""
    for n in range(round((t_end - t_start) / dt)):
        t = t_start + n * dt
        robot.step(t, dt)
        yield t + dt


# -- kinds -----------------------------------------------------------------------------------------
def test_the_four_kinds_of_the_paper_load():
    assert set(KINDS) == {"cargo", "manipulator", "cargo_forklift", "manipulator_forklift"}
    assert KINDS["cargo"].capabilities == frozenset()
    assert KINDS["manipulator"].capabilities == {"manipulator"}
    assert KINDS["cargo_forklift"].capabilities == {"forklift"}
    assert KINDS["manipulator_forklift"].capabilities == {"manipulator", "forklift"}
    fork = KINDS["cargo_forklift"]
    assert fork.lift_s > 0 and fork.action_s("pick") == fork.pick_s + fork.lift_s
    assert KINDS["cargo"].action_s("place") == KINDS["cargo"].place_s


@pytest.mark.parametrize("edit, expected", [
    (lambda d: d["cargo"].update(max_speed=-1), "kind 'cargo': max_speed must be a finite number > 0 (got -1)"),
    (lambda d: d["cargo"].update(pick_s=".nan"), "kind 'cargo': pick_s must be a finite number"),
    (lambda d: d["cargo"].update(payload_kg=True), "kind 'cargo': payload_kg must be a finite number"),
    (lambda d: d["manipulator"].pop("battery_wh"), "kind 'manipulator': battery_wh is missing"),
    (lambda d: d["cargo_forklift"].pop("lift_s"), "kind 'cargo_forklift': lift_s is missing"),
    (lambda d: d["cargo"].update(lift_s=3), "kind 'cargo': lift_s is only for kinds with the forklift"),
    (lambda d: d["cargo"].update(wheels=4), "kind 'cargo': unknown field(s) wheels"),
    (lambda d: d["cargo"].update(capabilities=["wings"]), "kind 'cargo': capabilities must be a list"),
    (lambda d: d["cargo"].update(capabilities=3), "kind 'cargo': capabilities must be a list"),
    (lambda d: d.update(drone=dict(d["cargo"])), "kind 'drone': unknown kind"),
])
def test_a_bad_kinds_file_names_the_kind_and_field(tmp_path, edit, expected):
    data = yaml.safe_load(config_path(KINDS_FILE).read_text())
    edit(data)
    path = tmp_path / "kinds.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(KindsError) as err:
        load_kinds(path)
    assert str(err.value).startswith(f"{path}: {expected}"), str(err.value)


def test_an_unreadable_kinds_file_says_so(tmp_path):
    with pytest.raises(KindsError, match="cannot read robot kinds"):
        load_kinds(tmp_path / "missing.yaml")
    (tmp_path / "list.yaml").write_text("- cargo\n")
    with pytest.raises(KindsError, match="expected a mapping of kind names"):
        load_kinds(tmp_path / "list.yaml")


# -- tracking a timed path ---------------------------------------------------------------------
def l_path(speed=1.0, departure=2.0):
    return timed_path_from_polyline("r1", 0.35, [(1.0, 1.0), (4.0, 1.0), (4.0, 3.0)], speed, departure)


def test_with_infinite_accel_the_robot_is_on_schedule_at_every_step():
    path = l_path()
    robot = RobotModel("r1", kind(max_accel=math.inf), 1.0, 1.0)
    t0 = 100.0
    robot.follow(path, t0, path_id=4)
    at_waypoint = {}
    for t in run(robot, t0, t0 + 9.0):
        due = path.position(t - t0)
        assert math.hypot(robot.x - due[0], robot.y - due[1]) < 1e-9, t
        assert robot.lateness_s == 0.0
        for x, y, tw in path.waypoints:
            if abs(t - t0 - tw) < DT / 2:
                at_waypoint[tw] = math.hypot(robot.x - x, robot.y - y)
    assert set(at_waypoint) == set(path.waypoints[1:, 2]) and max(at_waypoint.values()) < 1e-9
    assert robot.mode == "idle" and robot.progress == 1.0 and robot.speed == 0.0


def test_the_robot_waits_at_its_start_until_departure():
    robot = RobotModel("r1", kind(), 1.0, 1.0)
    robot.follow(l_path(departure=2.0), 0.0)
    for t in run(robot, 0.0, 2.0):
        assert (robot.x, robot.y, robot.mode, robot.lateness_s) == (1.0, 1.0, "waiting", 0.0), t
    for _ in run(robot, 2.0, 2.5):
        pass
    assert robot.x > 1.0 and robot.mode == "driving"


def test_with_finite_accel_the_robot_lags_and_reports_it():
    a, v = 0.5, 1.0
    path = l_path(speed=v, departure=0.0)
    robot = RobotModel("r1", kind(max_speed=v, max_accel=a), 1.0, 1.0)
    robot.follow(path, 0.0)
    speeds, S = [0.0], np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path.waypoints[:, :2], axis=0).T))])
    arrived = None
    for t in run(robot, 0.0, 10.0, dt=0.01):
        speeds.append(robot.speed)
        assert robot._s <= np.interp(t, path.waypoints[:, 2], S) + 1e-9  # never ahead of schedule
        if 2.9 < t < 3.0:
            # after accelerating to the planned speed it is v / (2a) = 1 s behind
            assert robot.lateness_s == pytest.approx(v / (2 * a), abs=0.02)
        if arrived is None and robot.progress == 1.0:
            arrived = t
    dv = np.diff(speeds)
    assert dv.max() <= a * 0.01 + 1e-9 and max(speeds) <= v * (1 + 1e-6)
    # 1 s lost speeding up, 1 s lost braking (v / 2a each); at rest and not late at the goal
    assert arrived == pytest.approx(path.arrival_time + 2 * v / (2 * a), abs=0.05)
    assert robot.speed == 0.0 and robot.lateness_s == 0.0 and robot.mode == "idle"


def test_with_finite_accel_the_robot_brakes_for_a_hold_and_waits_out_its_time():
    path = TimedPath("r1", 0.35, [(0, 0, 0), (4, 0, 4), (4, 0, 8), (8, 0, 12)])
    robot = RobotModel("r1", kind(max_speed=1.0, max_accel=0.5), 0.0, 0.0)
    robot.follow(path, 0.0)
    for _t in run(robot, 0.0, 8.0, dt=0.01):
        assert robot.x <= 4.0
    assert (robot.x, robot.mode, robot.lateness_s) == (4.0, "waiting", 0.0)
    list(run(robot, 8.0, 8.5, dt=0.01))
    assert robot.x > 4.0 and robot.mode == "driving"


def test_a_late_robot_catches_up_when_it_can_drive_faster_than_planned():
    path = timed_path_from_polyline("r1", 0.35, [(0.0, 0.0), (20.0, 0.0)], 0.5)
    robot = RobotModel("r1", kind(max_speed=1.0, max_accel=0.5), 0.0, 0.0)
    robot.follow(path, 0.0)
    worst = 0.0
    for _t in run(robot, 0.0, 10.0):
        worst = max(worst, robot.lateness_s)
    assert worst > 0.2 and robot.lateness_s == 0.0


def test_a_path_starting_away_from_the_robot_is_refused():
    robot = RobotModel("r1", kind(), 0.0, 0.0)
    with pytest.raises(ValueError, match="starts 2.000 m from the robot"):
        robot.follow(TimedPath("r1", 0.35, [(2.0, 0.0, 0.0), (3.0, 0.0, 1.0)]), 0.0)


# -- actions ------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["cargo", "cargo_forklift"])
def test_pick_and_place_last_their_durations(name):
    k = kind(name)
    robot = RobotModel("r1", k, 0.0, 0.0)
    robot.start_action("pick", t=10.0)
    assert robot.busy_until == 10.0 + k.pick_s + k.lift_s
    modes = [(t, robot.mode) for t in run(robot, 10.0, 10.0 + k.action_s("pick") + 1.0)]
    picking = [t for t, m in modes if m == "picking"]
    assert picking[-1] == pytest.approx(10.0 + k.action_s("pick") - DT)
    assert modes[-1][1] == "idle" and robot.busy_until is None
    robot.start_action("place", t=50.0, duration=3.0)
    assert [m for _, m in [(t, robot.mode) for t in run(robot, 50.0, 53.0)]][-2:] == ["placing", "idle"]


def test_an_action_holds_the_robot_and_it_falls_behind():
    robot = RobotModel("r1", kind(max_accel=math.inf), 1.0, 1.0)
    robot.follow(l_path(departure=1.0), 0.0)
    robot.start_action("pick", t=0.0, duration=3.0)
    for _ in run(robot, 0.0, 3.0):
        assert (robot.x, robot.y) == (1.0, 1.0)
    assert robot.lateness_s == pytest.approx(2.0)
    robot.step(3.0, DT)
    with pytest.raises(ValueError, match="cannot pick while driving"):
        robot.start_action("pick", t=3.0 + DT)


# -- battery -----------------------------------------------------------------------------------------
def test_battery_drains_faster_when_moving_and_charges_at_a_charger():
    k = kind(max_accel=math.inf)
    mover, sitter = RobotModel("m", k, 0.0, 0.0), RobotModel("s", k, 0.0, 0.0, chargers=[(0.1, 0.0)])
    mover.follow(timed_path_from_polyline("m", 0.35, [(0, 0), (100, 0)], 1.0), 0.0)
    for t in run(mover, 0.0, 100.0, dt=0.5):
        sitter.step(t - 0.5, 0.5)
    assert 1 - mover.battery == pytest.approx(k.drain_w_moving * 100 / 3600 / k.battery_wh)
    assert 1 - sitter.battery == pytest.approx(k.drain_w_idle * 100 / 3600 / k.battery_wh)
    sitter.battery = 0.5
    sitter.start_charging()
    for _ in run(sitter, 100.0, 110.0, dt=0.5):
        assert sitter.mode == "charging"
    assert sitter.battery - 0.5 == pytest.approx(k.charge_w * 10 / 3600 / k.battery_wh)
    with pytest.raises(ValueError, match="not at a charger"):
        mover.start_charging()


def test_an_empty_battery_stops_the_robot():
    robot = RobotModel("r1", kind(max_accel=math.inf), 1.0, 1.0, battery=1e-6)
    robot.follow(l_path(departure=0.0), 0.0)
    list(run(robot, 0.0, 3.0))
    assert robot.mode == "error" and robot.battery == 0.0 and robot.speed == 0.0
    assert robot.x < 1.5


def test_status_is_a_valid_robot_status_record():
    robot = RobotModel("r1", kind("manipulator"), 1.0, 1.0)
    robot.follow(l_path(), 0.0, path_id=2)
    robot.task_id = "t7"
    list(run(robot, 0.0, 3.0))
    rec = RobotStatus(**robot.status(3.0))
    assert (rec.kind, rec.mode, rec.path_id, rec.task_id, rec.radius) == ("manipulator", "driving", 2, "t7", 0.4)
    assert 0 < rec.progress < 1 and rec.vx > 0 and rec.lateness_s > 0
