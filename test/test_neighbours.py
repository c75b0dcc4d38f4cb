"""The neighbour relay (fleet_planner.fleet.neighbours): a robot never misses a neighbour inside its
safety range, over random fleets in motion; the selection is exact against brute force; watched
robots are always relayed; the record's fast encoding is the record."""
import math

import numpy as np
import pytest

from fleet_planner.fleet.coordination import AGENT_BEHAVIOR, STALE_S
from fleet_planner.fleet.legs import CONTROL_PERIOD_S
from fleet_planner.fleet.neighbours import (
    LATENCY_S,
    RELAY_PERIOD_S,
    STATUS_AGE_S,
    NeighbourRelay,
    horizon_s,
    select_neighbours,
    select_pairs,
)
from msg_schemas.records import Neighbours, RobotStatus

RADII = np.array([0.35, 0.40, 0.45, 0.45])
SPEEDS = np.array([1.0, 0.8, 0.8, 0.7])


def random_fleet(rng, n, side):
    kind = rng.integers(0, 4, n)
    return rng.uniform(0, side, (n, 2)), RADII[kind], SPEEDS[kind]


def net_range(radius, speed, sense_m):
    """How far the agent of robot i looks for j (row i, column j): CentralDriver.must_wait's cut
    (its step at top speed plus twice the staleness it allows a status), or the behaviour layer's
    comm_range."""
    central = radius[:, None] + radius[None, :] + (speed * (CONTROL_PERIOD_S + 2 * STALE_S))[:, None]
    return np.maximum(central, sense_m)


def misses(rng, horizon, sense_m, trials=30, n=60, side=25.0):
    """Pairs (i, j) where j came inside i's net range at some time while i used a record made
    without j. Each robot drives straight at its top speed in a random direction; the record is
    made at t = 0 from statuses up to STATUS_AGE_S old and used until RELAY_PERIOD_S + LATENCY_S."""
    missed = 0
    for _ in range(trials):
        xy, radius, speed = random_fleet(rng, n, side)
        heading = rng.uniform(0, 2 * math.pi, n)
        vel = speed[:, None] * np.column_stack([np.cos(heading), np.sin(heading)])
        age = rng.uniform(0, STATUS_AGE_S, n)
        reported = xy - vel * age[:, None]
        ids = [f"r{k}" for k in range(n)]
        heard = select_neighbours(ids, reported, radius, speed, horizon, sense_m)
        relayed = np.eye(n, dtype=bool)
        for i, rid in enumerate(ids):
            relayed[i, [int(o[1:]) for o in heard[rid]]] = True
        cut = net_range(radius, speed, sense_m)
        for t in np.linspace(-STATUS_AGE_S, RELAY_PERIOD_S + LATENCY_S, 25):
            p = xy + vel * t
            d = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1))
            missed += int(np.sum((d <= cut) & ~relayed))
    return missed


@pytest.mark.parametrize("sense_m", [0.0, AGENT_BEHAVIOR.comm_range], ids=["central", "behavior"])
def test_a_robot_never_misses_a_neighbour_inside_its_safety_range(sense_m):
    assert misses(np.random.default_rng(7), horizon_s(), sense_m) == 0


def test_the_motion_check_can_fail():
    """Without the motion allowance the same fleets miss neighbours: the check above has teeth."""
    assert misses(np.random.default_rng(7), 0.0, 0.0, trials=10) > 0


def test_the_selection_is_exactly_the_pairs_within_range():
    rng = np.random.default_rng(3)
    for n, side in ((1, 5.0), (2, 3.0), (40, 20.0), (300, 80.0)):
        xy, radius, speed = random_fleet(rng, n, side)
        got = {tuple(p) for p in select_pairs(xy, radius, speed, 1.5, 2.0).tolist()}
        want = {(i, j) for i in range(n) for j in range(i + 1, n)
                if math.dist(xy[i], xy[j]) <= max(radius[i] + radius[j], 2.0) + (speed[i] + speed[j]) * 1.5}
        assert got == want


def status(rid, x, y, stamp=1.0, kind="cargo"):
    return RobotStatus(id=rid, kind=kind, x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, battery=1.0, mode="idle",
                       progress=0.0, stamp=stamp, radius=0.35)


def test_watched_robots_are_relayed_however_far_and_records_parse_back():
    statuses = [status("a", 0.0, 0.0), status("b", 1.0, 0.0), status("far", 90.0, 0.0)]
    relay = NeighbourRelay({"cargo": 1.0}, watch=lambda rid: {"far", "nobody"} if rid == "a" else set())
    out = relay.records(statuses, 5.0)
    recs = {rid: Neighbours.from_json(text) for rid, text in out.items()}
    assert [s.id for s in recs["a"].robots] == ["b", "far"]
    assert [s.id for s in recs["b"].robots] == ["a"]       # watching is one-way
    assert recs["far"].robots == ()
    assert recs["a"].stamp == 5.0 and recs["a"].id == "a"
    assert recs["a"] == Neighbours(id="a", stamp=5.0, robots=(statuses[1], statuses[2]))
    moved = [status("a", 0.0, 0.0, 2.0), status("b", 50.0, 0.0, 2.0)]  # a new stamp is encoded afresh
    assert Neighbours.from_json(relay.records(moved, 6.0)["a"]).robots == ()
