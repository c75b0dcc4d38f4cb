"""Where robots may stand for long on a map: stations and parking spots that cut no passage.

* :func:`spread_stations` - stations spread over a map's free space (farthest-point sampling);
* :func:`choose_spots` - parking spots: the robots' homes, places to queue near busy stations, spares;
* :func:`driving_distances` - shortest driving distance from points to every cell.

A robot standing on a station or a parking spot is a disc of :data:`ROBOT_RADIUS`; it must leave
every other robot a way past it (:meth:`_StandingPlaces.usable`), and every parked robot must be
able to drive off again.
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from ..grid import GridMap
from ..model import Point
from ..paths import PathFinder

#: a 0.5 m x 0.5 m robot as a disc: half its diagonal
ROBOT_RADIUS = math.hypot(0.25, 0.25)
#: parked discs keep this much more than touching from each other and from stations
SPOT_MARGIN = 0.05
#: parking spots keep this far from every station (outside the behaviour layer's docking region)
STATION_CLEARANCE = 2.0
#: attempts at a set of spots every robot can leave (spots that shut a robot in are replaced)
_SPOT_ROUNDS = 8
#: packed spots (:func:`choose_spots` ``packed``, ours, for crowds the spread homes cannot hold): this far
#: from every station, the behaviour layer's docking region (``BehaviorParams.dock_region``)
PACKED_STATION_CLEARANCE = 1.5
#: :func:`queue_places` with ``keep``: the key of the parking spots kept
KEPT = ""
#: packed spots: only in passages whose free space for a robot's centre is at least this wide (m): a
#: parked robot against one side leaves a way for another past it
PACKED_MIN_PASSAGE = 2.0


class _StandingPlaces:
    """Cells a parked disc may take without cutting a passage for the other robots.

    ``free`` is where the centre of a robot fits (the path finder's mask, restricted to the largest
    4-connected part so every place is reachable from every other); ``taken`` the cells no robot
    centre may use because a station or a parking spot keeps them for a parked disc.
    """

    def __init__(self, grid: GridMap, radius: float):
        self.grid = grid
        free = PathFinder(grid, radius).free
        labels, count = ndimage.label(free)
        if count == 0:
            raise ValueError(f"{grid.name}: no cell fits a disc of radius {radius:g} m")
        largest = 1 + int(np.argmax(ndimage.sum_labels(free, labels, range(1, count + 1))))
        self.free = labels == largest
        self.taken = np.zeros_like(self.free)
        reach = 2 * radius + SPOT_MARGIN
        self.k = int(math.ceil(reach / grid.resolution))
        dc, dr = np.meshgrid(np.arange(-self.k, self.k + 1), np.arange(-self.k, self.k + 1))
        self.footprint = np.hypot(dc, dr) * grid.resolution < reach
        # the cells just outside a footprint: where a parked robot drives off to
        ring = ndimage.binary_dilation(np.pad(self.footprint, 1), np.ones((3, 3), bool)) & ~np.pad(self.footprint, 1)
        self.ring = np.argwhere(ring) - (self.k + 1)      # (drow, dcol) offsets
        self.window = self.k + max(2, int(math.ceil(1.0 / grid.resolution)))
        self.centres: list[tuple[int, int]] = []          # (col, row) of every station and spot

    def take(self, col: int, row: int) -> None:
        _stamp(self.taken, col, row, self.footprint)
        self.centres.append((col, row))

    def usable(self, col: int, row: int) -> bool:
        """The disc fits here, nothing is parked close, and parking here cuts no passage: within
        a window around the cell, the free cells on the window's border that were connected stay
        connected and no free pocket is cut off; and every robot parked close by (this one too)
        can still drive off to the window's border when all the others are parked."""
        if not self.free[row, col] or self.taken[row, col]:
            return False
        m, h, w = self.window, self.grid.height, self.grid.width
        r0, r1, c0, c1 = max(0, row - m), min(h, row + m + 1), max(0, col - m), min(w, col + m + 1)
        before = self.free[r0:r1, c0:c1] & ~self.taken[r0:r1, c0:c1]
        parked = np.zeros_like(before)
        _stamp(parked, col - c0, row - r0, self.footprint)
        after = before & ~parked
        lab_b, _ = ndimage.label(before)
        lab_a, n_a = ndimage.label(after)
        border = np.zeros_like(before)
        border[[0, -1], :] = True
        border[:, [0, -1]] = True
        if not (lab_b[row - r0, col - c0] and (border & (lab_b == lab_b[row - r0, col - c0])).any()):
            return False                              # an enclosed pocket of the window
        for comp in np.unique(lab_b[border & before]):
            if len(np.unique(lab_a[border & (lab_b == comp) & after])) > 1:
                return False                          # border cells separated
        on_border = set(np.unique(lab_a[border & after]).tolist())
        if not all(a in on_border for a in range(1, n_a + 1)):
            return False                              # a pocket cut off
        return self._all_can_leave(col, row)

    def _all_can_leave(self, col: int, row: int) -> bool:
        k, h, w = self.k, self.grid.height, self.grid.width
        m = 3 * k + 2                                 # holds the rings of all parked neighbours
        r0, r1, c0, c1 = max(0, row - m), min(h, row + m + 1), max(0, col - m), min(w, col + m + 1)
        blocked = self.taken[r0:r1, c0:c1].copy()
        _stamp(blocked, col - c0, row - r0, self.footprint)
        lab, _ = ndimage.label(self.free[r0:r1, c0:c1] & ~blocked)
        outer = np.unique(np.concatenate([lab[[0, -1], :].ravel(), lab[:, [0, -1]].ravel()]))
        outer = outer[outer > 0]
        for c, r in self.centres + [(col, row)]:
            if abs(c - col) > 2 * k + 1 or abs(r - row) > 2 * k + 1:
                continue
            rr, cc = self.ring[:, 0] + r - r0, self.ring[:, 1] + c - c0
            inside = (rr >= 0) & (rr < r1 - r0) & (cc >= 0) & (cc < c1 - c0)
            if not np.isin(lab[rr[inside], cc[inside]], outer).any():
                return False
        return True

    def cell(self, p: Point) -> tuple[int, int]:
        return self.grid.cell_of(*p)


class _TwoLanes:
    """Ours (queue places of ``queue="close"``): a parked disc must not cut a passage two robots wide. Two robots
    side by side pass where a disc of twice the radius passes, so the check is on the map of where the centre of
    that wide disc fits, clear of every disc parked so far: parking one more may not split a part of it into two
    parts that each hold the wide disc's own footprint (a nook it cuts off is no passage). A passage narrower than
    two robots is left to :meth:`_StandingPlaces.usable` (no cut)."""

    def __init__(self, places: _StandingPlaces, radius: float):
        self.free = PathFinder(places.grid, 2 * radius).free
        self.taken = np.zeros_like(self.free)
        res = places.grid.resolution
        reach = 3 * radius + SPOT_MARGIN   # a parked disc and the wide one just clear of it
        k = int(math.ceil(reach / res))
        dc, dr = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1))
        self.footprint = np.hypot(dc, dr) * res < reach
        self.min_part = max(1, int(np.count_nonzero(np.hypot(dc, dr) * res < 2 * radius)))
        self._parts = self._count(self.free)

    def _count(self, mask: np.ndarray) -> int:
        labels, n = ndimage.label(mask)
        return int(np.count_nonzero(np.bincount(labels.ravel(), minlength=n + 1)[1:] >= self.min_part))

    def take(self, col: int, row: int) -> None:
        _stamp(self.taken, col, row, self.footprint)
        self._parts = self._count(self.free & ~self.taken)

    def kept(self, col: int, row: int) -> bool:
        parked = np.zeros_like(self.taken)
        _stamp(parked, col, row, self.footprint)
        return self._count(self.free & ~(self.taken | parked)) <= self._parts


def _stamp(mask: np.ndarray, col: int, row: int, footprint: np.ndarray) -> None:
    """OR a square ``footprint`` centred on (col, row) into ``mask`` (clipped at the edges)."""
    k = footprint.shape[0] // 2
    h, w = mask.shape
    r0, c0 = row - k, col - k
    rs, cs = max(0, r0), max(0, c0)
    re, ce = min(h, r0 + 2 * k + 1), min(w, c0 + 2 * k + 1)
    if rs < re and cs < ce:
        mask[rs:re, cs:ce] |= footprint[rs - r0:re - r0, cs - c0:ce - c0]


def choose_spots(grid: GridMap, count: int, seed: int, stations: Sequence[Point] = (),
                 radius: float = ROBOT_RADIUS, queue: Sequence[int] = (), spare: int = 0,
                 packed: bool = False) -> list[Point]:
    """Parking spots where a parked robot cuts no passage, at least :data:`STATION_CLEARANCE`
    from every station and a disc apart from each other: ``count`` at seeded random places (the
    robots' homes), then ``queue[k]`` as close to ``stations[k]`` by driving distance as the map
    allows (where robots wait for the station; picked first, so they get the closest places), then
    up to ``spare`` more at random places where the map has room.

    The local rules of :meth:`_StandingPlaces.usable` are checked globally with the path finder:
    with a robot on every spot and every station, each of them must still be able to drive to the
    most open place of the map; spots that cannot (or that shut in a station) are dropped and others
    picked instead. Raises ValueError when the map has fewer than ``count`` places for the homes.

    ``packed`` (ours: a crowd the spread homes cannot hold, e.g. 200 robots on ``large``): the same
    rules, but the homes are lined up along the walls first, the widest passages first (parking rows,
    the seeded order only breaks ties), only :data:`PACKED_STATION_CLEARANCE` from the stations, and no
    queue spots (``queue`` is ignored); spare spots follow in the same order."""
    places = _StandingPlaces(grid, radius)
    for p in stations:
        places.take(*places.cell(p))
    rows, cols = np.nonzero(places.free & ~places.taken)
    centres = np.column_stack([(cols + 0.5) * grid.resolution, (rows + 0.5) * grid.resolution])
    if len(stations):
        clearance = PACKED_STATION_CLEARANCE if packed else STATION_CLEARANCE
        far = cKDTree(np.asarray(stations, dtype=float)).query(centres)[0] >= clearance
        rows, cols = rows[far], cols[far]

    def take(i: int) -> Point | None:
        if places.usable(int(cols[i]), int(rows[i])):
            places.take(int(cols[i]), int(rows[i]))
            return grid.centre(int(cols[i]), int(rows[i]))
        return None

    queued: list[Point] = []
    if not packed and any(q > 0 for q in queue):
        dist = driving_distances(grid, places.free, stations)[:, rows * grid.width + cols]
        ranked = [iter(np.argsort(d, kind="stable")) for d in dist]
        left = list(queue)
        for _ in range(max(queue)):           # round by round: every station gets its closest first
            for k in range(len(left)):
                if left[k] <= 0:
                    continue
                spot = next((q for i in ranked[k] if np.isfinite(dist[k, i]) and (q := take(int(i)))), None)
                left[k] = 0 if spot is None else left[k] - 1
                if spot is not None:
                    queued.append(spot)
    order = iter((_wall_first(places, rows, cols, seed) if packed else
                  np.random.default_rng(seed).permutation(len(rows))).tolist())
    homes: list[Point] = []
    hub: Point | None = None
    for _ in range(_SPOT_ROUNDS):
        while len(homes) < count + spare and (i := next(order, None)) is not None:
            if (spot := take(i)) is not None:
                homes.append(spot)
        if hub is None:   # the most open place once the spots are there
            open_space = ndimage.distance_transform_edt(places.free & ~places.taken)
            hub_row, hub_col = np.unravel_index(int(np.argmax(open_space)), open_space.shape)
            hub = grid.centre(int(hub_col), int(hub_row))
        shut = set(_shut_in(grid, radius, list(stations), homes + queued, hub))
        if not shut:
            break
        homes = [p for p in homes if p not in shut]
        queued = [p for p in queued if p not in shut]
    else:
        raise ValueError(f"{grid.name}: no set of parking spots found that every robot can leave")
    if len(homes) < count:
        raise ValueError(f"{grid.name}: only {len(homes)} parking spots that cut no passage, {count} needed "
                         f"(fewer robots or a larger map)")
    return homes[:count] + queued + homes[count:]


def queue_places(grid: GridMap, stations: dict[str, Point], spots: Sequence[Point], per_station: int | dict[str, int],
                 reach: float, radius: float = ROBOT_RADIUS, min_gap: float = 0.0,
                 keep: Sequence[Point] = (), two_lanes: bool = False,
                 prune_one: bool = False) -> dict[str, list[Point]]:
    """Ours (issue 8, the central methods' ``queue="near"`` and ``"close"``): up to ``per_station`` places to
    queue on per station (or as many as it gives the station: a dict), the closest to it by driving distance, at
    most ``reach`` m of driving from it and at least ``min_gap`` m (straight line) from it; each cuts no passage
    with a robot on every station, every parking spot of ``spots`` and every other queue place
    (:meth:`_StandingPlaces.usable`, then the global check of :func:`choose_spots`: a place from which a robot
    could not leave is dropped). The stations take turns, closest place first, so every station gets its
    nearest places; a place goes to one station only. Returns station -> its places, nearest first.

    ``keep`` (``"close"``): more parking spots, placed *after* the new places where they still fit (a spot
    that would cut a passage or shut in a place is left out); the kept ones are returned under the key
    :data:`KEPT` (not a station), in the order of ``keep``. ``two_lanes`` (``"close"``): a new place also
    cuts no passage two robots wide (:class:`_TwoLanes`). ``prune_one`` (``"close"``): when a robot on a spot
    or place could not leave, only the new place or kept spot nearest to it goes (else every one within two
    discs), in more rounds."""
    places = _StandingPlaces(grid, radius)
    lanes = _TwoLanes(places, radius) if two_lanes else None
    for p in list(stations.values()) + list(spots):
        places.take(*places.cell(p))
        if lanes is not None:
            lanes.take(*places.cell(p))
    rows, cols = np.nonzero(places.free & ~places.taken)
    names = list(stations)
    out: dict[str, list[Point]] = {s: [] for s in names}
    quota = per_station if isinstance(per_station, dict) else dict.fromkeys(names, per_station)
    if not len(rows) or not names or max(quota.values(), default=0) <= 0:
        return {**out, KEPT: list(keep)} if keep else out
    dist = driving_distances(grid, places.free, [stations[s] for s in names])[:, rows * grid.width + cols]
    centres = np.column_stack([(cols + 0.5) * grid.resolution, (rows + 0.5) * grid.resolution])
    for k, s in enumerate(names):   # too close to the station (straight line), or beyond reach: never
        dist[k, np.hypot(*(centres - np.asarray(stations[s])).T) < min_gap] = np.inf
    dist[dist > reach] = np.inf
    ranked = [[int(i) for i in np.argsort(d, kind="stable") if np.isfinite(d[i])] for d in dist]
    for n in range(max(quota.values())):   # round by round: every station gets its closest first
        for k, s in enumerate(names):
            while ranked[k] and quota.get(s, 0) > n:
                i = ranked[k].pop(0)
                c, r = int(cols[i]), int(rows[i])
                if places.usable(c, r) and (lanes is None or lanes.kept(c, r)):
                    places.take(c, r)
                    if lanes is not None:
                        lanes.take(c, r)
                    out[s].append(grid.centre(c, r))
                    break
    kept = []
    for p in keep:   # ("close") the other parking spots where they still fit beside the places
        if places.usable(*places.cell(p)):
            places.take(*places.cell(p))
            kept.append(p)
    open_space = ndimage.distance_transform_edt(places.free & ~places.taken)
    hub_row, hub_col = np.unravel_index(int(np.argmax(open_space)), open_space.shape)
    hub = grid.centre(int(hub_col), int(hub_row))
    for _ in range(2 * _SPOT_ROUNDS if prune_one else _SPOT_ROUNDS):
        every = [p for ps in out.values() for p in ps] + kept
        shut = _shut_in(grid, radius, list(stations.values()), list(spots) + every, hub) if every else []
        if not shut:
            break
        # a shut-in place goes, and so do the new places next to a shut-in parking spot (they shut it in)
        near = 2 * (2 * radius + SPOT_MARGIN)
        if prune_one:   # ("close") only the one new place or kept spot nearest to each shut-in spot or place
            ours = [p for p in every if p not in shut]
            gone = set(shut) | {min(ours, key=lambda p: math.dist(p, q)) for q in shut
                                if q not in every and ours and min(math.dist(p, q) for p in ours) <= near}
        else:
            gone = set(shut) | {p for p in every if any(math.dist(p, q) <= near for q in shut)}
        out = {s: [p for p in ps if p not in gone] for s, ps in out.items()}
        kept = [p for p in kept if p not in gone]
    else:   # no set of places every robot can leave: none, the parking spots as they were
        out, kept = {s: [] for s in names}, list(keep)
    if keep:
        out[KEPT] = kept
    return out


def _wall_first(places: _StandingPlaces, rows: np.ndarray, cols: np.ndarray, seed: int) -> np.ndarray:
    """Ours (packed spots): the candidate cells closest to a wall first (rows of robots along it), among
    those the ones in the widest passages, ties in seeded random order; none in a passage narrower than
    :data:`PACKED_MIN_PASSAGE` (a robot parked there would leave no room for one to pass)."""
    edt = ndimage.distance_transform_edt(places.free)
    reach = int(round(PACKED_MIN_PASSAGE / places.grid.resolution))
    width = ndimage.maximum_filter(edt, size=reach + 1)[rows, cols] * places.grid.resolution
    tie = np.random.default_rng(seed).random(len(rows))
    order = np.lexsort((tie, -width, edt[rows, cols]))
    return order[width[order] >= PACKED_MIN_PASSAGE / 2]


def _shut_in(grid: GridMap, radius: float, stations: list[Point], spots: list[Point], hub: Point) -> list[Point]:
    """Spots from which a robot cannot drive to ``hub`` while a robot stands on every other spot
    and station, plus the spots around a station that is shut in that way."""
    finder = PathFinder(grid, radius)
    discs = [(p, 2 * radius + SPOT_MARGIN) for p in stations + spots]
    out = [p for p in spots if finder.find(p, hub, avoid=discs) is None]
    for st in stations:
        if finder.find(st, hub, avoid=discs) is None:
            out += [p for p in spots if math.dist(p, st) < STATION_CLEARANCE + 2 * radius + 1.0]
    return out


def driving_distances(grid: GridMap, free: np.ndarray, points: Sequence[Point]) -> np.ndarray:
    """``(len(points), height * width)``: length of the shortest 8-connected drive (no corner
    cutting) over the ``free`` cells from the cell of each point to every cell (inf: unreachable)."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    h, w = free.shape
    idx = np.arange(h * w).reshape(h, w)
    src, dst, length = [], [], []
    for dc, dr in ((1, 0), (0, 1), (1, 1), (1, -1)):
        r0, r1, c1 = max(0, -dr), h - max(0, dr), w - dc      # moves from [r0:r1, 0:c1] by (dr, dc)
        ok = free[r0:r1, :c1] & free[r0 + dr:r1 + dr, dc:]
        if dc and dr:   # a diagonal move needs both cells beside it
            ok &= free[r0 + dr:r1 + dr, :c1] & free[r0:r1, dc:]
        ia, ib = idx[r0:r1, :c1][ok], idx[r0 + dr:r1 + dr, dc:][ok]
        src += [ia, ib]
        dst += [ib, ia]
        length.append(np.full(2 * len(ia), math.hypot(dc, dr) * grid.resolution))
    graph = csr_matrix((np.concatenate(length), (np.concatenate(src), np.concatenate(dst))), shape=(h * w, h * w))
    cells = [grid.cell_of(*p) for p in points]
    return np.atleast_2d(dijkstra(graph, indices=[r * w + c for c, r in cells]))


def spread_stations(grid: GridMap, count: int, seed: int, radius: float = ROBOT_RADIUS) -> dict[str, Point]:
    """``count`` stations ``S1``, ``S2``... at free cells spread over the map (farthest-point
    sampling from a seeded first pick), each one where a docked robot cuts no passage."""
    places = _StandingPlaces(grid, radius)
    rows, cols = np.nonzero(places.free)
    centres = np.column_stack([(cols + 0.5) * grid.resolution, (rows + 0.5) * grid.resolution])
    rng = np.random.default_rng(seed)
    dist = np.full(len(rows), np.inf)
    out: dict[str, Point] = {}
    for n in range(count):
        ranked = rng.permutation(len(rows)) if n == 0 else np.argsort(-dist, kind="stable")
        for i in ranked:
            if dist[i] <= 0:
                break
            if places.usable(int(cols[i]), int(rows[i])):
                places.take(int(cols[i]), int(rows[i]))
                out[f"S{n + 1}"] = grid.centre(int(cols[i]), int(rows[i]))
                dist = np.minimum(dist, np.hypot(*(centres - centres[i]).T))
                break
        else:
            raise ValueError(f"{grid.name}: room for only {n} stations, {count} asked for")
    return out
