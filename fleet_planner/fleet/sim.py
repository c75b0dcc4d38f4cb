"""Many simulated robots stepped together: :class:`SimFleet`, the core of ``fleet-sim``
(:mod:`fleet_planner.ros.fleet_sim`).

Each robot is a :class:`~.agent.RobotAgent` (the same as one agent process drives: its legs, its
safety net or behaviour layer, its picks, places and charging), so a simulated robot behaves
exactly as a real robot's agent does. What is shared is done once per step for all of them: who
hears whom comes from one k-d tree query over the fleet's last statuses (:mod:`.neighbours`, the
selection the planner's relay makes, here from statuses one step old), the robots' path tracking
is worked out for all of them in numpy arrays (:class:`~fleet_planner.robots.TrackBatch`: the same
result as each robot's own step), and robots of other processes can be added from the relay's
records (:meth:`SimFleet.hear`).

Times are seconds on one clock (ROS time): ``now`` is always passed in.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence

from msg_schemas.records import GateRecord, Heard, RobotStatus, Task, TaskEvent, WaitMessageRecord

from ..model import TimedPath
from ..robots import RobotKind, RobotModel, TrackBatch
from ..warehouse import Warehouse
from .agent import RobotAgent
from .coordination import AGENT_BEHAVIOR, get_coordination
from .fleet_file import FleetMember
from .gate import watched_robots
from .legs import CONTROL_PERIOD_S
from .neighbours import NeighbourRelay

#: the longest step a simulated robot drives at once (s). A loaded machine can let the clock jump
#: several seconds between two steps of fleet-sim; the robots then drive that stretch in steps of at
#: most this length, each after hearing the others' statuses of the step before, so their safety
#: nets and gates act as often as they would in real time (ours; a crossing of two robots driven in
#: one step of 1 s or 3 s overlapped: test_sim_gate.test_a_clock_jump_is_driven_in_short_steps).
MAX_STEP_S = 0.3
#: at most this many steps for one call (a jump longer than MAX_SUBSTEPS x MAX_STEP_S takes longer steps)
MAX_SUBSTEPS = 40


class SimFleet:
    """Simulated robots of ``members`` on ``warehouse`` under ``coordination``, stepped together."""

    def __init__(self, members: Sequence[FleetMember], kinds: Mapping[str, RobotKind], warehouse: Warehouse,
                 coordination: str = "central", period_s: float = CONTROL_PERIOD_S, gated: bool = False,
                 batch: bool = True, max_step_s: float = MAX_STEP_S):
        if not max_step_s > 0.0:
            raise ValueError(f"max_step_s: must be > 0, got {max_step_s!r}")
        self.max_step_s = max_step_s
        self._now: float | None = None   # the time of the last step
        strategy = get_coordination(coordination)
        chargers = [s.pose for s in warehouse.stations_of("charger")]
        self.agents: dict[str, RobotAgent] = {}
        for m in members:
            if m.id in self.agents:
                raise ValueError(f"robot {m.id!r}: listed twice")
            model = RobotModel(m.id, kinds[m.kind], m.x, m.y, m.yaw, m.battery, chargers)
            self.agents[m.id] = RobotAgent(model, warehouse, get_coordination(strategy.name), gated=gated)
        sense = AGENT_BEHAVIOR.comm_range if strategy.exchanges_wait_messages else 0.0
        # statuses of this fleet are one step old when heard, and heard at once
        self.relay = NeighbourRelay({k.name: k.max_speed for k in kinds.values()}, period_s, sense,
                                    latency_s=0.0)
        if gated:  # a gated robot hears every robot its links name, however far (as the planner's relay)
            self.relay.watch = self._watched
        self.last: dict[str, RobotStatus] = {}
        # the robots' path tracking worked out for all at once before each step (same result as one by one)
        self.batch = TrackBatch([a.model for a in self.agents.values()]) if batch else None
        self.foreign: dict[str, RobotStatus] = {}   # robots of other processes, from the relay

    def __len__(self) -> int:
        return len(self.agents)

    # -- input, routed to the robots it is for -------------------------------------------------------
    def on_path(self, robot_id: str, path: TimedPath, t0: float, path_id: int) -> None:
        """A leg for one robot (ValueError if it cannot follow it, as RobotAgent.on_path)."""
        self.agents[robot_id].on_path(path, t0, path_id)

    def _watched(self, robot_id: str) -> set[str]:
        agent = self.agents.get(robot_id)  # (robots of other processes are heard here, not simulated)
        return watched_robots(getattr(agent.driver, "gate", None)) if agent is not None else set()

    def on_gate(self, record: GateRecord) -> None:
        """A gate record, for the robot it names (fleet/gate.py)."""
        agent = self.agents.get(record.robot_id)
        if agent is not None:
            agent.on_gate(record)

    def on_heard(self, record: Heard) -> None:
        """Whom the planner hears (fleet/lease.py), for every robot it simulates (each reads its own
        entry; ValueError, naming the field, if one is stamped too far ahead: the others took it)."""
        problems = []
        for a in self.agents.values():
            try:
                a.on_heard(record, self._now)
            except ValueError as exc:
                problems.append(str(exc))
        if problems:
            raise ValueError(f"{problems[0]}" + (f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""))

    def on_task(self, task: Task) -> None:
        for a in self.agents.values():
            a.on_task(task)

    def on_event(self, event: TaskEvent, sender: str | None = None) -> None:
        for a in self.agents.values():
            a.on_event(event, sender)

    def on_wait_message(self, msg: WaitMessageRecord) -> None:
        agent = self.agents.get(msg.receiver)
        if agent is not None:
            agent.on_wait_message(msg)

    def hear(self, statuses: Iterable[RobotStatus]) -> None:
        """Statuses of robots that are not simulated here (relayed by the planner)."""
        for st in statuses:
            if st.id not in self.agents:
                last = self.foreign.get(st.id)
                if last is None or st.stamp >= last.stamp:
                    self.foreign[st.id] = st

    # -- the step ------------------------------------------------------------------------------------
    def step(self, now: float) -> list[RobotStatus]:
        """Every robot hears its neighbours (from the last statuses) and advances to ``now``, in steps
        of at most ``max_step_s``; their new statuses, to publish."""
        last = self._now
        if last is not None and now - last > self.max_step_s:
            n = min(math.ceil((now - last) / self.max_step_s), MAX_SUBSTEPS)
            for k in range(1, n):
                self._step_once(last + (now - last) * k / n)
        if last is None or now > last:
            self._now = now
        return self._step_once(now)

    def _step_once(self, now: float) -> list[RobotStatus]:
        known = list(self.last.values()) + [s for s in self.foreign.values() if s.id not in self.last]
        by_id = {s.id: s for s in known}
        chosen = self.relay.select(known) if known else {}
        if self.batch is not None:
            # each agent steps its robot over [its last tick, now] (RobotAgent.tick)
            lasts = [a._last if a._last is not None and now > a._last else None for a in self.agents.values()]
            self.batch.prepare(lasts, [0.0 if t is None else now - t for t in lasts])
        out = []
        for rid, agent in self.agents.items():
            agent.on_neighbours([by_id[o] for o in chosen.get(rid, ())], now)
            st = agent.tick(now)
            self.last[rid] = st
            out.append(st)
        return out

    def take_wait_messages(self) -> list[WaitMessageRecord]:
        return [w for a in self.agents.values() for w in a.take_wait_messages()]


__all__ = ["SimFleet"]
