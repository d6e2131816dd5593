#!/usr/bin/env python3
"""Time the whole paper protocol at vision 1 (6 shapes x 6 group sizes x 10 runs = 360 runs).

Runs ``swarm-ros experiment config/experiments/paper.yaml`` into a scratch directory,
as a user would (worker start-up, results file, statistics and figures included), and
prints the wall time. Target (issue 11, rules paper): under 60 s on the 2-core machine.

    .venv/bin/python scripts/bench_experiment.py [--jobs J] [--config FILE]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET_SECONDS = 60.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "config/experiments/paper.yaml")
    parser.add_argument("--jobs", type=int, help="worker processes (default: the command's default, all cores)")
    args = parser.parse_args()
    from swarm_ros.experiment import load_experiment
    from swarm_ros.results import read_results

    exp = load_experiment(args.config)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "exp"
        cmd = [sys.executable, "-m", "swarm_ros.cli", "experiment", str(args.config), "--out", str(out), "--quiet"]
        if args.jobs:
            cmd += ["--jobs", str(args.jobs)]
        start = time.perf_counter()
        done = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - start
        if done.returncode != 0:
            sys.exit(f"bench_experiment: the experiment failed: {done.stderr.strip()}")
        rows = read_results(out / "results.csv")
        ticks = sum(r["convergence_tick"] for r in rows)
        in_runs = sum(r["wall_seconds"] for r in rows)
    print(f"{args.config.name}: {len(rows)} runs ({len(exp.shapes)} shapes, {exp.repetitions} repetitions, "
          f"vision {', '.join(f'{v:g}' for v in exp.vision_radius)}, rules {', '.join(exp.rules)}), "
          f"{ticks:,} ticks in all")
    print(f"whole command (workers, results, statistics, figures): {wall:.1f} s")
    print(f"time inside the runs, summed over workers: {in_runs:.1f} s")
    print(f"Target: the paper protocol in under {TARGET_SECONDS:g} s: "
          f"{'MET' if wall < TARGET_SECONDS else 'NOT MET'} ({wall:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
