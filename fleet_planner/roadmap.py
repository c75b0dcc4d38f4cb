"""Road maps of directed lanes: which grid moves a robot may make where (one-way aisles, two-way
elsewhere), computed from the transport demand by ARMO-style linear programming or read from a
lanes file in ``config/`` (what integrators configure by hand in real warehouses).

A :class:`RoadMap` is a directed graph over the cells of one map: ``allowed[row, col]`` holds the
bits of the moves out of the cell the road map allows (bit d = ``_pathgraph.DIRS[d]``, the move
table's bits). It is *orthogonal* (Kleiner, Sun & Meyer-Delius, "ARMO: Adaptive Road Map
Optimization for Large Robot Teams", IROS 2011, as summarised in section V of paper 002: "ARMO
generates only orthogonal road map"): lanes run along rows and columns; a diagonal move is allowed
where both of its L-shaped orthogonal ways are (so a diagonal never cuts a one-way lane the wrong
way). Moves no lane restricts stay two-way.

How planners use it: :func:`with_lanes` returns a copy of the map carrying the road map
(``grid.lanes``); :class:`~fleet_planner.paths.PathFinder` on such a map removes the forbidden
directed moves from its move graph and does not straighten its paths (a straightened path would
leave the lanes), and PRIOR's roadmap does the same, so md, PRIOR and BBMRCA all plan along it
without knowing about it.

ARMO (:func:`armo_roadmap`) - ours after the paper's one-paragraph summary ("based on linear
programming, ARMO computes an optimal road map according to environmental constraints and the
demand for transportation tasks from stations"): the demand-weighted multi-commodity min-cost flow
over the directed moves between the cells the disc fits on, solved exactly by one shortest-path
tree per commodity (the program has no capacities; :func:`_flow_lp` is the same program for
HiGHS, checked to agree, far too slow at warehouse scale), head-on costs by successive averages
so that opposing flows take different aisles, and rounding to one-way runs (maximal straight row
or column stretches: aisle lanes) that keeps the free space strongly connected, so no lane is a
dead end and every station reaches every other in both directions.

Lanes file (YAML; :func:`load_lanes`, :func:`save_lanes`)::

    name: warehouse-armo
    radius: 0.354                # the disc the lanes were laid out for (cells it fits on)
    lanes:                       # one-way lanes, straight runs of cells (col, row): from -> to
      - {from: [2, 11], to: [75, 11]}

A lane whose cells are off the map or not free for the radius (an unknown cell), that is not
straight, runs against another lane, or leaves a cell with a way in but no way out (a dead end) is
rejected with a :class:`LanesError` naming the field.
"""
from __future__ import annotations

import heapq
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path

import numpy as np
import yaml

from ._pathgraph import DIRS
from .grid import GridMap
from .model import Point
from .validation import ValidationError, Vocabulary, in_file, read_yaml

_BIT = {d: 1 << k for k, d in enumerate(DIRS)}
_ORTHO = ((1, 0), (-1, 0), (0, 1), (0, -1))
ALL_ORTHOGONAL = _BIT[(1, 0)] | _BIT[(-1, 0)] | _BIT[(0, 1)] | _BIT[(0, -1)]


class LanesError(ValidationError):
    """A lanes file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class RoadMap:
    """Directed lanes over one map: ``allowed[row, col]`` = bits of the orthogonal moves out of
    the cell the road map allows (walls are not its business: the path finder keeps those)."""

    allowed: np.ndarray
    resolution: float
    name: str = "lanes"
    radius: float | None = None

    @classmethod
    def open(cls, grid: GridMap, name: str = "lanes", radius: float | None = None) -> RoadMap:
        """Every orthogonal move two-way (no lane)."""
        return cls(np.full(grid.blocked.shape, ALL_ORTHOGONAL, dtype=np.uint8), grid.resolution, name, radius)

    @property
    def restricts(self) -> bool:
        """Some move is not allowed (a road map that restricts none is the map itself: paths on
        it are straightened as without it)."""
        return bool(np.any(self.allowed != ALL_ORTHOGONAL))

    @property
    def shape(self) -> tuple[int, int]:
        h, w = self.allowed.shape
        return int(h), int(w)

    def allows(self, col: int, row: int, dcol: int, drow: int) -> bool:
        """The orthogonal move (dcol, drow) out of cell (col, row) is allowed."""
        return bool(self.allowed[row, col] & _BIT[(dcol, drow)])

    def move_mask(self, shape: tuple[int, int]) -> np.ndarray:
        """uint8 ``[row, col]``: the 8-move bits the road map allows (orthogonal as laid out; a
        diagonal where both of its L-shaped orthogonal ways are allowed)."""
        if tuple(shape) != self.shape:
            raise ValueError(f"lanes {self.name!r}: laid out for a {self.shape} map, not {tuple(shape)}")
        a = self.allowed
        h, w = a.shape
        out = a & np.uint8(ALL_ORTHOGONAL)

        def at(dcol: int, drow: int) -> np.ndarray:   # allowed bits of the neighbour (dcol, drow)
            pad = np.zeros((h + 2, w + 2), dtype=np.uint8)
            pad[1:-1, 1:-1] = a
            return pad[1 + drow:h + 1 + drow, 1 + dcol:w + 1 + dcol]

        for dc, dr in DIRS:
            if not (dc and dr):
                continue
            bx, by = np.uint8(_BIT[(dc, 0)]), np.uint8(_BIT[(0, dr)])
            via_x = ((a & bx) > 0) & ((at(dc, 0) & by) > 0)
            via_y = ((a & by) > 0) & ((at(0, dr) & bx) > 0)
            out |= (via_x & via_y).astype(np.uint8) * np.uint8(_BIT[(dc, dr)])
        return out

    def one_way_moves(self) -> int:
        """How many orthogonal moves between neighbouring cells are allowed one way only."""
        n = 0
        a = self.allowed
        h, w = a.shape
        for dc, dr in ((1, 0), (0, 1)):
            fwd = (a[:h - dr, :w - dc] & _BIT[(dc, dr)]) > 0
            back = (a[dr:, dc:] & _BIT[(-dc, -dr)]) > 0
            n += int(np.sum(fwd ^ back))
        return n

    def edges(self, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Directed orthogonal moves between traversable cells (``free[row, col]``) the road map
        allows: (tails, heads) as flat cell indices ``row * width + col``."""
        h, w = free.shape
        tails, heads = [], []
        for dc, dr in _ORTHO:
            rows, cols = np.nonzero(free & ((self.allowed & _BIT[(dc, dr)]) > 0))
            r2, c2 = rows + dr, cols + dc
            ok = (r2 >= 0) & (r2 < h) & (c2 >= 0) & (c2 < w)
            rows, cols, r2, c2 = rows[ok], cols[ok], r2[ok], c2[ok]
            ok = free[r2, c2]
            tails.append(rows[ok] * w + cols[ok])
            heads.append(r2[ok] * w + c2[ok])
        return np.concatenate(tails), np.concatenate(heads)

    def unreachable_pairs(self, free: np.ndarray, cells: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
        """Pairs (i, j) of ``cells`` (col, row) such that j cannot be reached from i along the lanes."""
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import shortest_path

        h, w = free.shape
        t, hd = self.edges(free)
        g = csr_matrix((np.ones(len(t)), (t, hd)), shape=(h * w, h * w))
        idx = [r * w + c for c, r in cells]
        d = shortest_path(g, indices=idx, unweighted=True)
        return [(i, j) for i in range(len(idx)) for j in range(len(idx)) if i != j and not np.isfinite(d[i, idx[j]])]

    def dead_ends(self, free: np.ndarray) -> list[tuple[int, int]]:
        """Traversable cells (col, row) with a way in along the lanes but no way out."""
        h, w = free.shape
        t, hd = self.edges(free)
        out_deg = np.bincount(t, minlength=h * w)
        in_deg = np.bincount(hd, minlength=h * w)
        bad = np.nonzero(free.ravel() & (in_deg > 0) & (out_deg == 0))[0]
        return [(int(k % w), int(k // w)) for k in bad]

    def arrows(self, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For drawing, in metres: one-way moves ``(k, 4)`` as (x, y, dx, dy), and two-way
        neighbour pairs ``(m, 4)`` as (x0, y0, x1, y1), between traversable cells."""
        h, w = free.shape
        res = self.resolution
        one, two = [], []
        a = self.allowed
        for dc, dr in ((1, 0), (0, 1)):
            both = free[:h - dr, :w - dc] & free[dr:, dc:]
            fwd = both & ((a[:h - dr, :w - dc] & _BIT[(dc, dr)]) > 0)
            back = both & ((a[dr:, dc:] & _BIT[(-dc, -dr)]) > 0)
            for mask, sign in ((fwd & ~back, 1), (back & ~fwd, -1)):
                rows, cols = np.nonzero(mask)
                x, y = (cols + 0.5) * res, (rows + 0.5) * res
                if sign < 0:
                    x, y = x + dc * res, y + dr * res
                one.append(np.column_stack([x, y, np.full(len(x), sign * dc * res), np.full(len(x), sign * dr * res)]))
            rows, cols = np.nonzero(fwd & back)
            x, y = (cols + 0.5) * res, (rows + 0.5) * res
            two.append(np.column_stack([x, y, x + dc * res, y + dr * res]))
        return np.vstack(one).reshape(-1, 4), np.vstack(two).reshape(-1, 4)


def with_lanes(grid: GridMap, lanes: RoadMap | None) -> GridMap:
    """A copy of ``grid`` whose path finders plan along ``lanes`` (``grid.lanes``); None: a plain copy."""
    if lanes is not None:
        lanes.move_mask(grid.blocked.shape)   # raises on a road map of another map
    out = replace(grid, name=grid.name if lanes is None else f"{grid.name}+{lanes.name}")
    out.lanes = lanes  # type: ignore[attr-defined]
    return out


def lanes_of(grid: GridMap) -> RoadMap | None:
    """The road map a map carries (:func:`with_lanes`), or None."""
    return getattr(grid, "lanes", None)


def free_cells(grid: GridMap, radius: float) -> np.ndarray:
    """``[row, col]``: the cells whose centre the disc fits on (the path finder's nodes)."""
    from .paths import PathFinder

    return PathFinder(replace(grid), radius).free


# -- lanes files ---------------------------------------------------------------------------------
_V = Vocabulary(LanesError)
_CELL = _V.list_of(_V.integer(), min_len=2, max_len=2)


def _lane_cells(a: tuple[int, int], b: tuple[int, int]) -> list[tuple[int, int]]:
    dc, dr = int(np.sign(b[0] - a[0])), int(np.sign(b[1] - a[1]))
    n = max(abs(b[0] - a[0]), abs(b[1] - a[1]))
    return [(a[0] + dc * k, a[1] + dr * k) for k in range(n + 1)]


def parse_lanes(data: object, grid: GridMap, radius: float | None = None, name: str = "lanes") -> RoadMap:
    """A :class:`RoadMap` from the parsed YAML of a lanes file (see the module docstring).
    ``radius`` overrides the file's."""
    top = _V.keys(data, "", ("name", "radius", "lanes"), ("lanes",))
    name = _V.string(min_len=1)(top.get("name", name), "name")
    r = _V.number(above=0)(top.get("radius", radius if radius is not None else 0.354), "radius")
    if radius is not None:
        r = float(radius)
    items = _V.list_of(lambda v, p: v, max_len=100_000)(top["lanes"], "lanes")
    free = free_cells(grid, r)
    h, w = free.shape
    allowed = np.full((h, w), ALL_ORTHOGONAL, dtype=np.uint8)
    owner: dict[tuple[int, int, int, int], int] = {}   # (col, row, dcol, drow) of a forbidden move -> lane
    lane_of_cell: dict[tuple[int, int], int] = {}
    for k, item in enumerate(items):
        path = f"lanes[{k}]"
        lane = _V.keys(item, path, ("from", "to"), ("from", "to"))
        ends = []
        for key in ("from", "to"):
            c, rr = _CELL(lane[key], f"{path}.{key}")
            if not (0 <= c < w and 0 <= rr < h):
                _V.fail(f"{path}.{key}", f"unknown cell [{c}, {rr}]: the map has {w} columns and {h} rows")
            if not free[rr, c]:
                _V.fail(f"{path}.{key}", f"cell [{c}, {rr}] is not free for a disc of radius {r:g}")
            ends.append((c, rr))
        a, b = ends
        if a == b or (a[0] != b[0] and a[1] != b[1]):
            _V.fail(path, f"a lane runs straight along a row or a column between two cells (got {list(a)} "
                          f"-> {list(b)})")
        cells = _lane_cells(a, b)
        for c, rr in cells:
            if not free[rr, c]:
                _V.fail(path, f"cell [{c}, {rr}] on the lane is not free for a disc of radius {r:g}")
            lane_of_cell.setdefault((c, rr), k)
        dc, dr = cells[1][0] - cells[0][0], cells[1][1] - cells[0][1]
        for (c0, r0), (c1, r1) in zip(cells, cells[1:]):
            if (c0, r0, dc, dr) in owner:
                _V.fail(path, f"runs against lanes[{owner[(c0, r0, dc, dr)]}] at cell [{c0}, {r0}]")
            allowed[r1, c1] &= np.uint8(~_BIT[(-dc, -dr)] & 0xFF)
            owner[(c1, r1, -dc, -dr)] = k
    rm = RoadMap(allowed, grid.resolution, name, r)
    dead = rm.dead_ends(free)
    if dead:
        c, rr = dead[0]
        owner_lane = lane_of_cell.get((c, rr))
        where = f"lanes[{owner_lane}]" if owner_lane is not None else "lanes"
        _V.fail(where, f"cell [{c}, {rr}] is a dead end: the lanes lead in but not out")
    return rm


def load_lanes(path: str | Path, grid: GridMap, radius: float | None = None) -> RoadMap:
    """Read and validate a lanes file for ``grid`` (errors start with the file and the field)."""
    path = Path(path)
    data = read_yaml(path, LanesError, what="lanes file")
    with in_file(path, LanesError):
        return parse_lanes(data, grid, radius, path.stem)


def lane_runs(rm: RoadMap, free: np.ndarray) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """The one-way moves of ``rm`` as maximal straight runs ``(from cell, to cell)``."""
    h, w = free.shape
    a = rm.allowed
    runs = []
    for dc, dr in _ORTHO:
        def one_way(c: int, r: int, dc: int = dc, dr: int = dr) -> bool:
            c2, r2 = c + dc, r + dr
            return (0 <= c2 < w and 0 <= r2 < h and bool(free[r, c]) and bool(free[r2, c2])
                    and bool(a[r, c] & _BIT[(dc, dr)]) and not a[r2, c2] & _BIT[(-dc, -dr)])
        seen = set()
        for r in range(h):
            for c in range(w):
                if (c, r) in seen or not one_way(c, r) or one_way(c - dc, r - dr):
                    continue
                c1, r1 = c, r
                while one_way(c1, r1):
                    seen.add((c1, r1))
                    c1, r1 = c1 + dc, r1 + dr
                runs.append(((c, r), (c1, r1)))
    return runs


def save_lanes(rm: RoadMap, grid: GridMap, path: str | Path, comment: str = "") -> Path:
    """Write ``rm`` as a lanes file that :func:`load_lanes` reads back to the same road map."""
    path = Path(path)
    r = rm.radius if rm.radius is not None else 0.354
    runs = lane_runs(rm, free_cells(grid, r))
    lines = [f"# {line}".rstrip() for line in comment.splitlines()]
    lines += [f"name: {yaml.safe_dump(rm.name).splitlines()[0]}", f"radius: {r!r}", "lanes:"]
    lines += [f"  - {{from: [{a[0]}, {a[1]}], to: [{b[0]}, {b[1]}]}}" for a, b in runs]
    if not runs:
        lines[-1] = "lanes: []"
    path.write_text("\n".join(lines) + "\n")
    return path


# -- ARMO: the road map from the demand ------------------------------------------------------------
@dataclass(frozen=True)
class ArmoInfo:
    """How the road map was computed. ``runs``: lanes (:func:`_lanes`: runs cut at narrow
    corridors, the parallel pieces of one such corridor together), ``one_way_runs`` those made
    one-way; ``variables``: of the flow program (arcs x commodities) whose optimum the
    shortest-path trees are; ``objective``: the demand-weighted driving distance (cells,
    keep-right costs, demand scaled to 1) along the final lanes, ``open_objective`` the same on
    the map without lanes (both round the parked robots); ``opposed``: share of the driving that
    meets opposing flow in its lane (the head-on traffic lanes remove), first on the open map
    (``opposed_open``), then on the road map; ``solve_s``: CPU seconds it took."""

    cells: int
    runs: int
    one_way_runs: int
    commodities: int
    variables: int
    status: str
    objective: float
    solve_s: float
    open_objective: float = math.nan
    opposed_open: float = math.nan
    opposed: float = math.nan


def _runs(free: np.ndarray) -> tuple[list[list[int]], np.ndarray, np.ndarray, np.ndarray]:
    """Maximal straight runs of traversable cells along rows and columns: their cells (flat), and
    per undirected edge (forward move of a run): tail, head, run index."""
    h, w = free.shape
    runs: list[list[int]] = []
    tails, heads, run_of = [], [], []
    lines = [(free[r, :], [r * w + k for k in range(w)]) for r in range(h)]   # rows: forward = +col
    lines += [(free[:, c], [k * w + c for k in range(h)]) for c in range(w)]  # columns: forward = +row
    for mask, flat in lines:
        i, n = 0, len(flat)
        while i < n:
            if not mask[i]:
                i += 1
                continue
            j = i
            while j + 1 < n and mask[j + 1]:
                j += 1
            if j > i:
                cells = flat[i:j + 1]
                for x, y in zip(cells, cells[1:]):
                    tails.append(x)
                    heads.append(y)
                    run_of.append(len(runs))
                runs.append(cells)
            i = j + 1
    return runs, np.array(tails, dtype=np.int64), np.array(heads, dtype=np.int64), np.array(run_of, dtype=np.int64)


def _nearest_free(free: np.ndarray, grid: GridMap, p: Point) -> int:
    h, w = free.shape
    c, r = grid.cell_of(*p)
    if 0 <= r < h and 0 <= c < w and free[r, c]:
        return r * w + c
    rows, cols = np.nonzero(free)
    k = int(np.argmin((cols - c) ** 2 + (rows - r) ** 2))
    return int(rows[k] * w + cols[k])


@dataclass(frozen=True)
class _Net:
    """The flow network: nodes = the traversable cells of the stations' component, arcs = the
    orthogonal moves between them, ``0..m-1`` along their run, ``m..2m-1`` against it."""

    cells: np.ndarray        # node -> flat cell
    tail: np.ndarray         # arc -> node
    head: np.ndarray
    run: np.ndarray          # arc -> run index
    cost: np.ndarray         # arc -> base cost (1 + keep right)
    m: int
    n_runs: int

    @property
    def n(self) -> int:
        return len(self.cells)

    @cached_property
    def arc_id(self) -> dict[int, int]:
        """``tail * n + head`` -> arc."""
        return {int(t) * self.n + int(h): j for j, (t, h) in enumerate(zip(self.tail, self.head))}

    def graph(self, cost: np.ndarray, open_arc: np.ndarray):
        from scipy.sparse import csr_matrix

        return csr_matrix((cost[open_arc], (self.tail[open_arc], self.head[open_arc])), shape=(self.n, self.n))

    def strongly_connected(self, open_arc: np.ndarray) -> bool:
        from scipy.sparse.csgraph import connected_components

        return connected_components(self.graph(self.cost, open_arc), directed=True, connection="strong")[0] == 1

    def run_flows(self, flow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per run: the flow along it and against it."""
        m = self.m
        return (np.bincount(self.run[:m], weights=flow[:m], minlength=self.n_runs),
                np.bincount(self.run[m:], weights=flow[m:], minlength=self.n_runs))

    def opposed(self, flow: np.ndarray) -> float:
        """Share of the flow (cells driven) on runs driven both ways that meets opposing flow."""
        fwd, back = self.run_flows(flow)
        total = float(fwd.sum() + back.sum())
        return float(2 * np.minimum(fwd, back).sum() / total) if total > 0 else 0.0


def _lanes(free: np.ndarray, runs: Sequence[Sequence[int]], tails: np.ndarray, heads: np.ndarray,
           run_of: np.ndarray, narrow: int) -> np.ndarray:
    """Per edge: its lane (ours), the unit a direction is chosen for. A run is cut where it enters or
    leaves a narrow corridor (at most ``narrow`` cells across: two discs in neighbouring runs of it
    cannot pass each other, e.g. a 2 m aisle on a 0.5 m grid has two rows of cells the disc fits
    on, 0.5 m apart), so an aisle is a lane of its own, not one with the cross aisle beyond it; and
    the parallel pieces side by side in a narrow corridor are one lane (one direction for all of
    them, else opposing robots would meet head-on in it anyway). Lanes numbered from 0."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    h, w = free.shape
    across = np.ones((2, h * w), dtype=np.int64)       # [0]: free extent along the column, [1]: along the row
    for cells in runs:
        vertical = cells[1] - cells[0] != 1
        across[0 if vertical else 1, cells] = len(cells)
    horizontal = heads - tails == 1
    width = np.where(horizontal, np.maximum(across[0, tails], across[0, heads]),
                     np.maximum(across[1, tails], across[1, heads]))
    is_narrow = width <= narrow
    # pieces: runs cut where the narrow flag changes (a run's edges are consecutive, in order)
    new = np.ones(len(tails), dtype=bool)
    new[1:] = (run_of[1:] != run_of[:-1]) | (is_narrow[1:] != is_narrow[:-1])
    piece = np.cumsum(new) - 1
    n_pieces = int(piece[-1]) + 1 if len(piece) else 0
    # each narrow edge joins its piece to that of the parallel narrow edge below / to the right of it
    orient = horizontal.astype(np.int64)
    edge_at = np.full((2, h * w), -1, dtype=np.int64)  # [orientation (1: horizontal), tail cell] -> edge
    edge_at[orient, tails] = np.arange(len(tails))
    k = np.nonzero(is_narrow)[0]
    beside = tails[k] + np.where(horizontal[k], w, 1)
    k, beside = k[beside < h * w], beside[beside < h * w]
    other = edge_at[orient[k], beside]
    k, other = k[other >= 0], other[other >= 0]
    k, other = k[is_narrow[other]], other[is_narrow[other]]
    g = csr_matrix((np.ones(len(k)), (piece[k], piece[other])), shape=(n_pieces, n_pieces))
    _, label = connected_components(g, directed=False)
    return label[piece]


def _net(grid: GridMap, radius: float, stations: Mapping[str, Point], keep_right: float,
         parked: Sequence[Point] = ()) -> tuple[_Net, dict]:
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    free = free_cells(grid, radius).copy()
    h, w = free.shape
    res = grid.resolution
    for x, y in parked:   # no centre within 2 radii of a parked robot (its cells stay unrestricted)
        c0, c1 = max(int((x - 2 * radius) / res) - 1, 0), min(int((x + 2 * radius) / res) + 2, w)
        r0, r1 = max(int((y - 2 * radius) / res) - 1, 0), min(int((y + 2 * radius) / res) + 2, h)
        cols, rows = np.meshgrid(np.arange(c0, c1), np.arange(r0, r1))
        near = ((cols + 0.5) * res - x) ** 2 + ((rows + 0.5) * res - y) ** 2 < (2 * radius) ** 2
        free[rows[near], cols[near]] = False
    runs, tails, heads, run_of = _runs(free)
    g = csr_matrix((np.ones(len(tails)), (tails, heads)), shape=(h * w, h * w))
    _, label = connected_components(g, directed=False)
    st_cell = {s: _nearest_free(free, grid, p) for s, p in stations.items()}
    comp = np.bincount([label[c] for c in st_cell.values()]).argmax() if st_cell else 0
    cells = np.nonzero(free.ravel() & (label == comp))[0]
    node = np.full(h * w, -1, dtype=np.int64)
    node[cells] = np.arange(len(cells))
    keep = node[tails] >= 0
    narrow = int(math.floor(2 * radius / grid.resolution - 1e-9)) + 1   # (k - 1) cells apart < 2 radius
    lane_of = _lanes(free, runs, tails, heads, run_of, narrow)
    tails, heads, run_of = tails[keep], heads[keep], lane_of[keep]
    arc_t = np.concatenate([tails, heads])
    arc_h = np.concatenate([heads, tails])
    dcol = arc_h % w - arc_t % w
    drow = arc_h // w - arc_t // w
    rc, rr = arc_t % w - drow, arc_t // w + dcol            # the cell on the right (y down): (-drow, dcol)
    right_free = (rc >= 0) & (rc < w) & (rr >= 0) & (rr < h)
    right_free[right_free] = free[rr[right_free], rc[right_free]]
    net = _Net(cells, node[arc_t], node[arc_h], np.concatenate([run_of, run_of]), 1.0 + keep_right * right_free,
               len(tails), int(lane_of.max()) + 1 if len(lane_of) else 0)
    return net, {s: int(node[c]) for s, c in st_cell.items()}


def _sources(st_node: Mapping[str, int],
             demand: Mapping[tuple[str, str], float]) -> list[tuple[int, dict[int, float]]]:
    """One commodity per station with demand out of it: (its node, {destination node: demand}),
    the demand scaled to a total of 1."""
    out: dict[int, dict[int, float]] = {}
    for (a, b), v in demand.items():
        if v > 0 and a != b and a in st_node and b in st_node and st_node[a] != st_node[b]:
            d = out.setdefault(st_node[a], {})
            d[st_node[b]] = d.get(st_node[b], 0.0) + float(v)
    total = sum(sum(d.values()) for d in out.values()) or 1.0
    return [(s, {t: v / total for t, v in d.items()}) for s, d in sorted(out.items())]


def _path_flows(net: _Net, cost: np.ndarray, open_arc: np.ndarray,
                sources: Sequence[tuple[int, Mapping[int, float]]]) -> np.ndarray:
    """The optimum of the multi-commodity min-cost flow :func:`_flow_lp` states, by shortest-path
    trees: without capacities the commodities do not interact (the program's matrix is block
    diagonal) and one source's optimal flow is its shortest-path tree to its destinations (a
    classical result; test_roadmap checks the objectives agree with HiGHS). Flow per arc."""
    from scipy.sparse.csgraph import dijkstra

    flow = np.zeros(len(cost))
    if not sources:
        return flow
    arc_id = net.arc_id
    dist, pred = dijkstra(net.graph(cost, open_arc), indices=[s for s, _ in sources], return_predecessors=True)
    n = net.n
    for k, (s, dests) in enumerate(sources):
        acc: dict[int, float] = {}
        for t, v in dests.items():
            if not np.isfinite(dist[k, t]):
                raise ValueError("armo: a station cannot reach another along the lanes")
            acc[t] = acc.get(t, 0.0) + v
        p = pred[k]
        # push the demand up the tree, farthest nodes first (each node once, with all it carries)
        heap = [(-dist[k, t], t) for t in acc]
        heapq.heapify(heap)
        seen = set()
        while heap:
            _, v = heapq.heappop(heap)
            if v in seen or v == s:
                continue
            seen.add(v)
            u = int(p[v])
            flow[arc_id[u * n + v]] += acc[v]
            if u not in acc:
                acc[u] = 0.0
                heapq.heappush(heap, (-dist[k, u], u))
            acc[u] += acc[v]
    return flow


def _flow_lp(net: _Net, cost: np.ndarray, open_arc: np.ndarray,
             sources: Sequence[tuple[int, Mapping[int, float]]]) -> tuple[np.ndarray, float]:
    """ARMO's flow program as a linear program (SciPy's HiGHS): one commodity per source station,
    flow conservation at every cell, arcs closed by the lanes bounded to 0, minimum total cost.
    (flow per arc summed over commodities, objective). The reference :func:`_path_flows` is checked
    against; too slow to solve at warehouse scale (a 161 x 63 map with 16 commodities: 280 896
    variables, 47 s CPU for one solve, more than 1000 s wall on the loaded machine)."""
    from scipy.optimize import linprog
    from scipy.sparse import block_diag, coo_matrix

    n, n_arcs = net.n, len(cost)
    inc = coo_matrix((np.concatenate([np.ones(n_arcs), -np.ones(n_arcs)]),
                      (np.concatenate([net.tail, net.head]), np.concatenate([np.arange(n_arcs)] * 2))),
                     shape=(n, n_arcs)).tocsr()
    supplies = []
    for s, dests in sources:
        b = np.zeros(n)
        for t, v in dests.items():
            b[t] += v
        b[s] -= b.sum()
        supplies.append(-b)          # out-flow minus in-flow: +supply at the source, -demand at sinks
    k = len(supplies)
    ub = np.tile(np.where(open_arc, np.inf, 0.0), k)
    res = linprog(np.tile(cost, k), A_eq=block_diag([inc] * k, format="csr"), b_eq=np.concatenate(supplies),
                  bounds=np.column_stack([np.zeros(len(ub)), ub]), method="highs")
    if not res.success:
        raise ValueError(f"armo: the flow program has no solution ({res.message})")
    return res.x.reshape(k, n_arcs).sum(axis=0), float(res.fun)


def armo_roadmap(grid: GridMap, radius: float, stations: Mapping[str, Point],
                 demand: Mapping[tuple[str, str], float], *, minor_share: float = 0.2, keep_right: float = 0.2,
                 head_on: float = 1.0, iterations: int = 8, rounds: int = 3, time_limit_s: float = 120.0,
                 name: str = "armo", parked: Sequence[Point] = ()) -> tuple[RoadMap, ArmoInfo]:
    """ARMO's road map for discs of ``radius``: one-way runs where the demand allows.

    The program (the paper's idea: "based on linear programming, ARMO computes an optimal road map
    according to environmental constraints and the demand for transportation tasks from stations";
    the formulation is ours): the demand-weighted multi-commodity min-cost flow over the directed
    orthogonal moves between the cells the disc fits on (one commodity per station with demand out
    of it), each move costing its length plus ``keep_right`` when the cell on its right is free
    (keep right: opposing flows take opposite sides of a wide aisle). It has no capacities, so its
    optimum is a shortest-path tree per commodity, which is how it is solved (:func:`_path_flows`;
    the same program for HiGHS is :func:`_flow_lp`, checked to agree).

    Head-on traffic (ours; ARMO separates opposing lanes, the flow program alone does not: with
    demand both ways every aisle carries both): ``iterations`` rounds of successive averages, each
    move costing ``head_on`` times the share of its run's flow going the other way on top, so
    opposing flows settle in different parallel aisles.

    Rounding, in ``rounds`` rounds: a run (maximal straight row or column stretch of cells: an
    aisle lane) whose flow against its main direction is at most ``minor_share`` of the flow along
    it becomes one-way, the clearest first, unless that breaks the strong connectivity of the free
    space (every cell keeps a way to every other, so no lane is a dead end and every station
    reaches every other both ways); then the flows are solved again along the lanes. Runs no flow
    uses stay two-way. No new round starts after ``time_limit_s`` CPU seconds (of this thread).
    ``demand[(a, b)]``: how often robots drive from station a to station b (any scale).

    ``parked`` (ours): where robots stand parked (their homes): the lanes are laid out round them,
    so a parked robot never cuts the only way along the lanes (on a map of two-way moves a robot
    can turn back; on one-way lanes it cannot). The cells near them keep every move. When the
    space round them is not connected, they are left out."""
    import time

    from .budget import Budget

    # CPU seconds of this thread (a loaded machine stopped the rounding early with a wall-clock limit:
    # on `large` 100 at load 20, 'time limit' after 145 s with 492 one-way runs against 541 at 'optimal',
    # so ARMO rows ran on another road map), with the budget's wall-clock backstop
    t0, budget = time.thread_time(), Budget(time_limit_s)
    net, st_node = _net(grid, radius, stations, keep_right, parked)
    if parked and not net.strongly_connected(np.ones(2 * net.m, dtype=bool)):
        net, st_node = _net(grid, radius, stations, keep_right)
    sources = _sources(st_node, demand)
    m = net.m
    open_arc = np.ones(2 * m, dtype=bool)
    if not net.strongly_connected(open_arc):
        raise ValueError("armo: the free space of the stations is not connected")
    is_fwd = np.arange(2 * m) < m

    def equilibrium(open_arc: np.ndarray) -> np.ndarray:
        # successive averages, one commodity after the other (all at once, two opposing flows of
        # the same size would swap aisles together for ever)
        own = [_path_flows(net, net.cost, open_arc, [c]) for c in sources]
        flow = np.sum(own, axis=0)
        for it in range(2, max(iterations, 1) + 1):
            for k, c in enumerate(sources):
                fwd, back = net.run_flows(flow)
                tot = (fwd + back)[net.run]
                share = np.where(is_fwd, back[net.run], fwd[net.run]) / np.maximum(tot, 1e-12)
                step = (_path_flows(net, net.cost * (1.0 + head_on * share), open_arc, [c]) - own[k]) / it
                own[k] += step
                flow += step
        return flow

    open_objective = float(_path_flows(net, net.cost, open_arc, sources) @ net.cost)
    opposed_open = net.opposed(_path_flows(net, net.cost, open_arc, sources))
    one_way_runs: set[int] = set()
    status = "no demand" if not sources else "optimal"
    for _ in range(max(rounds, 0) if sources else 0):
        if budget.passed():
            status = "time limit"
            break
        flow = equilibrium(open_arc)
        fwd, back = net.run_flows(flow)
        major, minor = np.maximum(fwd, back), np.minimum(fwd, back)
        cand = [int(r) for r in np.nonzero((major > 1e-9) & (minor <= minor_share * major))[0]
                if r not in one_way_runs]
        cand.sort(key=lambda r: (minor[r] / major[r], -major[r]))          # the clearest, busiest first
        added = 0
        for r in cand:
            against = (net.run == r) & (~is_fwd if fwd[r] >= back[r] else is_fwd)
            trial = open_arc & ~against
            if net.strongly_connected(trial):
                open_arc = trial
                one_way_runs.add(r)
                added += 1
        if not added:
            break
    flow = _path_flows(net, net.cost, open_arc, sources)
    h, w = grid.blocked.shape
    allowed = np.full((h, w), ALL_ORTHOGONAL, dtype=np.uint8)
    for j in np.nonzero(~open_arc)[0]:   # the move against the lane is forbidden
        t_cell, h_cell = int(net.cells[net.tail[j]]), int(net.cells[net.head[j]])
        d = (h_cell % w - t_cell % w, h_cell // w - t_cell // w)
        allowed[t_cell // w, t_cell % w] &= np.uint8(~_BIT[d] & 0xFF)
    rm = RoadMap(allowed, grid.resolution, name, float(radius))
    info = ArmoInfo(net.n, int(len(np.unique(net.run))), len(one_way_runs), len(sources), 2 * m * len(sources),
                    status, float(flow @ net.cost), time.thread_time() - t0, open_objective, opposed_open,
                    net.opposed(flow))
    return rm, info


def demand_of(deliveries: Sequence, stations: Sequence[str]) -> dict[tuple[str, str], float]:
    """Driving demand of a delivery sequence (objects with ``pick`` and ``drop``): loaded legs pick
    -> drop, and the empty legs from each drop to the next pick (robots take the next delivery)."""
    out: dict[tuple[str, str], float] = {}
    for d in deliveries:
        out[(d.pick, d.drop)] = out.get((d.pick, d.drop), 0.0) + 1.0
    picks = [d.pick for d in deliveries]
    drops = [d.drop for d in deliveries]
    pick_share = {s: picks.count(s) / len(picks) for s in set(picks)} if picks else {}
    for s in set(drops):
        n = drops.count(s)
        for p, share in pick_share.items():
            if p != s:
                out[(s, p)] = out.get((s, p), 0.0) + n * share
    return out


def draw_lanes(ax, grid: GridMap, lanes: RoadMap, radius: float | None = None, zorder: float = 1.5) -> None:
    """Draw the road map on a matplotlib axis (map coordinates, y down): one-way moves as small
    arrows, two-way neighbour pairs as thin grey lines."""
    from matplotlib.collections import LineCollection

    free = free_cells(grid, radius if radius is not None else (lanes.radius or 0.354))
    one, two = lanes.arrows(free)
    if len(two):
        ax.add_collection(LineCollection(list(two.reshape(-1, 2, 2)), colors=[(0.6, 0.6, 0.6, 0.5)], linewidths=0.4,
                                         zorder=zorder), autolim=False)
    if len(one):
        ax.quiver(one[:, 0], one[:, 1], one[:, 2], one[:, 3], angles="xy", scale_units="xy", scale=1.25,
                  color=(0.1, 0.35, 0.8, 0.8), width=0.0025, headwidth=4, headlength=4, zorder=zorder)


def plot_roadmap(grid: GridMap, lanes: RoadMap, path_png: str | Path,
                 stations: Mapping[str, Point] | None = None, title: str | None = None) -> None:
    """The map with its road map (and stations) to a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    w, h = grid.size_m
    fig, ax = plt.subplots(figsize=(min(16.0, max(6.0, w / 3)), min(12.0, max(4.0, h / 3))))
    ax.imshow(np.where(grid.blocked, 0.25, 0.97), cmap="gray", vmin=0, vmax=1, extent=(0, w, h, 0),
              origin="upper", interpolation="nearest")
    draw_lanes(ax, grid, lanes)
    for x, y in (stations or {}).values():
        ax.plot(x, y, "s", color="green", ms=5)
    ax.set(xlim=(0, w), ylim=(h, 0), aspect="equal", title=title or f"road map {lanes.name}",
           xlabel="x [m]", ylabel="y [m] (downwards)")
    fig.tight_layout()
    Path(path_png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path_png, dpi=120)
    plt.close(fig)
