"""The planner interface and the registry: every variant registered once, built by name."""
from __future__ import annotations

import pytest

from fleet_planner import planners
from fleet_planner.grid import GridMap
from fleet_planner.model import RobotSpec
from fleet_planner.planners import Planner, get_planner, planner_names, planner_summary
from fleet_planner.planners.md import MDPlanner
from fleet_planner.planners.prior import PriorPlanner


def test_the_registered_variants():
    assert planner_names() == ["md", "md-box", "prior", "md-departure", "md-holds", "md-routes", "crowd", "dense"]
    assert all(planner_summary(name) for name in planner_names())


def test_a_variant_is_its_class_with_its_options_and_the_callers():
    md, box, prior = get_planner("md"), get_planner("md-box"), get_planner("prior")
    assert type(md) is MDPlanner and md.mode == "exact"
    assert type(box) is MDPlanner and box.mode == "box"
    assert type(prior) is PriorPlanner
    merged = get_planner("md-box", margin=0.05, order="given")
    assert (merged.mode, merged.margin, merged.order) == ("box", 0.05, "given")
    assert get_planner("md-box", mode="box").mode == "box"
    assert get_planner("md", mode="box").mode == "box"


def test_a_variant_refuses_options_that_contradict_it():
    with pytest.raises(ValueError, match=r"planner 'md-box': mode is 'box' in this variant \(got mode='exact'\)"):
        get_planner("md-box", mode="exact")
    with pytest.raises(ValueError, match=r"unknown planner 'nope'; choose one of md, md-box, prior, md-departure, "
                                         r"md-holds, md-routes, crowd, dense"):
        get_planner("nope")
    with pytest.raises(TypeError):
        get_planner("prior", mode="box")


def test_a_name_is_registered_once(monkeypatch):
    monkeypatch.setattr(planners, "_REGISTRY", dict(planners._REGISTRY))
    with pytest.raises(ValueError, match="'md' is registered already"):
        planners.register("md", "fleet_planner.planners.md:MDPlanner")
    planners.register("md-given", "fleet_planner.planners.md:MDPlanner", "md in the listed order", order="given")
    assert get_planner("md-given").order == "given"


def test_both_methods_are_part_of_the_interface():
    assert Planner.__abstractmethods__ == {"plan", "plan_incremental"}

    class OneShotOnly(Planner):
        name = "one-shot"

        def plan(self, grid, robots, progress=None):
            raise NotImplementedError

    with pytest.raises(TypeError, match="plan_incremental"):
        OneShotOnly()  # type: ignore[abstract]


@pytest.mark.parametrize("name", planner_names())
def test_every_variant_plans_a_leg_around_a_driven_trajectory(name):
    """The same body over every variant: a first plan, then a new leg around it from t0."""
    grid = GridMap.from_rows(["." * 8] * 3)
    first = get_planner(name).plan(grid, [RobotSpec("a", 0.4, 1.0, (0.5, 1.5), (7.5, 1.5))])
    leg = get_planner(name).plan_incremental(grid, [RobotSpec("b", 0.4, 1.0, (7.5, 0.5), (0.5, 0.5))],
                                             first.paths, 1.0)
    assert [p.robot_id for p in leg] == ["b"]
    assert tuple(leg[0].waypoints[0]) == (7.5, 0.5, 1.0)
    assert tuple(leg[0].waypoints[-1, :2]) == (0.5, 0.5)


def test_md_keeps_its_path_finders_itself_not_on_the_map():
    grid = GridMap.from_rows(["." * 8] * 3)
    robots = [RobotSpec("a", 0.4, 1.0, (0.5, 1.5), (7.5, 1.5)), RobotSpec("b", 0.3, 1.0, (7.5, 0.5), (0.5, 0.5))]
    planner = get_planner("md", order="parking")
    first = planner.plan(grid, robots)
    assert not any(key.startswith("_md") for key in vars(grid))
    finders = planner._finders.of(grid)
    again = planner.plan(GridMap(grid.blocked.copy(), grid.resolution), robots)   # same map, another object
    assert planner._finders.of(grid) is finders
    assert [p.waypoints.tolist() for p in again.paths] == [p.waypoints.tolist() for p in first.paths]
    other = GridMap.from_rows(["." * 8] * 4)
    assert planner._finders.of(other) is not finders
