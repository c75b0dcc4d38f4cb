"""Execution gated by the (M,D) network: a robot does not enter a collision region before the
robot ranked above it there has left it, by their reported progress, whatever the clock says
(docs/ARCHITECTURE.md, "Gated execution"; the spirit of the Action Dependency Graph of Hoenig et
al., built on the collision regions of You & Ji, "Design of a Multi-robot Bin Packing System in
an Automatic Warehouse").

Two robots on fixed paths conflict where their discs (grown by :data:`PAD_M`) overlap: a set of
pairs (travelled length of one, travelled length of the other). Each connected piece of that set
is a collision region; one of the two robots passes it first. The other gets **links**
(:class:`Link`): "do not drive beyond ``entry`` metres along your path before ``robot`` reports
more than ``exit`` metres along its path ``path_id``" - one link per stretch of the region, so a
robot may follow another down an aisle (the exit grows along the entry, a staircase). Which robot
passes first comes from the plan's times (the curve of the two travelled lengths in time passes
on one side of the region), except where reality decides: a robot that may already be in the
region (its due position, which it is never ahead of, reaches it soon) passes first, and a robot
whose new path starts inside a region passes it first (unless the other may be in it already and
does not stand for good at the end of its latest path, or after refusing its latest leg: ours, :data:`STILL_MPS`,
:func:`stands_refused`).

The robot's end is pure and small: :func:`gate_limit` says how far the robot may drive along its
path now, given its :class:`~msg_schemas.records.GateRecord` and the other robots' last statuses
(any ``Mapping[robot id -> RobotStatus]``, so where they come from may change); unknown progress
(no status, a status on an earlier path, a later path its record was not checked against) means
wait. :func:`watched_robots` says whose statuses a robot's gate needs.

The planner's end is :class:`GateBook`: on every new leg (:meth:`GateBook.on_leg`) it computes
the leg's links against every other robot's live paths, and the links the others must get
because the new leg passes a region before them; those records grow and are re-sent whole (a
higher ``seq``). A robot that stops for good (:meth:`GateBook.forget`) is dropped from the
records of robots whose way does not pass it; the others keep waiting until they are re-planned.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.spatial.distance import cdist

from msg_schemas.records import MAX_RECORD_BYTES, GateRecord, RobotStatus

from ..geometry import arc_at_time, arc_lengths, polyline_passes_near
from ..model import TimedPath
from .state import FleetRobot

#: spacing (m) of the samples along each path the regions are found on; the sampling is covered by
#: growing the discs by one spacing
SAMPLE_M = 0.1
#: the gate keeps the discs this far (m) apart beyond the sum of radii; it must stay below the
#: planner's margin, so that a plan never enters the regions it is gated by
PAD_M = 0.08
#: a link covers a stretch of the waiting robot's path over which the exit it waits for grows by
#: at most this much (m): finer is closer to the plan, coarser is fewer links
PIECE_TOL_M = 0.05
#: a new link reaches a driving robot within this long (s); it is ranked first wherever its due
#: position gets within a region before then
REACH_S = 1.0
#: (ours) a robot at the end of its latest path, which it reports, slower than this (m/s) stands for good: a new
#: leg starting in a region with it passes first rather than being refused (:meth:`GateBook.on_leg`)
STILL_MPS = 0.05
#: spacing (m) of the fine samples that tell whether a robot may already be in a region: its disc
#: comes within the pad of the other path there (less twice this, the fine samples' own error)
FINE_M = 0.01
#: a gate record's links take at most this many characters of JSON (links merged the safe way
#: beyond it, :func:`compact`): well within what a record may be (``MAX_RECORD_BYTES``)
RECORD_BUDGET = MAX_RECORD_BYTES * 3 // 4


@dataclass(frozen=True)
class Link:
    """Do not drive beyond ``entry`` (m along my path) before ``robot`` reports more than ``exit``
    (m along its path ``path_id``; None: it never leaves the region on that path) or a later path."""

    robot: str
    path_id: int
    exit: float | None
    entry: float

    def to_dict(self) -> dict[str, object]:
        """The link as a record holds it: in whole millimetres, rounded the safe way (the exit up,
        the entry down). A long shared aisle gives hundreds of links, and full floats made the
        records of 100 robots on ``large`` outgrow what an agent takes (a 281,072-character one)."""
        ex = None if self.exit is None else math.ceil(self.exit * 1000 - 1e-6) / 1000
        return {"robot": self.robot, "path_id": self.path_id, "exit": ex,
                "entry": max(0.0, math.floor(self.entry * 1000 + 1e-6) / 1000)}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Link:
        """A link of a (validated) gate record."""
        ex = d["exit"]
        return cls(str(d["robot"]), int(d["path_id"]), None if ex is None else float(ex), float(d["entry"]))


def _key(d: Mapping[str, Any]) -> tuple[Any, ...]:
    """A link of a record as a hashable whole (robot, path, exit, entry)."""
    return d["robot"], d["path_id"], d["exit"], d["entry"]


def links_of(record: GateRecord) -> tuple[Link, ...]:
    """The links of ``record``, parsed once per record: a record (immutable) is asked every tick by
    its robot's gate, and a simulator of 100 gated robots spent a third of its time re-parsing them."""
    hit = _LINKS.get(id(record))
    if hit is not None and hit[0] is record:
        return hit[1]
    links = tuple(Link.from_dict(d) for d in record.links)
    if len(_LINKS) >= _LINKS_MAX:   # (each robot holds one record at a time: older ones go)
        _LINKS.clear()
    _LINKS[id(record)] = (record, links)
    return links


#: links_of's parsed records by id (the record kept with them, so that its id is not reused meanwhile)
_LINKS: dict[int, tuple[GateRecord, tuple[Link, ...]]] = {}
_LINKS_MAX = 4096


def _link_chars(d: Mapping[str, Any]) -> int:
    """At most how many characters of JSON the link ``d`` takes (its robot id and 96 for the rest)."""
    return len(d["robot"]) + 96


def compact(links: tuple[dict[str, Any], ...], budget: int | None = None) -> tuple[dict[str, Any], ...]:
    """``links`` merged the safe way until they take at most ``budget`` characters of JSON (ours):
    the robot with the most links on one path of another robot has them halved, neighbours by
    entry merged into one that stops at the earlier entry until the other robot is beyond both
    exits (never: if either is never). The robot waits at least as long as before: a robot that
    follows another down a long aisle gets a link every 0.1 m (over 700 on ``large``), and halving
    them there only keeps it a little farther back when the one ahead is late. ``budget``: by
    default :data:`RECORD_BUDGET`."""
    budget = RECORD_BUDGET if budget is None else budget
    size = sum(_link_chars(d) for d in links)
    if size <= budget:
        return links
    groups: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for d in links:
        groups.setdefault((d["robot"], d["path_id"]), []).append(d)
    while size > budget:
        key = max(groups, key=lambda k: len(groups[k]))
        g = sorted(groups[key], key=lambda d: d["entry"])
        if len(g) < 2:
            break   # one link per path of each robot: nothing left to merge (never near the budget)
        merged = []
        for a, b in zip(g[0::2], g[1::2]):
            ex = None if a["exit"] is None or b["exit"] is None else max(a["exit"], b["exit"])
            merged.append({**a, "exit": ex, "entry": min(a["entry"], b["entry"])})
        merged += g[len(g) - len(g) % 2:]
        size -= sum(_link_chars(d) for d in g) - sum(_link_chars(d) for d in merged)
        groups[key] = merged
    return tuple(d for g in groups.values() for d in g)


# -------------------------------------------------------------------------------------------------
# the robot's end
# -------------------------------------------------------------------------------------------------
def travelled(status: RobotStatus) -> float | None:
    """How far (m) ``status`` says its robot drove along its path (None: it does not say; a robot
    at the end of its path has driven all of it)."""
    if status.travelled_m is not None:
        return status.travelled_m
    return math.inf if status.progress >= 1.0 else None


def satisfied(link: Link, statuses: Mapping[str, RobotStatus], watch: Mapping[str, int]) -> bool:
    """Whether ``link``'s robot has left the region: its status shows it beyond the exit on the
    link's path, or on a later path that the record was checked against (``watch``)."""
    st = statuses.get(link.robot)
    if st is None or st.path_id is None:
        return False
    if st.path_id == link.path_id:
        done = travelled(st)
        return link.exit is not None and done is not None and done > link.exit
    return st.path_id > link.path_id and watch.get(link.robot, -1) >= st.path_id


def gate_limit(record: GateRecord | None, path_id: int | None, statuses: Mapping[str, RobotStatus]) -> float:
    """How far (m along its path ``path_id``) a robot may drive now: the nearest entry of a link
    not yet satisfied (infinite if none); 0 without a record for that path (wait for it)."""
    if record is None or path_id is None or record.path_id != path_id:
        return 0.0
    watch = record.watch or {}
    return min((lk.entry for lk in links_of(record) if not satisfied(lk, statuses, watch)), default=math.inf)


def blockers(record: GateRecord | None, statuses: Mapping[str, RobotStatus], before: float) -> list[str]:
    """The robots whose links, not yet satisfied, stop the robot before ``before`` m."""
    if record is None:
        return []
    watch = record.watch or {}
    return sorted({lk.robot for lk in links_of(record) if lk.entry < before and not satisfied(lk, statuses, watch)})


def watched_robots(record: GateRecord | None, statuses: Mapping[str, RobotStatus] | None = None) -> set[str]:
    """The robots whose statuses the gate of ``record`` needs: every robot its links name, or with
    ``statuses``, only those whose links are not yet satisfied by them."""
    if record is None:
        return set()
    links = links_of(record)
    if statuses is None:
        return {lk.robot for lk in links}
    watch = record.watch or {}
    return {lk.robot for lk in links if not satisfied(lk, statuses, watch)}


# -------------------------------------------------------------------------------------------------
# regions and links
# -------------------------------------------------------------------------------------------------
@dataclass
class _Samples:
    s: np.ndarray     # travelled length of each sample (m)
    xy: np.ndarray    # (n, 2) positions
    t: np.ndarray     # planned first arrival at each sample (s)
    h: float          # spacing
    parks: bool       # the last sample is where the path ends (the robot stays there for ever)


def sample(path: TimedPath, lo: float = 0.0, hi: float = math.inf, step: float = SAMPLE_M) -> _Samples:
    """Samples of ``path`` from ``lo`` to ``hi`` m along it, at most ``step`` apart."""
    wp, arc = path.waypoints, arc_lengths(path.waypoints)
    total = float(arc[-1])
    lo, hi = min(max(lo, 0.0), total), min(hi, total)
    hi = max(hi, lo)
    n = max(1, math.ceil((hi - lo) / step - 1e-9) + 1)
    s = np.linspace(lo, hi, n)
    keep = np.concatenate([[True], np.diff(arc) > 0])  # the first arrival where the path holds
    a = arc[keep]
    if len(a) == 1:
        xy = np.repeat(wp[:1, :2], n, axis=0)
        t = np.full(n, wp[0, 2])
    else:
        xy = np.column_stack([np.interp(s, a, wp[keep, 0]), np.interp(s, a, wp[keep, 1])])
        t = np.interp(s, a, wp[keep, 2])
    return _Samples(s, xy, t, (hi - lo) / (n - 1) if n > 1 else 0.0, hi >= total)


def arc_at(path: TimedPath, t: float) -> float:
    """How far along ``path`` its plan is at time ``t``."""
    return arc_at_time(path.waypoints, t)


def regions(a: _Samples, b: _Samples, reach: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The connected pieces of sample pairs closer than ``reach`` (grown by both spacings): each
    as the indices into ``a`` and into ``b`` of its pairs."""
    reach = reach + a.h / 2 + b.h / 2
    lo, hi = a.xy.min(axis=0) - reach, a.xy.max(axis=0) + reach
    near_b = np.nonzero(np.all((b.xy >= lo) & (b.xy <= hi), axis=1))[0]
    if not len(near_b):
        return []
    mask = np.zeros((len(a.s), len(b.s)), dtype=bool)
    mask[:, near_b] = cdist(a.xy, b.xy[near_b]) < reach
    if not mask.any():
        return []
    labels, n = ndimage.label(mask, structure=np.ones((3, 3), dtype=int))
    ia, ib = np.nonzero(labels)
    lab = labels[ia, ib]
    order = np.argsort(lab, kind="stable")
    cuts = np.searchsorted(lab[order], np.arange(1, n + 1))
    return [(ia[order[c:e]], ib[order[c:e]]) for c, e in zip(cuts, np.append(cuts[1:], len(order)))]


def pieces(first: _Samples, then: _Samples, i_first: np.ndarray,
           i_then: np.ndarray) -> list[tuple[float | None, float]]:
    """The links of one region that ``first`` passes before ``then``: (exit along first's path,
    entry along then's path), one per stretch of ``then``'s path where the exit grows by at most
    :data:`PIECE_TOL_M`."""
    rows, inv = np.unique(i_then, return_inverse=True)
    far = np.full(len(rows), -1, dtype=int)
    np.maximum.at(far, inv, i_first)
    out: list[tuple[float | None, float]] = []
    k = 0
    while k < len(rows):
        start, top = k, far[k]
        while (k + 1 < len(rows) and rows[k + 1] == rows[k] + 1
               and first.s[far[k + 1]] <= first.s[far[start]] + PIECE_TOL_M):
            k += 1
            top = max(top, far[k])
        parked = first.parks and top == len(first.s) - 1
        exit_m = None if parked else float(first.s[top] + first.h / 2)
        out.append((exit_m, max(0.0, float(then.s[rows[start]] - then.h / 2 - 1e-6))))
        k += 1
    return out


def first_by_plan(new: _Samples, new_path: TimedPath, other: _Samples, i_new: np.ndarray, i_other: np.ndarray) -> bool:
    """Whether the new path's robot passes the region first by the plan's times: when the other
    robot first reaches its part of a pair, the new robot is already beyond its part (majority)."""
    when = other.t[i_other]
    at = np.interp(when, new_path.waypoints[:, 2], arc_lengths(new_path.waypoints))
    return bool(np.count_nonzero(at > new.s[i_new]) * 2 > len(i_new))


# -------------------------------------------------------------------------------------------------
# the planner's end
# -------------------------------------------------------------------------------------------------
def stands_refused(o: FleetRobot, latest: int) -> bool:
    """Whether ``o`` stands for good because it refused ``latest``, the newest leg it was given (ours): its status
    names that leg as rejected and shows it slower than :data:`STILL_MPS`, not driven by hand. It stops where it
    is until its next leg (``CentralDriver.refused``) and never drives the refused one, so neither path of it
    has a region with a new leg: the new leg is planned round it standing, and its next leg is ranked against
    the new leg when it comes. Taken as one that may still drive on (its refused leg kept as its latest path),
    it made every leg starting near it a conflict, the hold the breaker gave the robot it blocked too:
    ``bench_dispatch --robots 22 --delay 6 --status-delay 1`` stalled at 78-80 of 100 jobs from t = 1100 s, r11
    standing mid-aisle after refusing leg 754.5, r12 stopped by its net short of it, neither given a leg for
    740 s. Only once the planner dropped the refused leg (``o.leg``; ``FleetManager._find_rejected``): until then
    it plans others round that leg, not round the robot standing."""
    st = o.status
    return (st.rejected_path_id is not None and st.rejected_path_id >= latest and not o.manual
            and (o.leg is None or o.leg.path_id != st.rejected_path_id) and math.hypot(st.vx, st.vy) <= STILL_MPS)


class GateBook:
    """Every robot's gate record and live paths, on the planner's end (pure)."""

    def __init__(self, pad_m: float = PAD_M, sample_m: float = SAMPLE_M, reach_s: float = REACH_S):
        self.pad_m, self.sample_m, self.reach_s = pad_m, sample_m, reach_s
        self.records: dict[str, GateRecord] = {}
        #: per robot, the paths it may be driving: its latest leg and the one its status names
        self.paths: dict[str, dict[int, TimedPath]] = {}
        #: id of a live path -> (the path, its bounding box) (:meth:`_box`)
        self._boxes: dict[int, tuple[TimedPath, tuple[float, float, float, float]]] = {}
        #: robot -> the robots whose records (may) have links naming it (a superset: checked on use)
        self._named_by: dict[str, set[str]] = {}
        #: robot -> the path of its latest leg and the links its first record for it had (as sent: :meth:`reach_limits`)
        self._first: dict[str, tuple[int, frozenset[tuple[Any, ...]]]] = {}

    def _live(self, o: FleetRobot) -> dict[int, TimedPath]:
        paths = self.paths.get(o.id, {})
        if paths:
            latest = max(paths)
            paths = {pid: p for pid, p in paths.items() if pid == latest or pid == o.status.path_id}
            self.paths[o.id] = paths
        return paths

    def on_leg(self, r: FleetRobot, path_id: int, path: TimedPath, fleet: Iterable[FleetRobot],
               now: float, refuse_conflicts: bool = False) -> list[GateRecord] | None:
        """``r`` gets leg ``path_id``: its gate record, and the records of others that grow (links
        where the new leg passes first; the watch of robots whose links name ``r``; links the
        planner heard satisfied are dropped from those). Returned to send.

        A leg that starts inside a region another robot may already be in (both in it at once:
        whoever passes first drives by the other standing in its way) is a conflict; its robots are
        in :attr:`conflicts` afterwards. Not so beside a robot that stands for good at the end of its
        latest path, which it reports (ours): it cannot move before its next leg, so the new leg passes
        first (planned around it standing, it never comes nearer to it than it starts). Refused, two
        robots stopped within the pad of each other never got a leg again (100 robots on large: a knot
        of 8 robots round r85, held at (138.25, 6.49) with r97 0.755 m away, for 1300 s).
        With ``refuse_conflicts`` such a leg is not taken (None, nothing changes): the robot keeps the
        leg it has, whose links still hold."""
        fleet = list(fleet)
        heard = {o.id: o.status for o in fleet}
        mine = sample(path, step=self.sample_m)
        links: list[Link] = []
        watch: dict[str, int] = {}
        grown: dict[str, list[Link]] = {}
        self.conflicts: list[str] = []
        (lx, ly), (hx, hy) = mine.xy.min(axis=0).tolist(), mine.xy.max(axis=0).tolist()
        for o in fleet:
            if o is r or o.immobile:
                continue
            paths = self._live(o)
            if not paths:
                continue
            latest = max(paths)
            recorded = o.id in self.records and self.records[o.id].path_id == latest
            # (ours) it refused the latest leg it was given (its status says so): it never drives that leg, and it
            # stands where it is until its next one, which is ranked against this one when it comes (see
            # :func:`stands_refused`)
            refused = stands_refused(o, latest)
            # a path whose bounding box keeps farther than the regions' reach from the new leg's
            # has no region with it (its samples lie in that box): skipped, nothing else changes
            near = r.radius + o.radius + self.pad_m + self.sample_m + 1e-6
            for pid, p in paths.items():
                if refused:
                    continue
                bx0, by0, bx1, by1 = self._box(p)
                if bx0 > hx + near or by0 > hy + near or bx1 < lx - near or by1 < ly - near:
                    continue
                on_it = o.status.path_id == pid
                done = travelled(o.status) if on_it else None
                done = 0.0 if done is None else min(done, p.length)
                # it stands at the end of its latest path, which it reports: it cannot move before its next
                # leg, which is ranked against this one when it comes (see :data:`STILL_MPS`; not driven by hand)
                parked = (on_it and pid == latest and done >= p.length - 1e-6 and not o.manual
                          and math.hypot(o.status.vx, o.status.vy) <= STILL_MPS)
                # where it may be when a new link reaches it: never ahead of its plan, nor farther
                # than its top speed takes it from its last report
                since = max(0.0, now - o.status.stamp) + self.reach_s
                cap = self._held_at(o, pid, done, heard)
                reach = max(done, min(arc_at(p, now + self.reach_s), done + o.kind.max_speed * since, cap))
                if pid == latest:
                    theirs = sample(p, done, step=self.sample_m)
                elif on_it:  # the path it drives until it takes its latest one: only near where it is
                    theirs = sample(p, done, reach, step=self.sample_m)
                else:
                    continue
                clear = r.radius + o.radius + self.pad_m
                for i_mine, i_theirs in regions(mine, theirs, clear):
                    # may it be in the region before a new link reaches it? By the fine geometry, not
                    # the region's grown samples: a robot its gate holds at the region's entry is not
                    enters = float(theirs.s[i_theirs].min()) - theirs.h / 2  # (grown: a first, coarse cut)
                    o_in = reach >= enters and self._may_be_in(p, done, reach, path, mine, i_mine, clear)
                    if o_in and i_mine.min() == 0:
                        if parked:   # (ours) beside a robot that stands: the new leg passes first
                            o_in = False
                        else:
                            self.conflicts.append(o.id)
                    o_first = (pid != latest or not recorded or o_in
                               or (i_mine.min() > 0 and not first_by_plan(mine, path, theirs, i_mine, i_theirs)))
                    if o_first:
                        links += [Link(o.id, pid, ex, en) for ex, en in pieces(theirs, mine, i_theirs, i_mine)]
                        watch[o.id] = latest
                    else:
                        grown.setdefault(o.id, []).extend(
                            Link(r.id, path_id, ex, en) for ex, en in pieces(mine, theirs, i_mine, i_theirs))
        if refuse_conflicts and self.conflicts:
            return None
        old = self._live(r)
        self.paths[r.id] = {pid: p for pid, p in old.items() if pid == r.status.path_id}
        self.paths[r.id][path_id] = path
        out = [self._set(GateRecord(robot_id=r.id, path_id=path_id, seq=0, stamp=float(now),
                                    links=tuple(lk.to_dict() for lk in links), watch=watch))]
        self._first[r.id] = (path_id, frozenset(_key(d) for d in out[0].links))
        # the records of others that grow or name r (in the records' order), not every record
        named = self._named_by.setdefault(r.id, set())
        rank = {oid: k for k, oid in enumerate(self.records)}
        for oid in sorted((set(grown) | named) & rank.keys(), key=rank.__getitem__):
            rec = self.records[oid]
            if oid == r.id:
                continue
            names_r = any(d["robot"] == r.id for d in rec.links)
            if not names_r:
                named.discard(oid)
            if oid not in grown and not names_r:
                continue
            watch = {**(rec.watch or {}), r.id: path_id}
            # links the planner heard satisfied stay satisfied (progress and path ids only grow): dropped
            kept = tuple(d for d in rec.links if not satisfied(Link.from_dict(d), heard, rec.watch or {}))
            added = tuple(lk.to_dict() for lk in grown.get(oid, []))
            out.append(self._set(GateRecord(robot_id=oid, path_id=rec.path_id, seq=rec.seq + 1, stamp=float(now),
                                            links=kept + added, watch=watch)))
        return out

    def _box(self, p: TimedPath) -> tuple[float, float, float, float]:
        """The bounding box (x min, y min, x max, y max) of the waypoints of a live path, kept with it."""
        box = self._boxes.get(id(p))
        if box is None or box[0] is not p:
            if len(self._boxes) > 4 * len(self.paths) + 64:  # (only live paths' boxes are kept)
                live = {id(q) for ps in self.paths.values() for q in ps.values()}
                self._boxes = {k: v for k, v in self._boxes.items() if k in live}
            xy = p.waypoints[:, :2]
            (x0, y0), (x1, y1) = xy.min(axis=0).tolist(), xy.max(axis=0).tolist()
            box = self._boxes[id(p)] = (p, (x0, y0, x1, y1))
        return box[1]

    def _may_be_in(self, p: TimedPath, done: float, reach: float, path: TimedPath, mine: _Samples,
                   i_mine: np.ndarray, clear: float) -> bool:
        """Whether a robot between ``done`` and ``reach`` m along ``p`` comes within ``clear`` of the
        stretch of ``path`` in a region (``i_mine``, indices of ``mine``), by fine samples of both."""
        there = sample(p, done, reach, step=FINE_M).xy
        lo, hi = float(mine.s[i_mine.min()]) - mine.h, float(mine.s[i_mine.max()]) + mine.h
        here = sample(path, lo, hi, step=FINE_M).xy
        return bool(cdist(there, here).min() < clear - 2 * FINE_M)

    def _held_at(self, o: FleetRobot, pid: int, done: float, heard: Mapping[str, RobotStatus]) -> float:
        """How far along its path ``pid`` robot ``o``'s gate lets it drive until its record changes
        (a record that grows also releases what held it before, in one message): its gate's limit
        on that path, where it stands if its record is for another path, infinite without one."""
        rec = self.records.get(o.id)
        if rec is None:
            return math.inf
        if rec.path_id != pid:
            return done
        return gate_limit(rec, pid, heard)

    def forget(self, r: FleetRobot, fleet: Iterable[FleetRobot], now: float,
               where: np.ndarray | None = None) -> tuple[list[GateRecord], list[str]]:
        """``r`` stopped for good where its status says (or anywhere on ``where``, n x 2 points: a robot
        that stopped unheard, fleet/lease.py): the records of robots whose way from where they are does
        not pass near it drop their links on it (re-sent); the ids of the robots whose way does are
        returned (they keep waiting for it: re-plan them)."""
        points = [r.pos] if where is None else [(float(x), float(y)) for x, y in where.tolist()]
        self.paths.pop(r.id, None)
        self.records.pop(r.id, None)
        out, stuck = [], []
        by_id = {o.id: o for o in fleet}
        for oid, rec in list(self.records.items()):
            if not any(d["robot"] == r.id for d in rec.links):
                continue
            o = by_id.get(oid)
            path = self.paths.get(oid, {}).get(rec.path_id)
            if o is not None and path is not None:
                done = travelled(o.status) if o.status.path_id == rec.path_id else 0.0
                ahead = sample(path, 0.0 if done is None else done, step=self.sample_m)
                clear = o.radius + r.radius + self.pad_m + self.sample_m
                way = np.vstack([ahead.xy, ahead.xy[-1:]])
                if any(polyline_passes_near(way, p, clear) for p in points):
                    stuck.append(oid)
                    continue
            out.append(self._set(GateRecord(robot_id=oid, path_id=rec.path_id, seq=rec.seq + 1, stamp=float(now),
                                            links=tuple(d for d in rec.links if d["robot"] != r.id),
                                            watch={k: v for k, v in (rec.watch or {}).items() if k != r.id})))
        return out, stuck

    def reach_limits(self, r: FleetRobot, fleet: Iterable[FleetRobot], until: float,
                     skew: float = 0.0) -> dict[int, float]:
        """How far along the path of its latest leg (path id -> m) robot ``r``, unheard, can have driven by ``until``
        whatever record of that leg it holds and whatever statuses of others it heard (ours; fleet/lease.py caps
        the stretch it reserves with it). Only links of the leg's first record count that every later record kept
        (a later record may not have reached it; one it holds has every link of the first that the planner did
        not drop), and of them only those whose robot cannot have left the region by ``until`` (+ ``skew``, the
        clocks' difference): last heard on the link's path short of the exit, and its due position or its top
        speed from there keeps it short of the exit by then (path ids and travelled lengths only grow: ``r``
        cannot have seen it beyond the exit). Empty: no limit known."""
        rec, first = self.records.get(r.id), self._first.get(r.id)
        if rec is None or first is None or first[0] != rec.path_id:
            return {}
        by_id = {o.id: o for o in fleet}
        limit = math.inf
        for d in rec.links:
            if _key(d) not in first[1]:
                continue
            lk = Link.from_dict(d)
            o = by_id.get(lk.robot)
            if o is None or o.status.path_id != lk.path_id:
                continue
            done = travelled(o.status)
            if done is None:
                continue
            then = until + skew
            bound = done + o.kind.max_speed * max(0.0, then - o.status.stamp)
            path = self.paths.get(o.id, {}).get(lk.path_id)
            if path is not None:   # (never ahead of its schedule)
                bound = min(bound, max(done, arc_at(path, then)))
            if lk.exit is None or bound <= lk.exit:
                limit = min(limit, lk.entry)
        return {rec.path_id: limit} if math.isfinite(limit) else {}

    def limit_of(self, r: FleetRobot, fleet: Iterable[FleetRobot]) -> float:
        """How far (m along the path its status names) ``r``'s gate lets it drive, by the statuses
        the planner heard (infinite if it has no gate on that path): a new leg never starts beyond
        it (a robot takes a new leg from its first waypoint, and must not get there past a region
        it waits for)."""
        rec, st = self.records.get(r.id), r.status
        if rec is None or st.path_id is None or rec.path_id != st.path_id:
            return math.inf
        return gate_limit(rec, st.path_id, {o.id: o.status for o in fleet})

    def _set(self, rec: GateRecord) -> GateRecord:
        links = compact(rec.links)
        if links is not rec.links:
            rec = replace(rec, links=links)
        self.records[rec.robot_id] = rec
        for d in rec.links:
            self._named_by.setdefault(d["robot"], set()).add(rec.robot_id)
        return rec
