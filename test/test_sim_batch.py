"""Many robots stepped at once (issue 10): the batched path tracking of :class:`TrackBatch` moves
every robot exactly as its own :meth:`RobotModel.step` does (the agent process of a real robot
steps one robot alone), a fleet simulator with it reports exactly the statuses of one without, and
the safety net's inlined critical-area test finds exactly the robot the area test finds."""
import math
from dataclasses import replace

import numpy as np
import pytest

from fleet_planner.behavior.areas import in_critical_area
from fleet_planner.behavior.params import BehaviorParams
from fleet_planner.behavior.safety import _SWEEP_STEP, safety_stop
from fleet_planner.behavior.views import RobotView
from fleet_planner.fleet.fleet_file import FleetMember
from fleet_planner.fleet.sim import SimFleet
from fleet_planner.model import TimedPath, timed_path_from_polyline
from fleet_planner.robots import RobotModel, TrackBatch, load_kinds
from fleet_planner.warehouse import load_warehouse

KINDS = load_kinds()
STATE = ("x", "y", "yaw", "vx", "vy", "speed", "battery", "mode", "lateness_s", "_s", "progress", "path_id")


def random_path(rng: np.random.Generator, rid: str, radius: float, start, speed: float, t0: float) -> TimedPath:
    """A polyline from ``start`` with a hold in the middle and a late departure, driven at ``speed``
    (or a little slower), times from ``t0``."""
    pts = [start]
    for _ in range(int(rng.integers(1, 6))):
        pts.append((pts[-1][0] + float(rng.uniform(-4, 4)), pts[-1][1] + float(rng.uniform(-4, 4))))
    path = timed_path_from_polyline(rid, radius, pts, speed * float(rng.uniform(0.5, 1.0)),
                                    departure=float(rng.uniform(0, 2)))
    wp = path.waypoints.copy()
    k, hold = int(rng.integers(1, len(wp))), float(rng.uniform(0.0, 1.5))
    wp = np.vstack([wp[:k], [wp[k - 1, 0], wp[k - 1, 1], wp[k - 1, 2] + hold], wp[k:] + [0.0, 0.0, hold]])
    wp[:, 2] += t0
    return TimedPath(rid, radius, wp)


def models(seed: int, n: int):
    rng = np.random.default_rng(seed)
    names = list(KINDS)
    out = []
    for i in range(n):
        kind = KINDS[names[i % len(names)]]
        if i % 5 == 4:
            kind = replace(kind, max_accel=math.inf)   # instant speed changes too
        out.append(RobotModel(f"r{i}", kind, float(rng.uniform(0, 20)), float(rng.uniform(0, 20))))
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_tracking_equals_each_robot_stepping_alone(seed):
    rng = np.random.default_rng(100 + seed)
    alone, batched = models(seed, 12), models(seed, 12)
    batch = TrackBatch(batched)
    t, used = 0.0, 0
    for step in range(400):
        dt = float(rng.choice([0.1, 0.1, 0.1, 0.05, 0.25]))
        for a, b in zip(alone, batched):
            if a.path is None or (rng.random() < 0.01) or (a.progress >= 1.0 and rng.random() < 0.2):
                path = random_path(rng, a.id, a.kind.radius, (a.x, a.y), a.kind.max_speed, t)
                a.follow(path, 0.0, step)
                b.follow(path, 0.0, step)
        batch.prepare([t] * len(batched), [dt] * len(batched))
        prepared = [m._pre is not None for m in batched]
        holds = rng.random(len(alone)) < 0.1
        for a, b, hold in zip(alone, batched, holds):
            a.step(t, dt, hold=bool(hold))
            b.step(t, dt, hold=bool(hold))
            for name in STATE:
                assert getattr(a, name) == getattr(b, name), (step, a.id, name)
        used += sum(p and m._pre is None for p, m in zip(prepared, batched))
        t += dt
    assert used > 2000   # prepared steps taken (a step consumes the one prepared for it)


def test_a_prepared_step_is_not_used_after_the_robot_changed():
    """A robot that got a new path (or a speed limit) after prepare works its step out itself."""
    (a,), (b,) = models(3, 1), models(3, 1)
    rng = np.random.default_rng(7)
    path = random_path(rng, a.id, a.kind.radius, (a.x, a.y), a.kind.max_speed, 0.0)
    a.follow(path, 0.0, 1)
    b.follow(path, 0.0, 1)
    batch = TrackBatch([b])
    for n in range(30):
        batch.prepare([n * 0.1], [0.1])
        if n == 20:
            b.kind = a.kind = replace(a.kind, max_speed=a.kind.max_speed / 2)
        a.step(n * 0.1, 0.1)
        b.step(n * 0.1, 0.1)
        assert (a.x, a.y, a.speed) == (b.x, b.y, b.speed)


def test_fleet_simulator_with_and_without_batch_reports_the_same():
    warehouse = load_warehouse()
    spots = [(3.0 + 1.5 * i, 2.0) for i in range(6)]
    names = list(KINDS)
    members = [FleetMember(f"r{i + 1}", names[i % 4], x, y, 0.0, 0.9) for i, (x, y) in enumerate(spots)]
    fleets = [SimFleet(members, KINDS, warehouse, batch=True), SimFleet(members, KINDS, warehouse, batch=False)]
    rng = np.random.default_rng(5)
    for i, (x, y) in enumerate(spots):
        pts = [(x, y), (x, y + 3.0 + i * 0.3), (x + 0.7, y + 6.0)]
        path = timed_path_from_polyline(f"r{i + 1}", KINDS[names[i % 4]].radius, pts, 0.8,
                                        departure=float(rng.uniform(0, 1)))
        for f in fleets:
            f.on_path(f"r{i + 1}", path, 0.5, i)
    for k in range(150):
        a, b = (f.step(0.1 * k) for f in fleets)
        assert a == b, k
    assert any(s.mode == "driving" for s in a) or all(s.progress == 1.0 for s in a)
    assert all(s.progress == 1.0 for s in a)


# -- the safety net ------------------------------------------------------------------------------
def reference_safety_stop(me, others, step, margin, sweep=None):
    """safety_stop as it was written with the area functions (before issue 10 inlined them)."""
    if step <= 0 or not me.travelling:
        return None
    area = BehaviorParams(front_length=me.radius + step, front_width=2 * me.radius, critical_margin=0.0)
    hit = []
    for o in others:
        if o.id == me.id:
            continue
        dx, dy = (sweep or {}).get(o.id, (0.0, 0.0))
        n = 1 + int(math.ceil(math.hypot(dx, dy) / _SWEEP_STEP))
        x, y = o.position
        if any(in_critical_area(me, replace(o, position=(x + dx * k / max(n - 1, 1), y + dy * k / max(n - 1, 1)),
                                            radius=o.radius + margin), area) for k in range(n)):
            hit.append(o)
    return min(hit, key=lambda o: math.dist(o.position, me.position), default=None)


def test_inlined_safety_net_finds_the_same_robot():
    rng = np.random.default_rng(11)
    found = 0
    for trial in range(3000):
        ahead = None if trial % 50 == 0 else (float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3)))
        me = RobotView("me", (float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1))), float(rng.uniform(0.3, 0.5)),
                       next_waypoint=ahead,
                       straight=float(rng.choice([math.inf, rng.uniform(0, 2)])))
        others = [RobotView(f"o{k}", (float(rng.uniform(-2, 2)), float(rng.uniform(-2, 2))),
                            float(rng.uniform(0.3, 0.5))) for k in range(int(rng.integers(0, 6)))]
        sweep = {o.id: (float(rng.uniform(-0.4, 0.4)), float(rng.uniform(-0.4, 0.4)))
                 for o in others if rng.random() < 0.5}
        step = float(rng.choice([0.0, rng.uniform(0, 0.15)]))
        margin = float(rng.uniform(0, 0.1))
        want = reference_safety_stop(me, others, step, margin, sweep)
        assert safety_stop(me, others, step, margin, sweep) == want, trial
        found += want is not None
    assert 100 < found < 2900
