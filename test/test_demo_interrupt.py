"""``fleet-demo --mode procs`` ended from outside: Ctrl-C (SIGINT) or SIGTERM ends it within seconds with
the summary of what was done so far and exit status 130, and no process of the fleet outlives it; killed
outright (SIGKILL, no chance to clean up), its processes still end by themselves (PR_SET_PDEATHSIG)."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fleet_planner.ros.demo.procstat import descendants, stat

REPO = Path(__file__).resolve().parent.parent
#: wall seconds for the fleet to come up and the first job to go out (a loaded machine), and to end
START_S, END_S = 90.0, 20.0


def _alive(pids):
    """Those of ``pids`` still running (not zombies)."""
    out = []
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            out.append(pid)
    return out


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
def test_the_demo_ended_from_outside_leaves_no_process_behind(tmp_path, sig):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    err = tmp_path / "stderr.txt"
    with open(err, "w") as stderr:
        demo = subprocess.Popen([sys.executable, "-m", "fleet_planner.ros.demo", "--mode", "procs", "--robots", "2",
                                 "--jobs", "40", "--out", str(tmp_path), "--timeout", str(START_S)],
                                stdout=subprocess.PIPE, stderr=stderr, text=True, env=env, cwd=REPO)
    children: list[int] = []
    try:
        deadline = time.monotonic() + START_S
        while "jobs done" not in err.read_text() and demo.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)   # polling a file the demo writes (its progress bar: the jobs go out)
        assert demo.poll() is None and "jobs done" in err.read_text(), err.read_text()[-2000:]
        children = [p for p in descendants(demo.pid) if p != demo.pid]
        assert len(children) == 4, [stat(p) for p in children]   # clock, planner, two agents
        t0 = time.monotonic()
        demo.send_signal(sig)
        out, _ = demo.communicate(timeout=END_S)
        while _alive(children) and time.monotonic() < t0 + END_S:
            time.sleep(0.1)   # (after SIGKILL the children end on their own)
        assert not _alive(children), [stat(p) for p in _alive(children)]
        if sig == signal.SIGINT:
            assert demo.returncode == 130, out + err.read_text()[-2000:]
            assert "(interrupted: what was done so far)" in out, out
            assert "CPU and memory per process" in out and "planner:" in out, out
            assert time.monotonic() - t0 < END_S
        else:
            assert demo.returncode == -signal.SIGKILL
    finally:
        if demo.poll() is None:
            demo.kill()
            demo.wait()
        for pid in _alive(children):
            os.kill(pid, signal.SIGKILL)
