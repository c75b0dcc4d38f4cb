#!/usr/bin/env python3
"""What two robots did around their closest approach in a recorded run (``fleet-demo --record
run.mcap``): the pair and the time (by the independent checker, over the status tracks), then for
each of the two, every status, timed path and gate record from ``--before`` s before to ``--after``
s after, in log order. A diagnosis aid, not a test.

    .venv/bin/python bench/diag_contact.py out/run.mcap [--pair r5 r15] [--before 8] [--after 2] [--every 1]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from fleet_planner.ros.replay import _messages, read_run  # noqa: E402
from msg_schemas.records import GateRecord, RobotStatus  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    p.add_argument("mcap", type=Path)
    p.add_argument("--pair", nargs=2, help="these two robots (default: the closest pair of the run)")
    p.add_argument("--at", type=float, help="around this simulated time (default: the closest approach's)")
    p.add_argument("--before", type=float, default=8.0)
    p.add_argument("--after", type=float, default=2.0)
    p.add_argument("--every", type=float, default=0.0,
                   help="a robot's status only when its mode or path changes or every this many s (0: all)")
    opts = p.parse_args()
    run = read_run(opts.mcap)
    gap, a, b, t = run.closest_robots()
    print(f"closest approach: {gap:+.3f} m between {a} and {b} at t = {t}")
    if opts.pair:
        a, b = opts.pair
    if opts.at is not None:
        t = opts.at
    if a is None or b is None or t is None:
        return
    lo, hi = t - opts.before, t + opts.after
    pair = {a, b}
    shown: dict[str, tuple] = {}
    for topic, t_ns, msg in _messages(opts.mcap):
        when = t_ns / 1e9
        if not lo <= when <= hi:
            continue
        if topic.endswith("fleet/robot_status"):
            st = RobotStatus.from_json(msg.data)
            key = (st.mode, st.path_id, round(st.stamp / opts.every) if opts.every > 0 else st.stamp)
            if st.id in pair and shown.get(st.id) != key:
                shown[st.id] = key
                print(f"{when:9.2f} status {st.id} stamp={st.stamp:.2f} ({st.x:.3f}, {st.y:.3f}) "
                      f"v=({st.vx:.2f}, {st.vy:.2f}) {st.mode} path={st.path_id} travelled={st.travelled_m} "
                      f"progress={st.progress:.3f} late={st.lateness_s:.2f} rejected={st.rejected_path_id} "
                      f"task={st.task_id} loaded={st.loaded}")
        elif any(topic.endswith(f"/robots/{r}/timed_path") for r in pair):
            t0 = msg.header.stamp.sec + msg.header.stamp.nanosec / 1e9
            pts = [(round(ps.pose.position.x, 2), round(ps.pose.position.y, 2),
                    round(ps.header.stamp.sec + ps.header.stamp.nanosec / 1e9 - t0, 2)) for ps in msg.poses]
            print(f"{when:9.2f} {topic} t0={t0:.2f} {pts}")
        elif any(topic.endswith(f"/robots/{r}/gate") for r in pair):
            rec = GateRecord.from_json(msg.data)
            other = (pair - {rec.robot_id}).pop()
            links = [(lk["path_id"], lk["exit"], round(lk["entry"], 2)) for lk in rec.links if lk["robot"] == other]
            print(f"{when:9.2f} gate of {rec.robot_id} path={rec.path_id} seq={rec.seq} stamp={rec.stamp:.2f} "
                  f"{len(rec.links)} links, on {other}: {links[:3]}{' ...' if len(links) > 3 else ''}"
                  f"{links[-1:] if len(links) > 3 else ''} watch={(rec.watch or {}).get(other)}")
        elif topic.endswith("fleet/task_events"):
            d = json.loads(msg.data)
            if d.get("robot_id") in pair:
                print(f"{when:9.2f} event {msg.data}")


if __name__ == "__main__":
    main()
