"""Holds anywhere along the path (issue 8, deliverable 1): the md scheduler lets a robot wait at
any vertex of its fixed path, against the higher robots' trajectories as timed (holds included).

The constructed case, worked out by hand (radii 0.5 m, margin 0, so R = 1 m; speeds 1 m/s;
priority 1, 2, j):
  robot 1: (11, 1) -> (11, 21), at y = 11 at t = 10
  robot 2: (3, 7)  -> (3, 21),  at y = 11 at t = 4
  robot j: (1, 11) -> (6, 11) -> (16, 11): 5 m then 10 m
Robot j crosses robot 2's line (x = 3) 2 m after its start and robot 1's (x = 11) 10 m after it.
Crossing a robot that moves at right angles at the same speed: with j at the crossing at t = c + s
where the other one is there at c, they are sqrt(s^2 + (s - e)^2) apart at time c + s ... the
smallest distance over t of two such discs is |e| / sqrt(2), e = (j's time at the crossing) -
(the other's), so they collide iff |e| < sqrt(2).
  departure only (delay d): robot 2: |(d + 2) - 4| < sqrt 2 -> d in (0.586, 3.414);
                            robot 1: |(d + 10) - 10| < sqrt 2 -> d in (-1.414, 1.414);
                            so d = 2 + sqrt 2, arrival 15 + 2 + sqrt 2 = 18.414.
  holds: leave at 0 (passes x = 3 at t = 2: |2 - 4| >= sqrt 2), reach (6, 11) at t = 5, wait there
         (it is 5 m from robot 1's line and 3 m from robot 2's) and leave at E with
         |(E + 5) - 10| >= sqrt 2: E = 5 + sqrt 2, arrival E + 10 = 15 + sqrt 2 = 16.414.
"""
import bisect
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from test_plans_valid import scenarios

from fleet_planner.checker import check_plan
from fleet_planner.grid import GridMap
from fleet_planner.model import Plan, PlanningError, RobotSpec, TimedPath
from fleet_planner.planners import get_planner
from fleet_planner.planners.md import MDPlanner, schedule_paths

IDS = ["1", "2", "j"]
PATHS = [np.array([[11, 1], [11, 21]], float), np.array([[3, 7], [3, 21]], float),
         np.array([[1, 11], [6, 11], [16, 11]], float)]
RADII = [0.5, 0.5, 0.5]
SPEEDS = [1.0, 1.0, 1.0]
GRID = GridMap(np.zeros((23, 18), dtype=bool), 1.0, "open")
SPECS = [RobotSpec(i, r, v, tuple(p[0]), tuple(p[-1])) for i, r, v, p in zip(IDS, RADII, SPEEDS, PATHS)]
S2 = math.sqrt(2)


@pytest.mark.parametrize("holds", ["none", "anywhere"])
def test_a_hold_en_route_beats_a_departure_delay(holds):
    result = schedule_paths(IDS, PATHS, RADII, SPEEDS, mode="exact", holds=holds)
    assert result.blocked is None
    assert check_plan(GRID, SPECS, Plan("md", result.paths)) == []
    j = result.paths[2]
    if holds == "none":
        assert j.start_time == pytest.approx(2 + S2)
        assert j.arrival_time == pytest.approx(17 + S2)
    else:
        assert j.start_time == pytest.approx(0.0)
        assert j.arrival_time == pytest.approx(15 + S2)
        # the hold: at (6, 11) from t = 5 to t = 5 + sqrt 2
        assert j.waypoints[:, :2].tolist() == [[1, 11], [6, 11], [6, 11], [16, 11]]
        assert j.waypoints[:, 2] == pytest.approx([0.0, 5.0, 5 + S2, 15 + S2])
        assert result.network.delay["j"] == pytest.approx(0.0)
        assert result.network.travel["j"] == pytest.approx(15 + S2)   # the hold counts as travel
    assert result.paths[0].arrival_time == pytest.approx(20.0)
    assert result.paths[1].arrival_time == pytest.approx(14.0)
    # the network under the final timing: j's links to both robots, none of them a collision
    assert {link.paper_tuple[:2] for link in result.network.links} == {("j", "1"), ("j", "2")}


def test_the_md_planner_holds_where_a_delay_costs_more():
    """The same case through the planner (given order, no margin): md-holds holds, md-departure delays."""
    arrivals = {}
    for name in ("md-holds", "md-departure"):
        plan = get_planner(name, order="given", margin=0.0).plan(GRID, SPECS)
        assert check_plan(GRID, SPECS, plan) == []
        arrivals[name] = plan.by_id()["j"].arrival_time
    assert arrivals["md-holds"] == pytest.approx(15 + S2)
    assert arrivals["md-departure"] == pytest.approx(17 + S2)


def test_holds_options():
    assert MDPlanner().holds == "anywhere" and get_planner("md").holds == "anywhere"   # md v2
    assert get_planner("md").detours == 2 and get_planner("md", holds="none").detours == 0
    assert get_planner("md-holds").holds == get_planner("md-routes").holds == "anywhere"
    assert get_planner("md-holds").detours == 0
    assert MDPlanner(mode="box").holds == "none"
    assert get_planner("md-departure").holds == "none"
    assert get_planner("md-box").holds == "none"
    with pytest.raises(ValueError, match="holds: must be one of none, anywhere"):
        MDPlanner(holds="sometimes")
    with pytest.raises(ValueError, match="holds: 'anywhere' needs mode 'exact'"):
        MDPlanner(mode="box", holds="anywhere")


def _from(path: TimedPath, t0: float) -> TimedPath:
    """What is left of a timed path from t0 (the robot where it is at t0, then the rest)."""
    wp = path.waypoints
    return TimedPath(path.robot_id, path.radius, np.vstack([[*path.position(t0), t0], wp[wp[:, 2] > t0]]))


@pytest.mark.parametrize("name", ["md", "md-holds", "md-departure", "md-routes"])
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=scenarios(), t0=st.sampled_from([0.0, 0.7, 2.0, 4.5]))
def test_every_incremental_leg_is_valid(name, case, t0):
    """Plan half the robots, then the other half as new legs from t0 around what the first half is
    driving (holds included); everything from t0 on must be valid for the checker."""
    grid, robots = case
    first, new = robots[: len(robots) // 2], robots[len(robots) // 2:]
    planner = get_planner(name)
    try:
        plan = planner.plan(grid, first)
    except PlanningError:
        return
    fixed = [_from(p, t0) for p in plan.paths]
    here = np.array([f.waypoints[0, :2] for f in fixed])
    for r in new:   # a new robot appears where no fixed robot is at t0
        assume(all(np.hypot(*(np.array(r.start) - q)) >= r.radius + f.radius + 0.05 for q, f in zip(here, fixed)))
    try:
        legs = planner.plan_incremental(grid, new, plan.paths, t0)
    except PlanningError as err:
        assert err.failures and set(err.failures) <= {r.id for r in new}
        return
    assert [p.robot_id for p in legs] == [r.id for r in new]
    assert all(p.waypoints[0, 2] == pytest.approx(t0) for p in legs)
    specs = [RobotSpec(r.id, r.radius, r.max_speed, tuple(f.waypoints[0, :2]), r.goal)
             for r, f in zip(first, fixed)] + new
    assert check_plan(grid, specs, Plan(name, fixed + legs)) == []


def test_the_cli_takes_holds_and_names_the_option_when_it_is_bad(tmp_path, capsys):
    from fleet_planner import cli
    from fleet_planner.scenario import read_plan

    scen = tmp_path / "s.yaml"
    scen.write_text("map:\n  rows: ['........', '........']\n  resolution: 1.0\nrobots:\n"
                    "  - {id: a, radius: 0.4, max_speed: 1.0, start: [0.5, 0.5], goal: [7.5, 0.5]}\n"
                    "  - {id: b, radius: 0.4, max_speed: 1.0, start: [7.5, 1.5], goal: [0.5, 1.5]}\n")
    out = tmp_path / "p.json"
    for holds in ("none", "anywhere"):
        assert cli.main([str(scen), "--out", str(out), "--holds", holds, "--quiet"]) == cli.EXIT_OK
        assert read_plan(out).planner == "md"
    with pytest.raises(SystemExit) as stop:
        cli.main([str(scen), "--out", str(out), "--holds", "sometimes"])
    assert stop.value.code == 2
    assert "--holds" in capsys.readouterr().err
    assert cli.main([str(scen), "--out", str(out), "--planner", "md-box", "--holds", "anywhere"]) == cli.EXIT_INPUT
    assert "holds" in capsys.readouterr().err


def test_route_choice_takes_the_detour_when_waiting_costs_more():
    """A higher robot comes head-on down the direct corridor (row 2) and leaves by a side stub
    next to the lower robot's start; without route choice the lower one waits at its start until
    the corridor is clear, with it it drives the northern corridor (16 m instead of 12, but it
    arrives earlier)."""
    grid = GridMap.from_rows([".............",
                              ".@@@@@@@@@@@.",
                              ".............",
                              "@." + "@" * 9 + ".@",
                              "@." + "@" * 9 + ".@"])
    robots = [RobotSpec("h", 0.4, 1.0, (11.5, 4.5), (1.5, 4.5)),
              RobotSpec("j", 0.4, 1.0, (0.5, 2.5), (12.5, 2.5))]
    plans = {name: get_planner(name, order="given").plan(grid, robots) for name in ("md-holds", "md-routes")}
    for plan in plans.values():
        assert check_plan(grid, robots, plan) == []
    held, routed = plans["md-holds"].by_id()["j"], plans["md-routes"].by_id()["j"]
    assert held.arrival_time > 20.0                     # waited for h to clear the corridor
    assert routed.arrival_time == pytest.approx(16.0)   # 16 m at 1 m/s, no wait
    assert plans["md-routes"].info["detours"] >= 1
    assert np.any(routed.waypoints[:, 1] < 1.0)         # it took the northern corridor
    # a robot that waits no longer than ``detour_min`` in all tries no detour: j waits about 22 s
    patient = get_planner("md-routes", order="given", detour_min=30.0).plan(grid, robots)
    assert check_plan(grid, robots, patient) == []
    assert patient.by_id()["j"].arrival_time > 20.0 and patient.info["detours"] == 0


def test_route_choice_thresholds_of_plans_and_legs():
    """One-shot plans try a detour from DETOUR_MIN_S of waits and a further one from DETOUR_AGAIN_S;
    legs (one robot at a time, cheap tries) from DETOUR_MIN_LEG_S; a detour_min given is used by both."""
    from fleet_planner.planners import md

    grid = GridMap.from_rows(["....."])
    robots = [RobotSpec("a", 0.4, 1.0, (0.5, 0.5), (4.5, 0.5))]
    plan_s = md._Session(get_planner("md"), grid, robots, [0], fixed=0)
    leg_s = md._Session(get_planner("md"), grid, robots, [0], fixed=0, incremental=True)
    assert (plan_s.detour_min, plan_s.detour_again) == (md.DETOUR_MIN_S, md.DETOUR_AGAIN_S)
    assert leg_s.detour_min == leg_s.detour_again == md.DETOUR_MIN_LEG_S
    assert md.DETOUR_MIN_LEG_S < md.DETOUR_MIN_S < md.DETOUR_AGAIN_S
    given = get_planner("md", detour_min=1.0)
    assert md._Session(given, grid, robots, [0], fixed=0).detour_min == 1.0
    assert md._Session(given, grid, robots, [0], fixed=0, incremental=True).detour_again == 1.0
    with pytest.raises(ValueError, match="detour_min"):
        get_planner("md", detour_min=-1.0)


# ---------------------------------------------------------------------------------------------
# the compiled hold search (fleet_planner._md_kernels) against the pure-Python loops it replaced
# ---------------------------------------------------------------------------------------------
# A plain transcription of the scheduler's search before it was compiled (issue 8, speed): the
# compiled kernels must give the very same numbers on any input.
INF = math.inf


def ref_safe(lo: list[float], hi: list[float]) -> list[tuple[float, float]]:
    """The closed safe intervals in [0, inf) outside open forbidden intervals sorted by lo (two
    that only touch leave the instant between them free)."""
    out: list[tuple[float, float]] = []
    cur = 0.0
    for a, b in zip(lo, hi):
        if b <= cur:
            continue
        if a >= cur:
            out.append((cur, a))
        cur = b
    if cur < INF:
        out.append((cur, INF))
    return out


def ref_allowed(lo: list[float], hi: list[float], a: float, e: float):
    """The closed pieces of [a, e] outside the open intervals (lo, hi) (sorted by lo), in order."""
    cur = a
    for x, y in zip(lo, hi):
        if y <= cur:
            continue
        if x >= e:
            break
        if x >= cur:
            yield cur, x
        cur = y
        if cur > e:
            return
    if cur <= e and cur < INF:
        yield cur, e


def ref_earliest(safes: list[list[tuple[float, float]]], edges: list[tuple[list[float], list[float]]],
              durations: np.ndarray, early_holds: bool = False) -> tuple[list[float], list[float]] | None:
    """Earliest arrival along a chain of hold vertices: ``safes[k]`` the safe intervals of vertex k,
    ``edges[k]`` the forbidden departure times from vertex k to k + 1 (sorted by lo), which takes
    ``durations[k]``. The robot is on vertex 0 at t = 0 and must stay on the last one for ever.
    Per (vertex, safe interval) only the earliest arrival is kept (waiting there is free, so it
    dominates). Returns (arrival, departure) per vertex, or None."""
    if not safes[0] or safes[0][0][0] > 0:
        return None
    best: list[dict[int, tuple[float, int, float]]] = [{0: (0.0, -1, 0.0)}]
    for k, dur in enumerate(durations.tolist()):
        lo, hi = edges[k]
        nxt = safes[k + 1]
        ends = [e for _, e in nxt]
        last_start = nxt[-1][0] if nxt else INF
        out: dict[int, tuple[float, int, float]] = {}
        for si, (t, _, _) in sorted(best[k].items(), key=lambda kv: kv[1][0]):
            e = safes[k][si][1]
            for al, be in ref_allowed(lo, hi, t, e):
                t_lo, t_hi = al + dur, be + dur
                n = bisect.bisect_left(ends, t_lo)
                while n < len(nxt) and nxt[n][0] <= t_hi:
                    t_arr = max(t_lo, nxt[n][0])
                    if n not in out or t_arr < out[n][0]:
                        out[n] = (t_arr, si, t_arr - dur)
                    n += 1
                if math.isinf(nxt[-1][1]) and (len(nxt) - 1) in out and t_lo >= last_start:
                    break
        if not out:
            return None
        best.append(out)
    final = len(safes[-1]) - 1
    if not safes[-1] or not math.isinf(safes[-1][final][1]) or final not in best[-1]:
        return None
    arrive, leave = [0.0] * len(safes), [INF] * len(safes)
    interval = [0] * len(safes)
    si = final
    for k in range(len(safes) - 1, 0, -1):
        t, parent, depart = best[k][si]
        arrive[k], leave[k - 1] = t, depart
        interval[k] = si
        si = parent
    if early_holds:
        ref_holds_early(safes, edges, durations.tolist(), arrive, leave, interval)
    return arrive, leave


def ref_holds_early(safes: list[list[tuple[float, float]]], edges: list[tuple[list[float], list[float]]],
                 durations: list[float], arrive: list[float], leave: list[float], interval: list[int]) -> None:
    """Move waits back along the path, keeping the arrival at the goal: from the last vertex back,
    leave each vertex as late as it can and still reach the next one by the time it leaves that one
    (staying in the safe interval it arrived in, outside the forbidden departure times). An earliest
    arrival rushes ahead and waits in front of the conflict, in an aisle others use (docs/ARCHITECTURE.md,
    measured fact 5); this waits where it was already standing, at its start if it can."""
    last = len(safes) - 1
    for k in range(last - 1, -1, -1):
        latest = arrive[last] if k + 1 == last else leave[k + 1]
        until = min(latest - durations[k], safes[k][interval[k]][1])
        if until <= leave[k]:
            continue
        lo, hi = edges[k]
        best = None
        for _, end in ref_allowed(lo, hi, leave[k], until):
            best = end
        if best is not None and best > leave[k]:
            leave[k] = best
            arrive[k + 1] = best + durations[k]


def _random_chain(rng, nh):
    """Forbidden intervals of a chain of ``nh`` hold vertices: per vertex (open, times >= 0) and
    per edge (departure times, may start before 0), some touching, some unbounded."""
    f_key, f_lo, f_hi, g_key, g_lo, g_hi = [], [], [], [], [], []
    grid = rng.integers(0, 3) == 0   # times on a coarse grid: many ties and touching intervals
    for k in range(nh):
        for _ in range(int(rng.integers(0, 4))):
            lo = float(rng.integers(0, 20)) if grid else float(rng.uniform(0, 20))
            size = float(rng.integers(1, 4)) if grid else float(rng.uniform(0.01, 5))
            hi = INF if rng.random() < 0.08 else lo + size
            f_key.append(k), f_lo.append(lo), f_hi.append(hi)
        if k < nh - 1:
            for _ in range(int(rng.integers(0, 4))):
                lo = float(rng.integers(-3, 20)) if grid else float(rng.uniform(-3, 20))
                hi = lo + (float(rng.integers(1, 4)) if grid else float(rng.uniform(0.01, 5)))
                g_key.append(k), g_lo.append(lo), g_hi.append(hi)
    durations = rng.integers(1, 4, nh - 1).astype(float) if grid else rng.uniform(0.2, 3, nh - 1)
    return (np.array(f_key, dtype=np.int64), np.array(f_lo), np.array(f_hi), np.array(g_key, dtype=np.int64),
            np.array(g_lo), np.array(g_hi), durations)


@pytest.mark.parametrize("early", [False, True])
def test_the_compiled_hold_search_gives_the_numbers_of_the_python_one(early):
    from fleet_planner import _md_kernels as K
    from fleet_planner.scheduler import _grouped

    rng = np.random.default_rng(8)
    found = 0
    for _ in range(400):
        nh = int(rng.integers(2, 9))
        f_key, f_lo, f_hi, g_key, g_lo, g_hi, durations = _random_chain(rng, nh)
        f_ptr, f_slo, f_shi = _grouped(f_key, f_lo, f_hi, nh)
        g_ptr, g_slo, g_shi = _grouped(g_key, g_lo, g_hi, nh - 1)
        safes = [ref_safe(f_slo[a:b].tolist(), f_shi[a:b].tolist()) for a, b in zip(f_ptr[:-1], f_ptr[1:])]
        edges = [(g_slo[a:b].tolist(), g_shi[a:b].tolist()) for a, b in zip(g_ptr[:-1], g_ptr[1:])]
        s_ptr, s_lo, s_hi = K.safe_intervals(f_ptr, f_slo, f_shi, False)
        assert [list(zip(s_lo[a:b].tolist(), s_hi[a:b].tolist())) for a, b in zip(s_ptr[:-1], s_ptr[1:])] == safes
        expect = ref_earliest(safes, edges, durations, early_holds=early)
        ok, arrive, leave = K.earliest(s_ptr, s_lo, s_hi, g_ptr, g_slo, g_shi, durations, early)
        assert ok == (expect is not None)
        if ok:
            found += 1
            assert arrive.tolist() == expect[0] and leave.tolist() == expect[1]   # exactly the same floats
    assert found > 100   # the cases are not all refusals


def test_the_compiled_merge_gives_the_regions_of_the_scipy_batch_in_the_same_order():
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from fleet_planner.collision import _merge_boxes_batch
    from fleet_planner.model import EPS

    rng = np.random.default_rng(4)
    chunks = []
    for _ in range(60):
        n = int(rng.integers(1, 30))
        lo = rng.integers(0, 12, (n, 2)).astype(float) if rng.random() < 0.5 else rng.uniform(0, 20, (n, 2))
        size = rng.integers(0, 3, (n, 2)).astype(float) if rng.random() < 0.5 else rng.uniform(0.1, 3, (n, 2))
        boxes = np.stack([lo[:, 0], lo[:, 0] + size[:, 0], lo[:, 1], lo[:, 1] + size[:, 1]], 1)
        chunks.append(boxes[np.argsort(boxes[:, 0], kind="stable")])
    # the SciPy batch the compiled merge replaced (issue 8, speed), as it was
    boxes = np.vstack(chunks)
    chunk = np.repeat(np.arange(len(chunks)), [len(c) for c in chunks])
    while True:
        n = len(boxes)
        sizes = np.bincount(chunk, minlength=len(chunks))
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        per = sizes[chunk]
        first = np.repeat(np.arange(n), per)
        block = np.concatenate([[0], np.cumsum(per)[:-1]])
        second = starts[chunk[first]] + (np.arange(len(first)) - np.repeat(block, per))
        sel = first < second
        first, second = first[sel], second[sel]
        a, b = boxes[first], boxes[second]
        touch = ((a[:, 0] <= b[:, 1] + EPS) & (b[:, 0] <= a[:, 1] + EPS)
                 & (a[:, 2] <= b[:, 3] + EPS) & (b[:, 2] <= a[:, 3] + EPS))
        graph = coo_matrix((np.ones(int(touch.sum())), (first[touch], second[touch])), shape=(n, n))
        count, comp = connected_components(graph, directed=False)
        if count == n:
            break
        merged = np.empty((count, 4))
        merged[:, [0, 2]], merged[:, [1, 3]] = np.inf, -np.inf
        for col, fn in ((0, np.minimum), (1, np.maximum), (2, np.minimum), (3, np.maximum)):
            fn.at(merged[:, col], comp, boxes[:, col])
        owner = np.empty(count, dtype=np.int64)
        owner[comp] = chunk
        boxes, chunk = merged, owner
    order = np.lexsort((boxes[:, 2], boxes[:, 0], chunk))
    boxes, chunk = boxes[order], chunk[order]
    bounds = np.searchsorted(chunk, np.arange(len(chunks) + 1))
    expect = [[tuple(r) for r in boxes[lo:hi].tolist()] for lo, hi in zip(bounds[:-1], bounds[1:])]
    assert _merge_boxes_batch(chunks) == expect


def ref_hold_constraints(sched, j: int, higher: list[int]):
    """The scheduler's forbidden intervals as numpy computed them before they were compiled (a
    transcription: rows seen from j, candidates of each kind stacked in order, then kept when
    lo < hi and hi > 0)."""
    from fleet_planner import collision as C
    from fleet_planner.scheduler import _SWAP

    def facing(i: int) -> np.ndarray:   # the pair's pieces with i in the x columns and j in the y columns
        raw = sched.model.pieces(i, j)
        if i < j:
            return raw
        out = raw[:, _SWAP]
        out[:, C.P_PHI_LO], out[:, C.P_PHI_HI] = -raw[:, C.P_PHI_HI], -raw[:, C.P_PHI_LO]
        return out

    tables = [facing(i) for i in higher]
    sizes = [len(t) for t in tables]
    P = np.vstack(tables)
    who = np.repeat(np.asarray(higher, dtype=np.int64), sizes)
    i_seg, j_seg = P[:, C.P_X_SEG].astype(np.int64), P[:, C.P_Y_SEG].astype(np.int64)
    lens = np.array([len(sched.arr[i]) for i in higher], dtype=np.int64)
    first, last = np.repeat(np.cumsum(lens) - lens, sizes), np.repeat(lens - 1, sizes)
    arr_all, dep_all = np.concatenate([sched.arr[i] for i in higher]), np.concatenate([sched.dep[i] for i in higher])
    s0 = np.minimum(i_seg, last)
    s1 = first + np.minimum(s0 + 1, last)
    s0 = first + s0
    a0, d0, a1, d1 = arr_all[s0], dep_all[s0], arr_all[s1], dep_all[s1]
    phi_lo, phi_hi = P[:, C.P_PHI_LO], P[:, C.P_PHI_HI]
    is_lo, is_hi, ie_lo, ie_hi = P[:, C.P_XS_LO], P[:, C.P_XS_HI], P[:, C.P_XE_LO], P[:, C.P_XE_HI]
    js_lo, js_hi, je_lo, je_hi = P[:, C.P_YS_LO], P[:, C.P_YS_HI], P[:, C.P_YE_LO], P[:, C.P_YE_HI]
    i_off, i_t0, i_v = P[:, C.P_X_OFF], P[:, C.P_X_T0], P[:, C.P_X_V]
    j_off, j_t0, j_v = P[:, C.P_Y_OFF], P[:, C.P_Y_T0], P[:, C.P_Y_V]
    cum_j = sched.model.cumlen[j]
    nv = len(cum_j)
    j_end = cum_j[np.minimum(j_seg + 1, nv - 1)]
    with np.errstate(invalid="ignore", over="ignore"):
        sh_i = d0 - i_t0
        held0, held1 = d0 > a0, d1 > a1
        g = [(np.isfinite(phi_lo) & np.isfinite(sh_i), sh_i + phi_lo + j_t0, sh_i + phi_hi + j_t0),
             (held0 & (is_lo <= is_hi), a0 - (is_hi - j_off) / j_v, d0 - (is_lo - j_off) / j_v),
             (held1 & (ie_lo <= ie_hi), a1 - (ie_hi - j_off) / j_v, d1 - (ie_lo - j_off) / j_v)]
        f = [(j_seg, np.isfinite(d0) & (js_lo <= js_hi), d0 + (js_lo - i_off) / i_v, d0 + (js_hi - i_off) / i_v),
             (j_seg, held0 & (is_lo <= j_off) & (j_off <= is_hi), a0, d0),
             (j_seg, held1 & (ie_lo <= j_off) & (j_off <= ie_hi), a1, d1),
             (j_seg + 1, np.isfinite(d0) & (je_lo <= je_hi), d0 + (je_lo - i_off) / i_v, d0 + (je_hi - i_off) / i_v),
             (j_seg + 1, held0 & (is_lo <= j_end) & (j_end <= is_hi), a0, d0),
             (j_seg + 1, held1 & (ie_lo <= j_end) & (j_end <= ie_hi), a1, d1)]

    def stack(parts):
        key = np.concatenate([p[0][p[1]] for p in parts])
        lo = np.concatenate([p[2][p[1]] for p in parts])
        hi = np.concatenate([p[3][p[1]] for p in parts])
        own = np.concatenate([who[p[1]] for p in parts])
        keep = (lo < hi) & (hi > 0)
        return key[keep], lo[keep], hi[keep], own[keep]

    return stack([(j_seg, *c) for c in g]), stack([(np.minimum(v, nv - 1), m, lo, hi) for v, m, lo, hi in f])


@pytest.mark.parametrize("seed", [0, 3])
def test_the_compiled_hold_constraints_are_the_numpy_ones(monkeypatch, seed):
    """Every call of the scheduler's compiled constraints while md plans 25 robots on the generated
    warehouse (route choice and the improvement search included, with holds of all kinds) gives
    exactly the arrays of the numpy transcription (the same floats, the same order)."""
    import sys
    from pathlib import Path

    from fleet_planner.scheduler import DelayScheduler

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
    import bench_md

    compiled = DelayScheduler.hold_constraints
    calls = []

    def both(self, j, higher):
        got = compiled(self, j, higher)
        want = ref_hold_constraints(self, j, higher)
        for a, b in zip(got + (), want):
            for x, y in zip(a, b):
                np.testing.assert_array_equal(x, y)
        calls.append(sum(len(a[0]) for a in got))
        return got

    monkeypatch.setattr(DelayScheduler, "hold_constraints", both)
    from fleet_planner.planners import md

    monkeypatch.setattr(md, "IMPROVE_ABOVE", 0.0)   # the improvement search runs however little the robots wait
    inst = bench_md.generated_instance(25, seed)
    # (a generous budget: the kernels may compile inside the first plan)
    plan = get_planner("md", compare_above=None, time_limit=600.0).plan(inst.grid, inst.robots)
    assert check_plan(inst.grid, inst.robots, plan) == []
    assert len(calls) > 25 and sum(calls) > 1000   # many calls, many intervals


def test_the_compiled_grouping_orders_intervals_as_a_stable_lexsort():
    from fleet_planner.scheduler import _grouped

    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(1, 7))
        m = int(rng.integers(0, 25))
        key = rng.integers(0, n, m).astype(np.int64)
        lo = rng.integers(0, 4, m).astype(float)   # many ties in lo: their order must be kept
        hi = lo + rng.uniform(0.1, 2.0, m)
        order = np.lexsort((lo, key))
        ptr, got_lo, got_hi = _grouped(key, lo, hi, n)
        assert ptr.tolist() == np.searchsorted(key[order], np.arange(n + 1)).tolist()
        assert got_lo.tolist() == lo[order].tolist() and got_hi.tolist() == hi[order].tolist()
