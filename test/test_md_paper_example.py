"""Paper 001, Sections 3.3 and 4: three robots, radii 5 m, speeds 1, 2, 1 m/s, priority 1-2-3.

Geometry (ours; the paper gives only a sketch), R = r_i + r_j = 10 m:
  robot 1: P1 (0, 0)   -> P4 (100, 0)                               v = 1, length 100
  robot 2: P2 (50, -90) -> P5 (50, 60)                              v = 2, length 150
  robot 3: P3 (20, -12) -> P6 (20, 15) -> P7 (80, 15) -> P8 (80, -12)  v = 1, legs 27 + 60 + 27

Regions worked out by hand (a robot is "in" a region while its disc is within 10 m of the other's path):
  (2,1,1): robot 1 at x in (40, 60)      -> T1 = 40, T4 = 60
           robot 2 at y in (-10, 10)     -> travelled (80, 100)  -> T2 = d2 + 40, T3 = d2 + 50
  (3,1,1): robot 1 at x in (10, 30)      -> T1 = 10, T4 = 30
           robot 3 on leg 1, y in (-10, 10) -> travelled (2, 22)   -> T2 = d3 + 2, T3 = d3 + 22
  (3,1,2): robot 1 at x in (70, 90)      -> T1 = 70, T4 = 90
           robot 3 on leg 3, y in (10, -10) -> travelled (92, 112) -> T2 = d3 + 92, T3 = d3 + 112
  (3,2,1): robot 2 at y in (5, 25), travelled (95, 115) -> T1 = d2 + 47.5, T4 = d2 + 57.5
           robot 3 on leg 2, x in (40, 60) -> travelled (47, 67)  -> T2 = d3 + 47, T3 = d3 + 67

Delays (Eq. 3):
  robot 2, d2 = 0: (2,1,1) M = 50 - 40 = 10 > 0, D = 60 - 40 = 20 > 0 -> d2 = 20; then D = 0: safe.
  robot 3, d3 = 0: (3,1,1) M = 22 - 10 = 12, D = 30 - 2 = 28       -> dangerous
                   (3,1,2) M = 112 - 70 = 42, D = 90 - 92 = -2      -> safe
                   (3,2,1) T1 = 67.5, T4 = 77.5: M = 67 - 67.5 = -0.5 -> safe      => d3 = 28
           d3 = 28: (3,1,1) D = 30 - 30 = 0 safe; (3,1,2) D = 90 - 120 < 0 safe;
                   (3,2,1) M = 95 - 67.5 = 27.5, D = 77.5 - 75 = 2.5 -> dangerous  => d3 = 30.5
           d3 = 30.5: every link has M <= 0 or D <= 0.
So the delay made a safe link dangerous, exactly the case the paper's iteration exists for.
"""
import numpy as np
import pytest

from fleet_planner.model import timed_path_from_polyline
from fleet_planner.planners.md import schedule_paths

IDS = ["1", "2", "3"]
PATHS = [np.array([[0, 0], [100, 0]], float),
         np.array([[50, -90], [50, 60]], float),
         np.array([[20, -12], [20, 15], [80, 15], [80, -12]], float)]
RADII = [5.0, 5.0, 5.0]
SPEEDS = [1.0, 2.0, 1.0]


@pytest.fixture(scope="module")
def result():
    return schedule_paths(IDS, PATHS, RADII, SPEEDS)


def test_link_set_is_the_papers(result):
    assert {link.paper_tuple for link in result.network.links} == {
        ("2", "1", 1), ("3", "1", 1), ("3", "1", 2), ("3", "2", 1)}


def test_delays_match_hand_computation(result):
    assert result.blocked is None
    assert result.delays == pytest.approx([0.0, 20.0, 30.5])
    assert result.network.delay == pytest.approx({"1": 0.0, "2": 20.0, "3": 30.5})
    assert result.network.travel == pytest.approx({"1": 100.0, "2": 75.0, "3": 114.0})


def test_every_link_is_safe_after_planning(result):
    for link in result.network.links:
        assert link.M <= 1e-9 or link.D <= 1e-9, link


def test_boxes_match_hand_computation(result):
    boxes = {link.paper_tuple: (link.ks, link.ke, link.ls, link.le) for link in result.network.links}
    assert boxes[("2", "1", 1)] == pytest.approx((40, 60, 80, 100))
    assert boxes[("3", "1", 1)] == pytest.approx((10, 30, 2, 22))
    assert boxes[("3", "1", 2)] == pytest.approx((70, 90, 92, 112))
    assert boxes[("3", "2", 1)] == pytest.approx((67.5, 77.5, 47, 67))


def test_undelayed_paths_collide_and_delayed_ones_do_not(result):
    """The delays matter: checked by brute-force sampling here, independently of the planner."""
    def min_gap(delays):
        tps = [timed_path_from_polyline(i, r, p, v, d)
               for i, r, p, v, d in zip(IDS, RADII, PATHS, SPEEDS, delays)]
        ts = np.linspace(0, 200, 40001)
        pos = np.array([[tp.position(t) for t in ts] for tp in tps])
        gaps = [np.hypot(*(pos[a] - pos[b]).T).min() - 10 for a, b in ((0, 1), (0, 2), (1, 2))]
        return min(gaps)

    assert min_gap([0, 0, 0]) < -5
    assert min_gap(result.delays) >= -1e-6


def test_parked_goal_in_the_way_is_reported_not_ignored():
    """Robot 2 (lower) must cross robot 1's goal after robot 1 has parked there: no delay helps."""
    paths = [np.array([[0, 0], [10, 0]], float), np.array([[10, -10], [10, 10]], float)]
    res = schedule_paths(["a", "b"], paths, [0.5, 0.5], [1.0, 0.1])
    assert res.blocked is not None
    assert (res.blocked.j, res.blocked.blocker) == (1, 0)
    assert "goal" in res.blocked.why
