"""Delivery simulation of paper 002, section V: N robots serve a fixed sequence of delivery tasks.

A *task* is "drive to station k, dock there, drive to station l, dock there". Every robot takes the
next task of one seeded sequence whenever it has finished its previous one; when the sequence is
used up it drives back to its home parking spot (or the closest free one). The run ends when every
delivery is done (its completion time is CTime), at a cap on simulated time, or when nothing has
moved for a long time (a stall).
Everything runs in simulated time, much faster than real time, without ROS.

Methods (:data:`METHODS`):

* ``md`` / ``md-box`` - central: each time a robot needs a new leg,
  :meth:`~fleet_planner.planners.md.MDPlanner.plan_incremental` plans it around the trajectories
  every other robot is driving (robots standing still are one-waypoint trajectories); robots follow
  their timed paths exactly. ``md-box`` uses the paper's collision boxes, ``md`` the exact regions.
* ``prior`` - the same flow with :meth:`~fleet_planner.planners.prior.PriorPlanner.plan_incremental`.
* ``behavior`` - BBMRCA: :class:`~fleet_planner.behavior.BehaviorFleet`, each robot plans its own A*
  path and the behaviours resolve conflicts locally, stepped with a fixed ``dt``.

Station discipline of the central methods (the behaviour layer has its own, the docking arbiter):
a planner needs a robot's goal to be free for ever after it arrives, so a station is *claimed* by
one robot from the moment it sets off for it until its next leg is planned. So that a station is
not held idle while its claimant drives from afar, a robot claims it only from within
:data:`CLAIM_RADIUS`; from farther away, or when the station is claimed, it first drives to the
free parking spot closest to the station (some spots are placed near the busy stations for this)
and queues there, first come first served. A robot that would block a station others queue for
(its next leg leaves more than :data:`EVACUATE_S` later, or cannot be planned) clears it for a
parking spot when that is sooner. Parking spots are chosen so that a robot parked on one never
cuts a passage (:func:`choose_spots`). A leg that cannot be planned is tried again a little later,
once some other robot got a new leg. These rules are the simulation's, the same for md and prior.

Measured per run (:class:`DeliveryResult`): CTime, a lower bound (each robot's own task sequence
driven alone: shortest-path legs at top speed plus docking, maximum over robots), the average
velocity (distance driven / CTime, averaged over robots), planner or decision wall time, the
number of pairs of discs that ever overlap (exactly on the executed trajectories for the central
methods, at every step for ``behavior``) and the robots left deadlocked.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .grid import GridMap
from .model import Plan, PlanningError, Point, RobotSpec, TimedPath
from .paths import PathFinder

METHODS = ("md", "md-box", "prior", "behavior")
#: a 0.5 m x 0.5 m robot as a disc: half its diagonal
ROBOT_RADIUS = math.hypot(0.25, 0.25)
TOP_SPEED = 0.8
DOCK_S = 5.0
#: parked discs keep this much more than touching from each other and from stations
SPOT_MARGIN = 0.05
#: parking spots keep this far from every station (outside the behaviour layer's docking region)
STATION_CLEARANCE = 2.0
#: central methods: a robot claims a station only from this close (m, straight line; from a parking
#: spot: driving distance); from farther away it first drives to a parking spot near the station
CLAIM_RADIUS = 8.0
#: central methods: a robot with no parking spot free to queue on decides again this much later (s)
RETARGET_S = 5.0
#: central methods: a robot on a station others queue for whose next leg would leave only this much
#: later (s), or could not be planned, drives to a parking spot near it instead if that is sooner
EVACUATE_S = 10.0

#: progress callback: (deliveries done, deliveries in total, simulated time)
SimProgress = Callable[[int, int, float], None]


# ---------------------------------------------------------------------------------------------
# the problem
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Task:
    """One delivery: load at station ``pick``, unload at station ``drop``."""

    pick: str
    drop: str


@dataclass
class DeliveryProblem:
    """Map, stations, the task sequence and where the robots start.

    ``spots`` are the parking spots, the robots' homes first (robot i starts on ``spots[i]``).
    """

    name: str
    grid: GridMap
    stations: dict[str, Point]
    tasks: list[Task]
    spots: list[Point]
    n_robots: int
    radius: float = ROBOT_RADIUS
    max_speed: float = TOP_SPEED
    dock_s: float = DOCK_S

    def __post_init__(self) -> None:
        if self.n_robots < 1:
            raise ValueError(f"{self.name}: n_robots must be >= 1 (got {self.n_robots})")
        if len(self.spots) < self.n_robots:
            raise ValueError(f"{self.name}: {len(self.spots)} parking spots for {self.n_robots} robots")
        for k, task in enumerate(self.tasks):
            for s in (task.pick, task.drop):
                if s not in self.stations:
                    raise ValueError(f"{self.name}: tasks[{k}] names unknown station {s!r}")
        if not (self.dock_s >= 0 and math.isfinite(self.dock_s)):
            raise ValueError(f"{self.name}: dock_s must be a finite number >= 0 (got {self.dock_s!r})")

    @property
    def homes(self) -> list[Point]:
        return self.spots[:self.n_robots]

    def robot_ids(self) -> list[str]:
        return [f"r{i}" for i in range(self.n_robots)]


class _Layout:
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
                 radius: float = ROBOT_RADIUS, queue: Sequence[int] = (), spare: int = 0) -> list[Point]:
    """Parking spots where a parked robot cuts no passage, at least :data:`STATION_CLEARANCE`
    from every station and a disc apart from each other: ``count`` at seeded random places (the
    robots' homes), then ``queue[k]`` as close to ``stations[k]`` by driving distance as the map
    allows (where robots wait for the station; picked first, so they get the closest places), then
    up to ``spare`` more at random places where the map has room.

    The local rules of :meth:`_Layout.usable` are checked globally with the path finder: with a
    robot on every spot and every station, each of them must still be able to drive to the most
    open place of the map; spots that cannot (or that shut in a station) are dropped and others
    picked instead. Raises ValueError when the map has fewer than ``count`` places for the homes."""
    layout = _Layout(grid, radius)
    for p in stations:
        layout.take(*layout.cell(p))
    rows, cols = np.nonzero(layout.free & ~layout.taken)
    centres = np.column_stack([(cols + 0.5) * grid.resolution, (rows + 0.5) * grid.resolution])
    if len(stations):
        far = cKDTree(np.asarray(stations, dtype=float)).query(centres)[0] >= STATION_CLEARANCE
        rows, cols = rows[far], cols[far]

    def take(i: int) -> Point | None:
        if layout.usable(int(cols[i]), int(rows[i])):
            layout.take(int(cols[i]), int(rows[i]))
            return grid.centre(int(cols[i]), int(rows[i]))
        return None

    queued: list[Point] = []
    if any(q > 0 for q in queue):
        dist = driving_distances(grid, layout.free, stations)[:, rows * grid.width + cols]
        ranked = [iter(np.argsort(d, kind="stable")) for d in dist]
        left = list(queue)
        for _ in range(max(queue)):           # round by round: every station gets its closest first
            for k in range(len(left)):
                if left[k] <= 0:
                    continue
                spot = next((p for i in ranked[k] if np.isfinite(dist[k, i]) and (p := take(int(i)))), None)
                left[k] = 0 if spot is None else left[k] - 1
                if spot is not None:
                    queued.append(spot)
    order = iter(np.random.default_rng(seed).permutation(len(rows)).tolist())
    homes: list[Point] = []
    hub = None
    for _ in range(_SPOT_ROUNDS):
        while len(homes) < count + spare and (i := next(order, None)) is not None:
            if (spot := take(i)) is not None:
                homes.append(spot)
        if hub is None:   # the most open place once the spots are there
            open_space = ndimage.distance_transform_edt(layout.free & ~layout.taken)
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


_SPOT_ROUNDS = 8


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
    layout = _Layout(grid, radius)
    rows, cols = np.nonzero(layout.free)
    centres = np.column_stack([(cols + 0.5) * grid.resolution, (rows + 0.5) * grid.resolution])
    rng = np.random.default_rng(seed)
    dist = np.full(len(rows), np.inf)
    out: dict[str, Point] = {}
    for n in range(count):
        ranked = rng.permutation(len(rows)) if n == 0 else np.argsort(-dist, kind="stable")
        for i in ranked:
            if dist[i] <= 0:
                break
            if layout.usable(int(cols[i]), int(rows[i])):
                layout.take(int(cols[i]), int(rows[i]))
                out[f"S{n + 1}"] = grid.centre(int(cols[i]), int(rows[i]))
                dist = np.minimum(dist, np.hypot(*(centres - centres[i]).T))
                break
        else:
            raise ValueError(f"{grid.name}: room for only {n} stations, {count} asked for")
    return out


def delivery_problem(grid: GridMap, stations: dict[str, Point], n_robots: int, n_deliveries: int, seed: int,
                     pick: Sequence[str] | None = None, drop: Sequence[str] | None = None,
                     name: str | None = None, queue_spots: int | None = None, radius: float = ROBOT_RADIUS,
                     max_speed: float = TOP_SPEED, dock_s: float = DOCK_S) -> DeliveryProblem:
    """A seeded delivery problem: each task loads at a station of ``pick`` and unloads at a
    different one of ``drop`` (both default to all stations). Parking spots: one home per robot,
    plus ``queue_spots`` (default N/2 + 8) close to the stations, shared out by how often the
    tasks visit each station (at most 4 per station), plus up to N/2 spare ones where the map has
    room (a robot on its way to a spot holds two)."""
    if n_deliveries < 1:
        raise ValueError(f"n_deliveries: must be >= 1 (got {n_deliveries})")
    pick = list(stations) if pick is None else list(pick)
    drop = list(stations) if drop is None else list(drop)
    if not pick or not drop or (len(pick) == 1 and pick == drop):
        raise ValueError("stations: need at least two stations to deliver between")
    rng = np.random.default_rng(seed)
    tasks = []
    while len(tasks) < n_deliveries:
        k, l = pick[int(rng.integers(len(pick)))], drop[int(rng.integers(len(drop)))]
        if k != l:
            tasks.append(Task(k, l))
    visits = {s: 0 for s in stations}
    for task in tasks:
        visits[task.pick] += 1
        visits[task.drop] += 1
    quota = {s: 0 for s in stations}
    for _ in range(n_robots // 2 + 8 if queue_spots is None else queue_spots):
        open_ = [s for s in stations if quota[s] < 4 and visits[s]]
        if not open_:
            break
        best = max(open_, key=lambda s: visits[s] / (quota[s] + 1))   # D'Hondt: by demand
        quota[best] += 1
    spots = choose_spots(grid, n_robots, seed, list(stations.values()), radius, list(quota.values()),
                         spare=n_robots // 2)
    return DeliveryProblem(name or grid.name, grid, dict(stations), tasks, spots, n_robots, radius,
                           max_speed, dock_s)


def warehouse_problem(warehouse, n_robots: int, n_deliveries: int, seed: int, **options) -> DeliveryProblem:
    """A delivery problem on a :class:`~fleet_planner.warehouse.Warehouse`: load at its chutes,
    unload at its storing sites (chargers are left out)."""
    chutes = [s.name for s in warehouse.stations_of("chute")]
    sites = [s.name for s in warehouse.stations_of("storage")]
    used = {n: warehouse.stations[n].pose for n in chutes + sites}
    options.setdefault("name", warehouse.name)
    return delivery_problem(warehouse.grid, used, n_robots, n_deliveries, seed, chutes or None, sites or None,
                            **options)


# ---------------------------------------------------------------------------------------------
# the result
# ---------------------------------------------------------------------------------------------
@dataclass
class DeliveryResult:
    """What one run measured. ``ctime`` is the completion time of the last delivery, or the
    simulated time at which the run stopped when ``stop`` is not "done"."""

    problem: str
    method: str
    n_robots: int
    n_deliveries: int
    completed: int
    stop: str                  # "done", "cap" (simulated-time cap), "stall" (nothing moved for long), "wall"
    ctime: float
    lower_bound: float
    avg_velocity: float
    decision_s: float          # planner wall s per planned leg, failed attempts included (central),
                               # or wall s per fleet step (behavior)
    decision_unit: str         # "leg" or "step"
    planner_wall_s: float      # all wall time spent planning / deciding
    legs: int                  # legs driven (planned and started)
    failed_plans: int          # planning attempts that raised PlanningError (retried later)
    collisions: int            # pairs of discs that overlapped (central), overlap events (behavior)
    min_gap: float             # smallest distance minus sum of radii seen over the run
    deadlocks: int             # robots with work left that made no progress for no_progress_s at the end
    wall_s: float
    violations: list[str] = field(default_factory=list)  # central: other plan-contract breaches
    trajectories: list[TimedPath] | None = None          # central: what every robot drove
    positions: np.ndarray | None = None                  # behavior with record=True: (steps + 1, N, 2)
    times: np.ndarray | None = None                      # the times of ``positions``
    extra: dict = field(default_factory=dict)

    @property
    def finished(self) -> bool:
        return self.stop == "done"


class _LegTimes:
    """Shortest-path driving times between points for the lower bound (cached)."""

    def __init__(self, problem: DeliveryProblem):
        self.finder = PathFinder(problem.grid, problem.radius)
        self.speed = problem.max_speed
        self._cache: dict[tuple[Point, Point], float] = {}

    def __call__(self, a: Point, b: Point) -> float:
        key = (tuple(a), tuple(b))
        if key not in self._cache:
            path = self.finder.find(a, b)
            if path is None:
                raise ValueError(f"no path from {a} to {b} for radius {self.finder.radius:g}")
            self._cache[key] = float(np.sum(np.hypot(*np.diff(path, axis=0).T))) / self.speed
        return self._cache[key]


# ---------------------------------------------------------------------------------------------
# dispatch: the part all methods share
# ---------------------------------------------------------------------------------------------
@dataclass
class _Robot:
    idx: int
    id: str
    pos: Point
    phase: str = "idle"          # need, drive, dock, queued (central), done
    task: Task | None = None
    picked: bool = False
    target: Point | None = None
    kind: str = ""               # what the target is: pick, drop, hold, park
    station: str | None = None   # the station the target is or queues for
    spot: int | None = None      # reserved parking spot (home, queue or final)
    here: str | None = None      # the station it stands on (claimed) after docking
    wake: float = 0.0
    since: float = 0.0           # progress: last time it made some
    best: float = math.inf       # behavior: the least path length left to the target on this leg
    lb: float = 0.0              # its task sequence driven alone
    lb_at: Point = (0.0, 0.0)
    pending: str = ""            # pick or drop: what it queues for at a parking spot
    reserved: int | None = None  # the parking spot it is heading for
    entered: float = 0.0         # when it entered its phase


class _Dispatch:
    """Task sequence, station claims and queues, parking spots, the lower bound, progress."""

    def __init__(self, problem: DeliveryProblem, claims: bool):
        self.p = problem
        self.claims = claims
        self.leg_time = _LegTimes(problem)
        self.robots = [_Robot(i, rid, problem.spots[i], spot=i, lb_at=problem.spots[i])
                       for i, rid in enumerate(problem.robot_ids())]
        self._spots = np.asarray(problem.spots, dtype=float)
        if claims:   # driving distance from each station to each parking spot, to queue close by
            drive = driving_distances(problem.grid, self.leg_time.finder.free, list(problem.stations.values()))
            cells = [problem.grid.cell_of(*p) for p in problem.spots]
            at = [row * problem.grid.width + col for col, row in cells]
            self.spot_dist = {s: drive[k, at] for k, s in enumerate(problem.stations)}
        self.spot_owner: list[int | None] = [None] * len(problem.spots)
        for r in self.robots:
            self.spot_owner[r.idx] = r.idx
        self.next_task = 0
        self.completed = 0
        self.ctime: float | None = None
        self.claim: dict[str, int] = {}
        self.queue: dict[str, list[int]] = {s: [] for s in problem.stations}
        self.released: list[int] = []     # robots a freed station was just handed to
        self.phase_s: dict[str, float] = {}  # robot-seconds spent in each phase
        self.hold_legs = 0

    def enter(self, r: _Robot, phase: str, t: float) -> None:
        """r goes into ``phase`` at t (the time spent in the old one is counted)."""
        self.phase_s[r.phase] = self.phase_s.get(r.phase, 0.0) + t - r.entered
        r.phase, r.entered = phase, t

    def mean_phase_s(self, t: float) -> dict[str, float]:
        """Mean seconds per robot in each phase until t (need: waiting for a leg to be planned or
        assigned; queued: on a parking spot waiting for a station; drive includes the wait at the
        start of a planned leg)."""
        total = dict(self.phase_s)
        for r in self.robots:
            total[r.phase] = total.get(r.phase, 0.0) + max(t - r.entered, 0.0)
        return {k: round(v / len(self.robots), 1) for k, v in total.items() if k not in ("idle", "done")}

    # -- decisions ------------------------------------------------------------------------------
    def next_target(self, r: _Robot, t: float) -> None:
        """After a dock (or at the start): where to go next; sets ``phase`` to need or queued."""
        if r.task is not None and not r.picked:
            self._to_station(r, r.task.pick, "pick", t)
        elif r.task is not None:
            self._to_station(r, r.task.drop, "drop", t)
        elif self.next_task < len(self.p.tasks):
            r.task, r.picked = self.p.tasks[self.next_task], False
            self.next_task += 1
            self.lb_add(r, self.p.stations[r.task.pick])
            self.lb_add(r, self.p.stations[r.task.drop])
            self._to_station(r, r.task.pick, "pick", t)
        else:
            # home, else the closest free spot (near a station, it would stand in others' way)
            spot = r.idx if self.spot_owner[r.idx] is None else \
                self._nearest_free_spot(np.hypot(*(self._spots - np.asarray(r.pos)).T))
            if spot is None:                  # every spot taken or promised: stay (nothing left to do)
                self.enter(r, "done", t)
                r.wake = math.inf
                return
            self.spot_owner[spot], r.reserved = r.idx, spot
            self._need(r, self.p.spots[spot], "park", None, t)

    def lb_add(self, r: _Robot, station: Point) -> None:
        r.lb += self.leg_time(r.lb_at, station) + self.p.dock_s
        r.lb_at = station

    def _to_station(self, r: _Robot, station: str, kind: str, t: float) -> None:
        """Central methods: claim the station only when close to it (it stays claimed until the
        robot leaves it again, so a claim made from afar would idle it for the whole drive);
        from afar, or when it is taken, wait on a parking spot near it first."""
        goal = self.p.stations[station]
        if not self.claims:
            self._need(r, goal, kind, station, t)
            return
        free = self.claim.get(station, r.idx) == r.idx
        drive = self.spot_dist[station]
        spot = self._nearest_free_spot(drive)
        on_spot = r.spot is not None and r.here is None and r.pos == self.p.spots[r.spot]
        if on_spot:
            close = drive[r.spot] <= CLAIM_RADIUS or (spot is not None and drive[r.spot] <= drive[spot])
        else:
            close = math.dist(r.pos, goal) <= CLAIM_RADIUS
        if free and (close or (spot is None and not on_spot)):
            # close, or standing on a station with nowhere to wait: better go than block it
            self.claim[station] = r.idx
            self._need(r, goal, kind, station, t)
        elif close and on_spot:
            self._queue(r, station, kind, t)  # wait right here
        elif spot is not None:
            self.spot_owner[spot] = r.idx
            r.reserved, r.pending = spot, kind
            self._need(r, self.p.spots[spot], "hold", station, t)
            self.hold_legs += 1
        else:                                 # nowhere to queue yet: decide again a little later
            self.enter(r, "wait", t)
            r.station, r.pending, r.wake = station, kind, t + RETARGET_S

    def _queue(self, r: _Robot, station: str, kind: str, t: float) -> None:
        self.enter(r, "queued", t)
        r.station, r.wake, r.pending = station, math.inf, kind
        self.queue[station].append(r.idx)

    def _need(self, r: _Robot, target: Point, kind: str, station: str | None, t: float) -> None:
        self.enter(r, "need", t)
        r.target, r.kind, r.station, r.wake = target, kind, station, t

    def retarget(self, r: _Robot, t: float) -> None:
        """A waiting robot decides again how to get to its station."""
        self._to_station(r, r.station, r.pending, t)

    def _nearest_free_spot(self, dist: np.ndarray) -> int | None:
        """The free parking spot of least ``dist`` (one entry per spot), if any is free."""
        return next((int(i) for i in np.argsort(dist, kind="stable") if self.spot_owner[i] is None), None)

    def queued_for_here(self, r: _Robot) -> bool:
        """r stands on a station others queue for."""
        return r.here is not None and bool(self.queue[r.here])

    def spot_near_here(self, r: _Robot) -> int | None:
        return self._nearest_free_spot(self.spot_dist[r.here])

    def evacuate(self, r: _Robot, spot: int) -> None:
        """r clears its station for the parking spot instead of going where it decided (that
        decision is undone; it decides again on the spot)."""
        if r.reserved is not None:
            self.spot_owner[r.reserved] = None
        if r.kind in ("pick", "drop") and r.station != r.here and self.claim.get(r.station) == r.idx:
            self.release(r.station)
        self.spot_owner[spot], r.reserved = r.idx, spot
        r.target, r.kind, r.station = self.p.spots[spot], "evac", None

    # -- events ---------------------------------------------------------------------------------
    def left(self, r: _Robot, t: float) -> None:
        """r drove off from where it stood: free its spot and the station it stood on."""
        if r.spot is not None and self.spot_owner[r.spot] == r.idx:
            self.spot_owner[r.spot] = None
        r.spot = r.reserved if r.kind in ("hold", "park", "evac") else None
        r.reserved = None
        if r.here is not None:
            self.release(r.here)
            r.here = None
        r.since = t

    def release(self, station: str) -> None:
        if self.claim.get(station) is None:
            return
        del self.claim[station]
        if self.queue[station]:
            q = self.robots[self.queue[station].pop(0)]
            self.claim[station] = q.idx
            self.released.append(q.idx)

    def arrived(self, r: _Robot, t: float) -> None:
        """r reached its target."""
        r.since = t
        r.pos = r.target
        if r.kind in ("pick", "drop"):
            self.enter(r, "dock", t)
            r.wake, r.here = t + self.p.dock_s, r.station if self.claims else None
        elif r.kind == "hold":
            station = r.station
            if self.claim.get(station) is None:
                self.claim[station] = r.idx
                self._need(r, self.p.stations[station], r.pending, station, t)
            else:
                self._queue(r, station, r.pending, t)
        elif r.kind == "evac":
            self.next_target(r, t)
        else:
            self.enter(r, "done", t)
            r.wake = math.inf

    def docked(self, r: _Robot, t: float) -> None:
        """r's docking time is over."""
        r.since = t
        if r.kind == "pick":
            r.picked = True
        else:
            r.task = None
            self.completed += 1
            if self.completed == len(self.p.tasks):
                self.ctime = t
        self.next_target(r, t)

    def take_released(self, t: float) -> list[_Robot]:
        """Robots that were queued and now hold their station: they need their leg to it."""
        out = []
        for i in self.released:
            r = self.robots[i]
            self._need(r, self.p.stations[r.station], r.pending, r.station, t)
            out.append(r)
        self.released = []
        return out

    # -- measures -------------------------------------------------------------------------------
    def busy(self, r: _Robot) -> bool:
        """r still has a delivery to make."""
        return r.task is not None

    def lower_bound(self) -> float:
        return max((r.lb for r in self.robots), default=0.0)

    def deadlocked(self, t: float, no_progress_s: float, moving: tuple[str, ...]) -> int:
        """Robots with a delivery left, in none of the ``moving`` phases, without progress for long."""
        return sum(1 for r in self.robots
                   if self.busy(r) and r.phase not in moving and t - r.since > no_progress_s)


# ---------------------------------------------------------------------------------------------
# central methods: event-driven, robots follow their timed paths exactly
# ---------------------------------------------------------------------------------------------
def _planner(method: str, options: dict | None):
    from .planners.md import MDPlanner
    from .planners.prior import PriorPlanner

    options = dict(options or {})
    if method == "md":
        return MDPlanner(**options)
    if method == "md-box":
        return MDPlanner(mode="box", **options)
    return PriorPlanner(**options)


def _simulate_central(problem: DeliveryProblem, method: str, cap_s: float, stall_s: float, no_progress_s: float,
                      retry_s: float, wall_cap_s: float, planner_options: dict | None,
                      progress: SimProgress | None) -> DeliveryResult:
    wall0 = time.perf_counter()
    planner = _planner(method, planner_options)
    d = _Dispatch(problem, claims=True)
    robots, n = d.robots, problem.n_robots
    legs: list[list[np.ndarray]] = [[np.array([[*r.pos, 0.0]])] for r in robots]
    traj: list[TimedPath] = [TimedPath(r.id, problem.radius, legs[r.idx][0]) for r in robots]
    tried = [-1] * n                       # plan version at the last failed attempt
    last_try = [0.0] * n
    version, plan_wall, n_legs, failed, delay = 0, 0.0, 0, 0, 0.0
    last_activity, t, stop = 0.0, 0.0, "done"

    for r in robots:
        d.next_target(r, 0.0)

    def fixed(q: _Robot, now: float) -> TimedPath:
        tp = traj[q.idx]
        if len(tp.waypoints) > 1 and tp.waypoints[-1, 2] <= now:
            tp = traj[q.idx] = TimedPath(q.id, problem.radius, [[*tp.waypoints[-1, :2], now]])
        return tp

    def plan(r: _Robot, goal: Point, others: list[TimedPath], now: float) -> TimedPath | None:
        nonlocal plan_wall, failed
        spec = RobotSpec(r.id, problem.radius, problem.max_speed, r.pos, goal)
        t0 = time.perf_counter()
        try:
            return planner.plan_incremental(problem.grid, [spec], others, now)[0]
        except PlanningError:
            failed += 1
            return None
        finally:
            plan_wall += time.perf_counter() - t0

    def attempt(r: _Robot, now: float) -> bool:
        nonlocal version, n_legs, delay
        if math.dist(r.pos, r.target) < 1e-9:
            d.arrived(r, now)
            return True
        others = [fixed(q, now) for q in robots if q is not r]
        leg = plan(r, r.target, others, now)
        if d.queued_for_here(r) and (leg is None or leg.start_time > now + EVACUATE_S):
            spot = d.spot_near_here(r)
            evac = None if spot is None else plan(r, problem.spots[spot], others, now)
            if evac is not None and (leg is None or evac.start_time < leg.start_time):
                d.evacuate(r, spot)
                leg = evac
        if leg is None:
            tried[r.idx], last_try[r.idx], r.wake = version, now, now + 15 * retry_s
            return False
        version += 1
        n_legs += 1
        delay += leg.arrival_time - now - leg.length / problem.max_speed
        traj[r.idx] = leg
        legs[r.idx].append(leg.waypoints)
        d.left(r, now)
        d.enter(r, "drive", now)
        r.wake = max(now, leg.arrival_time)
        return True

    while True:
        if d.ctime is not None:
            t = d.ctime
            break
        wake = np.array([r.wake for r in robots])
        t_next = float(wake.min())
        if t_next > cap_s:
            t, stop = cap_s, "cap"
            break
        if t_next - last_activity > stall_s:
            t, stop = last_activity + stall_s, "stall"
            break
        if time.perf_counter() - wall0 > wall_cap_s:
            stop = "wall"
            break
        t = t_next
        for i in np.nonzero(wake <= t)[0]:
            r = robots[int(i)]
            if r.wake > t:
                continue
            if r.phase == "drive":
                d.arrived(r, t)
                last_activity = t
            elif r.phase == "dock":
                d.docked(r, t)
                last_activity = t
                if progress:
                    progress(d.completed, len(problem.tasks), t)
            elif r.phase == "wait":
                d.retarget(r, t)
            if r.phase == "need" and r.wake <= t:
                if attempt(r, t):
                    last_activity = t
            for q in d.take_released(t):
                if attempt(q, t):
                    last_activity = t
        # robots that failed before may succeed now that others have new legs
        for r in robots:
            if r.phase == "need" and tried[r.idx] != version:
                r.wake = min(r.wake, max(t, last_try[r.idx] + retry_s))
                tried[r.idx] = version

    paths = [TimedPath(r.id, problem.radius, np.vstack(legs[r.idx])) for r in robots]
    collisions, gap, violations = _check_trajectories(problem, paths)
    driven = [_driven(p.waypoints, t) for p in paths]
    return DeliveryResult(problem.name, method, n, len(problem.tasks), d.completed, stop, t, d.lower_bound(),
                          float(np.mean(driven)) / t if t > 0 else 0.0, plan_wall / max(n_legs, 1), "leg",
                          plan_wall, n_legs, failed, collisions, gap, d.deadlocked(t, no_progress_s, ("dock", "drive")),
                          time.perf_counter() - wall0, violations, paths,
                          extra={"mean_leg_delay_s": round(delay / max(n_legs, 1), 2), "hold_legs": d.hold_legs,
                                 "mean_phase_s": d.mean_phase_s(t)})


def _check_trajectories(problem: DeliveryProblem, paths: list[TimedPath]) -> tuple[int, float, list[str]]:
    """Overlapping pairs, the smallest gap, and every other breach of the plan contract, by the
    independent checker on what the robots drove."""
    from .checker import check_plan, min_separation

    specs = [RobotSpec(p.robot_id, problem.radius, problem.max_speed, tuple(p.waypoints[0, :2]),
                       tuple(p.waypoints[-1, :2])) for p in paths]
    found = check_plan(problem.grid, specs, Plan("sim", paths))
    collisions = sum(1 for v in found if v.kind == "collision")
    return collisions, min_separation(paths)[0], [str(v) for v in found if v.kind != "collision"]


def _driven(wp: np.ndarray, t: float) -> float:
    """Distance driven along waypoints ``(x, y, t)`` until time t."""
    seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
    t0, t1 = wp[:-1, 2], wp[1:, 2]
    frac = np.clip((t - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0, 1.0)
    frac = np.where(t1 > t0, frac, (t >= t1).astype(float))
    return float(np.sum(seg * frac))


# ---------------------------------------------------------------------------------------------
# behaviour-based: time-stepped
# ---------------------------------------------------------------------------------------------
def _simulate_behavior(problem: DeliveryProblem, dt: float, cap_s: float, stall_s: float, no_progress_s: float,
                       retry_s: float, wall_cap_s: float, record: bool, progress: SimProgress | None) -> DeliveryResult:
    from .behavior import BehaviorFleet

    wall0 = time.perf_counter()
    d = _Dispatch(problem, claims=False)
    robots, n = d.robots, problem.n_robots
    specs = [RobotSpec(r.id, problem.radius, problem.max_speed, r.pos, r.pos) for r in robots]
    fleet = BehaviorFleet(problem.grid, specs)
    decide_wall, n_legs, failed, steps = 0.0, 0, 0, 0
    reach = 2 * problem.radius
    overlapping: set[tuple[int, int]] = set()
    events, min_gap = 0, math.inf
    driven = np.zeros(n)
    pos = fleet.positions()
    log = [pos.copy()] if record else None
    times = [0.0] if record else None
    stop = "done"

    def assign(r: _Robot, now: float) -> None:
        nonlocal decide_wall, n_legs, failed
        t0 = time.perf_counter()
        try:
            fleet.assign(r.id, r.target, r.station if r.kind in ("pick", "drop") else None)
        except PlanningError:
            failed += 1
            r.wake = now + retry_s
            return
        finally:
            decide_wall += time.perf_counter() - t0
        n_legs += 1
        d.left(r, now)
        d.enter(r, "drive", now)
        r.best = math.inf

    for r in robots:
        d.next_target(r, 0.0)
        assign(r, 0.0)
    while d.ctime is None:
        t = fleet.time
        if t >= cap_s:
            stop = "cap"
            break
        stuck = [r for r in robots if d.busy(r) and r.phase != "dock"]
        if stuck and all(t - r.since > stall_s for r in stuck):
            stop = "stall"
            break
        if time.perf_counter() - wall0 > wall_cap_s:
            stop = "wall"
            break
        t0 = time.perf_counter()
        fleet.step(dt)
        decide_wall += time.perf_counter() - t0
        steps += 1
        t = fleet.time
        new = fleet.positions()
        driven += np.hypot(*(new - pos).T)
        pos = new
        if record:
            log.append(pos.copy())
            times.append(t)
        now_overlapping = set()
        for a, b in cKDTree(pos).query_pairs(reach + 1.0):
            gap = float(np.hypot(*(pos[a] - pos[b]))) - reach
            min_gap = min(min_gap, gap)
            if gap < -1e-9:
                now_overlapping.add((a, b))
        events += len(now_overlapping - overlapping)
        overlapping = now_overlapping
        for r in robots:
            r.pos = (float(pos[r.idx, 0]), float(pos[r.idx, 1]))
            if r.phase == "drive":   # progress: 1 m less path left than ever before on this leg
                left = fleet.view(r.id).remaining
                if left <= r.best - 1.0:
                    r.best = left
                    r.since = t
            if r.phase == "drive" and fleet.arrived(r.id):
                d.arrived(r, t)
            elif r.phase == "dock" and t >= r.wake - 1e-9:
                d.docked(r, t)
                if progress:
                    progress(d.completed, len(problem.tasks), t)
            if r.phase == "need" and t >= r.wake - 1e-9:
                assign(r, t)
    t = d.ctime if d.ctime is not None else fleet.time
    stats = fleet.stats()   # the fleet's own counters (deadlocks found, re-plans...), as extras
    return DeliveryResult(problem.name, "behavior", n, len(problem.tasks), d.completed, stop, t, d.lower_bound(),
                          float(np.mean(driven)) / t if t > 0 else 0.0, decide_wall / max(steps, 1), "step",
                          decide_wall, n_legs, failed, events, min_gap, d.deadlocked(t, no_progress_s, ("dock",)),
                          time.perf_counter() - wall0, [], None,
                          np.array(log) if record else None, np.array(times) if record else None,
                          {"mean_phase_s": d.mean_phase_s(t),
                           **{k: v for k, v in asdict(stats).items() if k != "time"}})


# ---------------------------------------------------------------------------------------------
def simulate(problem: DeliveryProblem, method: str, *, dt: float = 0.1, cap_s: float = 4 * 3600.0,
             stall_s: float = 600.0, no_progress_s: float = 120.0, retry_s: float = 2.0,
             wall_cap_s: float = math.inf, record: bool = False, planner_options: dict | None = None,
             progress: SimProgress | None = None) -> DeliveryResult:
    """Run the deliveries of ``problem`` with ``method`` (one of :data:`METHODS`).

    ``dt``: step of the behaviour simulation (the central methods are event-driven and exact).
    ``cap_s``: stop at this simulated time; ``stall_s``: stop when no robot made progress for this
    long (a deadlock nobody resolves); ``no_progress_s``: at the end, robots with a delivery left
    that made no progress for this long count as deadlocked. ``retry_s``: a leg that could not be
    planned is tried again this much later (once another robot got a new leg; at the latest 15
    times as late). ``wall_cap_s``: stop after this much wall-clock time (stop "wall").
    ``record``: keep the behaviour fleet's positions at every step.
    """
    if method not in METHODS:
        raise ValueError(f"method: must be one of {', '.join(METHODS)} (got {method!r})")
    for name, value in (("dt", dt), ("cap_s", cap_s), ("stall_s", stall_s), ("no_progress_s", no_progress_s),
                        ("retry_s", retry_s)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name}: must be a finite number > 0 (got {value!r})")
    if not wall_cap_s > 0:
        raise ValueError(f"wall_cap_s: must be > 0 (got {wall_cap_s!r})")
    if method == "behavior":
        return _simulate_behavior(problem, dt, cap_s, stall_s, no_progress_s, retry_s, wall_cap_s, record, progress)
    return _simulate_central(problem, method, cap_s, stall_s, no_progress_s, retry_s, wall_cap_s, planner_options,
                             progress)


__all__ = ["DOCK_S", "METHODS", "ROBOT_RADIUS", "TOP_SPEED", "DeliveryProblem", "DeliveryResult", "Task",
           "choose_spots", "delivery_problem", "driving_distances", "simulate", "spread_stations",
           "warehouse_problem"]
