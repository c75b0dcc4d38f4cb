"""The seams of the fleet package: the coordination modes looked up by name (both ends take a name
or a strategy object) and the planner handed to the fleet manager instead of built in."""
import pytest

from fleet_planner.fleet import (
    COORDINATION,
    BehaviorCoordination,
    CentralCoordination,
    DispatchParams,
    FleetManager,
    RobotAgent,
    coordination_names,
    get_coordination,
    manager,
)
from fleet_planner.planners.md import MDPlanner
from fleet_planner.robots import RobotModel, load_kinds
from fleet_planner.warehouse import generate_warehouse
from msg_schemas.records import RobotStatus

CARGO = load_kinds()["cargo"]
SMALL = generate_warehouse(2, 2, 8, 2, 4, 0.5, "small", chutes=2, chargers=4)


def idle(rid="r1", x=2.25, y=10.75):
    return RobotStatus(id=rid, kind="cargo", x=x, y=y, yaw=0.0, vx=0.0, vy=0.0, battery=1.0, mode="idle",
                       progress=1.0, stamp=0.0, radius=CARGO.radius)


def test_the_modes_are_looked_up_by_name_and_both_ends_take_a_name_or_a_strategy():
    assert COORDINATION == ("central", "behavior") and coordination_names() == list(COORDINATION)
    assert isinstance(get_coordination("central"), CentralCoordination)
    assert isinstance(get_coordination("behavior"), BehaviorCoordination)
    mode = BehaviorCoordination()
    assert get_coordination(mode) is mode
    fm = FleetManager(SMALL, {"cargo": CARGO}, coordination=mode)
    agent = RobotAgent(RobotModel("r1", CARGO, 2.25, 10.75), SMALL, mode)
    assert fm.strategy is mode and fm.coordination == "behavior" == agent.coordination
    assert agent.controller is not None and agent.strategy.exchanges_wait_messages
    central = RobotAgent(RobotModel("r2", CARGO, 4.25, 10.75), SMALL)
    assert central.coordination == "central" and central.controller is None and central.waits_for is None
    for bad in ("swarm", None):
        with pytest.raises(ValueError, match="coordination: .* is not one of central, behavior"):
            get_coordination(bad)
        with pytest.raises(ValueError, match="coordination: .* is not one of central, behavior"):
            RobotAgent(RobotModel("r3", CARGO, 6.25, 10.75), SMALL, bad)


class CountingPlanner:
    """A planner handed in: the (M,D) planner, counting its calls."""

    def __init__(self, margin):
        self.inner, self.calls = MDPlanner(margin=margin, leg_lattice=manager.LIVE_LEG_LATTICE), 0

    def plan_incremental(self, grid, robots, fixed, t0):
        self.calls += 1
        return self.inner.plan_incremental(grid, robots, fixed, t0)


def test_the_manager_plans_central_legs_with_the_planner_it_is_given():
    default = FleetManager(SMALL, {"cargo": CARGO})
    assert isinstance(default.planner, MDPlanner) and default.planner.margin == default.margin
    assert default.planner.leg_lattice == manager.LIVE_LEG_LATTICE   # the live fleet's legs: the map's cells
    planner = CountingPlanner(default.margin)
    fm = FleetManager(SMALL, {"cargo": CARGO}, DispatchParams(), planner=planner)
    assert fm.planner is planner
    for m in (fm, default):
        m.on_status(idle(), 0.0)
        m.submit({"schema": "fleet/task@1", "id": "J1", "pick": "chute_1", "place": "B01-01"}, 0.0)
    [leg] = fm.step(0.5).legs
    [same] = default.step(0.5).legs
    assert planner.calls == 1 and (leg.path.waypoints == same.path.waypoints).all()
    behavior = FleetManager(SMALL, {"cargo": CARGO}, coordination="behavior", planner=planner)
    behavior.on_status(idle(), 0.0)
    behavior.submit({"schema": "fleet/task@1", "id": "J1", "pick": "chute_1", "place": "B01-01"}, 0.0)
    assert len(behavior.step(0.5).legs) == 1 and planner.calls == 1  # goals only: no planner
