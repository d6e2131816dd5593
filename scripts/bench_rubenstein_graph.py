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

``--before DIR`` runs the graph instead in this tree and in DIR, another checkout (``git archive <commit> | tar -x
-C DIR``), each ``swarm-ros run`` started inside its tree, alternating which goes first, after one run in each
that is not counted (it may compile the tree's kernels): each node's CPU per tick, median and range per tree,
and the ratio this tree / DIR.

    .venv/bin/python scripts/bench_rubenstein_graph.py [--rounds 3] [--ticks 2000] [--processes 1 2 4] [--smoke]
    .venv/bin/python scripts/bench_rubenstein_graph.py --before /tmp/base --processes 2 [--rounds 10]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from swarm_ros.core.params import Settings
from swarm_ros.core.rubenstein.run import RubensteinRun

ROOT = Path(__file__).resolve().parent.parent
DONE = re.compile(r"\[(\w+)\]: done, [\d.]+ s after the process started \(([\d.]+) s of CPU\)")
READY = re.compile(r"\[(\w+)\]: ready, [\d.]+ s after the process started \(([\d.]+) s of CPU")


def in_process_ms(shape: str, robots: int, ticks: int) -> float:
    shape_, params = Settings(shape=shape, algorithm="rubenstein", robots=robots, seed=1).resolve()
    RubensteinRun(shape_, params).run(5)  # the kernels loaded
    run = RubensteinRun(shape_, params)
    t0 = time.process_time()
    run.run(ticks)
    return (time.process_time() - t0) * 1000 / ticks


def graph(shape: str, robots: int, ticks: int, processes: int, tree: Path = ROOT) -> tuple[float, dict[str, float]]:
    """(wall seconds, CPU seconds by node) of one ``swarm-ros run`` of ``tree``'s package."""
    with tempfile.TemporaryDirectory(prefix="bench-rubenstein-") as tmp:
        out = Path(tmp) / "run"
        command = [sys.executable, "-m", "swarm_ros", "run", "--algorithm", "rubenstein", "--shape", shape]
        command += ["--robots", str(robots), "--seed", "1", "--max-ticks", str(ticks), "--quiet", "--out", str(out)]
        env = {**os.environ, "PYTHONPATH": str(tree)}  # run from inside the tree: its package, not this one's
        t0 = time.perf_counter()
        done = subprocess.run(
            [*command, "--processes", str(processes)], capture_output=True, text=True, cwd=tree, env=env
        )
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


def compare(before: Path, args: argparse.Namespace) -> None:
    """Each node's CPU per tick in this tree and in ``before``, alternating (see the module's docstring)."""
    trees = {"this tree": ROOT, "before": before}
    for k in args.processes:
        for tree in trees.values():
            graph(args.shape, args.robots, args.ticks, k, tree)  # not counted: the tree's kernels may compile
        got: dict[str, list[dict[str, float]]] = {name: [] for name in trees}
        for r in range(args.rounds):
            for name, tree in list(trees.items())[:: 1 if r % 2 else -1]:
                _, cpu = graph(args.shape, args.robots, args.ticks, k, tree)
                got[name].append({_role(node): s * 1000 / args.ticks for node, s in cpu.items()})
        print(f"K = {k}, CPU per tick in ms, median (range) of {args.rounds} rounds; this tree / before")
        for role in sorted(got["this tree"][0]):
            new, old = ([r[role] for r in got[name]] for name in trees)
            print(
                f"  {role:<14} {statistics.median(new):7.3f} ({min(new):.3f}-{max(new):.3f})  before "
                f"{statistics.median(old):7.3f} ({min(old):.3f}-{max(old):.3f})  "
                f"{statistics.median(new) / statistics.median(old):.3f}"
            )


def _role(node: str) -> str:
    """A node's role whatever a tree names its executable: world, monitor or robot_batch_<k>."""
    return next((role for role in ("world", "monitor") if role in node), node)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--ticks", type=int, default=2000)
    parser.add_argument("--robots", type=int, default=1024)
    parser.add_argument("--shape", default="star")
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--smoke", action="store_true", help="one round of 50 ticks, 100 robots, K = 2 (CI)")
    parser.add_argument("--before", type=Path, help="another checkout: the graph in both, alternating")
    args = parser.parse_args()
    if args.smoke:
        args.rounds, args.ticks, args.robots, args.processes = 1, 50, 100, [2]
    if args.before is not None:
        print(f"{args.shape}, {args.robots} robots, ticks 1-{args.ticks}: this tree against {args.before}")
        compare(args.before, args)
        return 0
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
