"""CPU time per message of the fleet's trust checks (issue 9, deliverable 5): signing and checking
a task event (fleet_planner/auth.py through fleet_planner/ros/signing.py), the digest of a timed
path of N poses, and the graph check of who publishes a topic (fleet_planner/ros/origin.py) with
P publishers on it.

    nice .venv/bin/python bench/bench_trust.py [--repeat 2000]
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time

import rclpy
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from std_msgs.msg import String

from fleet_planner.auth import new_key_line
from fleet_planner.ros.origin import OriginCheck
from fleet_planner.ros.signing import Keys, path_digest
from msg_schemas.records import TaskEvent

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def cpu_us(fn, repeat: int) -> float:
    t = time.process_time()
    for _ in range(repeat):
        fn()
    return (time.process_time() - t) / repeat * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=2000)
    opts = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        key = os.path.join(tmp, "k")
        with open(key, "w") as f:
            f.write(new_key_line("planner") + "\n")
        os.chmod(key, 0o600)
        signer, checker = Keys(sign_file=key), Keys(trust_file=key)
    ev = TaskEvent(task_id="job_12345678", event="assigned", stamp=1234.5, robot_id="r7")
    signed = [signer.sign(ev, "/fleet/task_events") for _ in range(opts.repeat)]
    it = iter(signed)
    rows = [("sign a task event", cpu_us(lambda: signer.sign(ev, "/fleet/task_events"), opts.repeat)),
            ("check a signed task event", cpu_us(lambda: checker.problem(next(it), "/fleet/task_events"),
                                                 opts.repeat))]
    for n in (50, 500):
        msg = Path()
        msg.poses = [PoseStamped() for _ in range(n)]
        rows.append((f"digest of a {n}-pose timed path", cpu_us(lambda m=msg: path_digest(m), opts.repeat // 10)))
    rclpy.init()
    try:
        node = rclpy.create_node("bench_trust")
        sub = node.create_subscription(String, "/bench_trust", lambda m: None, 10)
        pubs = [rclpy.create_node(f"bench_pub_{k}") for k in range(5)]
        for p in pubs:
            p.create_publisher(String, "/bench_trust", 10)
        check = OriginCheck(node, sub, "bench_pub_0")
        deadline = time.monotonic() + 5
        while len(node.get_publishers_info_by_topic("/bench_trust")) < len(pubs) and time.monotonic() < deadline:
            time.sleep(0.05)
        rows.append((f"origin check, {len(pubs)} publishers on the topic", cpu_us(check.problem, opts.repeat)))
        for p in pubs:
            p.destroy_node()
        node.destroy_node()
    finally:
        rclpy.shutdown()
    print(f"{'what':45s} {'CPU us/message':>15s}")
    for what, us in rows:
        print(f"{what:45s} {us:15.1f}")


if __name__ == "__main__":
    main()
