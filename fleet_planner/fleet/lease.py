"""A robot the planner cannot hear stops (ours; docs/ARCHITECTURE.md, "Leases").

A robot in a dead spot of the network keeps driving its leg while the planner, not hearing it, marks
it offline and plans the others round where it was last heard. Both ends close that gap here:

- **The robot's end** (:class:`Lease`, held by :class:`~.agent.RobotAgent`): three times a lease the
  planner says whom it hears (``fleet/heard@1``, :class:`~msg_schemas.records.Heard`): per robot, the
  stamp of the latest status it took in and the leg it keeps the others clear of. A robot stops (it
  brakes within its acceleration limit, holding where driving would hold) when the latest record
  says the planner hears others but not it - its stamp more than ``lease_s`` behind the newest stamp
  in the record, or left out - or when it heard no record stamped within ``silence_s`` of its clock
  (the planner is silent). It stays stopped until it is heard again and drives a leg the planner
  keeps (or a new leg: the planner gives one to a robot back online). Measured against the newest
  stamp, not the clock, so a planner whose input runs late for everyone (a loaded machine) does not
  stop the fleet: it takes nobody offline then either (``DEAF_FACTOR`` in :mod:`.manager`).
- **The planner's end** (:func:`heard_record`, :func:`stopped_by`, :func:`reachable`, used by
  :class:`~.manager.FleetManager`): a robot must have stopped by the first heard record that showed
  it unheard (``stale_since``; the next record if none did yet) + ``silence_s`` (had it missed that
  record and every later one) + its braking time + :data:`LEASE_SLACK_S`. Until then a robot marked
  offline keeps its leg and the others' links on it; after that it is an obstacle wherever it can be:
  the stretch of its leg it could have reached by then, not only its last heard point.

Times are seconds on one clock (ROS time): ``now`` is always passed in.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np

from msg_schemas.records import Heard

from ..model import TimedPath
from ..robots import RobotKind
from .gate import arc_at, sample
from .legs import MAX_CLOCK_SKEW_S
from .state import FleetRobot

#: (s) beyond the lease and the braking time: the robot notices its lease ran out at its next control
#: step (0.1 s) and its clock may differ a little from the planner's (one ROS time: sim clock or NTP)
LEASE_SLACK_S = 0.5
#: (m) spacing of the points of a reachable stretch (discs this far apart cover it, grown by the sag)
STRETCH_STEP_M = 0.1
#: stamps in a heard record are rounded down to this many decimals (ms): a robot never reads itself
#: heard later than it was
HEARD_DECIMALS = 3


# -------------------------------------------------------------------------------------------------
# the robot's end
# -------------------------------------------------------------------------------------------------
class Lease:
    """Whether robot ``robot_id`` may drive: the planner hears it (its heard records), or no planner
    ever named it (no lease yet: a planner without leases, or one that has not heard it)."""

    def __init__(self, robot_id: str, max_clock_skew_s: float = MAX_CLOCK_SKEW_S):
        self.robot_id = robot_id
        self.max_clock_skew_s = max_clock_skew_s
        self.record: Heard | None = None    # the newest heard record since one named it (None: no lease)
        self.heard: float | None = None     # the latest stamp of its statuses the planner took in
        self.kept: int | None = None        # the leg the planner keeps the others clear of for it
        self.stopped = False                # its lease ran out: it stands until heard on a good leg
        self.stopped_on: int | None = None  # the leg it drove when its lease ran out
        self.lapses = 0                     # how often its lease ran out

    @property
    def lease_s(self) -> float | None:
        return None if self.record is None else self.record.lease_s

    def on_heard(self, record: Heard, now: float | None = None) -> None:
        """A heard record (older ones than the newest are ignored); ValueError (naming the field) if it is
        stamped, or says the robot was heard at a stamp, more than ``max_clock_skew_s`` ahead of ``now``."""
        mine = record.robots.get(self.robot_id)
        if now is not None:
            for name, t in (("stamp", record.stamp), (f"robots.{self.robot_id}", mine)):
                if t is not None and t > now + self.max_clock_skew_s:
                    raise ValueError(f"heard.{name}: stamped {t - now:.3g} s ahead of the robot's clock "
                                     f"(at most {self.max_clock_skew_s:g} s)")
        if self.record is None and mine is None:
            return   # no planner named it yet: no lease
        if self.record is not None and record.stamp < self.record.stamp:
            return   # an older record overtaken by a newer one
        self.record = record
        if mine is not None:
            self.heard = max(mine, self.heard) if self.heard is not None else float(mine)
        self.kept = (record.legs or {}).get(self.robot_id) if mine is not None else None

    def expired(self, now: float) -> bool:
        """The lease ran out at ``now``: the newest record says the planner hears others but not this
        robot, or no record came for ``silence_s`` (never without a lease)."""
        rec = self.record
        if rec is None:
            return False
        mine = rec.robots.get(self.robot_id)
        if mine is None or now - rec.stamp > rec.silence_s:
            return True
        return max(rec.robots.values()) - mine > rec.lease_s

    def holds(self, now: float, path_id: int | None) -> bool:
        """Whether the robot, on leg ``path_id`` (None: none), must brake / stand at ``now``: its lease ran
        out, or it did and the planner has not yet said it keeps that leg clear (nor sent a new one)."""
        if self.expired(now):
            if not self.stopped:
                self.stopped, self.stopped_on = True, path_id
                self.lapses += 1
            return True
        if self.stopped and (path_id == self.kept or path_id != self.stopped_on):
            self.stopped = False
        return self.stopped


# -------------------------------------------------------------------------------------------------
# the planner's end
# -------------------------------------------------------------------------------------------------
def heard_record(robots: Iterable[FleetRobot], now: float, lease_s: float, silence_s: float) -> Heard:
    """Whom the planner hears now: every robot it counts online, with the stamp of its latest status
    (rounded down to ms) and the leg it keeps for it (if any). A robot the record shows unheard (left
    out, or its stamp more than ``lease_s`` behind the newest) gets ``stale_since`` (when first so)."""
    scale = 10 ** HEARD_DECIMALS
    robots = list(robots)
    heard, legs = {}, {}
    for r in robots:
        if r.online:
            heard[r.id] = math.floor(r.status.stamp * scale) / scale
            if r.leg is not None and not r.immobile:
                legs[r.id] = r.leg.path_id
    newest = max(heard.values(), default=now)
    for r in robots:
        stale = r.id not in heard or newest - heard[r.id] > lease_s
        if not stale:
            r.stale_since = None
        elif r.stale_since is None:
            r.stale_since = float(now)
    return Heard(stamp=float(now), lease_s=float(lease_s), silence_s=float(silence_s), robots=heard,
                 legs=legs or None)


def braking_s(kind: RobotKind) -> float:
    """How long a robot of ``kind`` takes to stop from its top speed."""
    return kind.max_speed / kind.max_accel if math.isfinite(kind.max_accel) and kind.max_accel > 0 else 0.0


def stopped_by(r: FleetRobot, now: float, silence_s: float, slack_s: float = LEASE_SLACK_S) -> float:
    """When robot ``r``, unheard, must stand whatever it did: the first heard record that showed it unheard
    (``r.stale_since``; if none did yet, the next one, from ``now`` on) stops it when it comes; had it
    missed that record and every later one, its silence does ``silence_s`` after the last record it had,
    sent before that one. Then its braking time and ``slack_s``."""
    shown = r.stale_since if r.stale_since is not None else now
    return shown + silence_s + braking_s(r.kind) + slack_s


def reachable(r: FleetRobot, paths: dict[int, TimedPath], until: float,
              limits: Mapping[int, float] | None = None) -> np.ndarray:
    """Where unheard robot ``r`` may stand at ``until`` (n x 2 points): its last heard position, and on
    each of its live ``paths`` (path id -> timed path, absolute times) the stretch it could have driven
    by then - from where its status says it was on the path it drove (from the start of one it had not
    yet taken) to where the path is due at ``until`` (a robot is never ahead of its schedule) or its top
    speed could take it, or (ours) where its gate must have held it (``limits``, path id -> m:
    ``GateBook.reach_limits``), whichever is nearest."""
    st = r.status
    limits = limits or {}
    out = [np.array([[st.x, st.y]])]
    for pid, path in paths.items():
        due = min(arc_at(path, until), limits.get(pid, math.inf))
        if pid == st.path_id:
            done = st.travelled_m if st.travelled_m is not None else st.progress * path.length
            hi = min(due, done + r.kind.max_speed * max(0.0, until - st.stamp))
            out.append(sample(path, done, hi, STRETCH_STEP_M).xy)
        elif st.path_id is None or pid > st.path_id:   # sent, not yet taken: it may take it from its start
            out.append(sample(path, 0.0, due, STRETCH_STEP_M).xy)
    return np.vstack(out)


__all__ = ["HEARD_DECIMALS", "LEASE_SLACK_S", "STRETCH_STEP_M", "Lease", "braking_s", "heard_record", "reachable",
           "stopped_by"]
