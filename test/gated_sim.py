"""A pure fleet (manager and agents on one simulated clock, no ROS) whose agents hear each other's
statuses and their gate records, with slow-downs and halts injected: the test bed of gated
execution (test/test_gate.py, bench/bench_gate.py)."""
from __future__ import annotations

import random

from test_dispatch import FAST, PARKING, WH, Sim

from fleet_planner.checker import min_separation
from fleet_planner.fleet import DispatchParams, FleetManager, RobotAgent


class GatedSim(Sim):
    """:class:`test_dispatch.Sim` where every agent hears every status (a status period late, as on
    the wire) and its gate records; ``gated`` agents respect them. ``slow`` holds
    ``(robot, from_s, to_s, scale)``: the robot drives at ``scale`` of its top speed meanwhile."""

    def __init__(self, fleet, gated=True, slow=(), wh=WH, parking=PARKING, kinds=FAST, **params):
        super().__init__(fleet, wh, parking, kinds, **params)
        self.fm = FleetManager(wh, kinds, DispatchParams(**params), parking, gated=gated)
        for rid, a in list(self.agents.items()):
            self.agents[rid] = RobotAgent(a.model, self.wh, gated=gated)
        self.slow = list(slow)
        self.gates_sent = self.links_sent = 0

    def _tick(self):
        self._ticks += 1
        self.t = round(self._ticks * self.dt, 9)
        heard = []
        for rid, a in self.agents.items():
            if rid in self.dead:
                continue
            scale = min([s for r, t0, t1, s in self.slow if r == rid and t0 <= self.t < t1], default=1.0)
            if scale != a.speed_scale:
                a.speed_scale = scale
            st = a.tick(self.t)
            self.track[rid].append((st.x, st.y, self.t))
            if rid not in self.mute:
                heard.append(st)
                self.fm.on_status(st, self.t)
        for st in heard:  # the others hear it too, at their next tick
            for rid, a in self.agents.items():
                if rid != st.id and rid not in self.dead | self.mute:
                    a.on_status(st, self.t)
        if self._ticks % round(self.period / self.dt) == 0:
            d = self.fm.step(self.t)
            self.notes += d.notes
            for rec in d.gates:  # before the legs, as the planner node publishes them
                self.gates_sent += 1
                self.links_sent += len(rec.links)
                if rec.robot_id in self.agents and rec.robot_id not in self.dead | self.mute:
                    self.agents[rec.robot_id].on_gate(rec)
            for leg in d.legs:
                self.legs[leg.robot_id].append(leg)
                if leg.robot_id not in self.dead | self.mute:
                    try:
                        self.agents[leg.robot_id].on_path(leg.relative(), leg.t0, leg.path_id)
                    except ValueError as exc:
                        self.notes.append(f"rejected: {exc}")
            for ev in d.events:
                self.events.append(ev)
                for rid, a in self.agents.items():
                    if rid not in self.dead | self.mute:
                        a.on_event(ev)

    def gap(self):
        return min_separation(self.driven())


def random_slowdowns(ids, seed, horizon_s=300.0, n=6, scale=(0.0, 0.3), length=(10.0, 20.0)):
    """``n`` random windows in which a random robot drives at a random fraction of its speed (0:
    halted), for 10-20 s each, within the first ``horizon_s``."""
    rng = random.Random(seed)
    out = []
    for _ in range(n):
        t0 = rng.uniform(5.0, horizon_s)
        out.append((rng.choice(sorted(ids)), t0, t0 + rng.uniform(*length), rng.choice([0.0, rng.uniform(*scale)])))
    return out
