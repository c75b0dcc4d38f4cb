""":class:`Clearance`: a robot's distance to the walls near a point, as
:meth:`~fleet_planner.grid.GridMap.clearance` gives it, from the blocked cells around the point
(a compiled loop over a small window) instead of a GEOS distance to the whole map's geometry.

Every robot asks this several times a step (is the disc at the next position free? is there room
to step aside?), so it was a large part of a behaviour fleet's step at 100 robots. The value is
the same distance (to the nearest blocked cell's square or the map's edge), exact up to rounding,
where it is below the window's reach (``reach``, 2 m rounded up to whole cells, by default); beyond, the window's reach
is returned, a lower bound that settles every question a robot asks (its radius is well below it).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..grid import GridMap

_numba_njit: Any
try:
    from numba import njit as _numba_njit
except ImportError:   # pragma: no cover - plain Python over the same arrays, slower
    _numba_njit = None


def _jit(fn: Any) -> Any:
    return fn if _numba_njit is None else _numba_njit(cache=True, nogil=True)(fn)


@_jit
def _clearance(blocked: np.ndarray, res: float, x: float, y: float, k: int) -> float:
    height, width = blocked.shape
    w, h = width * res, height * res
    edge = min(min(x, y), min(w - x, h - y))
    if edge <= 0.0:
        return 0.0
    best = min(edge, k * res)
    col, row = int(math.floor(x / res)), int(math.floor(y / res))
    for r in range(max(row - k, 0), min(row + k + 1, height)):
        y0, y1 = r * res, (r + 1) * res
        dy = max(y0 - y, 0.0, y - y1)
        if dy >= best:
            continue
        for c in range(max(col - k, 0), min(col + k + 1, width)):
            if not blocked[r, c]:
                continue
            x0, x1 = c * res, (c + 1) * res
            dx = max(x0 - x, 0.0, x - x1)
            d = math.hypot(dx, dy)
            if d < best:
                best = d
    return best


class Clearance:
    """Distance from a point to the nearest blocked cell or the map's edge, capped at ``reach``
    cells (see the module docstring); :meth:`disc_is_free` as :meth:`GridMap.disc_is_free`."""

    def __init__(self, grid: GridMap, reach: float = 2.0) -> None:
        self.blocked = np.ascontiguousarray(grid.blocked, dtype=np.bool_)
        self.res = float(grid.resolution)
        self.cells = max(1, int(math.ceil(reach / self.res)))

    def __call__(self, x: float, y: float) -> float:
        """The clearance, exact below ``reach`` (m); ``reach`` (rounded up to whole cells) or more beyond."""
        return float(_clearance(self.blocked, self.res, float(x), float(y), self.cells))

    def disc_is_free(self, x: float, y: float, radius: float) -> bool:
        """The disc is clear of walls and the map's edge (as GridMap.disc_is_free)."""
        cells = max(self.cells, int(math.ceil(radius / self.res)) + 1)
        return float(_clearance(self.blocked, self.res, float(x), float(y), cells)) >= radius - 1e-9

    @classmethod
    def of(cls, grid: GridMap) -> Clearance:
        """The one of a map (kept on the map object, like its path finders' move graphs)."""
        found = grid.__dict__.get("_behavior_clearance")
        if found is None:
            found = grid.__dict__["_behavior_clearance"] = cls(grid)
        return found
