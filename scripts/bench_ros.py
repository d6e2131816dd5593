#!/usr/bin/env python3
"""Benchmark the ROS 2 graph against the in-process engine on the full star (1036 robots).

For K = 1, 2, 4 robot-batch processes it runs ``swarm-ros run`` and reads two times:
the run itself (the monitor's ``wall_seconds``: tick 0 to the outcome) and the whole
command (process start-up, discovery and shutdown included). The same run (same seed)
is timed in process twice: ``Simulation.run()`` (many ticks per compiled call, the
engine ``simulate`` uses) and one ``Simulation.step()`` per tick (one Python call per
tick, the distributed engine's granularity without the messages). Ratios are taken
within this one invocation, since the machine is shared and noisy.

Targets (issue 3): >= 500 ticks/s with K = 2; within 4x of the in-process engine.

    .venv/bin/python scripts/bench_ros.py [--seed 1] [--repeats 2] [--processes 1 2 4]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from swarm_ros.core import RunParams, Shape, Simulation


def in_process(seed: int, repeats: int) -> tuple[int, float, float]:
    """(ticks, best seconds with run(), best seconds with step() per tick) for the star."""
    shape = Shape.load("star")
    params = RunParams(robots=shape.patches, seed=seed)
    Simulation(shape, params).run(max_ticks=10)  # compile
    fast, stepped, ticks = [], [], 0
    for _ in range(repeats):
        sim = Simulation(shape, params)
        t0 = time.perf_counter()
        sim.run()
        fast.append(time.perf_counter() - t0)
        ticks = sim.tick
        sim = Simulation(shape, params)
        t0 = time.perf_counter()
        while not sim.done:
            sim.step()
        stepped.append(time.perf_counter() - t0)
    return ticks, min(fast), min(stepped)


def over_graph(seed: int, processes: int, out: Path) -> tuple[int, float, float]:
    """(ticks, run seconds as the monitor measured them, whole command seconds)."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "swarm_ros.cli", "run", "--shape", "star", "--seed", str(seed),
                           "--processes", str(processes), "--out", str(out), "--overwrite", "--quiet"],
                          capture_output=True, text=True)
    whole = time.perf_counter() - t0
    if done.returncode != 0:
        sys.exit(f"bench_ros: swarm-ros run failed: {done.stderr.strip()}")
    summary = json.loads((out / "summary.json").read_text())
    return summary["convergence_tick"], summary["wall_seconds"], whole


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=2, help="runs per case; the best is kept")
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    args = parser.parse_args()

    ticks, fast, stepped = in_process(args.seed, args.repeats)
    fast_rate, step_rate = ticks / fast, ticks / stepped
    print(f"star, 1036 robots, seed {args.seed}: {ticks} ticks")
    print(f"{'engine':<34} {'run s':>8} {'ticks/s':>10} {'vs run()':>9} {'vs step()':>10} {'command s':>10}")
    print(f"{'in-process, run()':<34} {fast:>8.3f} {fast_rate:>10,.0f} {1:>8.1f}x {fast_rate / step_rate:>9.2f}x")
    print(f"{'in-process, step() per tick':<34} {stepped:>8.3f} {step_rate:>10,.0f} "
          f"{step_rate / fast_rate:>8.3f}x {1:>9.2f}x")
    rates = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in args.processes:
            best = None
            for r in range(args.repeats):
                got = over_graph(args.seed, k, Path(tmp) / f"k{k}-{r}")
                if got[0] != ticks:
                    sys.exit(f"bench_ros: the graph ran {got[0]} ticks, the in-process engine {ticks}")
                best = got if best is None or got[1] < best[1] else best
            _, secs, whole = best
            rate = ticks / secs
            rates[k] = rate
            print(f"{f'ROS 2 graph, K = {k}':<34} {secs:>8.3f} {rate:>10,.0f} {rate / fast_rate:>8.4f}x "
                  f"{rate / step_rate:>9.3f}x {whole:>10.2f}")
    if 2 in rates:
        r2 = rates[2]
        print(f"Target >= 500 ticks/s with K = 2: {'MET' if r2 >= 500 else 'NOT MET'} ({r2:,.0f})")
        print(f"Target within 4x of the in-process engine (run()): {'MET' if fast_rate / r2 <= 4 else 'NOT MET'} "
              f"({fast_rate / r2:,.0f}x slower)")
        print(f"Same, against one step() per tick: {'MET' if step_rate / r2 <= 4 else 'NOT MET'} "
              f"({step_rate / r2:,.1f}x slower)")


if __name__ == "__main__":
    main()
