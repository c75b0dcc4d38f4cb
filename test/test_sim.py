"""The delivery simulation: every method completes a tiny delivery run without any two discs
overlapping, and no faster than the robots could have done it alone.

Overlaps are recomputed here from what the robots drove (the trajectories of the central methods
sampled densely, the recorded positions of the behaviour fleet), not taken from the simulation's
own counter.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fleet_planner.delivery import METHODS, choose_spots, simulate, warehouse_problem
from fleet_planner.grid import GridMap
from fleet_planner.warehouse import generate_warehouse


@pytest.fixture(scope="module")
def problem():
    return warehouse_problem(generate_warehouse(2, 2, 8, 2, 4, 0.5, "tiny"), n_robots=4, n_deliveries=8, seed=3)


def _sample(paths, times: np.ndarray) -> np.ndarray:
    """Positions ``(len(times), n, 2)`` of timed paths, by plain interpolation."""
    out = np.empty((len(times), len(paths), 2))
    for k, p in enumerate(paths):
        wp = p.waypoints
        for axis in (0, 1):
            out[:, k, axis] = np.interp(times, wp[:, 2], wp[:, axis])
    return out


def _min_gap(positions: np.ndarray, radius: float) -> float:
    diff = positions[:, :, None, :] - positions[:, None, :, :]
    dist = np.hypot(diff[..., 0], diff[..., 1])
    n = positions.shape[1]
    dist[:, np.arange(n), np.arange(n)] = np.inf
    return float(dist.min()) - 2 * radius


def _dwells(wp: np.ndarray, point, at_least: float) -> int:
    """How often a trajectory stands still on ``point`` for ``at_least`` seconds."""
    count, since, prev_t = 0, None, 0.0
    for x, y, t in wp:
        on = math.dist((x, y), point) < 1e-6
        if on and since is None:
            since = t
        elif not on and since is not None:
            count += prev_t - since >= at_least - 1e-6
            since = None
        prev_t = t
    if since is not None:
        count += 1   # still there at the end: parked for ever
    return count


@pytest.mark.parametrize("method", METHODS)
def test_tiny_delivery_run(problem, method):
    result = simulate(problem, method, record=True)

    assert result.finished and result.completed == len(problem.deliveries) == 8
    assert result.ctime >= result.lower_bound > 0
    assert result.deadlocks == 0
    r = problem.radius
    if result.trajectories is not None:
        paths = result.trajectories
        assert [tuple(p.waypoints[0, :2]) for p in paths] == problem.homes
        for p in paths:
            assert np.all(np.diff(p.waypoints[:, 2]) >= -1e-9)
            seg = np.hypot(*np.diff(p.waypoints[:, :2], axis=0).T)
            assert np.all(seg <= problem.max_speed * np.diff(p.waypoints[:, 2]) + 1e-6)
        end = max(float(p.waypoints[-1, 2]) for p in paths)
        assert _min_gap(_sample(paths, np.arange(0.0, end + 0.02, 0.02)), r) >= -1e-6
        # every load and unload happened: a robot stood docked on the station for dock_s
        for name in {s for d in problem.deliveries for s in (d.pick, d.drop)}:
            visits = sum(_dwells(p.waypoints, problem.stations[name], problem.dock_s) for p in paths)
            needed = sum((d.pick == name) + (d.drop == name) for d in problem.deliveries)
            assert visits >= needed, name
    else:
        pos = result.positions
        assert pos.shape == (len(result.times), problem.n_robots, 2)
        assert _min_gap(pos, r) >= -1e-9
        # every station of a delivery was reached (the behaviour fleet drives to it exactly)
        for name in {s for d in problem.deliveries for s in (d.pick, d.drop)}:
            point = np.asarray(problem.stations[name])
            assert np.min(np.hypot(*(pos - point).reshape(-1, 2).T)) < 1e-6, name


def test_spots_never_cut_a_corridor():
    # two rooms joined by a corridor 1.5 m wide: at 0.5 m cells only its middle row fits a disc
    room = "@" + "." * 8 + "@" * 12 + "." * 8 + "@"
    rows = ["@" * 30] + [room] * 4 + ["@" + "." * 28 + "@"] * 3 + [room] * 4 + ["@" * 30]
    grid = GridMap.from_rows(rows, 0.5, "corridor")
    spots = choose_spots(grid, 6, seed=0, radius=0.354)
    for x, y in spots:
        col, row = grid.cell_of(x, y)
        assert not (9 <= col <= 20), f"spot ({x}, {y}) is in the corridor"
    with pytest.raises(ValueError, match="parking spots"):
        choose_spots(grid, 200, seed=0, radius=0.354)


def test_a_crowd_the_spread_homes_cannot_hold_gets_packed_homes():
    """200 robots on `large` (issue 13's stress run): the spread homes hold only 148 of them, 59
    besides the queue spots (the control raises), the packed ones (ours) hold all 200, each a disc
    apart, clear of the stations by the docking region, none in a one-robot rack aisle; a size that
    fits gets the spread homes as before."""
    from fleet_planner.delivery.layout import PACKED_STATION_CLEARANCE, ROBOT_RADIUS, SPOT_MARGIN

    large = generate_warehouse(5, 10, 24, 2, 3, 0.5, "large")
    problem = warehouse_problem(large, n_robots=200, n_deliveries=600, seed=0)
    homes = np.asarray(problem.homes)
    stations = list(problem.stations.values())
    with pytest.raises(ValueError, match="parking spots that cut no passage"):   # control: spread homes
        choose_spots(large.grid, 200, 0, stations)
    assert len(homes) == 200
    gaps = np.hypot(*(homes[:, None] - homes[None]).transpose(2, 0, 1)) + np.eye(200) * 99
    assert gaps.min() >= 2 * ROBOT_RADIUS + SPOT_MARGIN
    to_station = np.hypot(*(homes[:, None] - np.asarray(stations)[None]).transpose(2, 0, 1))
    assert to_station.min() >= PACKED_STATION_CLEARANCE - 1e-9
    # storage stations stand in the rack aisles (the top one opens into the wide top band)
    rack_aisle_ys = sorted({s[1] for s in stations if s[1] > 5.0})[:-1]
    assert not any(abs(y - ya) < 0.3 for _, y in homes for ya in rack_aisle_ys)

    small = warehouse_problem(large, n_robots=20, n_deliveries=60, seed=0)
    assert len(small.spots) > 20 + 10   # spread: homes, queue spots (packed: none), spares (N/2)
