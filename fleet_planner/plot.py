"""Pictures of a plan: the map with every robot's path, and the (M,D) view of paper 001 (Fig. 4).

Left: the map drawn like the ``.map`` file (row 0 on top, y downwards), one colour per robot,
hollow start discs, filled goal discs, ids at the starts. Right (when the plan carries the md
planner's ``network``): for the most constrained lower-priority robot(s), the travelled length
versus time curve (TLVSTC) and the collision boxes ``[ks, ke] x [ls, le]`` of their inlet links
``(i, j, k)``. A box bounds a collision region: a planner working with boxes steers the curve around
every box, one working with the exact regions may cut a box's corner where the region leaves room.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .grid import GridMap
from .model import Plan, RobotSpec, TimedPath

#: at most this many robots get their TLVSTC drawn on the right
MAX_TLVSTC_PANELS = 2
#: above this many robots, ids are not written on the map (they would only be noise)
MAX_LABELS = 60
#: at most this many collision boxes are named (i, j, k) in a TLVSTC panel
MAX_BOX_LABELS = 10


def _colours(n: int) -> list:
    import matplotlib

    if n <= 10:
        cmap = matplotlib.colormaps["tab10"]
        return [cmap(i) for i in range(n)]
    cmap = matplotlib.colormaps["turbo"]
    # spread neighbours in the list apart in hue so that adjacent robots are told apart
    step = 0.381966  # golden-ratio stride
    return [cmap(0.05 + 0.9 * ((i * step) % 1.0)) for i in range(n)]


def travelled_length(path: TimedPath) -> tuple[np.ndarray, np.ndarray]:
    """(times, travelled length) at the waypoints, starting at t = 0 with length 0."""
    wp = path.waypoints
    length = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(wp[:, :2], axis=0).T))])
    times = wp[:, 2]
    if times[0] > 0:
        times, length = np.concatenate([[0.0], times]), np.concatenate([[0.0], length])
    return times, length


def most_constrained(network: dict[str, Any], count: int = MAX_TLVSTC_PANELS) -> list[str]:
    """Lower robots with the most inlet links (ties: the longest delay), most constrained first."""
    inlets: dict[str, int] = {}
    for link in network.get("links", []):
        inlets[link["j"]] = inlets.get(link["j"], 0) + 1
    nodes = network.get("nodes", {})
    ranked = sorted(inlets, key=lambda j: (-inlets[j], -float(nodes.get(j, {}).get("delay", 0.0)), j))
    return ranked[:count]


def _draw_map(ax, grid: GridMap, robots: Sequence[RobotSpec], plan: Plan, colour: dict, focus: set[str]) -> None:
    from matplotlib import patheffects
    from matplotlib.patches import Circle

    halo = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    w, h = grid.size_m
    ax.imshow(np.where(grid.blocked, 0.25, 0.97), cmap="gray", vmin=0, vmax=1, extent=(0, w, h, 0),
              origin="upper", interpolation="nearest")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    paths = plan.by_id()
    # line widths and fonts follow the drawn size of a metre (points per metre of the map)
    bbox = ax.get_window_extent()
    pt_per_m = bbox.width * 72.0 / ax.figure.dpi / w
    scale = float(np.clip(0.35 * pt_per_m, 0.5, 2.0))
    for spec in robots:
        c = colour[spec.id]
        path = paths.get(spec.id)
        strong = spec.id in focus
        if path is not None:
            ax.plot(path.waypoints[:, 0], path.waypoints[:, 1], "-", color=c,
                    lw=scale * (2.2 if strong else 1.0), alpha=1.0 if strong or not focus else 0.75,
                    solid_capstyle="round", zorder=3 if strong else 2)
        ax.add_patch(Circle(spec.start, spec.radius, fill=False, ec=c, lw=scale * 1.2, zorder=4))
        ax.add_patch(Circle(spec.goal, spec.radius, fc=c, ec="black" if strong else c, lw=0.6, alpha=0.9, zorder=4))
        if len(robots) <= MAX_LABELS or strong:
            # in the hollow start disc, with a white halo so the path under it does not hide it
            ax.annotate(spec.id, spec.start, ha="center", va="center", fontsize=max(5.0, 8 * scale ** 0.5),
                        color=c, fontweight="bold", zorder=5, path_effects=halo)
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


def _draw_tlvstc(ax, rid: str, path: TimedPath, network: dict[str, Any], colour: dict) -> None:
    from matplotlib import patheffects
    from matplotlib.patches import Rectangle

    links = [lk for lk in network.get("links", []) if lk["j"] == rid]
    delay = float(network.get("nodes", {}).get(rid, {}).get("delay", path.start_time))
    times, length = travelled_length(path)
    t_end = max([times[-1]] + [float(lk["ke"]) for lk in links]) * 1.08 + 0.5
    times_ext, length_ext = np.append(times, t_end), np.append(length, length[-1])
    boxes = [tuple(float(lk[key]) for key in ("ks", "ke", "ls", "le")) for lk in links]
    # with many boxes, name only the ones the curve passes closest to (those that set the delay)
    slack = [_box_slack(times, length, b) for b in boxes]
    named = set(np.argsort(slack)[:MAX_BOX_LABELS].tolist())
    for n, (lk, (ks, ke, ls, le)) in enumerate(zip(links, boxes)):
        c = colour.get(lk["i"], "grey")
        size = (max(ke - ks, 1e-3), max(le - ls, 1e-3))
        ax.add_patch(Rectangle((ks, ls), *size, fc=c, ec="none", alpha=0.25))
        ax.add_patch(Rectangle((ks, ls), *size, fill=False, ec=c, lw=1.2))
        if n in named:
            ax.annotate(f"({lk['i']},{lk['j']},{lk.get('k', 1)})", ((ks + ke) / 2, le), xytext=(0, 2),
                        textcoords="offset points", ha="center", va="bottom", fontsize=7, color=c,
                        path_effects=[patheffects.withStroke(linewidth=2, foreground="white")])
    if delay > 0:
        moving = times >= delay
        ax.plot(np.concatenate([[0.0], times[moving] - delay, [t_end]]),
                np.concatenate([[0.0], length[moving], [length[-1]]]), ls=":", color="grey", lw=1.2,
                label="without delay")
    ax.plot(times_ext, length_ext, color=colour[rid], lw=2.2, label=f"{rid} (delay {delay:.2f} s)")
    ax.set_xlim(0, t_end)
    ax.set_ylim(0, max(length[-1], max([b[3] for b in boxes], default=0.0)) * 1.1 + 0.1)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"travelled length of {rid} [m]")
    shown = "" if len(links) <= MAX_BOX_LABELS else f", the {MAX_BOX_LABELS} nearest named"
    ax.set_title(f"TLVSTC of {rid}: {len(links)} inlet collision box(es){shown}", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)


def plot_plan(grid: GridMap, robots: Sequence[RobotSpec], plan: Plan, path_png: str | Path,
              network: dict[str, Any] | None = None) -> None:
    """Draw the plan to a PNG; ``network`` defaults to ``plan.info['network']`` when there is one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    network = network if network is not None else plan.info.get("network")
    colour = dict(zip([r.id for r in robots], _colours(len(robots))))
    paths = plan.by_id()
    focus = [rid for rid in most_constrained(network) if rid in paths] if network else []
    w, h = grid.size_m
    map_w = 7.5
    map_h = min(max(map_w * h / w, 3.5), 11.0)
    if focus:
        fig = plt.figure(figsize=(map_w + 6.5, max(map_h, 3.2 * len(focus))), layout="constrained")
        grid_spec = fig.add_gridspec(len(focus), 2, width_ratios=[map_w, 6.0])
        ax_map = fig.add_subplot(grid_spec[:, 0])
        for row, rid in enumerate(focus):
            _draw_tlvstc(fig.add_subplot(grid_spec[row, 1]), rid, paths[rid], network, colour)
    else:
        fig = plt.figure(figsize=(map_w, map_h), layout="constrained")
        ax_map = fig.add_subplot()
    _draw_map(ax_map, grid, robots, plan, colour, set(focus))
    ax_map.set_title(f"{plan.planner}: {len(plan.paths)} robots, sum of arrivals {plan.sum_of_arrivals:.1f} s, "
                     f"makespan {plan.makespan:.1f} s", fontsize=10)
    fig.savefig(path_png, dpi=130)
    plt.close(fig)


__all__ = ["most_constrained", "plot_plan", "travelled_length"]
