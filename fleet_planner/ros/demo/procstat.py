"""What the processes of a run cost, from ``/proc`` (Linux; stdlib only): CPU seconds, memory, the
role of a fleet process by its command line, a process's descendants. The demo's summary
(:func:`usage_lines`) and ``bench/bench_fleet.py`` read them."""
from __future__ import annotations

import os
from collections import defaultdict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path


def stat(pid: int) -> tuple[int, float, str] | None:
    """(parent pid, CPU seconds (user + system), command line) of a process, None if it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return None
    fields = text.rsplit(")", 1)[1].split()
    return int(fields[1]), (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK"), cmd


def memory_mb(pid: int, field: str = "VmRSS") -> float:
    """A memory figure of ``/proc/<pid>/status`` in MB (``VmRSS`` now, ``VmHWM`` the peak); 0 if gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


def role(cmd: str) -> str:
    """Which part of a fleet a command line runs: demo, clock, fleet-sim, agent, planner or other."""
    if "fleet_planner.ros.demo" in cmd or "fleet-demo" in cmd:
        return "demo"
    for key, name in (("sim_clock", "clock"), ("fleet_sim", "fleet-sim"), ("fleet-sim", "fleet-sim"),
                      ("robot_agent", "agent"), ("agent_node", "agent"), ("__node:=agent", "agent"),
                      ("planner", "planner")):
        if key in cmd:
            return name
    return "other"


def descendants(root: int) -> list[int]:
    """``root`` and every process below it."""
    parents: dict[int, list[int]] = defaultdict(list)
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            st = stat(int(entry.name))
            if st is not None:
                parents[st[0]].append(int(entry.name))
    out, todo = [], [root]
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo.extend(parents.get(pid, []))
    return out


@dataclass(frozen=True)
class Usage:
    """What one process cost up to now: CPU seconds and peak resident memory (MB)."""

    role: str
    cpu_s: float
    peak_mb: float


def usage(pids: Sequence[int]) -> list[Usage]:
    """The cost so far of each of ``pids`` still running (read before they are stopped)."""
    out = []
    for pid in pids:
        st = stat(pid)
        if st is not None:
            out.append(Usage(role(st[2]), st[1], memory_mb(pid, "VmHWM")))
    return out


def usage_lines(used: Sequence[Usage], wall_s: float, sim_s: float | None) -> list[str]:
    """One line per role: CPU seconds, per simulated second, % of one core over ``wall_s``, peak MB
    (processes of one role, such as agents, as their count, total and largest)."""
    by_role: Mapping[str, list[Usage]] = defaultdict(list)
    for u in used:
        by_role[u.role].append(u)
    lines = [f"CPU and memory per process (over {wall_s:.0f} s wall"
             + (f", {sim_s:.0f} s simulated)" if sim_s else ")") + ":"]
    for name in sorted(by_role, key=lambda r: -sum(u.cpu_s for u in by_role[r])):
        group = by_role[name]
        cpu = sum(u.cpu_s for u in group)
        per_sim = f", {cpu / sim_s:.3f} s per simulated s" if sim_s else ""
        count = f" x{len(group)} (total; each at most {max(u.cpu_s for u in group):.1f} s)" if len(group) > 1 else ""
        lines.append(f"  {name}{count}: {cpu:.1f} s CPU{per_sim}, {100 * cpu / max(wall_s, 1e-9):.0f}% of a core, "
                     f"peak {max(u.peak_mb for u in group):.0f} MB")
    return lines


__all__ = ["Usage", "descendants", "memory_mb", "role", "stat", "usage", "usage_lines"]
