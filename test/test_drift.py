"""The planner's picture of the fleet does not drift from the fleet (issue 9, deliverable 4): a
leg a robot could not take is never assumed driven - the robot is planned again from where its
status says it stands, and the legs of others, planned around the leg it never took, re-plan if
they pass where it stands."""
import numpy as np
from test_dispatch import PARKING, manager, status

from fleet_planner.fleet.legs import Leg
from fleet_planner.fleet.state import Target
from fleet_planner.model import TimedPath


def test_legs_passing_a_robot_whose_leg_was_refused_re_plan_around_where_it_stands():
    fm = manager()
    (ax, ay), (bx, by) = PARKING[0], PARKING[2]
    now = 10.0
    fm.on_status(status("a", "cargo", ax, ay, stamp=now), now)
    fm.on_status(status("b", "cargo", bx, by, stamp=now, mode="driving", path_id=9_000_000_000, progress=0.01),
                 now)
    a, b = fm.robots["a"], fm.robots["b"]
    # the planner sent a leg off to the north (never taken), and b's leg west along the wall past a's spot
    a.leg = Leg("a", TimedPath("a", a.radius, np.array([[ax, ay, 9.5], [ax, ay - 3.0, 14.0]])), 9_500_000_000,
                "park", "north")
    a.target, a.last_path_id = Target("park", "north", (ax, ay - 3.0)), a.leg.path_id
    b.leg = Leg("b", TimedPath("b", b.radius, np.array([[bx, by, 9.0], [ax - 2.0, by, 9.0 + (bx - ax + 2.0)]])),
                9_000_000_000, "park", "west")
    b.target, b.last_path_id = Target("park", "west", (ax - 2.0, by)), b.leg.path_id
    assert b.on_leg
    fm.on_status(status("a", "cargo", ax, ay, stamp=now + 0.1, rejected_path_id=a.leg.path_id), now + 0.1)
    d = fm.step(now + 0.1)
    assert any("could not take leg" in n for n in d.notes)
    assert a.leg is None or a.leg.path_id != 9_500_000_000            # a is planned again from where it is
    replanned = b.replan or any(leg.robot_id == "b" for leg in d.legs)
    assert replanned                                                  # b's way runs through a: b re-plans
