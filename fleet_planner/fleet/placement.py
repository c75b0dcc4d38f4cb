"""Fleets of any size: :func:`place_robots` puts N robots of the four kinds on free spots of a
warehouse, and :func:`warehouse_for` generates a warehouse large enough for them
(``fleet-demo --robots N --warehouse large``).

Where robots stand at the start: first on the chargers, then side by side along the outer wall
away from the chutes, then along the wall of the chutes (the main aisles of a generated
warehouse, which stay passable beside a row of parked robots), clear of every station by
:data:`STATION_CLEARANCE_M` so nobody blocks a chute, storing site or charger; where the walls
run out, on any spot with room around it. The spots off the chargers are where idle robots wait:
give them to the planner as its ``parking`` (:func:`parking_spots`).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.ndimage import distance_transform_edt

from ..model import ROBOT_KINDS
from ..robots import RobotKind
from ..warehouse import Warehouse, generate_warehouse
from .fleet_file import FleetMember

#: a robot placed at the start stands at least this far (m) from every station's pose (but chargers it is put on)
STATION_CLEARANCE_M = 2.5
#: and this much (m) beyond the sum of radii from the next robot
GAP_M = 0.25
#: how far (m) from the top or bottom edge of the map wall spots are looked for
WALL_BAND_M = 1.6


def _spots(warehouse: Warehouse, radius: float, spacing: float, need: int) -> list[tuple[float, float]]:
    """Up to ``need`` spots for robots of up to ``radius``, ``spacing`` apart: along the wall away from
    the chutes first (left to right), then along the chutes' wall, then anywhere with room (most
    room first)."""
    grid = warehouse.grid
    res = grid.resolution
    free = ~grid.blocked
    clear = distance_transform_edt(free) * res  # centre of a cell to the nearest blocked cell's centre
    rows, cols = np.nonzero(clear >= radius + res)
    xy = np.column_stack([(cols + 0.5) * res, (rows + 0.5) * res])
    stations = np.array([s.pose for s in warehouse.stations.values()], dtype=float).reshape(-1, 2)
    if len(stations):
        d = np.min(np.hypot(*(xy[:, None, :] - stations[None, :, :]).transpose(2, 0, 1)), axis=1)
        keep = d >= STATION_CLEARANCE_M
        xy, rows = xy[keep], rows[keep]
    h = grid.size_m[1]
    wall = np.minimum(xy[:, 1], h - xy[:, 1]) <= WALL_BAND_M
    chutes = [s.y for s in warehouse.stations_of("chute")]
    far_side = np.abs(xy[wall, 1] - (float(np.mean(chutes)) if chutes else 0.0))  # away from the chutes first
    order_wall = np.lexsort((xy[wall, 0], -np.abs(xy[wall, 1] - h / 2), -np.round(far_side / (h / 2))))
    rest = xy[~wall]
    room = clear[rows[~wall], (rest[:, 0] / res).astype(int)] if len(rest) else np.zeros(0)
    candidates = np.vstack([xy[wall][order_wall], rest[np.argsort(-room, kind="stable")]])
    # spacing kept on a raster: each chosen spot blocks the cells within ``spacing`` of it
    taken = np.zeros(grid.blocked.shape, dtype=bool)
    reach = int(np.ceil(spacing / res))
    dr, dc = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    disc = (dr * res) ** 2 + (dc * res) ** 2 < spacing ** 2 - 1e-9
    chosen: list[tuple[float, float]] = []
    for x, y in candidates:
        if len(chosen) >= need:
            break
        col, row = int(x / res), int(y / res)
        if taken[row, col] or not grid.disc_is_free(float(x), float(y), radius + 0.05):
            continue
        chosen.append((float(x), float(y)))
        rr, cc = dr[disc] + row, dc[disc] + col
        rows_n, cols_n = grid.blocked.shape
        ok = (rr >= 0) & (rr < rows_n) & (cc >= 0) & (cc < cols_n)
        taken[rr[ok], cc[ok]] = True
    return chosen


def place_robots(warehouse: Warehouse, kinds: Mapping[str, RobotKind], n: int, battery: float = 0.9,
                 prefix: str = "r") -> list[FleetMember]:
    """``n`` robots ``r1``..``rn`` of the four kinds in turn on free spots of ``warehouse`` (see the
    module docstring); ValueError if they do not fit."""
    if n < 1:
        raise ValueError(f"robots: at least 1 (got {n})")
    names = [k for k in ROBOT_KINDS if k in kinds] or list(kinds)
    largest = max(kinds[k].radius for k in names)
    spacing = 2 * largest + GAP_M
    spots = [s.pose for s in warehouse.stations_of("charger")]
    if len(spots) < n:
        taken = np.array(spots, dtype=float).reshape(-1, 2)
        for x, y in _spots(warehouse, largest, spacing, 2 * n):
            if len(spots) >= n:
                break
            if not len(taken) or np.min(np.hypot(taken[:, 0] - x, taken[:, 1] - y)) >= spacing:
                spots.append((x, y))
    if len(spots) < n:
        raise ValueError(f"robots: only {len(spots)} fit on warehouse {warehouse.name!r} (asked {n}); "
                         "use a larger warehouse (--warehouse large)")
    return [FleetMember(f"{prefix}{i + 1}", names[i % len(names)], x, y, 0.0, battery)
            for i, (x, y) in enumerate(spots[:n])]


def parking_spots(warehouse: Warehouse, members: Sequence[FleetMember]) -> list[tuple[float, float]]:
    """The start spots of ``members`` that are not chargers: the planner's parking spots."""
    chargers = [s.pose for s in warehouse.stations_of("charger")]
    return [(m.x, m.y) for m in members
            if all((m.x - cx) ** 2 + (m.y - cy) ** 2 > 1e-6 for cx, cy in chargers)]


def warehouse_for(robots: int, name: str = "large") -> Warehouse:
    """A generated warehouse for about ``robots`` robots: six rows of rack blocks 20 m long with
    2 m aisles, 25 m deep, as wide as it takes for the robots to start on the chargers and along
    the wall away from the chutes (about 1.75 m of wall per robot), with one chute and one charger
    for about every eight robots."""
    blocks_x = max(2, math.ceil(1.75 * robots / 23.0))
    width_cells = 2 + 8 + blocks_x * 40 + (blocks_x - 1) * 6
    chargers = min(max(6, robots // 8), len(range(4, width_cells - 4, 4)))
    chutes = min(max(6, robots // 8), (width_cells - 2) // 8)
    return generate_warehouse(blocks_x, 6, 40, 2, 4, 0.5, name, chutes=chutes, chargers=chargers)


def generated_warehouse(spec: str | None, robots: int) -> Warehouse | None:
    """The generated warehouse ``fleet-demo --warehouse SPEC`` (and ``bench_dispatch.py``) run on for
    ``robots`` robots: "large" is sized for ``max(robots, 50)``, a number for that many robots; None
    when ``spec`` names a warehouse file (or none: the default warehouse)."""
    if spec == "large":
        return warehouse_for(max(robots, 50))
    if spec is not None and spec.isdigit():
        return warehouse_for(int(spec))
    return None


__all__ = ["GAP_M", "STATION_CLEARANCE_M", "generated_warehouse", "parking_spots", "place_robots", "warehouse_for"]
