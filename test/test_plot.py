"""Plan pictures: the collision map drawn under each TLVSTC, the schedule, and that plots are written.

The collision map is the independent witness of the TLVSTC chart: computed from the timed paths
alone, it must match a hand-computed crossing and a valid plan's curve must stay out of it.
"""
import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from fleet_planner.grid import GridMap  # noqa: E402
from fleet_planner.model import Network, Plan, RobotSpec, TimedPath, timed_path_from_polyline  # noqa: E402
from fleet_planner.planners import get_planner  # noqa: E402
from fleet_planner.plot import (  # noqa: E402
    MAX_GANTT_ROWS,
    blocker_map,
    collision_map,
    plot_plan,
    plot_schedule,
    positions_at,
    schedule_rows,
    travelled_length,
    waiting_time,
)

PNG = b"\x89PNG\r\n\x1a\n"


# ------------------------------------------------------------------------------------------------
# the collision map against a hand computation
# ------------------------------------------------------------------------------------------------
def crossing_paths() -> dict[str, TimedPath]:
    """j drives (0,0) -> (10,0) at 1 m/s from t = 0, so it is at x = s whatever t; radii 0.5, reach 1.

    * cross: drives (5,-5) -> (5,5) at 1 m/s: at (5, t-5), so j at s collides iff |(s-5, t-5)| < 1.
    * leaver: parked on j's path at (2,0) until t = 4, then drives south: |(s-2, max(t-4, 0))| < 1.
    * parker: drives (8,-5) -> (8,0), arriving at t = 5, parked there for ever: |(s-8, min(t,5)-5)| < 1.
    * lower: parked on j's path at (6,0) for ever, but not a higher robot: never counts.
    """
    return {
        "j": TimedPath("j", 0.5, [[0, 0, 0], [10, 0, 10]]),
        "cross": TimedPath("cross", 0.5, [[5, -5, 0], [5, 5, 10]]),
        "leaver": TimedPath("leaver", 0.5, [[2, 0, 4], [2, -10, 14]]),
        "parker": TimedPath("parker", 0.5, [[8, -5, 0], [8, 0, 5]]),
        "lower": TimedPath("lower", 0.5, [[6, 0, 0]]),
    }


def test_positions_follow_timed_path_semantics():
    path = TimedPath("a", 0.5, [[2, 0, 4], [2, -10, 14], [3, -10, 15]])
    times = np.array([0.0, 4.0, 5.5, 14.0, 14.5, 15.0, 99.0])
    assert positions_at(path, times) == pytest.approx(np.array([path.position(t) for t in times]))


def test_collision_map_of_a_crossing_matches_hand_computation():
    paths = crossing_paths()
    higher = ["cross", "leaver", "parker"]
    t = np.arange(0.05, 20.0, 0.1)
    s = np.arange(0.05, 10.0, 0.1)
    T, S = np.meshgrid(t, s)
    dist = {"cross": np.hypot(S - 5, T - 5),
            "leaver": np.hypot(S - 2, np.maximum(T - 4, 0)),
            "parker": np.hypot(S - 8, np.minimum(T, 5) - 5)}
    expected = (dist["cross"] < 1) | (dist["leaver"] < 1) | (dist["parker"] < 1)
    clear_cut = np.all([np.abs(d - 1) > 1e-6 for d in dist.values()], axis=0)

    got = collision_map(list(paths.values()), "j", higher, t, s)
    assert got.shape == (len(s), len(t))
    assert np.array_equal(got[clear_cut], expected[clear_cut])

    def pixel(tt: float, ss: float) -> tuple[int, int]:
        return int(np.argmin(np.abs(s - ss))), int(np.argmin(np.abs(t - tt)))

    assert got[pixel(5.05, 5.05)] and got[pixel(5.55, 4.45)]          # where cross passes j's path
    assert not got[pixel(5.05, 6.55)] and not got[pixel(3.05, 5.05)]  # just beside it
    assert got[pixel(0.05, 2.05)] and got[pixel(4.35, 2.05)]          # leaver still (nearly) parked
    assert not got[pixel(5.55, 2.05)]                                 # ... and gone
    assert got[pixel(19.95, 8.05)] and not got[pixel(2.05, 8.05)]     # parker parks there for ever
    assert not got[pixel(0.05, 6.05)]                           # lower robots do not count
    who = blocker_map(paths, "j", higher, t, s)
    assert who[pixel(5.05, 5.05)] == 0 and who[pixel(0.05, 2.05)] == 1 and who[pixel(19.95, 8.05)] == 2
    assert who[pixel(10.05, 0.55)] == -1


def test_collision_map_chunks_give_the_same_answer(monkeypatch):
    import fleet_planner.plot as plot

    paths = crossing_paths()
    t, s = np.linspace(0, 20, 97), np.linspace(0, 10, 53)
    whole = collision_map(paths, "j", ["cross", "leaver", "parker"], t, s)
    monkeypatch.setattr(plot, "_CHUNK", 7 * len(s))
    assert np.array_equal(collision_map(paths, "j", ["cross", "leaver", "parker"], t, s), whole)
    assert whole.any()


# ------------------------------------------------------------------------------------------------
# a valid md plan's curves stay out of their collision maps
# ------------------------------------------------------------------------------------------------
OPEN = GridMap.from_rows(["." * 11] * 11)
CROSS = [RobotSpec("a", 0.4, 1.0, (0.5, 5.5), (10.5, 5.5)),
         RobotSpec("b", 0.4, 1.0, (5.5, 0.5), (5.5, 10.5)),
         RobotSpec("c", 0.35, 0.8, (10.5, 2.5), (0.5, 2.5))]


def _curve_pixels(path: TimedPath, t: np.ndarray, s_step: float, rows: int, shift: float = 0.0):
    times, length = travelled_length(path)
    s_at = np.interp(t + shift, times, length)
    return np.clip((s_at / s_step).astype(int), 0, rows - 1), np.arange(len(t))


def _eroded(mask: np.ndarray) -> np.ndarray:
    """True only where the pixel and its eight neighbours are all True (one-pixel tolerance)."""
    padded = np.pad(mask, 1, constant_values=True)
    out = np.ones_like(mask)
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            out &= padded[dr:dr + mask.shape[0], dc:dc + mask.shape[1]]
    return out


@pytest.mark.parametrize("mode", ["exact", "box"])
def test_valid_md_plan_curves_never_enter_their_collision_maps(mode):
    plan = get_planner("md", mode=mode, holds="none").plan(OPEN, CROSS)   # departure delays (md v2 holds en route)
    network = plan.network
    assert network is not None
    paths = plan.by_id()
    delayed = 0
    for rank, rid in enumerate(network.priority):
        path = paths[rid]
        t = np.linspace(0, plan.makespan + 5, 600)
        s_step = path.length / 300
        s = (np.arange(300) + 0.5) * s_step
        deep = _eroded(collision_map(paths, rid, network.priority[:rank], t, s))
        rows, cols = _curve_pixels(path, t, s_step, len(s))
        assert not deep[rows, cols].any(), f"{rid}'s curve enters its collision map"
        if path.start_time > 0:
            # the test can fail: the same curve without the delay runs into the map
            delayed += 1
            rows, cols = _curve_pixels(path, t, s_step, len(s), shift=path.start_time)
            assert deep[rows, cols].any(), f"{rid} was delayed for nothing"
    assert delayed >= 1


# ------------------------------------------------------------------------------------------------
# the schedule and the pictures
# ------------------------------------------------------------------------------------------------
def test_waiting_time_counts_the_delay_and_stops_until_arrival():
    path = TimedPath("a", 0.3, [[0, 0, 0], [0, 0, 2], [1, 0, 3], [1, 0, 5], [2, 0, 6], [2, 0, 9]])
    assert waiting_time(path) == pytest.approx(4.0)
    assert waiting_time(timed_path_from_polyline("b", 0.3, [(0, 0), (3, 4)], 1.0, departure=2.5)) == pytest.approx(2.5)


def test_schedule_rows_of_a_large_fleet_are_the_most_delayed_in_priority_order():
    n = MAX_GANTT_ROWS + 10
    paths = [timed_path_from_polyline(f"r{k}", 0.3, [(0, 2 * k), (5, 2 * k)], 1.0, departure=float(k))
             for k in range(n)]
    plan = Plan("test", paths)
    ids, how = schedule_rows(plan)
    assert ids == [f"r{k}" for k in range(10, n)]           # by id, naturally sorted, r0..r9 waited least
    assert str(MAX_GANTT_ROWS) in how and str(n) in how
    ids = [f"r{k}" for k in reversed(range(n))]
    network = Network(ids, dict.fromkeys(ids, 0.0), dict.fromkeys(ids, 5.0))
    assert schedule_rows(plan, network)[0] == [f"r{k}" for k in reversed(range(10, n))]
    small = Plan("test", paths[:3])
    assert schedule_rows(small)[0] == ["r0", "r1", "r2"]


@pytest.mark.parametrize("planner", ["md", "prior"])
def test_plot_plan_writes_a_png(tmp_path, planner):
    plan = get_planner(planner).plan(OPEN, CROSS)
    assert (plan.network is not None) == (planner == "md")
    out = tmp_path / "plan.png"
    plot_plan(OPEN, CROSS, plan, out)
    data = out.read_bytes()
    assert data[:8] == PNG and len(data) > 10_000


def test_plot_plan_and_schedule_with_an_empty_network(tmp_path):
    paths = [timed_path_from_polyline(r.id, r.radius, [r.start, r.goal], r.max_speed, departure=2.0 * k)
             for k, r in enumerate(CROSS[:2])]
    plan = Plan("given", paths)
    plot_plan(OPEN, CROSS[:2], plan, tmp_path / "plan.png", network=Network([], {}, {}, []))
    plot_schedule(plan, tmp_path / "schedule.png")
    for name in ("plan.png", "schedule.png"):
        assert (tmp_path / name).read_bytes()[:8] == PNG
