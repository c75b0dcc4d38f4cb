"""Which robot goes where: the delivery sequence, station claims and queues, parking spots.

:class:`_DeliveryRules` is the part every method shares: it hands out the deliveries in sequence,
decides each robot's next target and keeps the measures (the lower bound, time per phase,
progress). A robot's ``phase`` is one of :data:`PHASES`; its target is one of :data:`TARGET_KINDS`.

Station discipline of the central methods (``claims=True``; the behaviour layer has its own, the
docking arbiter): a planner needs a robot's goal to be free for ever after it arrives, so a station
is *claimed* by one robot from the moment it sets off for it until its next leg is planned. So that
a station is not held idle while its claimant drives from afar, a robot claims it only from within
:data:`CLAIM_RADIUS`; from farther away, or when the station is claimed, it first drives to the free
parking spot closest to the station (some spots are placed near the busy stations for this) and
queues there, first come first served (:class:`_StationQueues`). A robot that would block a station
others queue for (its next leg leaves more than :data:`EVACUATE_S` later, or cannot be planned)
clears it for a parking spot when that is sooner (:meth:`_DeliveryRules.evacuate`, decided by the
central run). These rules are the simulation's, the same for md and prior.

Queue places near the stations (``queue="near"``; ours, issue 8; the default ``"spots"`` is the rule
above): the robots waiting for a station stand on *queue places* a few metres from it, not on parking
spots anywhere (the busiest chute of the default warehouse turned over once in 16-20 s, its queue
standing on spots far off). Each station gets the places closest to it by driving distance, at most
:data:`QUEUE_REACH` of driving away and at most :data:`QUEUE_SLOTS` of them: the parking spots that
are not homes and, besides them, up to :data:`QUEUE_NEW` more places that cut no passage with a robot
on every station, spot and place (:func:`~fleet_planner.delivery.layout.queue_places`); a place
belongs to one station and is used only to queue for it. A robot bound for a station claims it at
once, from any distance, when nobody holds it, queues for it or drives to one of its places;
otherwise it takes the station's nearest free place (a parking spot near it, as before, when all its
places are taken) and queues there on arrival, first come first served. When the station is freed
the first robot in its queue gets it, and the robots behind it move up, in queue order, each to the
nearest free place closer to the station than its own (:meth:`_DeliveryRules._move_up`).

Queue places close to the busy stations (``queue="close"``; ours, issue 8): the same discipline, other places.
On the default warehouse at 40-50 robots the problem's queue spots for the chutes stand in the chute row 2 m
and 4.5 m from each chute and in front of the recesses by the chutes; near's places must fit round them, and
found 0-2 new ones per chute. Here the busy loading stations (where deliveries load and none unloads, with at
least :data:`CLOSE_BUSY` of the busiest one's loads: the chutes) get up to :data:`CLOSE_NEW` places first,
nearest by driving first, with only the stations and the robots' homes standing; then the problem's other
parking spots stay where they still fit beside them (the others are not used), then the other stations get
near's places. Every place also keeps every passage
two robots wide that wide (:class:`~fleet_planner.delivery.layout._TwoLanes`), so a queue does not narrow an
aisle the traffic needs both ways. A problem without such a station (stations spread over a MovingAI map, each
loaded and unloaded at) is run with the spots rule: there places beside the stations made CTime worse (md 1156 ->
1190 s, PRIOR 1213 -> 1424 on warehouse-10-20-10-2-1 at 20 robots).

Four rules of both place rules (ours, session 28; each a switch, for the tests' controls): a robot joins its
station's queue when it books the place it drives to, not when it gets there (:data:`JOIN_ON_BOOKING`: at 50 robots
the robots that found no place free queued on their homes 20-37 m off at once, ahead of the robots driving to the
places 1 m from the chute, and the chute idled 25-60 s while the first of them drove in); a robot handed its
station while it drives to a place turns to the station where it is (:data:`~.central.TURN_EN_ROUTE`,
:meth:`_DeliveryRules.to_station_now`); a robot docking at a station others queue for gets its next leg (leaving
when its docking ends) :data:`~.central.HAND_OVER_EARLY_S` before its docking ends, so the station is handed
over and the next robot's leg planned that much sooner; a robot with no delivery left parks on the closest free
parking spot, not its home (:data:`PARK_NEAREST`). Under the spots rule a freed station goes to the robot of its
queue that stands nearest to it by driving, not to the first come (:data:`SERVE_NEAREST`, ours, session 29): that
queue stands on parking spots anywhere, and first come first served called a robot in from afar while others
waited close by (warehouse-10-20-10-2-1, 100 robots: 6 m at the median, up to 40 m, the nearest 2 m); the place
rules' queues stand in order, nearest first, and keep first come first served.
``queue="auto"`` (ours) runs the close rule where every busy loading station gets at least :data:`AUTO_PLACES`
places, else the spots rule: on the default warehouse at 100 robots the homes fill the room by the chutes, close
finds 0-3 places per chute and was worse than spots.

Station admission of the behaviour fleet (``claims=False, admit=K``; ours, issue 13): paper 002
(Sun, Kleiner & Nebel, IV.A) lets a robot that reaches a station where another docks stop "at a
certain distance" and wait, first come first served (the fleet's docking arbiter); with 200 robots
on `large` every robot bound for the 11 chutes waited so, inside the one band that also carries the
loaded robots out, and the band locked (:class:`_StationAdmission`). Here a station admits at most
K robots at a time; a robot it does not admit waits for its turn on a *waiting place* (a parking
spot at least :data:`WAIT_AWAY` from every loading station, the closest free one to its station),
parked, out of the congested zone, and drives to the station when a robot admitted before it has
docked there. The behaviours (IV.B) and the docking arbiter are untouched: a waiting robot stands
as a parked robot does, an obstacle (IV.C.1).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..geometry import polyline_length
from ..model import Point
from ..paths import PathFinder
from .layout import KEPT, driving_distances, queue_places
from .problem import Delivery, DeliveryProblem

#: central methods: a robot claims a station only from this close (m, straight line; from a parking
#: spot: driving distance); from farther away it first drives to a parking spot near the station
CLAIM_RADIUS = 8.0
#: central methods: a robot with no parking spot free to queue on decides again this much later (s)
RETARGET_S = 5.0
#: central methods: a robot on a station others queue for whose next leg would leave more than this
#: much later (s), or could not be planned, drives to a parking spot near it instead if that is sooner
EVACUATE_S = 10.0
#: central methods with ``queue="near"`` (ours): a station's queue places are at most this far from it (m,
#: driving distance) ...
QUEUE_REACH = 6.0
#: ... at most this many per station ...
QUEUE_SLOTS = 6
#: ... of which at most this many are new places (not parking spots of the problem)
QUEUE_NEW = 4
#: queue="near": a robot may claim a free station nobody queues for from any distance (False: only from within
#: CLAIM_RADIUS, as the spots rule; from farther it drives to the station's nearest free place first)
NEAR_CLAIM_FROM_AFAR = True
#: central methods with ``queue="close"`` (ours): at most this many new places per station, placed before the
#: problem's parking spots that are not homes (those stay only where they still fit beside the places)
CLOSE_NEW = 6
#: ... for the loading stations (none unloads there) with at least this share of the busiest one's loads (the
#: others get near's places; a problem without such a station gets the spots rule)
CLOSE_BUSY = 0.5
#: queue="close": a new place never cuts a passage two robots wide (:class:`~.layout._TwoLanes`; False: only no
#: cut passage, as near's places - the control of the tests)
CLOSE_TWO_LANES = True
#: queue near, close: a robot joins its station's queue when it books the place it drives to wait on (False: on
#: arrival there)
JOIN_ON_BOOKING = True
#: the queue rules of the central methods: on parking spots near the station (the default, session 25's
#: rule), or on queue places near it with moving up (ours, see the module text): ``near`` among the problem's
#: parking spots, ``close`` in the room next to the station the parking spots would take
QUEUE_RULES = ("spots", "near", "close", "auto")
#: queue="auto" (ours): the close rule when each of its busy loading stations gets at least this many places, else
#: the spots rule (the default warehouse at 100 robots: its homes fill the room by the chutes, close finds 0-3 places
#: per chute and was worse than spots, md 1634 -> 1954 s)
AUTO_PLACES = 2
#: queue near, close: a robot with no delivery left parks on the closest free parking spot, not a queue place (ours,
#: session 28; False: on its home when free, else the closest free spot, as under the spots rule, where the robots
#: queue on parking spots near the stations and the closest spots made every row 0-3% slower)
PARK_NEAREST = True
#: spots rule (ours, session 29): a freed station goes to the robot of its queue standing nearest to it (driving
#: distance from its parking spot; ties: the first come), not to the first come (False: first come first served).
#: On warehouse-10-20-10-2-1 at 100 robots its busiest stations' turnover was 14-19 s, most of it the first-come
#: robot driving in from its spot (6 m at the median, up to 40 m; the nearest queued robot: 2 m). CTime, mean of seeds
#: 0-4, md / PRIOR: there 2143 / 2170 -> 1717 / 1837 s; the default warehouse at 100 robots 1827 / 1777 -> 1166 / 1164
#: (docs/BENCHMARKS.md, session 29)
SERVE_NEAREST = True
#: the central methods' queue rule unless one is asked for (session 28; before: spots)
DEFAULT_QUEUE = "auto"
#: the rules with queue places and moving up
PLACE_RULES = ("near", "close")
#: behaviour fleet with admission (ours): waiting places are parking spots at least this far (m,
#: straight line) from every station a delivery loads at (out of the crowd round the loading stations)
WAIT_AWAY = 4.0

#: what a robot is doing: idle (before the start), need (a leg to its target, to be planned or
#: assigned), drive, dock, queued (on a parking spot, for a station), wait (no spot free to queue
#: on yet: decides again later), done
PHASES = ("idle", "need", "drive", "dock", "queued", "wait", "done")
#: what a robot's target is: a station to load at (pick) or unload at (drop); a parking spot near a
#: station to queue on (hold), to clear a station for the robots queued for it (evac), or to park
#: on when the deliveries are used up (park)
TARGET_KINDS = ("pick", "drop", "hold", "evac", "park")


@dataclass
class _SimRobot:
    """One simulated robot, as the rules see it."""

    idx: int
    id: str
    pos: Point
    phase: str = "idle"              # one of PHASES
    delivery: Delivery | None = None
    loaded: bool = False             # it has loaded at its delivery's pick station
    target: Point | None = None
    target_kind: str = ""            # one of TARGET_KINDS
    station: str | None = None       # the station the target is or queues for
    spot: int | None = None          # its parking spot (home, queue or final): stands on it or drives to it
    on_station: str | None = None    # central: the station it stands on (claimed) after docking
    wake: float = 0.0                # when it is due next
    progress_t: float = 0.0          # the last time it made progress
    best_left: float = math.inf      # behavior: the least path length left to the target on this leg
    solo_s: float = 0.0              # its deliveries so far, driven alone (for the lower bound)
    solo_at: Point = (0.0, 0.0)      # where that solo drive ends
    station_kind: str = ""           # pick or drop: what it will do at the station it queues for
    booked_spot: int | None = None   # the parking spot its next leg goes to (reserved for it)
    phase_since: float = 0.0         # when it entered its phase


class _SoloTimes:
    """Shortest-path driving times between points at top speed, for the lower bound (cached)."""

    def __init__(self, problem: DeliveryProblem):
        self.finder = PathFinder(problem.grid, problem.radius)
        self.speed = problem.max_speed
        self._cache: dict[tuple[tuple[float, ...], tuple[float, ...]], float] = {}

    def __call__(self, a: Point, b: Point) -> float:
        key = (tuple(a), tuple(b))
        if key not in self._cache:
            path = self.finder.find(a, b)
            if path is None:
                raise ValueError(f"no path from {a} to {b} for radius {self.finder.radius:g}")
            self._cache[key] = polyline_length(path) / self.speed
        return self._cache[key]


class _ParkingSpots:
    """The parking spots and which robot owns each one (stands on it, drives to it or booked it)."""

    def __init__(self, points: list[Point], n_robots: int):
        self.xy = np.asarray(points, dtype=float)
        self.owner: list[int | None] = [None] * len(points)
        for i in range(n_robots):   # robot i starts on its home, spot i
            self.owner[i] = i

    def nearest_free(self, dist: np.ndarray, allowed: np.ndarray | None = None) -> int | None:
        """The free spot of least ``dist`` (one entry per spot), if any is free (and ``allowed``)."""
        return next((int(i) for i in np.argsort(dist, kind="stable")
                     if self.owner[i] is None and (allowed is None or allowed[i])), None)


class _StationQueues:
    """Central methods: which robot holds each station (its claim) and who queues for it, first come
    first served. A released station goes to the first robot in its queue at once, or with ``distance``
    (station, robot -> how far it has to drive there; inf: not standing by yet) to the nearest one, ties to
    the first come (:data:`SERVE_NEAREST`)."""

    def __init__(self, stations: list[str], distance: Callable[[str, int], float] | None = None):
        self.holder: dict[str, int] = {}
        self.waiting: dict[str, list[int]] = {s: [] for s in stations}
        self.handed_over: list[int] = []   # robots a released station was just handed to
        self.distance = distance

    def free_for(self, station: str, idx: int) -> bool:
        """Nobody but robot ``idx`` holds ``station``."""
        return self.holder.get(station, idx) == idx

    def claim(self, station: str, idx: int) -> None:
        self.holder[station] = idx

    def join(self, station: str, idx: int) -> None:
        if idx not in self.waiting[station]:   # (place rules: a robot moving up is in the queue already)
            self.waiting[station].append(idx)

    def leave(self, station: str, idx: int) -> None:
        """Robot ``idx`` is no longer in ``station``'s queue (if it was)."""
        if idx in self.waiting[station]:
            self.waiting[station].remove(idx)

    def has_queue(self, station: str) -> bool:
        return bool(self.waiting[station])

    def release(self, station: str) -> None:
        if self.holder.get(station) is None:
            return
        del self.holder[station]
        if self.waiting[station]:
            k = 0
            if self.distance is not None:
                d = [self.distance(station, i) for i in self.waiting[station]]
                k = int(np.argmin(d)) if min(d) < math.inf else 0
            idx = self.waiting[station].pop(k)
            self.holder[station] = idx
            self.handed_over.append(idx)

    def take_handed_over(self) -> list[int]:
        out, self.handed_over = self.handed_over, []
        return out


class _StationAdmission:
    """Behaviour fleet (ours, see the module text): at most ``cap`` robots are *admitted* to a
    station at a time (bound for it, until they have docked there); the others queue for it, first
    come first served, and are admitted in that order as admitted robots dock. ``force`` admits
    over the cap (a robot with no waiting place free goes to its station as before)."""

    def __init__(self, stations: list[str], cap: int):
        if cap < 1:
            raise ValueError(f"admit: must be >= 1 robot per station (got {cap})")
        self.cap = cap
        self.admitted: dict[str, set[int]] = {s: set() for s in stations}
        self.waiting: dict[str, list[int]] = {s: [] for s in stations}
        self.handed_over: list[int] = []   # robots just admitted from the queue

    def admit(self, station: str, idx: int) -> bool:
        """Robot ``idx`` may drive to ``station`` (admitted now or before); robots queued go first."""
        mine = self.admitted[station]
        if idx not in mine and len(mine) < self.cap and not self.waiting[station]:
            mine.add(idx)
        return idx in mine

    def force(self, station: str, idx: int) -> None:
        self.admitted[station].add(idx)

    def join(self, station: str, idx: int) -> None:
        if idx not in self.waiting[station]:
            self.waiting[station].append(idx)

    def docked(self, station: str, idx: int) -> None:
        """Robot ``idx`` docked at ``station``: the next in its queue is admitted."""
        mine = self.admitted[station]
        mine.discard(idx)
        while self.waiting[station] and len(mine) < self.cap:
            first = self.waiting[station].pop(0)
            mine.add(first)
            self.handed_over.append(first)

    def take_handed_over(self) -> list[int]:
        out, self.handed_over = self.handed_over, []
        return out


class _DeliveryRules:
    """The delivery sequence, station claims and queues, parking spots, the lower bound, progress.

    Every method calls the events (:meth:`left`, :meth:`arrived`, :meth:`docked`) as they happen;
    the rules set the robot's next ``phase``, ``target`` and ``wake``."""

    def __init__(self, problem: DeliveryProblem, claims: bool, admit: int | None = None, queue: str = "spots"):
        self.problem = problem
        self.claims = claims
        if queue not in QUEUE_RULES:
            raise ValueError(f"queue: must be one of {', '.join(QUEUE_RULES)} (got {queue!r})")
        if queue != "spots" and not claims:
            raise ValueError(f"queue: {queue!r} is a rule of the central methods (claims=True)")
        #: queue="close": the busy loading stations that get their places first (:meth:`_close_stations`)
        self.close_stations = self._close_stations(problem) if queue in ("close", "auto") else set()
        asked = queue
        if queue in ("close", "auto") and not self.close_stations:
            queue = "spots"   # no loading station to queue at: session 25's rule, as it was
        elif queue == "auto":
            queue = "close"   # unless its places are too few (below)
        #: the queue rule run (``auto``: the one chosen)
        self.queue_rule = queue
        #: behaviour fleet: at most ``admit`` robots bound for a station at a time (None: no limit)
        self.admission = None if claims or admit is None else _StationAdmission(list(problem.stations), admit)
        self.solo_time = _SoloTimes(problem)
        self.robots = [_SimRobot(i, rid, problem.spots[i], spot=i, solo_at=problem.spots[i])
                       for i, rid in enumerate(problem.robot_ids())]
        #: where robots may stand for long: the problem's parking spots, then (``queue`` near, close) new queue places
        self.spots: list[Point] = list(problem.spots)
        drive = None
        if claims or self.admission is not None:
            drive = driving_distances(problem.grid, self.solo_time.finder.free, list(problem.stations.values()))
        #: queue near, close: each station's queue places (spot indices, nearest first) and the station of each place
        self.slots: dict[str, list[int]] = {}
        self.slot_of: dict[int, str] = {}
        if queue in PLACE_RULES:
            assert drive is not None
            self._place_slots(drive)
            if asked == "auto" and min(len(self.slots.get(st, [])) for st in self.close_stations) < AUTO_PLACES:
                self.queue_rule, self.spots, self.slots, self.slot_of = "spots", list(problem.spots), {}, {}
                self.close_stations = set()
        self.parking = _ParkingSpots(self.spots, problem.n_robots)
        #: the spots any robot may take (not a station's queue place)
        self.general = np.array([i not in self.slot_of for i in range(len(self.spots))], dtype=bool)
        #: central: driving distance from each station to each parking spot, to queue close by
        self.spot_dist: dict[str, np.ndarray] = {}
        if drive is not None:
            self.spot_dist = self._spot_distances(drive)
        nearest = SERVE_NEAREST and claims and self.queue_rule == "spots"
        self.queues = _StationQueues(list(problem.stations), self._queue_distance if nearest else None)
        #: behaviour fleet with admission: the parking spots robots may wait on for their station
        self.waiting_place = np.zeros(len(problem.spots), dtype=bool)
        if self.admission is not None:
            loads = np.array([problem.stations[s] for s in sorted({d.pick for d in problem.deliveries})])
            spots = np.asarray(problem.spots, dtype=float)
            near = np.hypot(spots[:, None, 0] - loads[None, :, 0], spots[:, None, 1] - loads[None, :, 1])
            self.waiting_place = near.min(axis=1) >= WAIT_AWAY
        self.next_delivery = 0
        self.completed = 0
        self.ctime: float | None = None     # when the last delivery was done
        self.phase_s: dict[str, float] = {}  # robot-seconds spent in each phase
        self.hold_legs = 0
        #: queue near, close: robots handed their station while driving to a place (see :meth:`take_en_route`)
        self.en_route: list[_SimRobot] = []

    def _queue_distance(self, station: str, idx: int) -> float:
        """How far robot ``idx``, queued for ``station``, drives there (from the parking spot it stands on;
        inf when it does not stand on one)."""
        r = self.robots[idx]
        return float(self.spot_dist[station][r.spot]) if r.phase == "queued" and r.spot is not None else math.inf

    def _spot_distances(self, drive: np.ndarray) -> dict[str, np.ndarray]:
        """Station -> driving distance to each spot of :attr:`spots` (``drive``: from each station to each cell)."""
        grid = self.problem.grid
        at = [row * grid.width + col for col, row in (grid.cell_of(*p) for p in self.spots)]
        return {s: drive[k, at] for k, s in enumerate(self.problem.stations)}

    @staticmethod
    def _close_stations(p: DeliveryProblem) -> set[str]:
        """queue="close": the busy loading stations - where deliveries load and none unloads (the chutes), with
        at least :data:`CLOSE_BUSY` of the busiest one's loads."""
        loads = {s: 0 for s in p.stations}
        for d in p.deliveries:
            loads[d.pick] += 1
        for d in p.deliveries:
            loads.pop(d.drop, None)
        top = max(loads.values(), default=0)
        return {s for s, n in loads.items() if n and n >= CLOSE_BUSY * top}

    def _place_slots(self, drive: np.ndarray) -> None:
        """queue near, close: new queue places (appended to :attr:`spots`), then each place - a new one or a
        parking spot that is not a home - within :data:`QUEUE_REACH` goes to its nearest station, at most
        :data:`QUEUE_SLOTS` per station, nearest first."""
        p = self.problem
        if self.queue_rule == "close":   # the busy stations' places first, then the problem's other spots where
            homes = p.spots[:p.n_robots]  # they fit, then the other stations' places as near's
            busy = {s: CLOSE_NEW if s in self.close_stations else 0 for s in p.stations}
            new = queue_places(p.grid, p.stations, homes, busy, QUEUE_REACH, p.radius, keep=p.spots[p.n_robots:],
                               two_lanes=CLOSE_TWO_LANES, prune_one=True)
            self.spots = homes + new.pop(KEPT, [])
            first = [q for qs in new.values() for q in qs]
            rest = queue_places(p.grid, p.stations, self.spots + first, {s: 0 if busy[s] else QUEUE_NEW for s in busy},
                                QUEUE_REACH, p.radius, two_lanes=CLOSE_TWO_LANES, prune_one=True)
            new = {s: new[s] + rest[s] for s in new}
        else:
            new = queue_places(p.grid, p.stations, p.spots, QUEUE_NEW, QUEUE_REACH, p.radius)
        self.spots += [q for qs in new.values() for q in qs]
        dist = np.vstack(list(self._spot_distances(drive).values()))     # (stations, spots)
        names = list(p.stations)
        candidates = [i for i in range(p.n_robots, len(self.spots)) if dist[:, i].min() <= QUEUE_REACH]
        per: dict[str, list[int]] = {s: [] for s in names}
        for i in candidates:
            per[names[int(np.argmin(dist[:, i]))]].append(i)
        for k, s in enumerate(names):
            mine = sorted(per[s], key=lambda i: (dist[k, i], i))[:QUEUE_SLOTS]
            if mine:
                self.slots[s] = mine
                self.slot_of.update((i, s) for i in mine)

    def enter(self, r: _SimRobot, phase: str, t: float) -> None:
        """r goes into ``phase`` at t (the time spent in the old one is counted)."""
        self.phase_s[r.phase] = self.phase_s.get(r.phase, 0.0) + t - r.phase_since
        r.phase, r.phase_since = phase, t

    def mean_phase_s(self, t: float) -> dict[str, float]:
        """Mean seconds per robot in each phase until t (need: waiting for a leg to be planned or
        assigned; queued: on a parking spot waiting for a station; drive includes the wait at the
        start of a planned leg)."""
        total = dict(self.phase_s)
        for r in self.robots:
            total[r.phase] = total.get(r.phase, 0.0) + max(t - r.phase_since, 0.0)
        return {k: round(v / len(self.robots), 1) for k, v in total.items() if k not in ("idle", "done")}

    # -- decisions ------------------------------------------------------------------------------
    def next_target(self, r: _SimRobot, t: float) -> None:
        """After a dock (or at the start): where to go next; sets ``phase`` to need or queued."""
        if r.delivery is not None and not r.loaded:
            self._to_station(r, r.delivery.pick, "pick", t)
        elif r.delivery is not None:
            self._to_station(r, r.delivery.drop, "drop", t)
        elif self.next_delivery < len(self.problem.deliveries):
            r.delivery, r.loaded = self.problem.deliveries[self.next_delivery], False
            self.next_delivery += 1
            self._drive_solo(r, self.problem.stations[r.delivery.pick])
            self._drive_solo(r, self.problem.stations[r.delivery.drop])
            self._to_station(r, r.delivery.pick, "pick", t)
        else:
            # home, else the closest free spot (near a station, it would stand in others' way); queue near, close
            # (PARK_NEAREST): the closest free spot
            nearest = PARK_NEAREST and self.queue_rule in PLACE_RULES
            spot = r.idx if self.parking.owner[r.idx] is None and not nearest else \
                self.parking.nearest_free(np.hypot(*(self.parking.xy - np.asarray(r.pos)).T), self.general)
            if spot is None:                  # every spot taken or promised: stay (nothing left to do)
                self.enter(r, "done", t)
                r.wake = math.inf
                return
            self.parking.owner[spot], r.booked_spot = r.idx, spot
            self._need(r, self.spots[spot], "park", None, t)

    def _drive_solo(self, r: _SimRobot, station: Point) -> None:
        """The lower bound: r drives on to ``station`` alone and docks there."""
        r.solo_s += self.solo_time(r.solo_at, station) + self.problem.dock_s
        r.solo_at = station

    def _to_station(self, r: _SimRobot, station: str, kind: str, t: float) -> None:
        """Central methods: claim the station only when close to it (it stays claimed until the
        robot leaves it again, so a claim made from afar would idle it for the whole drive);
        from afar, or when it is taken, wait on a parking spot near it first."""
        goal = self.problem.stations[station]
        if self.admission is not None:
            self._admit_or_wait(r, station, kind, t)
            return
        if not self.claims:
            self._need(r, goal, kind, station, t)
            return
        if self.queue_rule in PLACE_RULES:
            self._to_station_near(r, station, kind, t)
            return
        free = self.queues.free_for(station, r.idx)
        drive = self.spot_dist[station]
        spot = self.parking.nearest_free(drive)
        on_spot = r.spot is not None and r.on_station is None and r.pos == self.spots[r.spot]
        if on_spot:
            close = drive[r.spot] <= CLAIM_RADIUS or (spot is not None and drive[r.spot] <= drive[spot])
        else:
            close = math.dist(r.pos, goal) <= CLAIM_RADIUS
        if free and (close or (spot is None and not on_spot)):
            # close, or standing on a station with nowhere to wait: better go than block it
            self.queues.claim(station, r.idx)
            self._need(r, goal, kind, station, t)
        elif close and on_spot:
            self._queue(r, station, kind, t)  # wait right here
        elif spot is not None:
            self._hold_on(r, spot, station, kind, t)
        else:                                 # nowhere to queue yet: decide again a little later
            self._decide_later(r, station, kind, t)

    def _hold_on(self, r: _SimRobot, spot: int, station: str, kind: str, t: float) -> None:
        """r books ``spot`` and drives there to wait for ``station`` (a "hold" leg)."""
        self.parking.owner[spot] = r.idx
        r.booked_spot, r.station_kind = spot, kind
        self._need(r, self.spots[spot], "hold", station, t)
        self.hold_legs += 1
        if self.queue_rule in PLACE_RULES and JOIN_ON_BOOKING:
            self.queues.join(station, r.idx)   # in the queue from now on, not from its arrival

    def _decide_later(self, r: _SimRobot, station: str, kind: str, t: float) -> None:
        """Nowhere to wait for ``station`` yet: r decides again :data:`RETARGET_S` later."""
        self.enter(r, "wait", t)
        r.station, r.station_kind, r.wake = station, kind, t + RETARGET_S

    def _to_station_near(self, r: _SimRobot, station: str, kind: str, t: float) -> None:
        """queue="near" (ours, see the module text): claim the station when nobody holds it, queues for it
        or is bound for one of its places; else queue on its nearest free place (the nearest free parking
        spot when all are taken; the spot r stands on when that is no nearer; nowhere: decide again later)."""
        slots = self.slots.get(station, [])
        bound = any(self.parking.owner[i] is not None and self.parking.owner[i] != r.idx for i in slots)
        afar = NEAR_CLAIM_FROM_AFAR or not slots or math.dist(r.pos, self.problem.stations[station]) <= CLAIM_RADIUS
        if self.queues.free_for(station, r.idx) and not self.queues.has_queue(station) and not bound and afar:
            self.queues.claim(station, r.idx)
            self._need(r, self.problem.stations[station], kind, station, t)
            return
        drive = self.spot_dist[station]
        spot = next((i for i in slots if self.parking.owner[i] is None), None)
        if spot is None:
            spot = self.parking.nearest_free(drive, self.general)
        on_spot = (r.spot is not None and r.on_station is None and self.parking.owner[r.spot] == r.idx
                   and r.pos == self.spots[r.spot])
        if on_spot and (spot is None or drive[r.spot] <= drive[spot]):
            self._queue(r, station, kind, t)   # wait right here
            self._move_up(t)
        elif spot is not None:
            self._hold_on(r, spot, station, kind, t)
        else:
            self._decide_later(r, station, kind, t)

    def _move_up(self, t: float) -> None:
        """queue near, close: robots standing in a queue, in its order, each move to the nearest free place of
        their station closer to it than where they stand (a freed place goes to the first robot behind)."""
        for station, waiting in self.queues.waiting.items():
            slots = self.slots.get(station)
            if not waiting or not slots:
                continue
            for i in waiting:
                q = self.robots[i]
                if q.phase != "queued":
                    continue                   # moving up already
                rank = slots.index(q.spot) if q.spot in slots else len(slots)
                spot = next((j for j in slots[:rank] if self.parking.owner[j] is None), None)
                if spot is not None:
                    self._hold_on(q, spot, station, q.station_kind, t)

    def _admit_or_wait(self, r: _SimRobot, station: str, kind: str, t: float) -> None:
        """Behaviour fleet with admission (ours, see the module text): to the station when it admits
        r; else r queues for it, standing on the parking spot it stands on, or on the free waiting
        place closest to the station (it drives there); with none free it goes as before."""
        admission = self.admission
        assert admission is not None
        if admission.admit(station, r.idx):
            self._need(r, self.problem.stations[station], kind, station, t)
            return
        admission.join(station, r.idx)
        on_spot = (r.spot is not None and self.parking.owner[r.spot] == r.idx
                   and r.pos == self.problem.spots[r.spot])
        if on_spot:
            self._queue(r, station, kind, t)   # (in the admission queue: waits to be admitted)
            return
        dist = np.where(self.waiting_place, self.spot_dist[station], np.inf)
        spot = self.parking.nearest_free(dist)
        if spot is None or not math.isfinite(dist[spot]):
            admission.waiting[station].remove(r.idx)
            admission.force(station, r.idx)
            self._need(r, self.problem.stations[station], kind, station, t)
            return
        self._hold_on(r, spot, station, kind, t)

    def _queue(self, r: _SimRobot, station: str, kind: str, t: float) -> None:
        self.enter(r, "queued", t)
        r.station, r.wake, r.station_kind = station, math.inf, kind
        self.queues.join(station, r.idx)

    def _need(self, r: _SimRobot, target: Point, kind: str, station: str | None, t: float) -> None:
        self.enter(r, "need", t)
        r.target, r.target_kind, r.station, r.wake = target, kind, station, t

    def retarget(self, r: _SimRobot, t: float) -> None:
        """A waiting robot decides again how to get to its station."""
        assert r.station is not None
        self._to_station(r, r.station, r.station_kind, t)

    def others_queue_here(self, r: _SimRobot) -> bool:
        """r stands on a station others queue for."""
        return r.on_station is not None and self.queues.has_queue(r.on_station)

    def spot_near_here(self, r: _SimRobot) -> int | None:
        """The free parking spot closest to the station r stands on."""
        assert r.on_station is not None
        return self.parking.nearest_free(self.spot_dist[r.on_station], self.general)

    def evacuate(self, r: _SimRobot, spot: int) -> None:
        """r clears its station for the parking spot instead of going where it decided (that
        decision is undone; it decides again on the spot)."""
        if r.booked_spot is not None:
            self.parking.owner[r.booked_spot] = None
        if (r.target_kind in ("pick", "drop", "hold") and r.station is not None and r.station != r.on_station
                and self.queues.holder.get(r.station) == r.idx):
            self.queues.release(r.station)
        elif r.target_kind == "hold" and r.station is not None:
            self.queues.leave(r.station, r.idx)
        self.parking.owner[spot], r.booked_spot = r.idx, spot
        r.target, r.target_kind, r.station = self.spots[spot], "evac", None

    # -- events ---------------------------------------------------------------------------------
    def left(self, r: _SimRobot, t: float) -> None:
        """r drove off from where it stood: free its spot and the station it stood on."""
        if r.spot is not None and self.parking.owner[r.spot] == r.idx:
            self.parking.owner[r.spot] = None
        r.spot = r.booked_spot if r.target_kind in ("hold", "park", "evac") else None
        r.booked_spot = None
        if r.on_station is not None:
            self.queues.release(r.on_station)
            r.on_station = None
        r.progress_t = t
        if self.queue_rule in PLACE_RULES:
            self._move_up(t)

    def arrived(self, r: _SimRobot, t: float) -> None:
        """r reached its target."""
        assert r.target is not None
        r.progress_t = t
        r.pos = r.target
        if r.target_kind in ("pick", "drop"):
            self.enter(r, "dock", t)
            r.wake, r.on_station = t + self.problem.dock_s, r.station if self.claims else None
        elif r.target_kind == "hold" and self.admission is not None:
            assert r.station is not None   # admitted meanwhile: handed over, its leg re-assigned
            self._queue(r, r.station, r.station_kind, t)
        elif r.target_kind == "hold":
            station = r.station
            assert station is not None
            holder = self.queues.holder.get(station)
            if holder is None or (self.queue_rule in PLACE_RULES and holder == r.idx):   # handed over en route
                self.queues.leave(station, r.idx)
                self.queues.claim(station, r.idx)
                self._need(r, self.problem.stations[station], r.station_kind, station, t)
            else:
                self._queue(r, station, r.station_kind, t)
            if self.queue_rule in PLACE_RULES:
                self._move_up(t)
        elif r.target_kind == "evac":
            self.next_target(r, t)
        else:
            self.enter(r, "done", t)
            r.wake = math.inf

    def docked(self, r: _SimRobot, t: float) -> None:
        """r's docking time is over."""
        r.progress_t = t
        if self.admission is not None and r.station is not None:
            self.admission.docked(r.station, r.idx)
        if r.target_kind == "pick":
            r.loaded = True
        else:
            r.delivery = None
            self.completed += 1
            if self.completed == len(self.problem.deliveries):
                self.ctime = t
        self.next_target(r, t)

    def take_handed_over(self, t: float) -> list[_SimRobot]:
        """Robots that were queued and now hold their station: they need their leg to it."""
        out = []
        handed = self.queues.take_handed_over()
        if self.admission is not None:
            handed += self.admission.take_handed_over()
        for i in handed:
            r = self.robots[i]
            assert r.station is not None
            if r.phase == "drive" and self.queue_rule in PLACE_RULES:   # moving up: on to the station on arrival
                self.en_route.append(r)   # (unless the central run turns it to the station at once: to_station_now)
                continue
            if r.phase == "need" and r.booked_spot is not None:   # its leg to a waiting place never began
                self.parking.owner[r.booked_spot], r.booked_spot = None, None
            self._need(r, self.problem.stations[r.station], r.station_kind, r.station, t)
            out.append(r)
        if handed and self.queue_rule in PLACE_RULES:
            self._move_up(t)
        return out

    def take_en_route(self) -> list[_SimRobot]:
        """queue near, close: the robots :meth:`take_handed_over` handed their station while they drive to a
        place (they go on to the station once there, unless turned to it at once: :meth:`to_station_now`)."""
        out, self.en_route = [r for r in self.en_route if r.phase == "drive" and r.target_kind == "hold"], []
        return out

    def to_station_now(self, r: _SimRobot, at: Point, t: float) -> None:
        """r, handed its station while driving to a place, leaves its leg at ``at`` (time t) for a leg to the
        station: its place is free again (the robots behind move up)."""
        assert r.station is not None and self.queues.holder.get(r.station) == r.idx
        if r.spot is not None and self.parking.owner[r.spot] == r.idx:
            self.parking.owner[r.spot] = None
        r.spot = None
        self.queues.leave(r.station, r.idx)
        r.pos, r.target, r.target_kind = at, self.problem.stations[r.station], r.station_kind
        r.progress_t = t
        self._move_up(t)

    # -- measures -------------------------------------------------------------------------------
    def busy(self, r: _SimRobot) -> bool:
        """r still has a delivery to make."""
        return r.delivery is not None

    def lower_bound(self) -> float:
        return max((r.solo_s for r in self.robots), default=0.0)

    def deadlocked(self, t: float, no_progress_s: float, moving: tuple[str, ...]) -> int:
        """Robots with a delivery left, in none of the ``moving`` phases, without progress for long."""
        return sum(1 for r in self.robots
                   if self.busy(r) and r.phase not in moving and t - r.progress_t > no_progress_s)
