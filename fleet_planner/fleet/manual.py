"""The operator's hand on the robot's end: the e-stop and manual drive (:class:`OperatorHand`, one
per :class:`~.agent.RobotAgent`), and the check of a velocity command (:func:`check_twist`).

* **e-stop** (:meth:`OperatorHand.set_estop`): the robot holds at once, whatever it was doing
  (an action under way runs out, it never moves), latched until released; after the release it
  still holds until it gets a leg planned after the stop (the old leg's times have passed, and
  driving it now would rush the robot to where it was due).
* **manual drive** (:meth:`OperatorHand.set_manual`): the robot drops its leg and drives by the
  operator's velocity commands (:meth:`OperatorHand.command`: forward speed and turn rate, as
  ``geometry_msgs/Twist`` ``linear.x`` and ``angular.z``), within its speed and acceleration, and
  stops when no command came for :data:`DEADMAN_S` (a dead man's switch). It never drives into a
  wall or into another robot's critical area (the safety net of a central robot,
  :func:`~fleet_planner.behavior.safety_stop`). Its statuses say ``manual``, so the planner plans
  around it as an obstacle; switched off, it stands until the planner gives it a new leg.

Times are seconds on the robot's clock: ``now`` is always passed in.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from msg_schemas.records import RobotStatus

from ..behavior import RobotView, safety_stop
from ..robots import RobotModel
from ..warehouse import Warehouse
from .coordination import NET_MARGIN_M, STALE_S

#: a manual robot stops when its last velocity command is older than this (s)
DEADMAN_S = 0.5
#: the fastest turn (rad/s) a velocity command may ask for
MAX_TURN_RATE = 2.0
_AXES = ("x", "y", "z")


def check_twist(linear: Sequence[float], angular: Sequence[float], max_speed: float) -> tuple[float, float]:
    """The (forward speed, turn rate) of a velocity command, or ValueError naming the field:
    every component finite, ``linear.x`` within ``max_speed``, ``angular.z`` within
    :data:`MAX_TURN_RATE`, the rest 0 (the robots drive forwards or backwards and turn)."""
    for part, values in (("linear", linear), ("angular", angular)):
        for axis, value in zip(_AXES, values):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"twist.{part}.{axis}: must be a finite number (got {value!r})")
    for part, axis, value in (("linear", "y", linear[1]), ("linear", "z", linear[2]),
                              ("angular", "x", angular[0]), ("angular", "y", angular[1])):
        if value != 0.0:
            raise ValueError(f"twist.{part}.{axis}: must be 0 (the robot drives forwards or backwards and "
                             f"turns; got {value!r})")
    v, w = float(linear[0]), float(angular[2])
    if abs(v) > max_speed:
        raise ValueError(f"twist.linear.x: {v:g} m/s is beyond the robot's top speed {max_speed:g} m/s")
    if abs(w) > MAX_TURN_RATE:
        raise ValueError(f"twist.angular.z: {w:g} rad/s is beyond the turn rate limit {MAX_TURN_RATE:g} rad/s")
    return v, w


class OperatorHand:
    """E-stop and manual drive of one robot (see the module's docstring)."""

    def __init__(self, model: RobotModel, warehouse: Warehouse):
        self.model = model
        self.warehouse = warehouse
        self.estopped = False
        self.manual = False
        self._stale_path: int | None | bool = False  # after an e-stop: hold while on this leg
        self._cmd: tuple[float, float, float] | None = None  # (v, w, stamp)
        self._heading = model.yaw
        self._v = 0.0                        # signed forward speed now
        self.blocked_by: str | None = None   # what stopped the last manual step, if anything

    # -- switches ---------------------------------------------------------------------------------
    def set_estop(self, engaged: bool) -> str:
        """Engage or release the e-stop; a message in words."""
        if engaged and not self.estopped:
            self.estopped = True
            self._stale_path = self.model.path_id
            self._cmd = None
            return f"robot {self.model.id}: e-stop engaged"
        if not engaged and self.estopped:
            self.estopped = False
            return f"robot {self.model.id}: e-stop released; it holds until it gets a new leg"
        return f"robot {self.model.id}: e-stop already {'engaged' if engaged else 'released'}"

    def set_manual(self, on: bool) -> str:
        """Switch manual drive on or off; ValueError (naming the field) if it cannot be now."""
        m = self.model
        if on and not self.manual:
            if m.busy_until is not None:
                raise ValueError(f"data: robot {m.id} is {m.mode}; switch to manual drive when it is done")
            if m.mode == "error":
                raise ValueError(f"data: robot {m.id} is out of battery")
            self.manual, self._cmd, self._heading = True, None, m.yaw
            m.steer(None)     # drops its leg; it stands where it is
            self._v = 0.0
            return f"robot {m.id}: manual drive on (cmd_vel)"
        if not on and self.manual:
            self.manual, self._cmd = False, None
            self._stale_path = m.path_id  # stands until the planner gives it a leg
            return f"robot {m.id}: manual drive off; it re-joins the plan"
        return f"robot {m.id}: manual drive already {'on' if on else 'off'}"

    def command(self, linear: Sequence[float], angular: Sequence[float], now: float) -> None:
        """A velocity command (``geometry_msgs/Twist`` parts); ValueError naming the field if it
        is bad or the robot is not in manual drive."""
        v, w = check_twist(linear, angular, self.model.kind.max_speed)
        if not self.manual:
            raise ValueError(f"twist: robot {self.model.id} is not in manual drive (switch it on first)")
        self._cmd = (v, w, float(now))

    # -- driving ----------------------------------------------------------------------------------
    def drive(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> bool:
        """Step the robot from ``t`` by ``dt`` if the operator has it (e-stop, held after one, or
        manual drive): True. False: the coordination's driver drives it."""
        m = self.model
        if self.estopped or (self._stale_path is not False and m.path_id == self._stale_path):
            if self.manual and not self.estopped:
                return self._drive_manual(t, dt, heard)
            m.step(t, dt, hold=True)
            return True
        self._stale_path = False
        if self.manual:
            return self._drive_manual(t, dt, heard)
        return False

    def _drive_manual(self, t: float, dt: float, heard: Mapping[str, RobotStatus]) -> bool:
        m, k = self.model, self.model.kind
        v, w = 0.0, 0.0
        if self._cmd is not None and t + dt - self._cmd[2] <= DEADMAN_S and not self.estopped:
            v, w = self._cmd[0], self._cmd[1]
        if math.isfinite(k.max_accel) and v:  # within its acceleration (a stop is always allowed)
            v = self._v + max(-k.max_accel * dt, min(k.max_accel * dt, v - self._v))
        self._heading = math.atan2(math.sin(self._heading + w * dt), math.cos(self._heading + w * dt))
        to = (m.x + v * dt * math.cos(self._heading), m.y + v * dt * math.sin(self._heading))
        self.blocked_by = self._blocker(t, dt, to, heard) if v else None
        if self.blocked_by is not None:
            to, v = (m.x, m.y), 0.0
        self._v = v
        m.step(t, dt, to=to, progress=1.0)
        m.yaw = self._heading
        return True

    def _blocker(self, t: float, dt: float, to: tuple[float, float], heard: Mapping[str, RobotStatus]) -> str | None:
        m, k = self.model, self.model.kind
        if not self.warehouse.grid.disc_is_free(to[0], to[1], k.radius):
            return "a wall"
        step = math.dist((m.x, m.y), to)
        others, sweep = [], {}
        for st in heard.values():
            if math.hypot(st.x - m.x, st.y - m.y) > k.radius + st.radius + step + 2 * k.max_speed * STALE_S:
                continue
            ahead_s = t + dt - st.stamp
            ahead_s = ahead_s if 0.0 <= ahead_s <= STALE_S else 0.0
            sweep[st.id] = (st.vx * ahead_s, st.vy * ahead_s)
            others.append(RobotView(st.id, (st.x, st.y), st.radius))
        me = RobotView(m.id, (m.x, m.y), k.radius, next_waypoint=to)
        blocker = safety_stop(me, others, step, NET_MARGIN_M, sweep)
        return None if blocker is None else f"robot {blocker.id}"

    def status_fields(self) -> dict[str, Any]:
        """The ``manual`` and ``estop`` fields of the robot's status (left out when off)."""
        return {"manual": True if self.manual else None, "estop": True if self.estopped else None}
