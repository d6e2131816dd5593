"""How fast the graph recovers from process faults: restart-to-resume after a SIGKILLed robot batch,
and node exit after a SIGKILLed launcher.

    .venv/bin/python scripts/bench_faults.py [--trials 3]

Each trial starts ``swarm-ros run`` on the star (rules local, ~3600 ticks, K = 3) and
either kills robot_batch_1 once ticks flow, or kills the launcher itself. Reported:

- kill -> back: from the SIGKILL to the world's log line saying the batch's new process
  announced itself (``is back``), when the world sends it the snapshot from which it
  decides the awaited tick (the lockstep resumes with that one message);
- launcher kill -> nodes gone: from the launcher's SIGKILL until none of its five node
  processes is alive (they get SIGTERM from the kernel through PR_SET_PDEATHSIG).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUN = ["--shape", "star", "--seed", "5", "--rules", "local", "--processes", "3", "--quiet"]


def _nodes(out: Path) -> dict[str, int]:
    found = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes().decode(errors="replace")
            state = (proc / "stat").read_text().split(")")[-1].split()[0]
        except OSError:
            continue
        if f".{out.name}.logs-" in cmd and str(out.parent) in cmd and state != "Z":
            m = re.search(r"__node:=(\w+)", cmd)
            if m:
                found[m.group(1)] = int(proc.name)
    return found


def _wait_ticks(out: Path, size: int = 400_000, timeout: float = 120) -> None:
    partial = out.parent / f"{out.name}.partial.rrd"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if partial.exists() and partial.stat().st_size > size:
            return
        time.sleep(0.02)
    raise SystemExit("the run never got going")


def restart_trial(base: Path) -> float:
    out = base / "restart"
    launcher = subprocess.Popen([sys.executable, "-m", "swarm_ros", "run", *RUN, "--out", str(out)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    _wait_ticks(out)
    victim = _nodes(out)["robot_batch_1"]
    os.kill(victim, signal.SIGKILL)
    killed = time.time()
    _, err = launcher.communicate(timeout=300)
    if launcher.returncode != 0:
        raise SystemExit(f"run failed: {err}")
    log = (out / "logs" / "world.log").read_text()
    back = re.search(r"\[WARN\] \[(\d+\.\d+)\] \[world\]: robot_batch_1 is back", log)
    if not back:
        raise SystemExit("the world never saw the batch come back")
    return float(back.group(1)) - killed


def launcher_trial(base: Path) -> float:
    out = base / "launcher"
    launcher = subprocess.Popen([sys.executable, "-m", "swarm_ros", "run", *RUN, "--out", str(out)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _wait_ticks(out, 200_000)
    pids = list(_nodes(out).values())
    launcher.kill()
    killed = time.monotonic()
    while time.monotonic() - killed < 20:
        alive = [p for p in pids if Path(f"/proc/{p}").exists()
                 and Path(f"/proc/{p}/stat").read_text().split(")")[-1].split()[0] != "Z"]
        if not alive:
            break
        time.sleep(0.005)
    took = time.monotonic() - killed
    launcher.wait()
    return took


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3)
    args = parser.parse_args()
    backs, exits = [], []
    for k in range(args.trials):
        with tempfile.TemporaryDirectory(prefix="swarm_ros-bench-faults-") as tmp:
            backs.append(restart_trial(Path(tmp)))
            exits.append(launcher_trial(Path(tmp)))
        print(f"trial {k + 1}: kill -> batch back in the lockstep {backs[-1]:.2f} s; "
              f"launcher SIGKILL -> all nodes gone {exits[-1]:.2f} s", flush=True)
    print(f"restart to resume (SIGKILL of a robot batch -> its new process back, snapshot sent): "
          f"median {statistics.median(backs):.2f} s, max {max(backs):.2f} s")
    print(f"node exit after the launcher's SIGKILL: median {statistics.median(exits):.2f} s, "
          f"max {max(exits):.2f} s (target < 2 s: {'MET' if max(exits) < 2 else 'NOT MET'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
