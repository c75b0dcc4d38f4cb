"""The ways the BBMRCA fleet stalled in the delivery benchmark (issue 13), each on a constructed
scene that stays stuck without its fix and completes with it (paper 002, Sun, Kleiner & Nebel,
"Behavior-based Multi-Robot Collision Avoidance", sections IV.A-IV.C; the fixes are ours where
the paper leaves the case open, see the "Interpretation" notes in fleet_planner/behavior)."""
from __future__ import annotations

import numpy as np

from fleet_planner.behavior import Behavior, BehaviorFleet, BehaviorParams
from fleet_planner.grid import GridMap
from fleet_planner.model import RobotSpec


def _drive(fleet: BehaviorFleet, limit_s: float, dt: float = 0.1) -> float:
    """Step until every robot arrived or ``limit_s``; the smallest gap between discs seen."""
    radii = np.array([fleet.view(i).radius for i in fleet.ids])
    need = radii[:, None] + radii[None, :]
    np.fill_diagonal(need, -np.inf)
    smallest = np.inf
    while fleet.time < limit_s and not all(fleet.arrived(i) for i in fleet.ids):
        fleet.step(dt)
        p = fleet.positions()
        gap = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1]) - need
        np.fill_diagonal(gap, np.inf)
        smallest = min(smallest, float(gap.min()))
        assert all(fleet.grid.disc_is_free(x, y, r) for (x, y), r in zip(p, radii)), f"t={fleet.time}"
    return smallest


def test_a_docking_robot_pushed_behind_a_wall_corner_replans():
    """Dock keeps moving (IV.B.5) but its straight way to the next waypoint may graze a wall
    corner once it was pushed off its path (WaitForDocking backs off): it must re-plan from where
    it is, not press against the corner for ever."""
    grid = GridMap.from_rows([".....",
                              ".@@..",
                              "....."])
    params = BehaviorParams(dock_region=3.0, dock_give_up=3.0)
    fleet = BehaviorFleet(grid, [RobotSpec("r0", 0.35, 1.0, (0.5, 2.5), (0.5, 2.5))], params)
    fleet.assign("r0", (2.5, 0.5), station="S")
    fleet.step(0.1)
    robot = fleet.controller("r0")
    assert robot.behavior is Behavior.DOCK and robot.holds is not None
    assert robot.path is not None and np.allclose(robot.path[robot.wp], (0.5, 0.5))
    robot.pos = np.array([2.5, 2.5])   # pushed off its path: the way to (0.5, 0.5) crosses the wall
    assert not grid.disc_is_free(1.5, 1.5, 0.35)
    _drive(fleet, limit_s=20.0)
    assert fleet.arrived("r0")
    assert np.allclose(fleet.positions()[0], (2.5, 0.5))
