#!/usr/bin/env python3
"""Compute ARMO's road map (fleet_planner/roadmap.py) for the default warehouse of config/ and the
demand of a seeded delivery sequence (load at chutes, unload at storing sites), write it as a lanes
file and draw it.

    .venv/bin/python bench/make_lanes.py [--out config/lanes_warehouse.yaml] [--plot out/lanes_warehouse.png]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from fleet_planner.delivery import ROBOT_RADIUS, warehouse_problem  # noqa: E402
from fleet_planner.roadmap import armo_roadmap, demand_of, plot_roadmap, save_lanes  # noqa: E402
from fleet_planner.warehouse import load_warehouse  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=REPO / "config" / "lanes_warehouse.yaml")
    p.add_argument("--plot", type=Path, default=REPO / "out" / "lanes_warehouse.png")
    p.add_argument("--deliveries", type=int, default=300)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    problem = warehouse_problem(load_warehouse(), 1, a.deliveries, a.seed)
    lanes, info = armo_roadmap(problem.grid, ROBOT_RADIUS, problem.stations,
                               demand_of(problem.deliveries, list(problem.stations)), name="warehouse-armo")
    print(info)
    save_lanes(lanes, problem.grid, a.out,
               f"ARMO's road map of the default warehouse (config/warehouse.yaml) for discs of radius "
               f"{ROBOT_RADIUS:.3f} m,\nfrom the demand of {a.deliveries} seeded deliveries (seed {a.seed}): "
               f"bench/make_lanes.py. One-way lanes, cells (col, row);\nevery move no lane restricts is two-way.")
    plot_roadmap(problem.grid, lanes, a.plot, problem.stations, "ARMO road map, default warehouse")
    print(f"wrote {a.out} and {a.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
