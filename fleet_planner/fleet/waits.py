"""Who waits for whom in gated execution, and the wait cycles nobody else breaks (ours; pure).

Gated execution (:mod:`.gate`, in the spirit of the Action Dependency Graph of Hoenig et al. on the
collision regions of You & Ji's (M,D) network) orders robots region by region; the planner plans each
new leg around the others' trajectories as fixed. The two meet in a cycle no rule of either breaks:
robot B's gate holds it until A has left a region, while A's new leg cannot be planned because B's
trajectory (planned when A was to leave in time) drives through A's start disc, or A's new leg is
refused because it would start in a region B may be in. Each waits for the other for good (100
robots on ``large``: r11 <-> r69 <-> r100; bench_dispatch --rate 10 jammed at 49 jobs).

A **wait-for graph** (:func:`wait_for_graph`) has an edge ``r -> o`` where

* ``gate``: ``r``'s gate holds it (it stands within :data:`HELD_NEAR_M` of its gate's limit) on a
  link naming ``o`` that the planner has not heard satisfied;
* ``leg``: ``r``'s last leg search failed naming ``o`` as the blocker (LegNotPlanned.blocker), or the
  gate refused ``r``'s last new leg for ``o`` (a region ``o`` may be in), within :data:`FRESH_S`.

:func:`cycles` gives its strongly connected pieces of two robots or more. The
manager breaks one (:meth:`~.manager.FleetManager._break_waits`): a robot its gate holds for a robot
whose leg waits for it gets a hold leg where its gate lets it stand, so the other is planned around
it standing (the gate's own rules keep every link of the hold leg, a new record, higher ``seq``).
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from msg_schemas.records import RobotStatus

from .gate import STILL_MPS, GateBook, blockers, gate_limit, travelled
from .state import FleetRobot

#: a robot this near (m) its gate's limit, and slower than :data:`.gate.STILL_MPS`, is held by its gate (it
#: stops within one control step of the limit: its top speed x 0.1 s)
HELD_NEAR_M = 0.3
#: a failed or refused leg names its blocker for this long (s) after it failed: an older one may be out of date
FRESH_S = 6.0


def gate_waits(book: GateBook, robots: Iterable[FleetRobot]) -> dict[str, list[str]]:
    """Per robot its gate holds, the robots its unsatisfied links there name (by the statuses the planner heard)."""
    robots = list(robots)
    heard: Mapping[str, RobotStatus] = {o.id: o.status for o in robots}
    out: dict[str, list[str]] = {}
    for r in robots:
        st, rec = r.status, book.records.get(r.id)
        if rec is None or st.path_id is None or rec.path_id != st.path_id or r.immobile:
            continue
        done = travelled(st)
        if done is None or math.isinf(done) or math.hypot(st.vx, st.vy) > STILL_MPS:
            continue
        if done + HELD_NEAR_M < gate_limit(rec, st.path_id, heard):
            continue
        names = blockers(rec, heard, done + HELD_NEAR_M)
        if names:
            out[r.id] = names
    return out


def wait_for_graph(book: GateBook, robots: Iterable[FleetRobot], now: float) -> dict[str, dict[str, str]]:
    """``graph[r][o]``: why ``r`` waits for ``o`` (``"gate"`` or ``"leg"``; see the module's text)."""
    robots = list(robots)
    graph: dict[str, dict[str, str]] = {}
    for rid, names in gate_waits(book, robots).items():
        graph.setdefault(rid, {}).update(dict.fromkeys(names, "gate"))
    for r in robots:
        if r.immobile or now - r.waits_since > FRESH_S:
            continue
        for oid in r.waits_on:
            graph.setdefault(r.id, {}).setdefault(oid, "leg")
    return graph


def cycles(graph: Mapping[str, Mapping[str, str]]) -> list[list[str]]:
    """The strongly connected pieces of ``graph`` with two robots or more, each sorted (SciPy's
    ``connected_components``, strong connection)."""
    ids = sorted(set(graph) | {o for edges in graph.values() for o in edges})
    if not ids:
        return []
    at = {rid: k for k, rid in enumerate(ids)}
    rows = [at[r] for r, edges in graph.items() for _ in edges]
    cols = [at[o] for edges in graph.values() for o in edges]
    adj = csr_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(len(ids), len(ids)))
    _, labels = connected_components(adj, directed=True, connection="strong")
    pieces: dict[int, list[str]] = {}
    for rid, lab in zip(ids, labels.tolist()):
        pieces.setdefault(lab, []).append(rid)
    return [piece for piece in pieces.values() if len(piece) > 1]
