"""A behaviour robot's state on the wire (fleet_planner/fleet/wire.py, robot_status.behavior):
the retreat wave travels with it, and statuses from before the field still parse."""
from __future__ import annotations

import json

import pytest

from fleet_planner.behavior import Behavior, RobotView
from fleet_planner.fleet.wire import behavior_state, view_of_status
from msg_schemas.records import RecordError, RobotStatus


def _status(state: dict) -> RobotStatus:
    return RobotStatus(id="r1", kind="cargo", x=1.0, y=2.0, yaw=0.0, vx=0.0, vy=0.0, battery=1.0,
                       mode="driving", progress=0.0, stamp=5.0, radius=0.3, behavior=state)


def test_the_retreat_wave_goes_over_the_wire_and_back():
    view = RobotView("r1", (1.0, 2.0), 0.3, Behavior.FOLLOW_WAYPOINT, (2.0, 2.0), 4.0, 1.0, "S1", None, False,
                     None, None, (12.5, "r7"))
    back = view_of_status(RobotStatus.from_json(_status(behavior_state(view)).to_json()))
    assert back.retreat == (12.5, "r7")
    assert view_of_status(RobotStatus.from_json(_status(behavior_state(
        RobotView("r1", (1.0, 2.0), 0.3, remaining=0.0, straight=0.0))).to_json())).retreat is None


def test_a_status_without_the_retreat_key_parses_and_a_bad_one_is_rejected_naming_the_field():
    state = behavior_state(RobotView("r1", (1.0, 2.0), 0.3, next_waypoint=(2.0, 2.0), remaining=1.0,
                                     straight=1.0))
    old = json.loads(_status(state).to_json())
    del old["behavior"]["retreat"]             # a status sent before the field
    assert view_of_status(RobotStatus.from_json(json.dumps(old))).retreat is None
    bad = json.loads(_status(state).to_json())
    bad["behavior"]["retreat"] = {"since": 1.0}
    with pytest.raises(RecordError) as err:
        RobotStatus.from_json(json.dumps(bad))
    assert "behavior.retreat.by" in str(err.value)
