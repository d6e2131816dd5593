"""How fast the graph recovers from a SIGKILL of each kind of node process, and what the fault costs the run.

    .venv/bin/python scripts/bench_faults.py [--trials 3] [--at 1000] [--smoke]

Each trial runs ``swarm-ros run`` on the star (rules local, seed 5, 3,604 ticks, K = 3, recording and bag on,
the README's defaults) once without a fault, then once for each node kind with that process SIGKILLed once the
world has saved tick ``--at``. Reported per kind, as median (min-max) over the trials:

- kill -> moving: from the SIGKILL until the run moves again. For a robot batch and the world: the world saves
  a tick past the one it had stopped at 50 ms after the kill (read from its checkpoint's header, as a
  restarted world reads it). For the monitor: the world hears a held report past the last one it had then
  (the same header); the world runs on up to ``monitor_window`` ticks without the monitor, then waits.
- slowdown: the faulted command's wall time over the unfaulted one's, in the same trial.
- same: metrics.csv and final_state.csv byte-identical to the unfaulted run's.

Then, as before, the launcher itself is killed: the time until none of its node processes is alive (they get
SIGHUP from the kernel through PR_SET_PDEATHSIG).

First, in this process, what being restartable costs each tick: the world's checkpoint write, and the
monitor's making its bag durable (a tick of the star: 300 changed rows, a 12-kB rows message).
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

import numpy as np

RUN = ["--shape", "star", "--seed", "5", "--rules", "local", "--processes", "3", "--quiet"]
KINDS = ("robot_batch_1", "world", "monitor")
_MAGIC, _DONE, _MONITOR = 0, 7, 8  # the checkpoint header's int64s (swarm_ros.protocol.checkpoint)


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


def _header(out: Path) -> np.ndarray | None:
    for logs in out.parent.glob(f".{out.name}.logs-*"):
        try:
            head = np.fromfile(logs / "world.checkpoint", dtype=np.int64, count=9)
        except (OSError, ValueError):
            return None
        if head.size == 9 and head[_MAGIC] != 0:
            return head
    return None


def _wait(out: Path, column: int, above: int, timeout: float = 180) -> float:
    """Poll the checkpoint header until ``column`` exceeds ``above``; return time.monotonic() then."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        head = _header(out)
        if head is not None and head[column] > above:
            return time.monotonic()
        time.sleep(0.001)
    raise SystemExit(f"the run never passed {above} (header column {column})")


def one_run(base: Path, name: str, victim: str | None, at: int) -> tuple[float, float | None, Path]:
    """(command seconds, kill -> moving seconds or None, run directory)."""
    out = base / name
    began = time.monotonic()
    launcher = subprocess.Popen(
        [sys.executable, "-m", "swarm_ros", "run", *RUN, "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    moving = None
    if victim is not None:
        _wait(out, _DONE, at - 1)
        pid = _nodes(out)[victim]
        column = _MONITOR if victim == "monitor" else _DONE
        os.kill(pid, signal.SIGKILL)
        killed = time.monotonic()
        # where the run stops: what was under way when the process died lands within moments (the world
        # applies a tick whose decisions were in, a report in flight arrives); a restart takes over a second
        time.sleep(0.05)
        before = int(_header(out)[column])
        moving = _wait(out, column, before) - killed
    _, err = launcher.communicate(timeout=600)
    if launcher.returncode != 0:
        raise SystemExit(f"{name}: run failed: {err.strip()}")
    return time.monotonic() - began, moving, out


def launcher_trial(base: Path, at: int = 300) -> float:
    out = base / "launcher"
    launcher = subprocess.Popen(
        [sys.executable, "-m", "swarm_ros", "run", *RUN, "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    _wait(out, _DONE, at)
    pids = list(_nodes(out).values())
    launcher.kill()
    killed = time.monotonic()
    while time.monotonic() - killed < 20:
        alive = [
            p
            for p in pids
            if Path(f"/proc/{p}").exists() and Path(f"/proc/{p}/stat").read_text().split(")")[-1].split()[0] != "Z"
        ]
        if not alive:
            break
        time.sleep(0.005)
    took = time.monotonic() - killed
    launcher.wait()
    return took


def tick_costs(base: Path, ticks: int = 3000) -> tuple[float, float, float]:
    """Microseconds per tick: the world's checkpoint write; the monitor's bag writes of a tick without and with
    making them durable."""
    from swarm_ros.core.metrics import METRIC_COLUMNS
    from swarm_ros.protocol.checkpoint import Checkpoint
    from swarm_ros.protocol.rows import DECISION_ROW, ROBOT_ROW
    from swarm_ros.ros import graph as msgs
    from swarm_ros.ros.bag_writer import BagRecorder

    ck = Checkpoint(base / "ck", 1036, 100_000, len(METRIC_COLUMNS), 130)
    ck.create()
    rows, applied = np.zeros(300, ROBOT_ROW), np.zeros(300, DECISION_ROW)
    rows["id"] = np.arange(300) + 4
    metrics = np.zeros(len(METRIC_COLUMNS), dtype=np.int64)
    began = time.perf_counter()
    for t in range(ticks):
        ck.write(t, rows, applied, metrics)
    write = (time.perf_counter() - began) / ticks * 1e6
    bag, out = BagRecorder(base / "run"), []
    for durable in (False, True):
        began = time.perf_counter()
        for _ in range(ticks):
            bag.write(msgs.ROBOTS, bytes(12_000))
            bag.write(msgs.METRICS, bytes(200))
            bag.write(msgs.CLOCK, bytes(20))
            if durable:
                bag.durable()
        out.append((time.perf_counter() - began) / ticks * 1e6)
    bag.close()
    return write, out[0], out[1]


def _same(a: Path, b: Path) -> bool:
    return all((a / f).read_bytes() == (b / f).read_bytes() for f in ("metrics.csv", "final_state.csv"))


def _spread(values: list[float], fmt: str = "{:.2f}") -> str:
    return f"{fmt.format(statistics.median(values))} ({fmt.format(min(values))}-{fmt.format(max(values))})"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--at", type=int, default=1000, help="kill once the world has saved this tick")
    parser.add_argument(
        "--smoke",
        action="store_true",
        help="a batch killed in runs of 400 ticks, once: checks the script runs (test_scripts.py); no real numbers",
    )
    args = parser.parse_args()
    if args.smoke:
        RUN.extend(["--max-ticks", "400"])
        args.trials, args.at = 1, 100
    kinds = KINDS[:1] if args.smoke else KINDS  # --smoke: a robot batch only
    back: dict[str, list[float]] = {k: [] for k in kinds}
    slow: dict[str, list[float]] = {k: [] for k in kinds}
    same: dict[str, list[bool]] = {k: [] for k in kinds}
    plain, exits = [], []
    with tempfile.TemporaryDirectory(prefix="swarm_ros-bench-faults-") as tmp:
        write, bag, durable = tick_costs(Path(tmp), 100 if args.smoke else 3000)
    print(
        f"per tick: the world's checkpoint {write:.1f} us; the monitor's bag {bag:.1f} us, made durable "
        f"{durable:.1f} us",
        flush=True,
    )
    for trial in range(args.trials):
        with tempfile.TemporaryDirectory(prefix="swarm_ros-bench-faults-") as tmp:
            base = Path(tmp)
            seconds, _, ref = one_run(base, "plain", None, args.at)
            plain.append(seconds)
            for kind in kinds:
                took, moving, out = one_run(base, kind, kind, args.at)
                back[kind].append(moving)
                slow[kind].append(took / seconds)
                same[kind].append(_same(ref, out))
            exits.append(launcher_trial(base, min(300, args.at)))
        print(
            f"trial {trial + 1}: plain {seconds:.2f} s; "
            + "; ".join(f"{k} back in {back[k][-1]:.2f} s, x{slow[k][-1]:.2f}" for k in kinds),
            flush=True,
        )
    print(
        f"\nstar, rules local, seed 5, K = 3, recording and bag on{'; --smoke: 400 ticks' if args.smoke else ''}; "
        f"kill once tick {args.at} is saved; "
        f"{args.trials} trials; unfaulted command {_spread(plain)} s"
    )
    print(f"{'killed':>14} {'kill -> moving s':>22} {'slowdown':>22} {'same':>6}")
    for k in kinds:
        print(f"{k:>14} {_spread(back[k]):>22} {_spread(slow[k], '{:.2f}x'):>22} {'yes' if all(same[k]) else 'NO':>6}")
    print(
        f"node exit after the launcher's SIGKILL: {_spread(exits)} s (target < 2 s: "
        f"{'MET' if max(exits) < 2 else 'NOT MET'})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
