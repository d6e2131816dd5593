#!/usr/bin/env python3
"""Time the whole paper protocol at vision 1 (6 shapes x 6 group sizes x 10 runs = 360 runs).

Runs ``swarm-ros experiment config/experiments/paper.yaml`` into a scratch directory,
as a user would (worker start-up, results file, statistics and figures included), once
per executor (``local`` worker processes, then ``dask``, a LocalCluster of as many
workers), and prints the wall time and runs per second of each.
Targets: the paper protocol under 60 s on the 2-core machine (issue 11, rules paper); the
Dask executor at least 80% of the local executor's runs per second (issue 14).

    .venv/bin/python scripts/bench_experiment.py [--jobs J] [--config FILE] [--executors local dask]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_SECONDS = 60.0
DASK_SHARE = 0.8


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "config/experiments/paper.yaml")
    parser.add_argument("--jobs", type=int, help="worker processes (default: the command's default, all cores)")
    parser.add_argument("--executors", nargs="+", choices=("local", "dask"), default=["local", "dask"])
    parser.add_argument("--repeats", type=int, default=1, help="whole commands per executor (min, median, max)")
    args = parser.parse_args()
    from swarm_ros.app.experiment_file import load_experiment
    from swarm_ros.app.results_file import read_results

    exp = load_experiment(args.config)
    rate = {}
    for executor in args.executors:
        walls = []
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp) / "exp"
                cmd = [
                    sys.executable,
                    "-m",
                    "swarm_ros",
                    "experiment",
                    str(args.config),
                    "--out",
                    str(out),
                    "--quiet",
                    "--executor",
                    executor,
                ]
                if args.jobs:
                    cmd += ["--jobs", str(args.jobs)]
                start = time.perf_counter()
                done = subprocess.run(cmd, capture_output=True, text=True)
                walls.append(time.perf_counter() - start)
                if done.returncode != 0:
                    sys.exit(f"bench_experiment: the experiment failed ({executor}): {done.stderr.strip()}")
                rows = read_results(out / "results.csv")
                ticks = sum(r["convergence_tick"] for r in rows)
                in_runs = sum(r["wall_seconds"] for r in rows)
        wall = statistics.median(walls)
        rate[executor] = len(rows) / wall
        print(
            f"{args.config.name}, executor {executor}: {len(rows)} runs ({len(exp.shapes)} shapes, "
            f"{exp.repetitions} repetitions, vision {', '.join(f'{v:g}' for v in exp.vision_radius)}, "
            f"rules {', '.join(exp.rules)}), {ticks:,} ticks in all"
        )
        print(
            f"  whole command (workers, results, statistics, figures), {len(walls)} runs: median {wall:.1f} s "
            f"(min {min(walls):.1f}, max {max(walls):.1f}), {rate[executor]:.2f} runs/s"
        )
        print(f"  time inside the runs, summed over workers (last run): {in_runs:.1f} s")
        print(
            f"  Target: the paper protocol in under {TARGET_SECONDS:g} s: "
            f"{'MET' if wall < TARGET_SECONDS else 'NOT MET'} ({wall:.1f} s)"
        )
    if {"local", "dask"} <= set(rate):
        ratio = rate["dask"] / rate["local"]
        print(
            f"Target: the Dask executor at >= {DASK_SHARE:.0%} of the local executor's runs/s: "
            f"{'MET' if ratio >= DASK_SHARE else 'NOT MET'} ({ratio:.0%})"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
