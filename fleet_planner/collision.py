"""Collision regions and collision boxes of paper 001, in continuous geometry.

For two robots x and y on fixed polyline paths, the set of travelled-length pairs ``(a, b)`` at which
their discs overlap, ``|p_x(a) - p_y(b)| < r_x + r_y``, is what paper 001 calls the collision region
(drawn there in time x travelled-length coordinates; with a known velocity profile the two views are
the same set). For one segment of each path that set is convex, so its extent along each path is
one interval: the part of the segment inside the *capsule* of radius ``R`` around the other
segment. Those per-segment-pair boxes are computed for all nearby segment pairs at once with numpy
(pairs found with a shapely STRtree, never by looping over all pairs of path samples) and merged
into connected components: one component is one collision region ``k`` of the pair, its bounding
box ``[a_lo, a_hi] x [b_lo, b_hi]`` its collision box.

Paths are stored by robot index. Nothing here knows about priorities or delays: that is the
scheduler's business (:mod:`fleet_planner.scheduler`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

EPS = 1e-9


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


def _segments(paths: Sequence[np.ndarray]):
    """Flatten polylines into segment arrays. A path of one point (a robot that does not move) is a
    zero-length segment, so a parked robot still has regions with everyone passing by."""
    starts, dirs, lens, owner, offset = [], [], [], [], []
    for idx, pts in enumerate(paths):
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        if len(pts) == 1:
            pts = np.vstack([pts, pts])
        d = np.diff(pts, axis=0)
        seg_len = np.hypot(d[:, 0], d[:, 1])
        unit = np.divide(d, seg_len[:, None], out=np.tile([1.0, 0.0], (len(d), 1)), where=seg_len[:, None] > 0)
        starts.append(pts[:-1])
        dirs.append(unit)
        lens.append(seg_len)
        owner.append(np.full(len(d), idx))
        offset.append(np.concatenate([[0.0], np.cumsum(seg_len)[:-1]]))
    return (np.vstack(starts), np.vstack(dirs), np.concatenate(lens), np.concatenate(owner),
            np.concatenate(offset))


def _circle_interval(w: np.ndarray, u: np.ndarray, R: np.ndarray):
    """Parameters s with |w + s*u| < R for unit u: roots of s^2 + 2 s (u.w) + |w|^2 - R^2."""
    b = np.einsum("ij,ij->i", u, w)
    c = np.einsum("ij,ij->i", w, w) - R * R
    disc = b * b - c
    root = np.sqrt(np.maximum(disc, 0.0))
    lo, hi = -b - root, -b + root
    empty = disc <= 0
    return np.where(empty, np.inf, lo), np.where(empty, -np.inf, hi)


def capsule_interval(p0: np.ndarray, u: np.ndarray, length: np.ndarray,
                     q0: np.ndarray, v: np.ndarray, qlen: np.ndarray, R: np.ndarray):
    """For each row: the interval [lo, hi] of s in [0, length] such that the point p0 + s*u lies within
    R of the segment q0 + t*v, t in [0, qlen] (u, v unit vectors). Empty rows have lo > hi.

    The capsule is convex, so its intersection with a line is one interval: the union of the two
    end discs' intervals and the slab's."""
    w0 = p0 - q0
    lo_a, hi_a = _circle_interval(w0, u, R)
    lo_b, hi_b = _circle_interval(w0 - v * qlen[:, None], u, R)
    # slab: perpendicular distance to q's line < R and projection within [0, qlen]
    cross0 = v[:, 0] * w0[:, 1] - v[:, 1] * w0[:, 0]
    cross1 = v[:, 0] * u[:, 1] - v[:, 1] * u[:, 0]
    proj0 = np.einsum("ij,ij->i", v, w0)
    proj1 = np.einsum("ij,ij->i", v, u)
    with np.errstate(divide="ignore", invalid="ignore"):
        # |cross0 + s*cross1| < R
        s1 = (-R - cross0) / cross1
        s2 = (R - cross0) / cross1
        perp_lo = np.where(cross1 != 0, np.minimum(s1, s2), np.where(np.abs(cross0) < R, -np.inf, np.inf))
        perp_hi = np.where(cross1 != 0, np.maximum(s1, s2), np.where(np.abs(cross0) < R, np.inf, -np.inf))
        # 0 <= proj0 + s*proj1 <= qlen
        t1 = -proj0 / proj1
        t2 = (qlen - proj0) / proj1
        inside = (proj0 >= 0) & (proj0 <= qlen)
        proj_lo = np.where(proj1 != 0, np.minimum(t1, t2), np.where(inside, -np.inf, np.inf))
        proj_hi = np.where(proj1 != 0, np.maximum(t1, t2), np.where(inside, np.inf, -np.inf))
    slab_lo = np.maximum(perp_lo, proj_lo)
    slab_hi = np.minimum(perp_hi, proj_hi)
    slab_empty = slab_lo >= slab_hi
    slab_lo = np.where(slab_empty, np.inf, slab_lo)
    slab_hi = np.where(slab_empty, -np.inf, slab_hi)
    lo = np.minimum(np.minimum(lo_a, lo_b), slab_lo)
    hi = np.maximum(np.maximum(hi_a, hi_b), slab_hi)
    return np.maximum(lo, 0.0), np.minimum(hi, length)


class CollisionModel:
    """Collision regions of every pair of robots, kept up to date as paths change.

    ``radii`` are the robots' radii; two discs are in conflict when closer than
    ``r_x + r_y + margin``. ``set_path`` replaces one robot's path and recomputes only its pairs
    (re-ordering robots re-plans one or two paths; everything else is kept).
    """

    def __init__(self, paths: Sequence[np.ndarray], radii: Sequence[float], margin: float = 0.0):
        self.radii = np.asarray(radii, dtype=float)
        self.margin = float(margin)
        self.paths = [np.asarray(p, dtype=float).reshape(-1, 2) for p in paths]
        self.lengths = np.array([_length(p) for p in self.paths])
        self._regions: dict[tuple[int, int], list[Region]] = {}
        self._compute(range(len(self.paths)), all_pairs=True)

    # -- queries --------------------------------------------------------------------------------
    def regions(self, x: int, y: int) -> list[Region]:
        """Regions between robots x and y (any order), sorted along the smaller index's path."""
        return self._regions.get((min(x, y), max(x, y)), [])

    def neighbours(self, x: int) -> Iterable[int]:
        for (a, b) in self._regions:
            if a == x:
                yield b
            elif b == x:
                yield a

    def pairs(self) -> Iterable[tuple[int, int]]:
        return self._regions.keys()

    @property
    def region_count(self) -> int:
        return sum(len(v) for v in self._regions.values())

    # -- updates --------------------------------------------------------------------------------
    def set_path(self, x: int, path: np.ndarray) -> None:
        self.set_paths({x: path})

    def set_paths(self, changed: dict[int, np.ndarray]) -> None:
        for x, path in changed.items():
            self.paths[x] = np.asarray(path, dtype=float).reshape(-1, 2)
            self.lengths[x] = _length(self.paths[x])
        dirty = set(changed)
        self._regions = {k: v for k, v in self._regions.items() if k[0] not in dirty and k[1] not in dirty}
        self._compute(sorted(dirty), all_pairs=False)

    # -- the geometry ---------------------------------------------------------------------------
    def _compute(self, robots: Iterable[int], all_pairs: bool) -> None:
        import shapely

        robots = list(robots)
        if not robots or len(self.paths) < 2:
            return
        p0, u, seg_len, owner, offset = _segments(self.paths)
        p1 = p0 + u * seg_len[:, None]
        lines = shapely.linestrings(np.stack([p0, p1], axis=1))
        reach = 2 * float(self.radii.max()) + self.margin
        tree = shapely.STRtree(lines)
        if all_pairs:
            qi, ti = tree.query(lines, predicate="dwithin", distance=reach)
        else:
            mine = np.nonzero(np.isin(owner, robots))[0]
            qi, ti = tree.query(lines[mine], predicate="dwithin", distance=reach)
            qi = mine[qi]
        # keep each unordered segment pair once, of two different robots
        keep = owner[qi] < owner[ti]
        if not all_pairs:
            # a pair of two changed robots is found from both sides; a pair (changed, unchanged)
            # only from the changed side, possibly with the changed robot second
            swap = (owner[qi] > owner[ti]) & ~np.isin(owner[ti], robots)
            qi, ti = np.concatenate([qi[keep], ti[swap]]), np.concatenate([ti[keep], qi[swap]])
        else:
            qi, ti = qi[keep], ti[keep]
        if len(qi) == 0:
            return
        R = self.radii[owner[qi]] + self.radii[owner[ti]] + self.margin
        a_lo, a_hi = capsule_interval(p0[qi], u[qi], seg_len[qi], p0[ti], u[ti], seg_len[ti], R)
        b_lo, b_hi = capsule_interval(p0[ti], u[ti], seg_len[ti], p0[qi], u[qi], seg_len[qi], R)
        hit = (a_lo <= a_hi) & (b_lo <= b_hi)
        boxes = np.column_stack([owner[qi], owner[ti], offset[qi] + a_lo, offset[qi] + a_hi,
                                 offset[ti] + b_lo, offset[ti] + b_hi])[hit]
        order = np.lexsort((boxes[:, 2], boxes[:, 1], boxes[:, 0]))
        boxes = boxes[order]
        if len(boxes) == 0:
            return
        pair_key = boxes[:, 0] * len(self.paths) + boxes[:, 1]
        cuts = np.nonzero(np.diff(pair_key))[0] + 1
        for chunk in np.split(boxes, cuts):
            x, y = int(chunk[0, 0]), int(chunk[0, 1])
            self._regions[(x, y)] = [Region(x, y, *b) for b in _merge_boxes(chunk[:, 2:])]


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
    return [tuple(c) for c in comps]


def _length(path: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(path, axis=0).T))) if len(path) > 1 else 0.0
