"""A robot the planner cannot hear stops (ours; docs/ARCHITECTURE.md, "Leases").

A robot in a dead spot of the network keeps driving its leg while the planner, not hearing it, marks
it offline and plans the others round where it was last heard. Both ends close that gap here:

- **The robot's end** (:class:`Lease`, held by :class:`~.agent.RobotAgent`): at every step the planner
  says whom it hears (``fleet/heard@1``, :class:`~msg_schemas.records.Heard`): per robot, the stamp of
  the latest status it took in and the leg it keeps the others clear of. A robot whose latest heard
  status is older than ``lease_s`` by its own clock brakes to a stop (within its acceleration limit)
  and stays stopped until it is heard again and drives a leg the planner keeps (or a new leg: the
  planner gives one to a robot back online).
- **The planner's end** (:func:`heard_record`, :func:`stopped_by`, :func:`reachable`, used by
  :class:`~.manager.FleetManager`): until the robot must have stopped (its last heard status's
  stamp + ``lease_s`` + its braking time + :data:`LEASE_SLACK_S`), a robot marked offline keeps its
  leg and the links of the others on it; after that it is an obstacle wherever it can be: the stretch
  of its leg it could have reached by then, not only its last heard point.

Times are seconds on one clock (ROS time): ``now`` is always passed in.
"""
from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from msg_schemas.records import Heard

from ..model import TimedPath
from ..robots import RobotKind
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
    """Whether robot ``robot_id`` may drive: it is heard by the planner (its heard records), or no
    planner ever named it (no lease yet: a planner without leases, or one that has not heard it)."""

    def __init__(self, robot_id: str, max_clock_skew_s: float = MAX_CLOCK_SKEW_S):
        self.robot_id = robot_id
        self.max_clock_skew_s = max_clock_skew_s
        self.heard: float | None = None     # the latest stamp of its statuses the planner took in
        self.lease_s: float | None = None   # None: no lease (no planner named it yet)
        self.kept: int | None = None        # the leg the planner keeps the others clear of for it
        self.stopped = False                # its lease ran out: it stands until heard on a good leg
        self.stopped_on: int | None = None  # the leg it drove when its lease ran out
        self.lapses = 0                     # how often its lease ran out

    def on_heard(self, record: Heard, now: float | None = None) -> None:
        """A heard record; ValueError (naming the field) if it says the robot was heard at a stamp more
        than ``max_clock_skew_s`` ahead of ``now`` (it would hold the lease for good)."""
        stamp = record.robots.get(self.robot_id)
        if stamp is None:
            return   # not heard (offline to the planner, or not known yet): its lease runs out
        if now is not None and stamp > now + self.max_clock_skew_s:
            raise ValueError(f"heard.robots.{self.robot_id}: stamped {stamp - now:.3g} s ahead of the robot's "
                             f"clock (at most {self.max_clock_skew_s:g} s)")
        if self.heard is not None and stamp < self.heard:
            return   # an older record overtaken by a newer one
        self.heard, self.lease_s = float(stamp), float(record.lease_s)
        self.kept = (record.legs or {}).get(self.robot_id)

    def expired(self, now: float) -> bool:
        """The lease ran out at ``now`` (never without one)."""
        return self.lease_s is not None and self.heard is not None and now - self.heard > self.lease_s

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
def heard_record(robots: Iterable[FleetRobot], now: float, lease_s: float) -> Heard:
    """Whom the planner hears now: every robot it counts online, with the stamp of its latest status
    (rounded down to ms) and the leg it keeps for it (if any)."""
    scale = 10 ** HEARD_DECIMALS
    heard, legs = {}, {}
    for r in robots:
        if r.online:
            heard[r.id] = math.floor(r.status.stamp * scale) / scale
            if r.leg is not None and not r.immobile:
                legs[r.id] = r.leg.path_id
    return Heard(stamp=float(now), lease_s=float(lease_s), robots=heard, legs=legs or None)


def braking_s(kind: RobotKind) -> float:
    """How long a robot of ``kind`` takes to stop from its top speed."""
    return kind.max_speed / kind.max_accel if math.isfinite(kind.max_accel) and kind.max_accel > 0 else 0.0


def stopped_by(r: FleetRobot, lease_s: float, slack_s: float = LEASE_SLACK_S) -> float:
    """When robot ``r`` must stand, whatever it does unheard: the stamp of its latest status the planner
    heard (it never echoes a newer one) plus its lease, its braking time and ``slack_s``."""
    return r.status.stamp + lease_s + braking_s(r.kind) + slack_s


def _arc(path: TimedPath) -> np.ndarray:
    wp = path.waypoints
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(wp[:, :2], axis=0).T))])


def stretch(path: TimedPath, lo: float, hi: float, step: float = STRETCH_STEP_M) -> np.ndarray:
    """Points of ``path`` from ``lo`` to ``hi`` m along it, at most ``step`` apart, ends included."""
    arc = _arc(path)
    lo, hi = max(0.0, min(lo, float(arc[-1]))), max(0.0, min(hi, float(arc[-1])))
    s = np.linspace(lo, hi, max(2, math.ceil((hi - lo) / step) + 1)) if hi > lo else np.array([lo])
    wp = path.waypoints
    return np.column_stack([np.interp(s, arc, wp[:, 0]), np.interp(s, arc, wp[:, 1])])


def reachable(r: FleetRobot, paths: dict[int, TimedPath], until: float) -> np.ndarray:
    """Where unheard robot ``r`` may stand at ``until`` (n x 2 points): its last heard position, and on
    each of its live ``paths`` (path id -> timed path, absolute times) the stretch it could have driven
    by then - from where its status says it was on the path it drove (from the start of one it had not
    yet taken) to where the path is due at ``until`` (a robot is never ahead of its schedule) or its top
    speed could take it, whichever is nearer."""
    st = r.status
    out = [np.array([[st.x, st.y]])]
    for pid, path in paths.items():
        wp = path.waypoints
        due = float(np.interp(until, wp[:, 2], _arc(path)))
        if pid == st.path_id:
            done = st.travelled_m if st.travelled_m is not None else st.progress * float(_arc(path)[-1])
            hi = min(due, done + r.kind.max_speed * max(0.0, until - st.stamp))
            out.append(stretch(path, done, hi))
        elif st.path_id is None or pid > st.path_id:   # sent, not yet taken: it may take it from its start
            out.append(stretch(path, 0.0, due))
    return np.vstack(out)


__all__ = ["HEARD_DECIMALS", "LEASE_SLACK_S", "STRETCH_STEP_M", "Lease", "braking_s", "heard_record", "reachable",
           "stopped_by", "stretch"]
