"""Plane geometry of discs and polylines, the one home for distances (numpy only, nothing of ours).

Every part of the planner that asks "how close does this path come to that point?" asks here:

* :func:`segment_point_distance` - point(s) to segment(s), broadcasting over leading axes;
* :func:`segment_point_distance_xy` - the same for one segment and one point as plain floats (for
  the inner loops of the prioritized search, where numpy's per-call cost would dominate);
* :func:`polyline_point_distances` - each of many points to one polyline;
* :func:`polyline_passes_near` - does a polyline come closer than ``dist`` to a point;
* :func:`polyline_keeps_off` - does a polyline stay farther than each disc's radius from its centre;
* :func:`polyline_length`, :func:`arc_lengths`, :func:`point_at_arc` - lengths and points along a polyline.

A polyline is an array of shape (n, 2); a single point counts as a polyline of one (degenerate)
segment. The swept disc of a robot driving a segment is a *capsule*: the points within its radius
of the segment, so "the capsules of two robots overlap" is "a distance below a sum of radii".
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

Point = tuple[float, float]


def segment_point_distance(a: np.ndarray, b: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Distance from point(s) ``p`` to segment(s) ``a -> b`` (arrays ending in 2, broadcasting over
    the leading axes). A zero-length segment is its point."""
    ab = b - a
    ap = p - a
    den = np.sum(ab * ab, axis=-1)
    t = np.clip(np.sum(ap * ab, axis=-1) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    d = ap - t[..., None] * ab
    return np.hypot(d[..., 0], d[..., 1])


def segment_point_distance_xy(ax: float, ay: float, bx: float, by: float, px: float, py: float) -> float:
    """Distance from point p to the segment a-b, in plain floats."""
    dx, dy = bx - ax, by - ay
    dd = dx * dx + dy * dy
    s = 0.0 if dd == 0.0 else min(max(((px - ax) * dx + (py - ay) * dy) / dd, 0.0), 1.0)
    return math.hypot(ax + s * dx - px, ay + s * dy - py)


def _segments(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    poly = np.asarray(poly, dtype=float).reshape(-1, 2)
    if len(poly) < 2:
        return poly, poly
    return poly[:-1], poly[1:]


def polyline_point_distances(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance from each point (shape (n, 2)) to the polyline (shape (m, 2)): shape (n,)."""
    a, b = _segments(poly)
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    return segment_point_distance(a[None], b[None], pts[:, None, :]).min(axis=1)


def polyline_passes_near(poly: np.ndarray, point: Sequence[float], dist: float) -> bool:
    """True if some point of the polyline is closer than ``dist`` to ``point``."""
    a, b = _segments(poly)
    return bool(np.min(segment_point_distance(a, b, np.asarray(point, dtype=float))) < dist)


def polyline_keeps_off(poly: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> bool:
    """True if the polyline stays farther than ``radii[k]`` from every ``centres[k]``."""
    c = np.asarray(centres, dtype=float).reshape(-1, 2)
    if len(c) == 0:
        return True
    a, b = _segments(poly)
    d = segment_point_distance(a[None], b[None], c[:, None, :])
    return bool((d > np.asarray(radii, dtype=float)[:, None]).all())


def polyline_length(points: Sequence[Point] | np.ndarray) -> float:
    """Length of a polyline (0 for fewer than two points)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 2)
    return float(np.sum(np.hypot(*np.diff(pts, axis=0).T))) if len(pts) > 1 else 0.0


def arc_lengths(points: np.ndarray) -> np.ndarray:
    """The arc length at each point of a polyline (its first two columns: x, y), from 0 at the first."""
    pts = np.asarray(points, dtype=float)
    if len(pts) < 2:
        return np.zeros(len(pts))
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts[:, :2], axis=0).T))])


def points_at_arcs(points: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The points of the polyline ``points`` (its first two columns) at the given arc lengths (clamped to its
    ends), shape (len(lengths), 2)."""
    pts = np.asarray(points, dtype=float)
    cum = arc_lengths(pts)
    s = np.asarray(lengths, dtype=float)
    return np.column_stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])])


def positions_at_times(waypoints: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Where a timed path's robot is at each of ``times`` (waypoints (x, y, t)), shape (len(times), 2): as
    ``TimedPath.position``, on the first waypoint until its time and on the last one after it."""
    wp = np.asarray(waypoints, dtype=float)
    t = np.asarray(times, dtype=float)
    if len(wp) == 1:
        return np.broadcast_to(wp[0, :2], (len(t), 2)).copy()
    k = np.clip(np.searchsorted(wp[:, 2], t, side="right") - 1, 0, len(wp) - 2)
    t0, t1 = wp[k, 2], wp[k + 1, 2]
    span = t1 - t0
    a = np.clip(np.where(span > 0, (t - t0) / np.where(span > 0, span, 1.0), 0.0), 0.0, 1.0)
    p = wp[k, :2] + a[:, None] * (wp[k + 1, :2] - wp[k, :2])
    p[t <= wp[0, 2]] = wp[0, :2]      # as position() even where the first or last waypoints
    p[t >= wp[-1, 2]] = wp[-1, :2]    # share a time
    return p


def arc_at_time(waypoints: np.ndarray, t: float) -> float:
    """How far along its polyline a timed path (waypoints (x, y, t)) is at time ``t`` (clamped to its ends)."""
    wp = np.asarray(waypoints, dtype=float)
    return float(np.interp(t, wp[:, 2], arc_lengths(wp)))


def point_at_arc(pts: np.ndarray, arc: np.ndarray, s: float) -> Point:
    """The point at arc length ``s`` along the polyline ``pts`` (``arc``: arc length at each point;
    clamped to the ends)."""
    keep = np.concatenate([[True], np.diff(arc) > 0])
    return float(np.interp(s, arc[keep], pts[keep, 0])), float(np.interp(s, arc[keep], pts[keep, 1]))
