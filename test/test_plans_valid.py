"""Property: every plan a planner returns is valid, judged by the independent checker.

Random scenarios (hypothesis): a small grid with random obstacles, 2-8 robots of different radii,
speeds and accelerations on distinct free cells. A planner may refuse (PlanningError naming robots), never
return an invalid plan. The same body runs over every planner and collision mode.
"""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap
from fleet_planner.model import PlanningError, RobotSpec
from fleet_planner.planners import get_planner, planner_names


@st.composite
def scenarios(draw):
    w, h = draw(st.integers(6, 12)), draw(st.integers(6, 12))
    density = draw(st.sampled_from([0.0, 0.1, 0.2]))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    blocked = rng.random((h, w)) < density
    free = [(c, r) for r in range(h) for c in range(w) if not blocked[r, c]]
    n = draw(st.integers(2, min(8, len(free) // 2)))
    cells = rng.permutation(len(free))[: 2 * n]
    grid = GridMap(blocked, 1.0, "random")
    ramps = draw(st.booleans())   # robots that accelerate (md plans ramps) or change speed at once
    robots = [RobotSpec(f"r{k}", float(rng.uniform(0.25, 0.45)), float(rng.uniform(0.5, 1.5)),
                        grid.centre(*free[cells[2 * k]]), grid.centre(*free[cells[2 * k + 1]]),
                        max_accel=float(rng.uniform(0.3, 1.0)) if ramps else None)
              for k in range(n)]
    return grid, robots


@pytest.mark.parametrize("name", planner_names())
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=scenarios())
def test_every_plan_is_valid(name, case):
    grid, robots = case
    try:
        plan = get_planner(name).plan(grid, robots)
    except PlanningError as err:
        assert err.failures and set(err.failures) <= {r.id for r in robots}
        return
    assert check_plan(grid, robots, plan) == []


def test_exact_mode_never_delays_more_than_boxes_on_a_shared_aisle():
    """Two robots going the same way down one aisle: boxes make the aisle exclusive, the exact
    regions let the second follow at a safe distance."""
    grid = GridMap.from_rows(["." * 30])
    robots = [RobotSpec("lead", 0.4, 1.0, (2.5, 0.5), (29.5, 0.5)),
              RobotSpec("follow", 0.4, 1.0, (0.5, 0.5), (27.5, 0.5))]
    exact = get_planner("md", mode="exact").plan(grid, robots)
    box = get_planner("md-box").plan(grid, robots)
    for plan in (exact, box):
        assert check_plan(grid, robots, plan) == []
    d_exact = exact.by_id()["follow"].start_time
    d_box = box.by_id()["follow"].start_time
    assert d_exact == pytest.approx(0.0)
    assert d_box > 20.0   # waits until the leader has left the whole shared stretch
