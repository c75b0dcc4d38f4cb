"""The demo's jobs: random pick-and-place tasks that some robot of the fleet can do."""
from __future__ import annotations

import random
from collections.abc import Mapping, Sequence

from fleet_planner.fleet import FleetMember
from fleet_planner.model import ROBOT_KINDS
from fleet_planner.robots import RobotKind
from fleet_planner.warehouse import Warehouse
from msg_schemas.records import Task

#: task events after which a job is over
TERMINAL = ("done", "failed", "rejected", "cancelled")


def random_jobs(warehouse: Warehouse, kinds: Mapping[str, RobotKind], members: Sequence[FleetMember], count: int,
                seed: int) -> list[Task]:
    """``count`` jobs between random chutes and address tags, each doable by some robot of the fleet:
    its needs are those of a random kind of the fleet's (each kind alike, however many robots it has),
    its payload within that kind's. Fleets with the same kinds get the same jobs, whatever their
    size: one job stream to compare fleets of 9 and 30 robots by."""
    rng = random.Random(seed)
    present = {m.kind for m in members}
    names = [k for k in ROBOT_KINDS if k in present] + sorted(present - set(ROBOT_KINDS))
    chutes = [s.name for s in warehouse.stations_of("chute")]
    tags = [t for s in warehouse.stations_of("storage") for t in s.tags]
    jobs = []
    for i in range(count):
        kind = kinds[names[rng.randrange(len(names))]]
        needs = tuple(sorted(c for c in kind.capabilities if rng.random() < 0.7))
        jobs.append(Task(id=f"job_{i + 1:03d}", pick=rng.choice(chutes), place=rng.choice(tags), needs=needs,
                         payload_kg=round(rng.uniform(0.0, min(25.0, kind.payload_kg)), 1)))
    return jobs
