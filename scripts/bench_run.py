#!/usr/bin/env python3
"""The README's main command, ``swarm-ros run --shape star`` (K = 2, recording and bag on), A/B against a base tree.

    .venv/bin/python scripts/bench_run.py --before /tmp/base [--pairs 5] [--warm 1] [-- extra run flags]

``--before DIR`` is a checkout of the base revision (``git archive <rev> | tar -x -C DIR``); its runs take the package
from there (PYTHONPATH), this tree's from here. The two alternate, pair by pair, after ``--warm`` unmeasured runs
of each (1: numba's cache, the OS's file cache). Per side: the whole command's seconds, the run's own (summary.json's
``wall_seconds``, tick 0 to the outcome) and the command's CPU seconds (its children's), as median (min-max); then
this tree's over the base's, per pair, as median (min-max). Both runs' metrics.csv and final_state.csv must be
byte-identical, or the script says so and exits 1.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def timed(argv: list[str], env: dict[str, str], cwd: Path | None = None) -> tuple[float, float, str]:
    """(seconds, CPU seconds of it and its children) of one command, and its stderr; exits in one line if it fails."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    done = subprocess.run(argv, env=env, cwd=cwd, capture_output=True, text=True)
    took = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv[2:4])} failed: {done.stderr.strip()[-2000:]}")
    return took, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), done.stderr


def one(tree: Path, out: Path, flags: list[str]) -> tuple[float, float, float]:
    """(command seconds, run seconds, CPU seconds) of one ``swarm-ros run`` with the package from ``tree``."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    env.pop("ROS_DOMAIN_ID", None)
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # as a user runs it: bytecode caches written (docs/benchmarks.md)
    took, cpu, _ = timed([sys.executable, "-m", "swarm_ros", "run", *flags, "--out", str(out), "--quiet"], env)
    return took, float(json.loads((out / "summary.json").read_text())["wall_seconds"]), cpu


def _spread(values: list[float], fmt: str = "{:.2f}") -> str:
    return f"{fmt.format(statistics.median(values))} ({fmt.format(min(values))}-{fmt.format(max(values))})"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, required=True, help="a checkout of the base revision")
    parser.add_argument("--pairs", type=int, default=5)
    parser.add_argument("--warm", type=int, default=1, help="unmeasured runs of each tree first (default: 1)")
    parser.add_argument("flags", nargs="*", help="run flags (default: --shape star)")
    args = parser.parse_args()
    if args.pairs < 1 or args.warm < 0:
        parser.error(f"--pairs {args.pairs} --warm {args.warm}: at least 1 pair, and no fewer than 0 warm runs")
    if not (args.before / "swarm_ros" / "__init__.py").is_file():
        parser.error(f"--before {args.before}: no swarm_ros package there")
    flags = args.flags or ["--shape", "star"]
    sides = {"base": args.before.resolve(), "this": HERE}
    got: dict[str, list[tuple[float, float, float]]] = {name: [] for name in sides}
    with tempfile.TemporaryDirectory(prefix="swarm_ros-bench-run-") as tmp:
        base = Path(tmp)
        for warm in range(args.warm):  # unmeasured: caches
            for name, tree in sides.items():
                one(tree, base / f"warm-{name}-{warm}", flags)
        for pair in range(args.pairs):
            for name, tree in sides.items():
                out = base / f"{name}-{pair}"
                got[name].append(one(tree, out, flags))
                if name == "this":
                    for f in ("metrics.csv", "final_state.csv"):
                        if (out / f).read_bytes() != (base / f"base-{pair}" / f).read_bytes():
                            print(f"pair {pair + 1}: {f} differs from the base's", file=sys.stderr)
                            return 1
            print(
                f"pair {pair + 1}: base {got['base'][-1][0]:.2f} s, this {got['this'][-1][0]:.2f} s (command)",
                flush=True,
            )
    print(
        f"\nswarm-ros run {' '.join(flags)} (otherwise the defaults: K = 2, recording and bag on), {args.pairs} pairs, "
        "alternating"
    )
    print(f"{'':>6} {'command s':>20} {'run s':>20} {'CPU s':>20}")
    for name in sides:
        cols = [_spread([r[i] for r in got[name]]) for i in range(3)]
        print(f"{name:>6} {cols[0]:>20} {cols[1]:>20} {cols[2]:>20}")
    ratios = [_spread([t[i] / b[i] for b, t in zip(got["base"], got["this"], strict=True)], "{:.3f}") for i in range(3)]
    print(f"{'this/base':>6} {ratios[0]:>20} {ratios[1]:>20} {ratios[2]:>20}")
    print("metrics.csv and final_state.csv: identical in every pair")
    return 0


if __name__ == "__main__":
    sys.exit(main())
