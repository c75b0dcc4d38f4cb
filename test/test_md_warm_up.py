"""md's warm-up (issue 8): once ``MDPlanner.warm_up`` has run (the fleet manager runs it when it is set
up), legs compile or load no numba kernel, so no leg's budget pays for it (a cold cache compiled for
seconds inside the first legs' budgets); a one-shot plan warms the dense solver's kernels too, before
its budget starts. Judged in a fresh process, where no kernel is loaded yet: the kernels'
signatures after the warm-ups must be all that legs and a plan that hands over to the dense solver use."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("numba")

REPO = Path(__file__).resolve().parent.parent

CHILD = textwrap.dedent("""
    import importlib, json, sys
    import numpy as np
    from numba.core.registry import CPUDispatcher
    from fleet_planner.model import RobotSpec
    from fleet_planner.paths import PathFinder
    from fleet_planner.planners import get_planner
    from fleet_planner.warehouse import generate_warehouse

    MODULES = ["fleet_planner._path_kernels", "fleet_planner._md_kernels", "fleet_planner.planners.crowd_kernels",
               "fleet_planner.planners.crowd_st", "fleet_planner.planners.crowd_sipp"]

    def signatures():
        out = set()
        for name in MODULES:
            for key, fn in vars(importlib.import_module(name)).items():
                if isinstance(fn, CPUDispatcher):
                    out |= {f"{name}.{key}{sig}" for sig in fn.signatures}
        return out

    md = get_planner("md")
    warm = sys.argv[1] == "warm"
    if warm:
        md.warm_up()
    before = signatures()
    # 1-cell aisles, 2000+ traversable cells (landmarks), 60 robots
    grid = generate_warehouse(8, 12, 10, 2, 1, 1.0, "warm-up test").grid
    free = PathFinder(grid, 0.45).free
    rows, cols = np.nonzero(free)
    rng = np.random.default_rng(0)
    cells = rng.permutation(len(rows))
    robots = [RobotSpec(f"r{i}", float(rng.uniform(0.35, 0.45)), float(rng.uniform(0.7, 1.0)),
                        grid.centre(int(cols[s]), int(rows[s])), grid.centre(int(cols[g]), int(rows[g])))
              for i, (s, g) in enumerate(zip(cells[:60], cells[60:120]))]
    # legs: 20 robots of md's own plan drive, 2 more get legs round them
    own = get_planner("md", crowded=False, compare_above=None, fallback=None).plan(grid, robots[:20])
    md.plan_incremental(grid, robots[20:22], own.paths, 1.0)
    legs = signatures() - before
    # a one-shot plan of all 60 (crowded: the dense solver plans; plan() warms its kernels itself)
    if warm:
        get_planner("dense").warm_up()
    before = signatures()
    plan = md.plan(grid, robots)
    print(json.dumps({"dense": "fallback" in plan.info, "legs": sorted(legs), "plan": sorted(signatures() - before)}))
""")


def _new_signatures(mode: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True, env=env,
                         cwd=REPO, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_after_the_warm_up_planning_loads_no_compiled_kernel():
    found = _new_signatures("warm")
    assert found["dense"], "the one-shot plan should have been the dense solver's (its kernels are warmed too)"
    assert found["legs"] == [] and found["plan"] == []
    # the control: without the warm-ups, the same legs and plan load kernels of all three kinds
    cold = _new_signatures("cold")
    for module in ("_path_kernels.astar", "_md_kernels.segment_pieces"):
        assert any(module in s for s in cold["legs"]), module
    assert any("crowd_kernels." in s for s in cold["plan"])
