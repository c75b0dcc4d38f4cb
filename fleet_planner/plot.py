"""Pictures of a plan: the map, the (M,D) view of You & Ji, "Design of a Multi-robot Bin Packing
System in an Automatic Warehouse" (its Fig. 4), and the schedule.

* Map (left): drawn like the ``.map`` file (row 0 on top, y downwards), one colour per robot,
  hollow start discs, filled goal discs, ids at the starts.
* TLVSTC charts (right), for the most constrained lower-priority robots j (with the md planner's
  ``network``; without one, the robots that wait longest): j's travelled length versus time curve
  over its *collision map*, the set of (time, travelled length of j) at which a higher-priority
  robot would overlap j standing there. The map is computed here from the timed paths alone
  (:func:`collision_map`), not taken from the planner, so it is an independent witness: a valid
  plan's curve never enters it. On top, the paper's collision boxes ``[ks, ke] x [ls, le]`` of the
  inlet links ``(i, j, k)`` as outlines. A box bounds a region: the paper's "box" mode keeps the
  curve out of every box, our default "exact" mode only out of the regions, so its curve may cut a
  box's corner where the region leaves room (a robot following another down an aisle).
* Schedule (below): a Gantt chart, one row per robot, waiting and driving until arrival.
"""
from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .geometry import arc_lengths, points_at_arcs, polyline_point_distances, positions_at_times
from .grid import GridMap
from .model import Network, Plan, RobotSpec, TimedPath

#: at most this many robots get their TLVSTC drawn on the right
MAX_TLVSTC_PANELS = 2
#: above this many robots, ids are not written on the map (they would only be noise)
MAX_LABELS = 60
#: at most this many collision boxes are named (i, j, k) in a TLVSTC panel
MAX_BOX_LABELS = 10
#: at most this many robots get a row in the schedule (the most delayed ones)
MAX_GANTT_ROWS = 40
#: pixels of the collision map of a TLVSTC panel: time columns x travelled-length rows
MAP_COLUMNS, MAP_ROWS = 600, 300
#: at most this many point-to-point distances are held in memory at once by collision_map
_CHUNK = 1 << 20
#: opacity of the shaded collision regions
_REGION_ALPHA = 0.4


# ------------------------------------------------------------------------------------------------
# geometry of timed paths (TimedPath.position semantics, vectorised)
# ------------------------------------------------------------------------------------------------
def positions_at(path: TimedPath, times: np.ndarray) -> np.ndarray:
    """Where the robot is at each of ``times``, shape (len(times), 2): as
    :meth:`TimedPath.position`, parked on the first waypoint until its time and on the last one
    after it (:func:`~fleet_planner.geometry.positions_at_times`)."""
    return positions_at_times(path.waypoints, times)


def points_along(path: TimedPath, lengths: np.ndarray) -> np.ndarray:
    """The points of the path's polyline at the given travelled lengths (clamped to its ends),
    shape (len(lengths), 2) (:func:`~fleet_planner.geometry.points_at_arcs`)."""
    return points_at_arcs(path.waypoints, lengths)


def travelled_length(path: TimedPath) -> tuple[np.ndarray, np.ndarray]:
    """(times, travelled length) at the waypoints, starting at t = 0 with length 0."""
    wp = path.waypoints
    length = arc_lengths(wp)
    times = wp[:, 2]
    if times[0] > 0:
        times, length = np.concatenate([[0.0], times]), np.concatenate([[0.0], length])
    return times, length


def _by_id(paths: Sequence[TimedPath] | Mapping[str, TimedPath]) -> Mapping[str, TimedPath]:
    return paths if isinstance(paths, Mapping) else {p.robot_id: p for p in paths}


def blocker_map(paths: Sequence[TimedPath] | Mapping[str, TimedPath], j_id: str, higher_ids: Sequence[str],
                t_grid: np.ndarray, s_grid: np.ndarray) -> np.ndarray:
    """Which higher robot makes each (s, t) sample a collision for ``j_id``: an int array of shape
    (len(s_grid), len(t_grid)) holding the index in ``higher_ids`` of the first robot i closer than
    ``r_i + r_j`` to the point of j's path at travelled length s at time t, or -1 where none is."""
    paths = _by_id(paths)
    pj = paths[j_id]
    q = points_along(pj, s_grid)
    t_grid = np.asarray(t_grid, dtype=float)
    out = np.full((len(q), len(t_grid)), -1, dtype=np.int32)
    lo, hi = q.min(axis=0), q.max(axis=0)
    step = max(1, _CHUNK // max(len(q), 1))
    for n, i in enumerate(higher_ids):
        pi = paths[i]
        reach = pi.radius + pj.radius
        p = positions_at(pi, t_grid)
        # only the times at which i is within reach of j's path can matter: first the bounding
        # box (cheap), then the polyline itself
        cols = np.nonzero(np.all((p > lo - reach) & (p < hi + reach), axis=1))[0]
        cols = cols[polyline_point_distances(p[cols], pj.waypoints[:, :2]) < reach]
        for a in range(0, len(cols), step):
            c = cols[a:a + step]
            d2 = (q[:, None, 0] - p[None, c, 0]) ** 2 + (q[:, None, 1] - p[None, c, 1]) ** 2
            block = out[:, c]
            block[(d2 < reach * reach) & (block < 0)] = n
            out[:, c] = block
    return out


def collision_map(paths: Sequence[TimedPath] | Mapping[str, TimedPath], j_id: str, higher_ids: Sequence[str],
                  t_grid: np.ndarray, s_grid: np.ndarray) -> np.ndarray:
    """The collision map of robot ``j_id``: a bool array of shape (len(s_grid), len(t_grid)), True
    where j standing at travelled length s at time t would overlap one of ``higher_ids`` (closer
    than the sum of radii). j's own curve (t, s(t)) of a valid plan stays out of it."""
    return blocker_map(paths, j_id, higher_ids, t_grid, s_grid) >= 0


# ------------------------------------------------------------------------------------------------
# what the charts show
# ------------------------------------------------------------------------------------------------
def _phases(path: TimedPath) -> list[tuple[float, float, bool]]:
    """(from, to, moving) runs of the path from t = 0 until it arrives: parked before its first
    waypoint, then waiting (standing still) or driving between consecutive waypoints."""
    wp = path.waypoints
    arrival = path.arrival_time
    runs: list[tuple[float, float, bool]] = []

    def add(t0: float, t1: float, moving: bool) -> None:
        if t1 <= t0:
            return
        if runs and runs[-1][2] == moving and runs[-1][1] >= t0:
            runs[-1] = (runs[-1][0], t1, moving)
        else:
            runs.append((t0, t1, moving))

    add(0.0, min(float(wp[0, 2]), arrival), False)
    moving = np.any(wp[1:, :2] != wp[:-1, :2], axis=1)
    for k in range(len(wp) - 1):
        if wp[k, 2] >= arrival:
            break
        add(float(wp[k, 2]), float(min(wp[k + 1, 2], arrival)), bool(moving[k]))
    return runs


def waiting_time(path: TimedPath) -> float:
    """How long the robot stands still before it arrives (its departure delay plus any stops)."""
    return float(sum(t1 - t0 for t0, t1, moving in _phases(path) if not moving))


def most_constrained(network: Network, count: int = MAX_TLVSTC_PANELS) -> list[str]:
    """Lower robots with the most inlet links (ties: the longest delay), most constrained first."""
    inlets: dict[str, int] = {}
    for link in network.links:
        inlets[link.j] = inlets.get(link.j, 0) + 1
    ranked = sorted(inlets, key=lambda j: (-inlets[j], -float(network.delay.get(j, 0.0)), j))
    return ranked[:count]


def _natural(rid: str) -> list:
    """Sort key putting r2 before r10."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", rid)]


def _higher(rid: str, paths: Mapping[str, TimedPath], network: Network | None) -> list[str]:
    """The robots j must give way to: those before it in the network's priority list, or, without
    a network, every other robot."""
    if network is not None and rid in network.priority:
        before = network.priority[:network.priority.index(rid)]
        return [i for i in before if i in paths]
    return [i for i in paths if i != rid]


# ------------------------------------------------------------------------------------------------
# drawing
# ------------------------------------------------------------------------------------------------
def _colours(ids: Sequence[str]) -> dict[str, Any]:
    import matplotlib

    n = len(ids)
    if n <= 10:
        cmap = matplotlib.colormaps["tab10"]
        return {rid: cmap(k) for k, rid in enumerate(ids)}
    cmap = matplotlib.colormaps["turbo"]
    # spread neighbours in the list apart in hue so that adjacent robots are told apart
    step = 0.381966  # golden-ratio stride
    return {rid: cmap(0.05 + 0.9 * ((k * step) % 1.0)) for k, rid in enumerate(ids)}


def _draw_map(ax, grid: GridMap, robots: Sequence[RobotSpec], plan: Plan, colour: dict, focus: set[str]) -> None:
    from matplotlib import patheffects
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.patches import Circle

    halo = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    w, h = grid.size_m
    ax.imshow(np.where(grid.blocked, 0.25, 0.97), cmap="gray", vmin=0, vmax=1, extent=(0, w, h, 0),
              origin="upper", interpolation="nearest")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    lanes = getattr(grid, "lanes", None)   # a road map of directed lanes (fleet_planner.roadmap)
    if lanes is not None:
        from .roadmap import draw_lanes

        draw_lanes(ax, grid, lanes, radius=max((r.radius for r in robots), default=None))
    paths = plan.by_id()
    # line widths and fonts follow the drawn size of a metre (points per metre of the map)
    bbox = ax.get_window_extent()
    pt_per_m = bbox.width * 72.0 / ax.figure.dpi / w
    scale = float(np.clip(0.35 * pt_per_m, 0.5, 2.0))
    # collections, not one artist per robot: hundreds of robots draw in a fraction of a second
    for strong in (False, True):
        drawn = [r.id for r in robots if r.id in paths and (r.id in focus) == strong]
        if drawn:
            ax.add_collection(LineCollection(
                [paths[rid].waypoints[:, :2] for rid in drawn], colors=[colour[rid] for rid in drawn],
                linewidths=scale * (2.2 if strong else 1.0), alpha=1.0 if strong or not focus else 0.75,
                capstyle="round", zorder=3 if strong else 2), autolim=False)
    ax.add_collection(PatchCollection(
        [Circle(r.start, r.radius) for r in robots], facecolors="none",
        edgecolors=[colour[r.id] for r in robots], linewidths=scale * 1.2, zorder=4), autolim=False)
    ax.add_collection(PatchCollection(
        [Circle(r.goal, r.radius) for r in robots], facecolors=[colour[r.id] for r in robots],
        edgecolors=["black" if r.id in focus else colour[r.id] for r in robots], linewidths=0.6,
        alpha=0.9, zorder=4), autolim=False)
    for spec in robots:
        if len(robots) <= MAX_LABELS or spec.id in focus:
            # in the hollow start disc, with a white halo so the path under it does not hide it
            ax.annotate(spec.id, spec.start, ha="center", va="center", fontsize=max(5.0, 8 * scale ** 0.5),
                        color=colour[spec.id], fontweight="bold", zorder=5, path_effects=halo)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m] (downwards, as in the map file)")


def _box_slack(times: np.ndarray, length: np.ndarray, box: tuple[float, float, float, float]) -> float:
    """How far in time the curve passes from a box: >= 0 when it passes before (above-left: leaves
    ``le`` before ``ks``) or after it (below-right: reaches ``ls`` after ``ke``), < 0 when it crosses."""
    ks, ke, ls, le = box
    up = np.concatenate([[True], np.diff(length) > 0])        # first instant at each length
    down = np.concatenate([np.diff(length) > 0, [True]])      # last instant at each length
    first_at_ls = float(np.interp(ls, length[up], times[up]))
    last_at_le = float(np.interp(le, length[down], times[down]))
    return max(first_at_ls - ke, ks - last_at_le)


def _draw_tlvstc(ax, rid: str, paths: Mapping[str, TimedPath], network: Network | None,
                 colour: dict) -> tuple[bool, bool]:
    """j's curve over its collision map (shaded per blocking robot) and its collision boxes.
    Returns what the legend has to explain: (a curve without the delay drawn, boxes drawn)."""
    from matplotlib import patheffects
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    path = paths[rid]
    links = [lk for lk in network.links if lk.j == rid] if network is not None else []
    delay = waiting_time(path)
    times, length = travelled_length(path)
    boxes = [(float(lk.ks), float(lk.ke), float(lk.ls), float(lk.le)) for lk in links]
    t_end = max([times[-1]] + [b[1] for b in boxes if np.isfinite(b[1])]) * 1.08 + 0.5
    total = float(length[-1])

    # the collision map, one light colour per blocking robot, as an RGBA image
    higher = _higher(rid, paths, network)
    t_grid = (np.arange(MAP_COLUMNS) + 0.5) * t_end / MAP_COLUMNS
    s_grid = (np.arange(MAP_ROWS) + 0.5) * total / MAP_ROWS
    who = blocker_map(paths, rid, higher, t_grid, s_grid)
    palette = np.array([colour.get(i, (0.5, 0.5, 0.5, 1.0)) for i in higher] + [(0, 0, 0, 0)], dtype=float)
    palette[:-1, 3] = _REGION_ALPHA   # the last entry, transparent, is what index -1 (free) picks
    if total > 0:
        ax.imshow(palette[who], origin="lower", extent=(0, t_end, 0, total), aspect="auto",
                  interpolation="nearest", zorder=1)

    slack = [_box_slack(times, length, b) for b in boxes]
    named = set(np.argsort(slack)[:MAX_BOX_LABELS].tolist())
    halo = [patheffects.withStroke(linewidth=2, foreground="white")]
    # a box whose robot parks in it (ke = inf) reaches beyond the chart
    ax.add_collection(PatchCollection(
        [Rectangle((ks, ls), max(min(ke, 2 * t_end) - ks, 1e-3), max(le - ls, 1e-3)) for ks, ke, ls, le in boxes],
        facecolors="none", edgecolors=[colour.get(lk.i, "grey") for lk in links], linewidths=1.1,
        linestyles=[(0, (4, 2))], zorder=2), autolim=False)
    for n, (lk, (ks, ke, _, le)) in enumerate(zip(links, boxes)):
        c = colour.get(lk.i, "grey")
        if n in named:
            ax.annotate(f"({lk.i},{lk.j},{lk.k})", ((ks + min(ke, t_end)) / 2, le), xytext=(0, 2),
                        textcoords="offset points", ha="center", va="bottom", fontsize=7, color=c,
                        path_effects=halo, zorder=4)
    shifted = delay > 0 and abs(path.start_time - delay) < 1e-9
    if shifted:
        # a pure departure delay: the same curve moved back to t = 0 is what the delay avoided
        moving = times >= delay
        ax.plot(np.concatenate([[0.0], times[moving] - delay, [t_end]]),
                np.concatenate([[0.0], length[moving], [total]]), ls=":", color="grey", lw=1.2, zorder=3)
    ax.plot(np.append(times, t_end), np.append(length, total), color=colour[rid], lw=2.2, zorder=3,
            path_effects=[patheffects.withStroke(linewidth=3.6, foreground="white")])
    ax.set_xlim(0, t_end)
    ax.set_ylim(0, total * 1.1 + 0.1)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"travelled length of {rid} [m]")
    whom = "higher-priority" if network is not None and rid in network.priority else "other"
    ax.set_title(f"TLVSTC of {rid}: waits {delay:.1f} s for {len(higher)} {whom} robots"
                 + (f" ({len(links)} collision boxes)" if links else ""), fontsize=10)
    ax.grid(alpha=0.3, zorder=0)
    return shifted, bool(links)


def _tlvstc_legend(ax, undelayed: bool, boxes: bool) -> None:
    """One legend for the stack of TLVSTC charts, under the lowest one."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Line2D([], [], color="black", lw=2.2, label="travelled length vs time (colour of the robot)"),
               Patch(fc=(0.55, 0.55, 0.55, _REGION_ALPHA), ec="none",
                     label="collision region (exact), colour of the robot in the way")]
    if undelayed:
        handles.insert(1, Line2D([], [], ls=":", color="grey", lw=1.2, label="same, without the delay"))
    if boxes:
        handles.append(Patch(fill=False, ec="dimgrey", ls=(0, (4, 2)), label="collision box (You & Ji)"))
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncols=2, fontsize=7,
              frameon=False)


def schedule_rows(plan: Plan, network: Network | None = None) -> tuple[list[str], str]:
    """The robots of the Gantt chart, top to bottom, and how they were chosen (for the title): in
    priority order when the network ranks every robot, else by id; of a large fleet only the
    :data:`MAX_GANTT_ROWS` that wait longest."""
    paths = plan.by_id()
    priority = [rid for rid in (network.priority if network is not None else []) if rid in paths]
    if priority and len(priority) == len(paths):
        ids, how = priority, "priority order, highest on top"
    else:
        ids, how = sorted(paths, key=_natural), "by id"
    if len(ids) > MAX_GANTT_ROWS:
        wait = {rid: waiting_time(paths[rid]) for rid in ids}
        kept = set(sorted(ids, key=lambda rid: -wait[rid])[:MAX_GANTT_ROWS])
        ids = [rid for rid in ids if rid in kept]
        how = f"the {MAX_GANTT_ROWS} most delayed of {len(paths)} robots, {how}"
    return ids, how


def _draw_schedule(ax, plan: Plan, network: Network | None, colour: dict) -> None:
    """Gantt chart: per robot, hatched bars while it waits, solid ones while it drives."""
    from matplotlib.patches import Patch

    paths = plan.by_id()
    ids, how = schedule_rows(plan, network)
    for row, rid in enumerate(ids):
        runs = _phases(paths[rid])
        c = colour.get(rid, (0.5, 0.5, 0.5, 1.0))
        waits = [(t0, t1 - t0) for t0, t1, moving in runs if not moving]
        drives = [(t0, t1 - t0) for t0, t1, moving in runs if moving]
        ax.broken_barh(waits, (row - 0.35, 0.7), facecolors=(*c[:3], 0.18), edgecolors=c, hatch="////",
                       linewidth=0.0)
        ax.broken_barh(drives, (row - 0.35, 0.7), facecolors=c, edgecolors="none")
    makespan = plan.makespan
    ax.axvline(makespan, color="black", lw=1.2, ls="--")
    ax.annotate(f"makespan {makespan:.1f} s", (makespan, 1.0), xycoords=("data", "axes fraction"),
                xytext=(-3, -3), textcoords="offset points", ha="right", va="top", fontsize=8)
    ax.set_yticks(range(len(ids)), ids, fontsize=8 if len(ids) <= 20 else 6)
    ax.set_ylim(max(len(ids), 1) - 0.5, -0.5)
    ax.set_xlim(0, max(makespan, 1e-3) * 1.03)
    ax.set_xlabel("time [s]")
    ax.grid(axis="x", alpha=0.3)
    ax.set_axisbelow(True)
    ax.set_title(f"schedule ({how}): sum of arrivals {plan.sum_of_arrivals:.1f} s", fontsize=10)
    ax.legend(handles=[Patch(fc=(0.5, 0.5, 0.5, 0.18), ec="grey", hatch="////", lw=0, label="waiting"),
                       Patch(fc="grey", label="driving")], loc="center left", bbox_to_anchor=(1.0, 0.5),
              fontsize=7, frameon=False)


def _gantt_height(plan: Plan, network: Network | None) -> float:
    return 1.1 + 0.17 * len(schedule_rows(plan, network)[0])


def plot_schedule(plan: Plan, path_png: str | Path, network: Network | None = None) -> None:
    """Draw the plan's schedule (Gantt chart) to a PNG; ``network`` defaults to ``plan.network``
    (its priority order sorts the rows)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    network = network if network is not None else plan.network
    colour = _colours([p.robot_id for p in plan.paths])
    fig = plt.figure(figsize=(9.0, _gantt_height(plan, network)), layout="constrained")
    _draw_schedule(fig.add_subplot(), plan, network, colour)
    fig.savefig(path_png, dpi=130)
    plt.close(fig)


def plot_plan(grid: GridMap, robots: Sequence[RobotSpec], plan: Plan, path_png: str | Path,
              network: Network | None = None) -> None:
    """Draw the plan to a PNG: map and TLVSTC charts on top, schedule below. ``network`` defaults
    to ``plan.network`` when there is one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    network = network if network is not None else plan.network
    colour = _colours([r.id for r in robots])
    paths = plan.by_id()
    colour.update({rid: (0.5, 0.5, 0.5, 1.0) for rid in paths if rid not in colour})
    if network is not None and network.links:
        focus = [rid for rid in most_constrained(network) if rid in paths]
    else:
        wait = {rid: waiting_time(p) for rid, p in paths.items()}
        by_wait = sorted(wait, key=lambda r: (-wait[r], _natural(r)))
        focus = [rid for rid in by_wait if wait[rid] > 0][:MAX_TLVSTC_PANELS]
    focus = [rid for rid in focus if paths[rid].length > 0]
    w, h = grid.size_m
    map_w = 7.5
    map_h = min(max(map_w * h / w, 3.5), 11.0)
    top_h = max(map_h, 3.4 * len(focus))
    gantt_h = _gantt_height(plan, network)
    width = map_w + 6.5 if focus else max(map_w, 9.0)
    fig = plt.figure(figsize=(width, top_h + gantt_h), layout="constrained")
    outer = fig.add_gridspec(2, 1, height_ratios=[top_h, gantt_h])
    if focus:
        top = outer[0].subgridspec(len(focus), 2, width_ratios=[map_w, 6.0])
        ax_map = fig.add_subplot(top[:, 0])
        drawn = [_draw_tlvstc(ax, rid, paths, network, colour)
                 for ax, rid in ((fig.add_subplot(top[row, 1]), rid) for row, rid in enumerate(focus))]
        _tlvstc_legend(fig.axes[-1], any(d[0] for d in drawn), any(d[1] for d in drawn))
    else:
        ax_map = fig.add_subplot(outer[0])
    _draw_map(ax_map, grid, robots, plan, colour, set(focus))
    mode = f" ({plan.network.mode} mode)" if plan.network is not None and plan.network.mode else ""
    ax_map.set_title(f"{plan.planner}{mode}: {len(plan.paths)} robots, sum of arrivals {plan.sum_of_arrivals:.1f} s, "
                     f"makespan {plan.makespan:.1f} s", fontsize=10)
    _draw_schedule(fig.add_subplot(outer[1]), plan, network, colour)
    fig.savefig(path_png, dpi=130)
    plt.close(fig)


__all__ = ["blocker_map", "collision_map", "most_constrained", "plot_plan", "plot_schedule", "points_along",
           "positions_at", "schedule_rows", "travelled_length", "waiting_time"]
