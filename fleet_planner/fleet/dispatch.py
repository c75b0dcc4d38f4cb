"""Who takes which job, and where a robot waits for the next one: the dispatcher of the fleet
manager (:mod:`.manager`), as pure algorithms over positions, speeds and the warehouse map.

* :class:`TravelTimes` - estimated driving time from anywhere to a station: the length of the
  shortest 8-connected way over the free cells (SciPy's compiled Dijkstra, one field per station,
  cached) at the robot's planned speed. Straight-line distance misjudges a warehouse, where the
  nearest robot as the crow flies may be behind a rack block.
* :func:`assign` - batch assignment of queued jobs to free robots: per chute nobody is bound for,
  the first job in the queue's order (priority, deadline, submission) that some free robot can
  do; then the pairing of robots and these jobs with the smallest sum of estimated arrival times
  (``scipy.optimize.linear_sum_assignment``), instead of handing each job in turn to the robot
  nearest to it (which sends a far robot to one chute while the one next to it goes elsewhere).
  One job per chute at a time: a second robot bound for an occupied chute would only queue in the
  aisle in front of it. One job per storing site at a time too (policy ``sites``): a robot that has
  picked for a site another robot is bound for or placing at cannot plan its way there (the other
  "parks on its goal in the way") and stands on the chute meanwhile, and the chute's next job with it.
* :func:`staging_spots` - where idle robots wait: spots along the chutes' wall, between it and the
  chutes' line (the recesses a chute wall leaves between its chutes), clear of every station, so
  that the next job starts a few metres from its chute rather than from a parking spot across the
  warehouse. Robots go charging only when their battery asks for it (:class:`DispatchPolicy`), so
  a quiet minute does not send the whole fleet to the chargers at once.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment  # (imported here: a first import inside a step costs its budget)

from ..model import Point
from ..warehouse import Warehouse

#: a staging spot is at least this far (m) beyond the sum of radii from every station's pose
STAGING_CLEARANCE_M = 0.6
#: and at most this far (m) from the wall of the chutes
STAGING_BAND_M = 1.6
#: cost of a pair that cannot be (a robot that cannot do the job): never chosen
_NEVER = 1e12


#: how long a job holds its storing site for the dispatcher (policy ``sites``): until done; until
#: picked; until done, or picked and done before a robot given a job there now could get there
SITE_HOLDS = ("done", "picked", "soon")


@dataclass(frozen=True)
class DispatchPolicy:
    """How the dispatcher chooses (the manager's :attr:`~.manager.FleetManager.policy`).

    ``batch``: pair free robots and jobs by the smallest sum of estimated arrival times (else each
    job in turn takes the nearest robot, the old rule); ``staging``: idle robots wait at staging
    spots near the chutes rather than at chargers; ``queue`` (with ``batch``): while a chute is
    taken, the next job there goes to a robot that waits on the chute's waiting spot (a staging spot
    in the recess beside it, :func:`queue_spots`) and drives the last metres as soon as the robot
    that picked there drives off (one robot waiting per chute); ``sites``: a chute's next job is the
    first whose storing site no active job (nor one chosen before it in the round) goes to, a job
    holding its site (``site_hold``, :data:`SITE_HOLDS`) until done, until picked, or ("soon") until
    done or picked and about to place before a robot given a job there now could get there;
    ``charge_below``: an idle robot goes to a charger rather than a staging spot only below this
    battery (1.0: always, the old rule); ``leave_charger_at``: an idle robot at a charger leaves for
    a staging spot once charged this far.

    Default: :data:`PIPELINED`, batch with the chute queue and sites held until "soon". It was opt-in
    for a session: with it a scene of four robots and two people deadlocked (``test_obstacles``'
    walkers); the cause was not the policy but two robots held within the planner's margin of each
    other, which no leg could then start from (mended in :func:`.coordination.room_to_leave`; the
    policy only brought them there). :data:`SERIAL` is the session-18 default. Measured (ours,
    ``bench/bench_dispatch.py --robots 30 --jobs 100 --interval 1.2``, jobs per simulated hour, job
    seeds 1 / 2): PIPELINED 355 / 285; SERIAL (batch and sites held until done) 264-279 / -, the
    queue with that 300 / 242, with "picked" 321 / -: with
    the chutes pipelined the busiest storing site (9-12 of 100 jobs) held from assignment to done
    (~130 s a job) set the span; the demo's nine robots (``--robots 0``, seeds 1-4) 147 / 183 / 178 / 163,
    were 128 / 135 / 143 / 160. Earlier: batch alone 224 / 273 (seed 3), the nearest robot per job
    231; staging for idle robots (``staged-no-queue``) 282 / 284 (97 of 100 with seed 2) and
    :data:`STAGED` 277: with 17 staging spots the north aisle jammed (ROS run); idle robots are not
    staged by default. A queued robot once stood by its chute for ever (93 of 100 jobs, with
    staging; not reproduced): two possible causes are mended, the queue's jobs went without the
    site rule, and nothing sent a free robot standing on the chute off from there."""

    batch: bool = True
    staging: bool = False
    queue: bool = True
    sites: bool = True
    site_hold: str = "soon"
    charge_below: float = 1.0
    leave_charger_at: float = 1.0

    def __post_init__(self) -> None:
        if self.site_hold not in SITE_HOLDS:
            raise ValueError(f"site_hold: one of {', '.join(SITE_HOLDS)} (got {self.site_hold!r})")
        for name in ("charge_below", "leave_charger_at"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name}: must be in [0, 1] (got {value!r})")


#: pipelined chutes (the default): the next job of a taken chute waits on its spot, sites freed soon
PIPELINED = DispatchPolicy(queue=True, site_hold="soon")
#: the session-18 default: no chute queue, a job holds its storing site until done
SERIAL = DispatchPolicy(queue=False, site_hold="done")
#: idle robots wait by the chutes, the next job of a taken chute waits on its spot (not the default: see above)
STAGED = DispatchPolicy(staging=True, queue=True, site_hold="done", charge_below=0.6, leave_charger_at=0.95)
#: the old rules: the nearest robot for each job in turn, idle robots charge
LEGACY = DispatchPolicy(batch=False, staging=False, queue=False, sites=False, site_hold="done", charge_below=1.0,
                        leave_charger_at=1.0)


class TravelTimes:
    """Shortest-way lengths (m) over the free cells of ``warehouse`` from each station (8-connected,
    one Dijkstra per station, done when first asked for and kept)."""

    def __init__(self, warehouse: Warehouse):
        self.grid = warehouse.grid
        self.poses = {s.name: s.pose for s in warehouse.stations.values()}
        self._fields: dict[str, np.ndarray] = {}
        self._graph = None

    def _build(self):
        from scipy.sparse import coo_matrix

        g = self.grid
        free = ~g.blocked
        h, w = free.shape
        idx = np.arange(h * w).reshape(h, w)
        rows, cols, vals = [], [], []
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            # cell (r, c) and its neighbour (r + dr, c + dc), both on the map
            ra, rb = slice(0, h - dr), slice(dr, h)
            ca, cb = (slice(0, w - dc), slice(dc, w)) if dc >= 0 else (slice(-dc, w), slice(0, w + dc))
            ok = free[ra, ca] & free[rb, cb]
            if dr and dc:  # a diagonal step only past two free corner cells
                ok &= free[ra, cb] & free[rb, ca]
            src, dst = idx[ra, ca][ok], idx[rb, cb][ok]
            step = g.resolution * (math.sqrt(2.0) if dr and dc else 1.0)
            rows += [src, dst]
            cols += [dst, src]
            vals += [np.full(len(src), step), np.full(len(src), step)]
        n = h * w
        self._graph = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                 shape=(n, n)).tocsr()

    def field(self, station: str) -> np.ndarray:
        """The way length (m) from every cell to ``station`` (inf where there is no way)."""
        out = self._fields.get(station)
        if out is None:
            from scipy.sparse.csgraph import dijkstra

            if self._graph is None:
                self._build()
            g = self.grid
            col, row = g.cell_of(*self.poses[station])
            dist = dijkstra(self._graph, directed=False, indices=row * g.width + col)
            out = self._fields[station] = np.asarray(dist).reshape(g.blocked.shape)
        return out

    def length(self, station: str, points: np.ndarray) -> np.ndarray:
        """Way lengths (m) from each of ``points`` (n x 2) to ``station``; a point off the map or in a
        blocked cell counts its straight-line distance times 1.5."""
        field = self.field(station)
        g = self.grid
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        cols = np.floor(pts[:, 0] / g.resolution).astype(int)
        rows = np.floor(pts[:, 1] / g.resolution).astype(int)
        inside = (cols >= 0) & (cols < g.width) & (rows >= 0) & (rows < g.height)
        out = np.full(len(pts), np.inf)
        out[inside] = field[rows[inside], cols[inside]]
        sx, sy = self.poses[station]
        straight = np.hypot(pts[:, 0] - sx, pts[:, 1] - sy)
        bad = ~np.isfinite(out)
        out[bad] = 1.5 * straight[bad]
        return np.maximum(out, straight)  # never shorter than the straight line (cell rounding)


@dataclass(frozen=True)
class Candidate:
    """A free robot as the dispatcher sees it: where it is, how fast it drives its legs, its battery."""

    id: str
    pos: Point
    speed: float
    battery: float


def assign(robots: Sequence[Candidate], jobs: Sequence[tuple[str, str]], able: Callable[[str, str], bool],
           lengths: Callable[[str, np.ndarray], np.ndarray], busy: Callable[[str], bool] = lambda c: False,
           site_of: Callable[[str], str] | None = None, taken_sites: Collection[str] = (),
           ) -> list[tuple[str, str, float]]:
    """Pair free ``robots`` with queued ``jobs`` ((job id, chute), in the queue's order):
    per chute not ``busy``, the first job some robot is ``able(robot id, job id)`` to do whose
    storing site (``site_of(job id)``, if given) is neither in ``taken_sites`` (another robot's job
    goes there) nor that of a job chosen before it; then the pairing
    with the smallest sum of estimated arrival times (way length from ``lengths(chute, points)``
    over the robot's speed; ties to the fuller battery). Returns (robot id, job id, estimated s) in
    order of arrival.

    A job whose site is taken waits for it (it stays first in its chute's line once the site is
    free): its robot would otherwise pick and then stand on the chute until the other robot has
    placed and left, and the chute's next job with it (measured at 30 robots: the largest loss of
    chute time, ``bench/bench_dispatch.py --time-use``)."""
    if not robots or not jobs:
        return []
    chosen: list[tuple[str, str]] = []
    seen: set[str] = set()
    sites = set(taken_sites)
    for job, chute in jobs:
        site = site_of(job) if site_of is not None else None
        if chute in seen or busy(chute) or site in sites:
            continue
        if any(able(r.id, job) for r in robots):
            chosen.append((job, chute))
            seen.add(chute)
            if site is not None:
                sites.add(site)
    if not chosen:
        return []
    pts = np.array([r.pos for r in robots], dtype=float)
    speed = np.array([max(r.speed, 1e-6) for r in robots])
    cost = np.empty((len(robots), len(chosen)))
    for k, (job, chute) in enumerate(chosen):
        t = lengths(chute, pts) / speed
        ok = np.array([able(r.id, job) for r in robots])
        cost[:, k] = np.where(ok & np.isfinite(t), t, _NEVER)
    tie = 1e-3 * (1.0 - np.array([r.battery for r in robots]))[:, None]  # fuller battery first among equals
    rows, cols = linear_sum_assignment(cost + tie)
    out = [(robots[i].id, chosen[k][0], float(cost[i, k])) for i, k in zip(rows, cols) if cost[i, k] < _NEVER]
    return sorted(out, key=lambda p: p[2])


def staging_spots(warehouse: Warehouse, radius: float, spacing: float | None = None, per_chute: int = 1) -> list[Point]:
    """Spots where idle robots of up to ``radius`` wait near the chutes: between the chutes' line and
    the wall they stand on (within :data:`STAGING_BAND_M` of it), at least :data:`STAGING_CLEARANCE_M`
    beyond two radii from every station's pose, ``spacing`` (default two radii + 0.25 m) apart, the
    nearest to a chute first, at most ``per_chute`` for each chute (its nearest: a crowd waiting by
    the chutes jams the aisle in front of them). Empty for a warehouse without chutes."""
    chutes = np.array([s.pose for s in warehouse.stations_of("chute")], dtype=float).reshape(-1, 2)
    if not len(chutes):
        return []
    spacing = 2 * radius + 0.25 if spacing is None else spacing
    g = warehouse.grid
    h = g.size_m[1]
    north = float(np.mean(chutes[:, 1])) < h / 2   # the chutes stand on the north (y = 0) wall
    rows, cols = np.nonzero(~g.blocked)
    xy = np.column_stack([(cols + 0.5) * g.resolution, (rows + 0.5) * g.resolution])
    # half-cell offsets too: a spot need not be a cell centre (a 1 m recess holds a 0.9 m disc only at its middle)
    xy = np.vstack([xy, xy + [0.0, g.resolution / 2], xy - [0.0, g.resolution / 2]])
    wall = xy[:, 1] if north else h - xy[:, 1]
    line = float(np.min(chutes[:, 1])) if north else float(h - np.max(chutes[:, 1]))
    keep = (wall <= STAGING_BAND_M) & (wall < line)
    xy = xy[keep]
    stations = np.array([s.pose for s in warehouse.stations.values()], dtype=float).reshape(-1, 2)
    d_st = np.min(np.hypot(xy[:, None, 0] - stations[None, :, 0], xy[:, None, 1] - stations[None, :, 1]), axis=1)
    xy = xy[d_st >= 2 * radius + STAGING_CLEARANCE_M]
    d_ch = np.min(np.hypot(xy[:, None, 0] - chutes[None, :, 0], xy[:, None, 1] - chutes[None, :, 1]), axis=1)
    depth = wall[keep][d_st >= 2 * radius + STAGING_CLEARANCE_M]
    order = np.lexsort((xy[:, 0], np.round(d_ch, 1), np.round(depth / 0.25)))  # deepest in the recess first
    chosen: list[Point] = []
    count = np.zeros(len(chutes), dtype=int)
    for x, y in xy[order]:
        near = int(np.argmin(np.hypot(chutes[:, 0] - x, chutes[:, 1] - y)))
        if count[near] >= per_chute or not g.disc_is_free(float(x), float(y), radius + 0.02):
            continue
        if any(math.hypot(x - cx, y - cy) < spacing for cx, cy in chosen):
            continue
        chosen.append((float(x), float(y)))
        count[near] += 1
    return chosen


def queue_spots(chutes: Mapping[str, Point], spots: Mapping[str, Point], within: float = 4.0) -> dict[str, str]:
    """Each chute's waiting spot: the nearest of ``spots`` within ``within`` m that no other chute has
    nearer (by name)."""
    out: dict[str, str] = {}
    for chute, (cx, cy) in chutes.items():
        best = min(spots.items(), key=lambda item: math.hypot(item[1][0] - cx, item[1][1] - cy), default=None)
        if best is None or math.hypot(best[1][0] - cx, best[1][1] - cy) > within:
            continue
        owner = min(chutes, key=lambda c: math.dist(chutes[c], best[1]))
        if owner == chute:
            out[chute] = best[0]
    return out


def nearest_free(spots: Mapping[str, Point], taken: Callable[[Point], bool], origin: Point,
                 length: Callable[[Point, Point], float] | None = None) -> tuple[str, Point] | None:
    """The spot of ``spots`` nearest to ``origin`` (by ``length``, default straight) not ``taken``."""
    best, best_d = None, math.inf
    for name, p in spots.items():
        d = length(origin, p) if length is not None else math.dist(origin, p)
        if d < best_d and not taken(p):
            best, best_d = (name, p), d
    return best


__all__ = ["LEGACY", "PIPELINED", "SERIAL", "STAGED", "Candidate", "DispatchPolicy", "TravelTimes", "assign",
           "nearest_free", "queue_spots", "staging_spots"]
