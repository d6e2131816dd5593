#!/usr/bin/env python3
"""Benchmark the rubenstein algorithm over the ROS 2 graph: each process's CPU per tick against the in-process tick.

The star with 1,024 robots, ``--ticks`` ticks from tick 0 (the pack waiting, then the first edge-followers),
as the README's command runs it (``swarm-ros run``, recording on), for K = 1, 2, 4 robot-batch processes,
``--rounds`` rounds. The in-process engine runs the same ticks in this process for the reference
(``RubensteinRun.run``, compiled kernels loaded first). Each node's CPU is what it reports in its log when it
ends ("done, ... (S s of CPU)") less what it had spent when it was ready ("ready, ... (S s of CPU"): its
imports and ROS start-up are not a tick's work. The robot batches' share should follow the robots they
host: a batch's CPU per tick against the in-process tick shows it. Prints, per K, the wall time, the world's,
the monitor's and each batch's CPU per tick in ms, and the in-process tick in ms.

    .venv/bin/python scripts/bench_rubenstein_graph.py [--rounds 3] [--ticks 2000] [--processes 1 2 4] [--smoke]
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from swarm_ros.core.params import Settings
from swarm_ros.core.rubenstein.run import RubensteinRun

DONE = re.compile(r"\[(\w+)\]: done, [\d.]+ s after the process started \(([\d.]+) s of CPU\)")
READY = re.compile(r"\[(\w+)\]: ready, [\d.]+ s after the process started \(([\d.]+) s of CPU")


def in_process_ms(shape: str, robots: int, ticks: int) -> float:
    shape_, params = Settings(shape=shape, algorithm="rubenstein", robots=robots, seed=1).resolve()
    RubensteinRun(shape_, params).run(5)  # the kernels loaded
    run = RubensteinRun(shape_, params)
    t0 = time.process_time()
    run.run(ticks)
    return (time.process_time() - t0) * 1000 / ticks


def graph(shape: str, robots: int, ticks: int, processes: int) -> tuple[float, dict[str, float]]:
    """(wall seconds, CPU seconds by node) of one ``swarm-ros run``."""
    with tempfile.TemporaryDirectory(prefix="bench-rubenstein-") as tmp:
        out = Path(tmp) / "run"
        command = [sys.executable, "-m", "swarm_ros", "run", "--algorithm", "rubenstein", "--shape", shape]
        command += ["--robots", str(robots), "--seed", "1", "--max-ticks", str(ticks), "--quiet", "--out", str(out)]
        t0 = time.perf_counter()
        done = subprocess.run([*command, "--processes", str(processes)], capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if done.returncode != 0:
            raise SystemExit(f"bench: swarm-ros run failed: {done.stderr.strip()[-500:]}")
        cpu: dict[str, float] = {}
        for log in (out / "logs").glob("*.log"):
            text = log.read_text()
            for node, seconds in DONE.findall(text):
                cpu[node] = cpu.get(node, 0.0) + float(seconds)
            for node, seconds in READY.findall(text):  # start-up (imports, ROS) is not a tick's work
                cpu[node] = cpu.get(node, 0.0) - float(seconds)
        return wall, cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--ticks", type=int, default=2000)
    parser.add_argument("--robots", type=int, default=1024)
    parser.add_argument("--shape", default="star")
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--smoke", action="store_true", help="one round of 50 ticks, 100 robots, K = 2 (CI)")
    args = parser.parse_args()
    if args.smoke:
        args.rounds, args.ticks, args.robots, args.processes = 1, 50, 100, [2]
    ref = [in_process_ms(args.shape, args.robots, args.ticks) for _ in range(args.rounds)]
    print(f"{args.shape}, {args.robots} robots, ticks 1-{args.ticks}, {args.rounds} rounds")
    print(f"in-process tick: {statistics.median(ref):.3f} ms (range {min(ref):.3f}-{max(ref):.3f})")
    for k in args.processes:
        rows = [graph(args.shape, args.robots, args.ticks, k) for _ in range(args.rounds)]
        walls = [w for w, _ in rows]
        print(f"K = {k}: wall {statistics.median(walls):.1f} s (range {min(walls):.1f}-{max(walls):.1f})")
        for node in sorted(rows[0][1]):
            per_tick = [cpu[node] * 1000 / args.ticks for _, cpu in rows if node in cpu]
            ratio = statistics.median(per_tick) / statistics.median(ref)
            print(
                f"  {node:<16} CPU {statistics.median(per_tick):7.3f} ms/tick "
                f"(range {min(per_tick):.3f}-{max(per_tick):.3f}), {ratio:.2f}x the in-process tick"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
