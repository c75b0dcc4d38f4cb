"""Collision regions and collision boxes of You & Ji, "Design of a Multi-robot Bin Packing System in
an Automatic Warehouse", in continuous geometry.

For two robots x and y on fixed polyline paths, the set of travelled-length pairs ``(a, b)`` at which
their discs overlap, ``|p_x(a) - p_y(b)| < r_x + r_y``, is what the paper calls the collision region
(drawn there in time x travelled-length coordinates; with a known velocity profile the two views are
the same set). For one segment of each path that set is convex, so its extent along each path is
one interval: the part of the segment inside the *capsule* of radius ``R`` around the other
segment. Those per-segment-pair boxes are computed for all nearby segment pairs in one compiled pass
(pairs found with a shapely STRtree, never by looping over all pairs of path samples) and merged
into connected components: one component is one collision region ``k`` of the pair, its bounding
box ``[a_lo, a_hi] x [b_lo, b_hi]`` its collision box.

Paths are stored by robot index. Nothing here knows about priorities or delays: that is the
scheduler's business (:mod:`fleet_planner.scheduler`).
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import _md_kernels as K
from .geometry import arc_lengths
from .model import EPS


@dataclass(frozen=True)
class Region:
    """One collision region between robots x < y (indices): x's travelled length in [a_lo, a_hi],
    y's in [b_lo, b_hi]."""

    x: int
    y: int
    a_lo: float
    a_hi: float
    b_lo: float
    b_hi: float

    def oriented(self, first: int) -> tuple[float, float, float, float]:
        """(lo, hi) of robot ``first`` then (lo, hi) of the other robot."""
        if first == self.x:
            return self.a_lo, self.a_hi, self.b_lo, self.b_hi
        return self.b_lo, self.b_hi, self.a_lo, self.a_hi


class _Segs(NamedTuple):
    """Segment arrays of one or more robots' paths (one row per segment)."""

    p0: np.ndarray      # start point
    u: np.ndarray       # unit direction
    length: np.ndarray
    owner: np.ndarray   # robot index
    offset: np.ndarray  # travelled length at the segment start
    first: np.ndarray   # first segment of its path
    last: np.ndarray    # last segment of its path
    t0: np.ndarray      # undelayed time at the segment start
    speed: np.ndarray
    seg: np.ndarray     # index of the segment along its path


def _robot_segments(idx: int, pts: np.ndarray, tt: np.ndarray) -> _Segs:
    """One path as segments (with each segment's start time and speed). A path of one point (a
    robot that does not move) is a zero-length segment, so a parked robot still has regions with
    everyone passing by."""
    pts = np.asarray(pts, dtype=float).reshape(-1, 2)
    tt = np.asarray(tt, dtype=float)
    if len(pts) == 1:
        pts, tt = np.vstack([pts, pts]), np.array([0.0, 1.0])
    d = np.diff(pts, axis=0)
    seg_len = np.hypot(d[:, 0], d[:, 1])
    unit = np.divide(d, seg_len[:, None], out=np.tile([1.0, 0.0], (len(d), 1)), where=seg_len[:, None] > 0)
    n = len(d)
    index = np.arange(n)
    return _Segs(pts[:-1], unit, seg_len, np.full(n, idx), np.concatenate([[0.0], np.cumsum(seg_len)[:-1]]),
                 index == 0, index == n - 1, tt[:-1],
                 np.where(seg_len > 0, seg_len / np.maximum(np.diff(tt), 1e-12), 1.0), index)


def _cat(parts: Sequence[_Segs]) -> _Segs:
    return _Segs(*(np.concatenate(col) for col in zip(*parts)))


def _kernel_cols(segs: _Segs) -> tuple:
    """A segment table's columns in the order :func:`fleet_planner._md_kernels.segment_pieces` takes them."""
    return (segs.p0, segs.u, segs.length, segs.owner, segs.offset, segs.t0, segs.speed, segs.seg,
            segs.first, segs.last)


class CollisionModel:
    """Collision regions of every pair of robots, kept up to date as paths change.

    ``radii`` are the robots' radii; two discs are in conflict when closer than
    ``r_x + r_y + margin``. How each robot drives its path is given either by constant ``speeds``
    or by ``times``: per robot, the time (from its departure) at which it passes each vertex
    (a speed profile with ramps, :func:`fleet_planner.model.drive_profile`). ``set_paths`` replaces
    robots' paths and recomputes only their pairs: their new segments are looked up in a segment
    index of the fleet that is rebuilt only after many paths have changed (the segments of robots
    changed since are tested against a small index of their own), so a route-choice try or a
    re-ordering costs what that robot touches, not the fleet. Regions (the pieces merged into
    components) are computed when first asked for: the scheduler works on the pieces.
    """

    #: rebuild the fleet's segment index when this share of its segments has changed since
    REBUILD_SHARE = 0.2

    def __init__(self, paths: Sequence[np.ndarray], radii: Sequence[float], margin: float = 0.0,
                 speeds: Sequence[float] | None = None, times: Sequence[np.ndarray] | None = None,
                 fast_merge: bool = False, focus: Iterable[int] | None = None):
        #: merge a pair's pieces into regions with compiled connected components (the same regions;
        #: ties in ``a_lo`` may be numbered differently): for paths with many short segments (holds)
        self.fast_merge = fast_merge
        self.radii = np.asarray(radii, dtype=float)
        self.margin = float(margin)
        self.paths = [np.asarray(p, dtype=float).reshape(-1, 2) for p in paths]
        self.cumlen = [arc_lengths(p) for p in self.paths]   # travelled length at each vertex
        if times is None:
            v = np.ones(len(self.paths)) if speeds is None else np.asarray(speeds, dtype=float)
            times = [c / v[x] for x, c in enumerate(self.cumlen)]
        self.times = [np.asarray(t, dtype=float) for t in times]
        self.lengths = np.array([c[-1] for c in self.cumlen])
        self.travel = np.array([float(t[-1]) for t in self.times])
        self._segs = [_robot_segments(x, p, t) for x, (p, t) in enumerate(zip(self.paths, self.times))]
        self._bb = np.empty((len(self.paths), 4))
        for x in range(len(self.paths)):
            self._set_bbox(x)
        #: only pairs with at least one of these robots are computed (None: every pair)
        self.focus = None if focus is None else sorted(set(int(x) for x in focus))
        self._regions: dict[tuple[int, int], list[Region]] = {}
        self._pieces: dict[tuple[int, int], np.ndarray] = {}
        self._adj: dict[int, set[int]] = {}
        #: the segment index: an STRtree of segment envelopes, the segments it was built from, and
        #: the robots whose paths changed since (their rows in it are stale)
        self._tree = None
        self._tree_segs: _Segs | None = None
        self._stale: set[int] = set()
        self._stale_rows = 0
        self._compute(range(len(self.paths)) if self.focus is None else self.focus, all_pairs=True)

    # -- queries --------------------------------------------------------------------------------
    def regions(self, x: int, y: int) -> list[Region]:
        """Regions between robots x and y (any order), sorted along the smaller index's path."""
        key = (min(x, y), max(x, y))
        found = self._regions.get(key)
        if found is None:
            chunk = self._pieces.get(key)
            if chunk is None:
                return []
            if self.fast_merge:   # every pair still to merge, in one batch
                missing = [k for k in self._pieces if k not in self._regions]
                merged = _merge_boxes_batch([self._pieces[k][:, P_A_LO:P_B_HI + 1] for k in missing])
                for k, boxes in zip(missing, merged):
                    self._regions[k] = [Region(k[0], k[1], *b) for b in boxes]
                return self._regions[key]
            found = self._regions[key] = [Region(key[0], key[1], *b) for b in _merge_boxes(chunk[:, P_A_LO:P_B_HI + 1])]
        return found

    def pieces(self, x: int, y: int) -> np.ndarray:
        """Per-segment-pair pieces of the regions of x < y: rows indexed by the ``P_*`` columns."""
        return self._pieces.get((min(x, y), max(x, y)), _NO_PIECES)

    def pieces_with(self, x: int, others: Iterable[int]) -> list[np.ndarray]:
        """:meth:`pieces` of x with each of ``others``, in that order (one pass)."""
        get = self._pieces.get
        return [get((y, x) if y < x else (x, y), _NO_PIECES) for y in others]

    def neighbours(self, x: int) -> Iterable[int]:
        """Robots that have at least one collision region with x."""
        return self._adj.get(x, ())

    def pairs(self) -> Iterable[tuple[int, int]]:
        return self._pieces.keys()

    @property
    def region_count(self) -> int:
        return sum(len(regs) for regs in self._all_regions())

    def region_table(self) -> np.ndarray:
        """Every region of every pair as rows (x, y, a_lo, a_hi, b_lo, b_hi) with x < y, pair by pair,
        each pair's regions in the order :meth:`regions` lists them (one pass: the network of a plan
        reads them all)."""
        rows = [(r.x, r.y, r.a_lo, r.a_hi, r.b_lo, r.b_hi) for regs in self._all_regions() for r in regs]
        return np.array(rows, dtype=float).reshape(-1, 6)

    def _all_regions(self) -> list[list[Region]]:
        """The regions of every pair, in the order of :meth:`pairs` (those not merged yet merged now,
        with ``fast_merge`` in one batch)."""
        regions = self._regions
        missing = next((k for k in self._pieces if k not in regions), None)
        if missing is not None:
            self.regions(*missing)   # with fast_merge: every pair still to merge, in one batch
        return [regions[k] if k in regions else self.regions(*k) for k in self._pieces]

    # -- updates --------------------------------------------------------------------------------
    def tau(self, x: int, s):
        """Time after its departure at which robot x has travelled ``s`` along its path."""
        return np.interp(s, self.cumlen[x], self.times[x])

    def set_paths(self, changed: dict[int, tuple[np.ndarray, np.ndarray]]) -> None:
        """Replace robots' (path, vertex times) and recompute only their pairs."""
        for x, (path, times) in changed.items():
            self.paths[x] = np.asarray(path, dtype=float).reshape(-1, 2)
            self.times[x] = np.asarray(times, dtype=float)
            self.cumlen[x] = arc_lengths(self.paths[x])
            self.lengths[x] = self.cumlen[x][-1]
            self.travel[x] = float(self.times[x][-1])
            self._segs[x] = _robot_segments(x, self.paths[x], self.times[x])
            self._set_bbox(x)
        dirty = set(changed)
        for x in dirty:
            self._forget(x)
        self._compute(sorted(dirty), all_pairs=False)

    def _forget(self, x: int) -> None:
        """Drop every pair of robot x (its pieces, regions and adjacency)."""
        adj, pieces, regions = self._adj, self._pieces, self._regions
        for y in adj.pop(x, ()):
            key = (x, y) if x < y else (y, x)
            pieces.pop(key, None)
            regions.pop(key, None)
            theirs = adj.get(y)
            if theirs is not None:
                theirs.discard(x)

    def _link(self, x: int, y: int) -> None:
        """Record that robots x and y have a pair (both ways)."""
        adj = self._adj
        mine = adj.get(x)
        if mine is None:
            mine = adj[x] = set()
        mine.add(y)
        theirs = adj.get(y)
        if theirs is None:
            theirs = adj[y] = set()
        theirs.add(x)

    def checkpoint(self) -> tuple:
        """What :meth:`rollback` needs to put the whole model back as it is now (an improvement
        try of the planner that does not pay is undone without recomputing anything). Arrays are
        replaced, never changed in place, except the per-robot ones copied here."""
        return (list(self.paths), list(self.times), list(self.cumlen), self.lengths.copy(), self.travel.copy(),
                list(self._segs), self._bb.copy(), dict(self._regions), dict(self._pieces),
                {x: set(ys) for x, ys in self._adj.items()}, self._tree, self._tree_segs, set(self._stale),
                self._stale_rows)

    def rollback(self, state: tuple) -> None:
        """The model as it was at :meth:`checkpoint` (state taken from this model)."""
        (paths, times, cumlen, lengths, travel, segs, bb, regions, pieces, adj, tree, tree_segs, stale,
         stale_rows) = state
        self.paths, self.times, self.cumlen = list(paths), list(times), list(cumlen)
        self.lengths, self.travel, self._segs, self._bb = lengths.copy(), travel.copy(), list(segs), bb.copy()
        self._regions, self._pieces = dict(regions), dict(pieces)
        self._adj = {x: set(ys) for x, ys in adj.items()}
        self._tree, self._tree_segs, self._stale, self._stale_rows = tree, tree_segs, set(stale), stale_rows

    def snapshot(self, x: int) -> tuple:
        """What :meth:`restore` needs to put robot x's path and pairs back as they are now (a
        route-choice try that does not pay is undone without recomputing anything)."""
        pairs = {y: ((min(x, y), max(x, y))) for y in self._adj.get(x, ())}
        return (x, self.paths[x], self.times[x], self.cumlen[x], float(self.lengths[x]), float(self.travel[x]),
                self._segs[x], {y: self._pieces[k] for y, k in pairs.items()},
                {y: self._regions[k] for y, k in pairs.items() if k in self._regions})

    def restore(self, snap: tuple) -> None:
        """Robot x back as it was at :meth:`snapshot` (its path may have changed since, nobody
        else's)."""
        x, path, times, cumlen, length, travel, segs, pieces, regions = snap
        self._forget(x)
        self.paths[x], self.times[x], self.cumlen[x] = path, times, cumlen
        self.lengths[x], self.travel[x] = length, travel
        self._segs[x] = segs
        self._set_bbox(x)
        for y, chunk in pieces.items():
            key = (min(x, y), max(x, y))
            self._pieces[key] = chunk
            if y in regions:
                self._regions[key] = regions[y]
            self._link(x, y)
        if x not in self._stale and self._tree_segs is not None:   # its rows in the index are stale
            self._stale.add(x)
            self._stale_rows += len(segs.p0)

    # -- the geometry ---------------------------------------------------------------------------
    def _set_bbox(self, x: int) -> None:
        """(min x, min y, max x, max y) of robot x's path, kept in ``_bb``."""
        pts = self.paths[x]
        self._bb[x, :2], self._bb[x, 2:] = pts.min(0), pts.max(0)

    def _near(self, robots: list[int], others: Iterable[int], reach: float) -> list[int]:
        """Those of ``others`` (ascending) whose path's bounding box comes within ``reach`` of the
        bounding box of one of ``robots``' paths."""
        others = np.array(sorted(others), dtype=np.int64)
        mine, theirs = self._bb[robots], self._bb[others]
        close = np.any(np.all((theirs[:, None, :2] <= mine[None, :, 2:] + reach)
                              & (mine[None, :, :2] <= theirs[:, None, 2:] + reach), axis=2), axis=1)
        return others[close].tolist()

    def _build_tree(self) -> None:
        import shapely

        segs = _cat(self._segs)
        p1 = segs.p0 + segs.u * segs.length[:, None]
        lo, hi = np.minimum(segs.p0, p1), np.maximum(segs.p0, p1)
        self._tree = shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
        self._tree_segs = segs
        self._stale, self._stale_rows = set(), 0

    def _compute(self, robots: Iterable[int], all_pairs: bool) -> None:
        import shapely

        robots = list(robots)
        if not robots or len(self.paths) < 2:
            return
        reach = 2 * float(self.radii.max()) + self.margin
        mine = self._segs[robots[0]] if len(robots) == 1 else _cat([self._segs[x] for x in robots])
        # candidates by envelopes grown by the reach (the exact test is the capsule computation
        # below); not the "dwithin" predicate, which misses zero-length segments (parked robots)
        # in GEOS 3.14
        p1 = mine.p0 + mine.u * mine.length[:, None]
        lo, hi = np.minimum(mine.p0, p1) - reach, np.maximum(mine.p0, p1) + reach
        if self.focus is not None:
            # pairs with the focus only: no index of the fleet, the robots whose paths come near
            # (bounding boxes) and their segments' envelopes compared directly
            rsegs, qi, ti = self._direct(robots, range(len(self.paths)), mine, lo, hi, reach)
            parts = [(qi, ti, rsegs)]
        else:
            if all_pairs or self._tree is None or self._stale_rows > self.REBUILD_SHARE * len(self._tree_segs.p0):
                self._build_tree()
            tree, tsegs = self._tree, self._tree_segs
            assert tree is not None and tsegs is not None
            qi, ti = tree.query(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
            if all_pairs:
                keep = mine.owner[qi] < tsegs.owner[ti]
                parts = [(qi[keep], ti[keep], tsegs)]
            else:
                # unchanged robots from the fleet's index
                changed = self._stale | set(robots)
                stale = np.zeros(len(self.paths), dtype=bool)
                stale[list(changed)] = True
                fresh = ~stale[tsegs.owner[ti]]
                # robots changed since the index was built (these included): envelopes compared
                # directly (cheaper than building an index per call)
                rsegs, rq, rt = self._direct(robots, changed, mine, lo, hi, reach)
                parts = [(qi[fresh], ti[fresh], tsegs), (rq, rt, rsegs)]
                for x in robots:
                    if x not in self._stale:
                        self._stale.add(x)
                        self._stale_rows += len(self._segs[x].p0)
        # the exact test and the pieces, each pair oriented so that the smaller robot index is x
        # (compiled: fleet_planner._md_kernels.segment_pieces)
        tables = [K.segment_pieces(q, t, *_kernel_cols(mine), *_kernel_cols(b), self.radii, self.margin,
                                   _NO_PIECES.shape[1]) for q, t, b in parts if len(q)]
        pieces = np.vstack(tables) if len(tables) > 1 else tables[0] if tables else _NO_PIECES
        if not len(pieces):
            return
        # by pair, then along the pair; ties by the segments, so that the order does not depend on
        # how the candidates were found (the fleet's index or directly)
        pieces = pieces[np.lexsort((pieces[:, P_Y_SEG], pieces[:, P_X_SEG], pieces[:, P_B_LO], pieces[:, P_A_LO],
                                    pieces[:, P_Y], pieces[:, P_X]))]
        pair_key = pieces[:, P_X] * len(self.paths) + pieces[:, P_Y]
        first = np.concatenate([[0], np.nonzero(np.diff(pair_key))[0] + 1])
        cuts = [*first.tolist(), len(pieces)]
        keys = list(zip(pieces[first, P_X].astype(np.int64).tolist(), pieces[first, P_Y].astype(np.int64).tolist()))
        self._pieces.update(zip(keys, [pieces[c0:c1] for c0, c1 in zip(cuts[:-1], cuts[1:])]))
        regions = self._regions
        for key in keys:
            if regions:
                regions.pop(key, None)
            self._link(*key)

    def _direct(self, robots: list[int], others: Iterable[int], mine: _Segs, lo: np.ndarray, hi: np.ndarray,
                reach: float) -> tuple[_Segs, np.ndarray, np.ndarray]:
        """Candidate pairs of ``mine`` (the segments of ``robots``, envelopes ``lo``/``hi`` grown by
        the reach) with the segments of those of ``others`` whose whole path comes within reach:
        (their segments, rows of mine, rows of theirs), rows of mine ascending, then theirs; a pair
        of two of ``robots`` once (owner order), never a robot with itself."""
        near = self._near(robots, others, reach)
        if not near:
            return mine, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        rsegs = self._segs[near[0]] if len(near) == 1 else _cat([self._segs[x] for x in near])
        rp1 = rsegs.p0 + rsegs.u * rsegs.length[:, None]
        rlo, rhi = np.minimum(rsegs.p0, rp1), np.maximum(rsegs.p0, rp1)
        rq, rt = K.box_pairs(lo, hi, rlo, rhi)
        inside = np.zeros(len(self.paths), dtype=bool)
        inside[robots] = True
        both = inside[rsegs.owner[rt]]
        keep = np.where(both, mine.owner[rq] < rsegs.owner[rt], mine.owner[rq] != rsegs.owner[rt])
        return rsegs, rq[keep], rt[keep]


# Columns of a piece table: one row per pair of segments (one of robot x, one of robot y, x < y)
# whose discs come closer than R. A/B: travelled lengths of x/y bounding the piece. PHI: the range of
# t_x(a) - t_y(b) (undelayed) over the piece, so that y collides with a delayed x here iff
# d_y - d_x lies strictly inside (PHI_LO, PHI_HI). E_*: the piece's extent on the edges of the
# segment pair where a robot may be parked (x at the start / end of its segment, y likewise), as
# the other robot's travelled length (lo > hi when empty). OFF/T0/V: where each segment starts
# (travelled length, undelayed time) and its speed, so t(s) = T0 + (s - OFF) / V on it. SEG: the
# index of each robot's segment along its path (a one-point path has one segment of length 0).
(P_X, P_Y, P_A_LO, P_A_HI, P_B_LO, P_B_HI, P_PHI_LO, P_PHI_HI,
 P_XS_LO, P_XS_HI, P_XE_LO, P_XE_HI, P_YS_LO, P_YS_HI, P_YE_LO, P_YE_HI,
 P_X_FIRST, P_X_LAST, P_Y_FIRST, P_Y_LAST,
 P_X_OFF, P_X_T0, P_X_V, P_Y_OFF, P_Y_T0, P_Y_V, P_X_SEG, P_Y_SEG) = range(28)
_NO_PIECES = np.zeros((0, 28))


def _merge_boxes(boxes: np.ndarray) -> list[tuple[float, float, float, float]]:
    """Connected components of boxes (a_lo, a_hi, b_lo, b_hi) sorted by a_lo; two boxes that overlap
    or touch are one component. Returns the components' bounding boxes sorted by a_lo."""
    comps: list[list[float]] = []
    for a_lo, a_hi, b_lo, b_hi in boxes.tolist():
        hits = [c for c in comps if a_lo <= c[1] + EPS and c[0] <= a_hi + EPS
                and b_lo <= c[3] + EPS and c[2] <= b_hi + EPS]
        if not hits:
            comps.append([a_lo, a_hi, b_lo, b_hi])
            continue
        merged = [min([a_lo] + [c[0] for c in hits]), max([a_hi] + [c[1] for c in hits]),
                  min([b_lo] + [c[2] for c in hits]), max([b_hi] + [c[3] for c in hits])]
        comps = [c for c in comps if not any(c is h for h in hits)]
        comps.append(merged)
        # a grown box may now touch others: re-merge until stable (rare, components are few)
        changed = True
        while changed:
            changed = False
            last = comps[-1]
            for c in comps[:-1]:
                if (last[0] <= c[1] + EPS and c[0] <= last[1] + EPS
                        and last[2] <= c[3] + EPS and c[2] <= last[3] + EPS):
                    comps.remove(c)
                    comps[-1] = [min(last[0], c[0]), max(last[1], c[1]), min(last[2], c[2]), max(last[3], c[3])]
                    changed = True
                    break
    comps.sort(key=lambda c: c[0])
    return [(c[0], c[1], c[2], c[3]) for c in comps]


def _merge_boxes_batch(chunks: Sequence[np.ndarray]) -> list[list[tuple[float, float, float, float]]]:
    """What :func:`_merge_boxes` computes (boxes that overlap or touch, and the bounding boxes of
    what they form, merged until none touch another) for many pairs' boxes at once, in compiled
    code (:func:`fleet_planner._md_kernels.merge_boxes`: union-find over each chunk's touching
    pairs, repeated on the merged boxes until none touch); each chunk's boxes sorted by
    (a_lo, b_lo), ties in the order of their first box."""
    if not chunks:
        return []
    sizes = [len(c) for c in chunks]
    ptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    boxes, out_ptr = K.merge_boxes(np.ascontiguousarray(np.vstack(chunks), dtype=float), ptr, EPS)
    rows = boxes.tolist()
    bounds = out_ptr.tolist()
    return [[(r[0], r[1], r[2], r[3]) for r in rows[lo:hi]] for lo, hi in zip(bounds[:-1], bounds[1:])]


