"""``fleet-replay run.mcap --plot out.png``: what a recorded run (:mod:`.record`) shows, read back
from the MCAP file with its own schemas (``mcap-ros2-support``, no ROS graph): the robots' tracks
from their status reports, the obstacles' from their records, the jobs from the task events; a
summary (messages per topic, jobs done, the closest approach between two robots and between a robot
and an obstacle, by the independent checker) and a picture of the run over the warehouse map.
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from fleet_planner.checker import min_separation
from fleet_planner.fleet import samples_to_path
from fleet_planner.fleet.obstacles import closest_approach
from fleet_planner.model import TimedPath
from msg_schemas import topics
from msg_schemas.records import ObstacleRecord, RecordError, RobotStatus, TaskEvent


@dataclass
class Run:
    """A recorded run as read back: tracks ``(x, y, t)`` by robot and by obstacle, task events, and
    how many messages each topic had."""

    robots: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    robot_radius: dict[str, float] = field(default_factory=dict)
    obstacles: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    obstacle_radius: dict[str, float] = field(default_factory=dict)
    events: list[TaskEvent] = field(default_factory=list)
    messages: Counter = field(default_factory=Counter)
    span: tuple[float, float] = (0.0, 0.0)   # first and last log time (s)
    skipped: int = 0                          # records that did not parse

    def robot_paths(self) -> list[TimedPath]:
        return [samples_to_path(rid, self.robot_radius[rid], tr) for rid, tr in sorted(self.robots.items())]

    def obstacle_paths(self) -> list[TimedPath]:
        return [samples_to_path(oid, self.obstacle_radius[oid], tr) for oid, tr in sorted(self.obstacles.items())]

    def done(self) -> list[str]:
        return sorted({e.task_id for e in self.events if e.event == "done"})

    def closest_robots(self) -> tuple[float, str | None, str | None, float | None]:
        return min_separation(self.robot_paths())

    def closest_obstacle(self) -> tuple[float, str | None, str | None, float | None]:
        """Between a robot and an obstacle, only while the obstacle was reported."""
        return closest_approach(self.robot_paths(), self.obstacle_paths())


def _messages(path: Path) -> Iterator[tuple[str, int, object]]:
    """(topic, log time in ns, decoded message) of every message, in log time order, decoded with
    the file's own schemas."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            yield channel.topic, message.log_time, decoded


def _is(topic: str, name: str) -> bool:
    """Whether the recorded ``topic`` (a full name) is the fleet topic ``name`` in any namespace."""
    return topic == "/" + name or topic.endswith("/" + name)


def read_run(path: str | Path) -> Run:
    """Read a recorded run; ValueError if the file is not an MCAP file of ROS 2 messages."""
    run = Run()
    first = last = None
    try:
        for topic, t_ns, msg in _messages(Path(path)):
            run.messages[topic] += 1
            first = t_ns if first is None else min(first, t_ns)
            last = t_ns if last is None else max(last, t_ns)
            try:
                if _is(topic, topics.ROBOT_STATUS):
                    st = RobotStatus.from_json(msg.data)  # type: ignore[attr-defined]
                    assert isinstance(st, RobotStatus)
                    run.robots.setdefault(st.id, []).append((st.x, st.y, st.stamp))
                    run.robot_radius[st.id] = st.radius
                elif _is(topic, topics.OBSTACLES):
                    ob = ObstacleRecord.from_json(msg.data)  # type: ignore[attr-defined]
                    assert isinstance(ob, ObstacleRecord)
                    if not ob.cleared:
                        run.obstacles.setdefault(ob.id, []).append((ob.x, ob.y, ob.stamp))
                        run.obstacle_radius[ob.id] = ob.radius
                elif _is(topic, topics.TASK_EVENTS):
                    ev = TaskEvent.from_json(msg.data)  # type: ignore[attr-defined]
                    assert isinstance(ev, TaskEvent)
                    run.events.append(ev)
            except RecordError:
                run.skipped += 1
    except (OSError, ValueError, KeyError, EOFError) as exc:
        raise ValueError(f"{path}: not a readable MCAP file of ROS 2 messages ({exc})") from exc
    except Exception as exc:  # the mcap readers raise their own error types for a bad file
        raise ValueError(f"{path}: not a readable MCAP file of ROS 2 messages ({type(exc).__name__}: {exc})") from exc
    if first is not None and last is not None:
        run.span = (first / 1e9, last / 1e9)
    return run


def summary_lines(run: Run) -> list[str]:
    out = [f"recorded {run.span[1] - run.span[0]:.1f} s (log time {run.span[0]:.1f}-{run.span[1]:.1f} s), "
           f"{sum(run.messages.values())} messages"]
    out += [f"  {topic}: {n}" for topic, n in sorted(run.messages.items())]
    out.append(f"robots: {len(run.robots)}, obstacles: {len(run.obstacles)}, jobs done: {len(run.done())}")
    gap, a, b, t = run.closest_robots()
    if a is not None and t is not None:
        out.append(f"closest approach of two robots: {gap:+.3f} m beyond the sum of radii ({a}, {b}, t = {t:.1f} s)")
    gap, a, b, t = run.closest_obstacle()
    if a is not None and t is not None:
        out.append(f"closest approach of a robot and an obstacle: {gap:+.3f} m beyond the sum of radii "
                   f"({a}, {b}, t = {t:.1f} s)")
    if run.skipped:
        out.append(f"{run.skipped} records did not parse")
    return out


def main(args: list[str] | None = None) -> None:
    argv = sys.argv[1:] if args is None else args
    p = argparse.ArgumentParser(prog="fleet-replay", description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("run", type=Path, help="an MCAP file written by fleet-record or fleet-demo --record")
    p.add_argument("--plot", type=Path, help="draw the run to this PNG")
    p.add_argument("--warehouse", type=Path, help="warehouse YAML (default: config/warehouse.yaml)")
    opts = p.parse_args(argv)
    try:
        run = read_run(opts.run)
    except ValueError as exc:
        print(f"fleet-replay: {exc}", file=sys.stderr)
        sys.exit(2)
    print("\n".join(summary_lines(run)))
    if opts.plot:
        from fleet_planner.ros.demo.summary import plot_run
        from fleet_planner.warehouse import load_warehouse

        title = (f"fleet-replay {opts.run.name}: {len(run.done())} jobs done, {len(run.robots)} robots, "
                 f"{len(run.obstacles)} obstacles")
        plot_run(load_warehouse(opts.warehouse), run.robot_paths(), opts.plot, title, obstacles=run.obstacle_paths())
        print(f"picture: {opts.plot}")


if __name__ == "__main__":
    main()
