"""What a demo run did: :func:`summarise` (jobs done, completion time, speeds, closest approach of two
robots, all from the monitor's records of the robots' own status reports, not from the planner) and
:func:`plot_run` (the reported trajectories over the map)."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fleet_planner.model import TimedPath
from fleet_planner.ros.demo.monitor import FleetMonitor
from fleet_planner.warehouse import Warehouse
from msg_schemas.records import Task


@dataclass
class Summary:
    jobs: int
    done: int
    failed: int
    rejected: int
    completion_s: float | None     # from the first submission to the last job done (simulated)
    distance_m: float               # driven by the whole fleet
    average_speed: float            # fleet distance / (robots x completion time)
    moving_speed: float             # fleet distance / time spent moving
    min_gap: float                  # smallest distance minus the sum of radii
    closest: tuple[str | None, str | None, float | None]
    wall_s: float
    start: float = 0.0              # the first submission (simulated s)
    interrupted: bool = False       # Ctrl-C or SIGTERM ended the run: what was done so far

    @property
    def jobs_per_hour(self) -> float:
        """Throughput: jobs done per simulated hour, from the first submission to the last job done."""
        return 3600.0 * self.done / self.completion_s if self.completion_s else 0.0

    @property
    def sim_rate(self) -> float:
        """Simulated seconds per wall second reached (over the same span)."""
        return self.completion_s / self.wall_s if self.completion_s and self.wall_s > 0 else 0.0

    def lines(self, radius: Mapping[str, float], asked_rate: float | None = None) -> list[str]:
        out = [f"jobs: {self.done} done, {self.failed} failed, {self.rejected} rejected of {self.jobs}"
               + (" (interrupted: what was done so far)" if self.interrupted else "")]
        if self.completion_s is not None:
            out.append(f"completion time: {self.completion_s:.1f} s simulated ({self.wall_s:.1f} s wall, "
                       f"{self.sim_rate:.1f}x real time)")
            out.append(f"throughput: {self.jobs_per_hour:.0f} jobs per simulated hour; simulated time ran at "
                       f"{self.sim_rate:.1f}x real time" + (f" (asked {asked_rate:g}x)" if asked_rate else ""))
        out.append(f"average speed: {self.average_speed:.2f} m/s per robot over the run, {self.moving_speed:.2f} m/s "
                   f"while moving ({self.distance_m:.0f} m driven)")
        a, b, t = self.closest
        if a is not None and b is not None and t is not None:  # all three or none
            reach = radius[a] + radius[b]
            verdict = "no contact" if self.min_gap >= 0 else "DISCS OVERLAPPED"
            out.append(f"closest approach: {reach + self.min_gap:.3f} m between {a} and {b} at t = {t:.1f} s; "
                       f"sum of radii {reach:.3f} m ({verdict}, clearance {self.min_gap:+.3f} m)")
        return out


def summarise(monitor: FleetMonitor, jobs: Sequence[Task], first_submit: float, wall_s: float) -> Summary:
    states = [monitor.last_event.get(j.id) for j in jobs]
    done_times = [e.stamp for e in states if e is not None and e.event == "done"]
    distance = moving_time = 0.0
    span = (max(done_times) - first_submit) if done_times else None
    for path in monitor.trajectories():
        wp = path.waypoints
        seg = np.hypot(*np.diff(wp[:, :2], axis=0).T)
        dt = np.diff(wp[:, 2])
        distance += float(seg.sum())
        moving_time += float(dt[seg > 1e-6].sum())
    gap, a, b, t = monitor.min_separation()
    robots = max(1, len(monitor.tracks))
    return Summary(len(jobs), len(done_times), sum(e is not None and e.event == "failed" for e in states),
                   sum(e is not None and e.event == "rejected" for e in states), span, distance,
                   distance / (robots * span) if span else 0.0, distance / moving_time if moving_time else 0.0,
                   gap, (a, b, t), wall_s, first_submit)


def plot_run(warehouse: Warehouse, trajectories: Sequence[TimedPath], path_png: str | Path, title: str,
             parking: Sequence[tuple[float, float]] = (), obstacles: Sequence[TimedPath] = ()) -> None:
    """The robots' reported trajectories over the map (drawn like the map file, y downwards), and
    the obstacles' (people...) dashed in black."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    grid = warehouse.grid
    w, h = grid.size_m
    fig, ax = plt.subplots(figsize=(10, max(3.5, 10 * h / w)), layout="constrained")
    ax.imshow(np.where(grid.blocked, 0.25, 0.97), cmap="gray", vmin=0, vmax=1, extent=(0, w, h, 0),
              origin="upper", interpolation="nearest")
    marks = {"chute": ("v", "tab:red"), "storage": ("s", "tab:blue"), "charger": ("P", "tab:green")}
    for kind, (marker, colour) in marks.items():
        pts = np.array([s.pose for s in warehouse.stations_of(kind)]).reshape(-1, 2)
        ax.scatter(pts[:, 0], pts[:, 1], marker=marker, c=colour, s=30, label=kind, zorder=3)
    if len(parking):
        pts = np.asarray(parking, dtype=float).reshape(-1, 2)
        ax.scatter(pts[:, 0], pts[:, 1], marker="x", c="grey", s=25, label="parking", zorder=3)
    cmap = matplotlib.colormaps["tab10" if len(trajectories) <= 10 else "turbo"]
    for i, path in enumerate(sorted(trajectories, key=lambda p: p.robot_id)):
        c = cmap(i % 10 if len(trajectories) <= 10 else i / max(1, len(trajectories) - 1))
        wp = path.waypoints
        ax.plot(wp[:, 0], wp[:, 1], "-", color=c, lw=1.1, alpha=0.8, zorder=4)
        ax.add_patch(Circle(tuple(wp[0, :2]), path.radius, fill=False, ec=c, lw=1.2, zorder=5))
        ax.add_patch(Circle(tuple(wp[-1, :2]), path.radius, fc=c, ec="black", lw=0.5, zorder=5))
        ax.annotate(path.robot_id, tuple(wp[0, :2]), ha="center", va="center", fontsize=6, zorder=6)
    for k, path in enumerate(obstacles):
        wp = path.waypoints
        ax.plot(wp[:, 0], wp[:, 1], "--", color="black", lw=0.8, alpha=0.6, zorder=4,
                label="obstacle (person...)" if k == 0 else None)
        ax.add_patch(Circle(tuple(wp[-1, :2]), path.radius, fc="none", ec="black", ls="--", lw=0.8, zorder=5))
        ax.annotate(path.robot_id, tuple(wp[-1, :2]), ha="center", va="bottom", fontsize=5, zorder=6)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m] (downwards, as in the map file)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper right", fontsize=7, framealpha=0.8)
    fig.savefig(path_png, dpi=120)
    plt.close(fig)
