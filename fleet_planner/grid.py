"""Grid maps: the occupancy grid every planner works on, and MovingAI ``.map`` / ``.scen`` files.

Cell ``(col, row)`` has its centre at ``((col + 0.5) * res, (row + 0.5) * res)`` in metres; row 0 is
the first row of a ``.map`` file and also the first row of a ``nav_msgs/OccupancyGrid`` (origin at
(0, 0)), so the two agree without flipping. Plots draw y downwards to look like the file.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

FREE_CHARS = frozenset(".G")


class MapError(ValueError):
    """A map that cannot be read; the message names the file and the reason."""


@dataclass
class GridMap:
    """``blocked[row, col]`` is True for an obstacle cell."""

    blocked: np.ndarray
    resolution: float = 1.0
    name: str = "map"

    def __post_init__(self) -> None:
        self.blocked = np.asarray(self.blocked, dtype=bool)
        if self.blocked.ndim != 2 or self.blocked.size == 0:
            raise MapError(f"{self.name}: a grid map needs a non-empty 2-D array")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise MapError(f"{self.name}: resolution must be > 0, got {self.resolution!r}")

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_rows(cls, rows: Sequence[str], resolution: float = 1.0, name: str = "inline") -> GridMap:
        rows = [r.rstrip("\n") for r in rows]
        if not rows or not rows[0]:
            raise MapError(f"{name}: no rows")
        width = len(rows[0])
        for i, r in enumerate(rows):
            if len(r) != width:
                raise MapError(f"{name}: row {i} has {len(r)} cells, row 0 has {width}")
        blocked = np.array([[c not in FREE_CHARS for c in r] for r in rows], dtype=bool)
        return cls(blocked, resolution, name)

    @classmethod
    def from_movingai(cls, path: str | Path, resolution: float = 1.0) -> GridMap:
        path = Path(path)
        try:
            lines = path.read_text().splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise MapError(f"{path}: cannot read map file ({exc})") from exc
        header: dict[str, str] = {}
        for i, line in enumerate(lines):
            if line.strip() == "map":
                body = lines[i + 1:]
                break
            parts = line.split()
            if len(parts) == 2:
                header[parts[0]] = parts[1]
        else:
            raise MapError(f"{path}: no 'map' line; not a MovingAI .map file")
        try:
            h, w = int(header["height"]), int(header["width"])
        except (KeyError, ValueError) as exc:
            raise MapError(f"{path}: header needs integer 'height' and 'width'") from exc
        body = [r for r in body if r.strip()]
        if len(body) < h:
            raise MapError(f"{path}: header says height {h} but {len(body)} rows follow")
        rows = [r[:w] for r in body[:h]]
        grid = cls.from_rows(rows, resolution, path.stem)
        if grid.width != w:
            raise MapError(f"{path}: header says width {w} but rows have {grid.width} cells")
        return grid

    def refined(self, k: int) -> GridMap:
        """The same obstacles on cells ``k`` times finer (``k`` odd, so that every cell centre of this map is a
        cell centre of the finer one: a point a planner puts on this map's lattice stays on the finer one)."""
        if isinstance(k, bool) or not isinstance(k, int) or k < 1 or k % 2 == 0:
            raise MapError(f"{self.name}: refine by an odd integer >= 1 (got {k!r})")
        if k == 1:
            return self
        return GridMap(np.repeat(np.repeat(self.blocked, k, axis=0), k, axis=1), self.resolution / k,
                       f"{self.name}/{k}")

    # -- queries ------------------------------------------------------------------------------
    @property
    def height(self) -> int:
        return int(self.blocked.shape[0])

    @property
    def width(self) -> int:
        return int(self.blocked.shape[1])

    @property
    def size_m(self) -> tuple[float, float]:
        return self.width * self.resolution, self.height * self.resolution

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """(col, row) of the cell containing the point."""
        return int(math.floor(x / self.resolution)), int(math.floor(y / self.resolution))

    def centre(self, col: int, row: int) -> tuple[float, float]:
        return (col + 0.5) * self.resolution, (row + 0.5) * self.resolution

    def in_bounds(self, col: int, row: int) -> bool:
        return 0 <= col < self.width and 0 <= row < self.height

    def is_free_cell(self, col: int, row: int) -> bool:
        return self.in_bounds(col, row) and not self.blocked[row, col]

    @cached_property
    def obstacle_geometry(self):
        """Blocked cells and the outside of the map as one prepared shapely geometry."""
        import shapely
        from shapely.geometry import box

        res = self.resolution
        boxes = []
        # merge horizontal runs of blocked cells into one box each (far fewer polygons)
        for row in range(self.height):
            line = self.blocked[row]
            col = 0
            while col < self.width:
                if line[col]:
                    end = col
                    while end + 1 < self.width and line[end + 1]:
                        end += 1
                    boxes.append(box(col * res, row * res, (end + 1) * res, (row + 1) * res))
                    col = end + 1
                else:
                    col += 1
        w, h = self.size_m
        frame = box(-1e3, -1e3, w + 1e3, h + 1e3).difference(box(0, 0, w, h))
        geom = shapely.union_all(boxes + [frame])
        shapely.prepare(geom)
        return geom

    def clearance(self, x: float, y: float) -> float:
        """Distance from the point to the nearest obstacle or map edge."""
        import shapely
        from shapely.geometry import Point as SPoint

        return float(shapely.distance(self.obstacle_geometry, SPoint(x, y)))

    def disc_is_free(self, x: float, y: float, radius: float) -> bool:
        return self.clearance(x, y) >= radius - 1e-9


def load_scen(path: str | Path, count: int | None = None) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """Start and goal cells ``((col, row), (col, row))`` of a MovingAI ``.scen`` file, in file order."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise MapError(f"{path}: cannot read scenario file ({exc})") from exc
    out = []
    for n, line in enumerate(lines, 1):
        parts = line.split("\t") if "\t" in line else line.split()
        if not parts or parts[0].lower() == "version":
            continue
        if len(parts) < 8:
            raise MapError(f"{path}:{n}: expected 9 columns, got {len(parts)}")
        try:
            sx, sy, gx, gy = (int(parts[i]) for i in (4, 5, 6, 7))
        except ValueError as exc:
            raise MapError(f"{path}:{n}: start/goal columns must be integers") from exc
        out.append(((sx, sy), (gx, gy)))
        if count is not None and len(out) >= count:
            break
    return out
