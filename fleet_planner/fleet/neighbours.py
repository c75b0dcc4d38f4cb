"""The neighbour relay: which robots each robot must hear, so that an agent's cost does not grow
with the fleet (docs/ARCHITECTURE.md, "Topics and QoS", ``/robots/<id>/neighbours``).

Before the relay every agent heard every robot's status at 10 Hz: N x N x 10 parses a second for
the fleet, a cost that grows with the square of the fleet on every robot's computer. The planner
hears every status anyway; a few times a second it sends each robot the last statuses of the
robots within its *safety range* (and of the robots its execution gate watches), and the agent's
safety net (and behaviour layer) works from those alone.

The safety range of a pair (i, j) is ``sense_ij + (v_i + v_j) * horizon_s`` from the reported
centres, with ``sense_ij`` the distance at which the agents start to care (the sum of radii for
the safety net of central coordination, at least the behaviour layer's ``comm_range`` under
behaviour coordination) and ``v`` the top speeds of the kinds. The horizon covers what the net
looks ahead (:data:`NET_REACH_S`: one control step and twice the staleness a net allows itself),
plus how old the statuses the relay used may be, how long a record is used before the next one
replaces it and its transport: :func:`horizon_s`. So between two records no robot can come into
the net's view without having been in the last record (``test/test_neighbours.py`` checks that
over random fleets in motion).

Selection is pure and vectorised: all pairs within the largest possible range from a k-d tree
(:class:`scipy.spatial.cKDTree`), then the exact per-pair range on the array of pairs.
"""
from __future__ import annotations

import json
from collections.abc import Callable, Container, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from msg_schemas.records import MAX_NEIGHBOURS, Neighbours, RobotStatus

from .coordination import STALE_S
from .legs import CONTROL_PERIOD_S

#: seconds of motion the safety net of a central robot looks at (CentralDriver.must_wait): one
#: control step of its own driving and twice the staleness it allows a heard status
NET_REACH_S = CONTROL_PERIOD_S + 2 * STALE_S
#: default seconds of ROS time between two records for a robot
RELAY_PERIOD_S = 0.2
#: default bound on the age of the statuses a record is made from (two status periods at 10 Hz)
STATUS_AGE_S = 0.2
#: default allowance for delivering a record
LATENCY_S = 0.5
#: statuses older than this (s) at relay time count at this age: their robots stopped reporting
MAX_AGE_S = 3.0

Watch = Callable[[str], "set[str]"]


def no_watch(robot_id: str) -> set[str]:
    """The default :data:`Watch`: a robot's gate watches nobody."""
    return set()


def horizon_s(period_s: float = RELAY_PERIOD_S, status_age_s: float = STATUS_AGE_S,
              latency_s: float = LATENCY_S) -> float:
    """Seconds of motion a record must cover: what the net looks ahead, how old its statuses may be,
    how long it is used until the next one arrives."""
    return NET_REACH_S + status_age_s + period_s + latency_s


def select_pairs(xy: np.ndarray, radius: np.ndarray, speed: np.ndarray, horizon: float,
                 sense_m: float = 0.0) -> np.ndarray:
    """Every unordered pair (i, j), i < j, of robots at centres ``xy`` (N x 2) with radii and top
    speeds (N) whose distance is at most ``max(r_i + r_j, sense_m) + (v_i + v_j) * horizon``; an
    (M, 2) array of indices."""
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    n = len(xy)
    if n < 2:
        return np.zeros((0, 2), dtype=np.intp)
    radius = np.asarray(radius, dtype=float)
    speed = np.asarray(speed, dtype=float)
    reach = max(2 * float(radius.max()), sense_m) + 2 * float(speed.max()) * horizon
    pairs = cKDTree(xy).query_pairs(reach, output_type="ndarray")
    if not len(pairs):
        return np.zeros((0, 2), dtype=np.intp)
    i, j = pairs[:, 0], pairs[:, 1]
    limit = np.maximum(radius[i] + radius[j], sense_m) + (speed[i] + speed[j]) * horizon
    d = np.hypot(*(xy[i] - xy[j]).T)
    keep = pairs[d <= limit]
    return np.sort(keep, axis=1)


def neighbour_lists(n: int, pairs: np.ndarray) -> list[np.ndarray]:
    """For each of ``n`` robots the indices of its partners in ``pairs`` (both directions), sorted."""
    if not len(pairs):
        return [np.zeros(0, dtype=np.intp) for _ in range(n)]
    a = np.concatenate([pairs[:, 0], pairs[:, 1]])
    b = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.lexsort((b, a))
    a, b = a[order], b[order]
    cuts = np.searchsorted(a, np.arange(n + 1))
    return [b[cuts[k]:cuts[k + 1]] for k in range(n)]


def select_neighbours(ids: Sequence[str], xy: np.ndarray, radius: np.ndarray, speed: np.ndarray,
                      horizon: float, sense_m: float = 0.0, watch: Watch = no_watch) -> dict[str, list[str]]:
    """For each robot id, the ids it must hear: those within the pair's safety range
    (:func:`select_pairs`) and those ``watch(id)`` names (if they are among ``ids``), sorted, itself
    never; nearest first when a robot has more than :data:`MAX_NEIGHBOURS`."""
    ids = list(ids)
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    lists = neighbour_lists(len(ids), select_pairs(xy, radius, speed, horizon, sense_m))
    index = {rid: k for k, rid in enumerate(ids)}
    out: dict[str, list[str]] = {}
    for k, rid in enumerate(ids):
        near = set(lists[k].tolist())
        for other in watch(rid):
            m = index.get(other)
            if m is not None and m != k:
                near.add(m)
        chosen = sorted(near)
        if len(chosen) > MAX_NEIGHBOURS:  # nearest first
            chosen = sorted(chosen, key=lambda m: float(np.hypot(*(xy[m] - xy[k]))))[:MAX_NEIGHBOURS]
        out[rid] = sorted(ids[m] for m in chosen)
    return out


@dataclass
class _Cached:
    stamp: float
    text: str


class NeighbourRelay:
    """Makes the neighbours records of a fleet from its robots' last statuses.

    ``speeds`` maps a robot kind to its top speed (m/s); ``sense_m`` the distance at which agents care
    beyond the sum of radii (behaviour coordination: the behaviour layer's ``comm_range``);
    ``watch(id)`` the robots a robot's execution gate watches (always relayed to it). Each status is
    encoded once however many records carry it (:meth:`encode`)."""

    def __init__(self, speeds: dict[str, float], period_s: float = RELAY_PERIOD_S, sense_m: float = 0.0,
                 watch: Watch = no_watch, latency_s: float = LATENCY_S, horizon: float | None = None):
        self.speeds = dict(speeds)
        self.period_s = float(period_s)
        self.latency_s = float(latency_s)
        self.fixed_horizon = horizon
        self.horizon = horizon_s(period_s, STATUS_AGE_S, latency_s) if horizon is None else float(horizon)
        self.sense_m = float(sense_m)
        self.watch = watch
        self._json: dict[str, _Cached] = {}

    def horizon_for(self, statuses: Sequence[RobotStatus], now: float) -> float:
        """The horizon for records made ``now`` from ``statuses``: their actual age counts (a planner
        that falls behind relays wider), between :data:`STATUS_AGE_S` and :data:`MAX_AGE_S`; statuses
        older than that are of robots that stopped reporting (the agents take them as standing)."""
        if self.fixed_horizon is not None:
            return self.fixed_horizon
        ages = np.array([now - s.stamp for s in statuses], dtype=float)
        ages = ages[ages <= MAX_AGE_S]
        age = min(MAX_AGE_S, max(STATUS_AGE_S, float(ages.max()) if len(ages) else MAX_AGE_S))
        return horizon_s(self.period_s, age, self.latency_s)

    def select(self, statuses: Sequence[RobotStatus]) -> dict[str, list[str]]:
        """For each robot of ``statuses`` (one status per robot), the ids of the robots it must hear."""
        top = max(self.speeds.values(), default=0.0)
        xy = np.array([(s.x, s.y) for s in statuses], dtype=float).reshape(-1, 2)
        radius = np.array([s.radius for s in statuses], dtype=float)
        speed = np.array([self.speeds.get(s.kind, top) for s in statuses], dtype=float)
        return select_neighbours([s.id for s in statuses], xy, radius, speed, self.horizon, self.sense_m,
                                 self.watch)

    def records(self, statuses: Iterable[RobotStatus], now: float,
                only: Container[str] | None = None) -> dict[str, str]:
        """The JSON of each robot's neighbours record (``fleet/neighbours@1``) stamped ``now``
        (``only``: of these robots only; every status still counts as a neighbour)."""
        statuses = list(statuses)
        by_id = {s.id: s for s in statuses}
        self.horizon = self.horizon_for(statuses, now)
        chosen = self.select(statuses)
        for gone in set(self._json) - set(by_id):
            del self._json[gone]
        return {rid: self.encode(rid, now, [by_id[o] for o in others]) for rid, others in chosen.items()
                if only is None or rid in only}

    def offer_json(self, status: RobotStatus, text: str) -> None:
        """``text`` is the JSON ``status`` came in as (it parsed to exactly that record): records carry
        it as it is, without encoding the status again."""
        if len(text) <= 2048:
            self._json[status.id] = _Cached(status.stamp, text)

    def encode(self, robot_id: str, now: float, statuses: Sequence[RobotStatus]) -> str:
        """The JSON of ``Neighbours(robot_id, now, statuses)``, from each status's cached JSON."""
        parts = []
        for s in statuses:
            cached = self._json.get(s.id)
            if cached is None or cached.stamp != s.stamp:
                cached = self._json[s.id] = _Cached(s.stamp, s.to_json())
            parts.append(cached.text)
        return (f'{{"schema":"{Neighbours.SCHEMA}","id":{json.dumps(robot_id)},'
                f'"stamp":{json.dumps(float(now))},"robots":[{",".join(parts)}]}}')


__all__ = ["LATENCY_S", "MAX_AGE_S", "NET_REACH_S", "RELAY_PERIOD_S", "STATUS_AGE_S", "NeighbourRelay", "Watch",
           "horizon_s", "neighbour_lists", "no_watch", "select_neighbours", "select_pairs"]
