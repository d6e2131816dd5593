#!/usr/bin/env python3
"""The graph at scale: disc shapes of 10,000 robots and more, at the star's density, K = 1, 2, 4 against
the in-process engine.

A disc of N patches (N robots) in a world whose area holds N robots at the star's density
(1,036 robots in a 65 x 65 world): radius 100 for 10,000. Each run stops after ``--ticks``
ticks. Printed per run: seconds of the run (tick 0 to its end) and of the whole command, and
each node's CPU per tick (its CPU from "ready" to "done" in its log, over the ticks); then
what each batch receives per tick (the world's rows of the robots that changed, 40 bytes
each, from the in-process run of the same seed). docs/ros_graph.md discusses the numbers.

    .venv/bin/python scripts/bench_scale.py [--robots 10000 50000] [--processes 1 2 4] [--ticks 300]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

STAR_DENSITY = 1036 / 65 ** 2  #: robots per patch of the star's world
_CPU = re.compile(r"\[(\w+)\]: (ready|done), .* \((\d+\.\d+) s of CPU\)")


def disc_file(robots: int, folder: Path) -> tuple[Path, int]:
    """A text shape file of a disc of about ``robots`` patches, and the world radius for it."""
    r = math.sqrt(robots / math.pi)
    half = math.ceil(r) + 1
    yy, xx = np.mgrid[-half:half + 1, -half:half + 1]
    mask = xx ** 2 + yy ** 2 <= r * r
    path = folder / f"disc{robots}.txt"
    path.write_text("".join("".join("#" if v else "." for v in row) + "\n" for row in mask))
    return path, round(math.sqrt(robots / STAR_DENSITY) / 2)


def _swarm(args: list[str]) -> float:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "swarm_ros", *args, "--quiet", "--overwrite"],
                          capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"bench_scale: swarm-ros {args[0]} failed: {done.stderr.strip()[-500:]}")
    return time.perf_counter() - t0


def node_cpu(logs: Path, ticks: int) -> dict[str, float]:
    """Milliseconds of CPU per tick of each node, between its 'ready' and 'done' lines."""
    cpu: dict[str, dict[str, float]] = {}
    for log in logs.glob("*.log"):
        for m in _CPU.finditer(log.read_text(errors="replace")):
            cpu.setdefault(m[1], {})[m[2]] = float(m[3])
    return {node: 1000 * (c["done"] - c["ready"]) / ticks for node, c in sorted(cpu.items())
            if "ready" in c and "done" in c}


def received_per_tick(shape_file: Path, radius: int, ticks: int, seed: int) -> float:
    """Mean bytes of /swarm/robots per tick (every batch receives all of it)."""
    from swarm_ros.core import RunParams, Shape, Simulation
    from swarm_ros.core.grid import World

    shape = Shape.load(shape_file, World(radius))
    sim = Simulation(shape, RunParams(robots=shape.patches, seed=seed, max_ticks=ticks))
    rows = []
    while not sim.done:
        sim.step()
        rows.append(np.union1d(sim.last_joins()[0], sim.last_removed).size)
    return 40 * float(np.mean(rows)) + 300


def scale(sizes: list[int], processes: list[int], tmp: Path, ticks: int = 300, seed: int = 1,
          repeats: int = 1) -> None:
    for robots in sizes:
        shape, radius = disc_file(robots, tmp)
        common = ["--shape", str(shape), "--world-radius", str(radius), "--seed", str(seed), "--max-ticks",
                  str(ticks)]
        print(f"\n{robots:,} robots (disc, world radius {radius}), {ticks} ticks, seed {seed}, recording and bag on")
        print(f"{'engine':<22} {'run s':>8} {'command s':>10} {'vs in-process':>14}   CPU per tick of each node (ms)")
        runs = [_swarm(["simulate", *common, "--out", str(tmp / f"sim{robots}")]) for _ in range(repeats)]
        sim_run = json.loads((tmp / f"sim{robots}" / "summary.json").read_text())["wall_seconds"]
        print(f"{'in-process':<22} {sim_run:>8.2f} {statistics.median(runs):>10.2f} {1:>13.1f}x")
        for k in processes:
            out = tmp / f"run{robots}-{k}"
            whole = statistics.median(_swarm(["run", *common, "--processes", str(k), "--out", str(out)])
                                      for _ in range(repeats))
            run = json.loads((out / "summary.json").read_text())["wall_seconds"]
            cpu = ", ".join(f"{node} {ms:.1f}" for node, ms in node_cpu(out / "logs", ticks).items())
            print(f"{f'ROS 2 graph, K = {k}':<22} {run:>8.2f} {whole:>10.2f} {run / sim_run:>13.1f}x   {cpu}")
        print(f"each batch receives {received_per_tick(shape, radius, ticks, seed) / 1e3:,.1f} kB per tick of "
              f"/swarm/robots (and sends its share of the decisions, 48 bytes a moving robot)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10_000])
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--ticks", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scale(args.robots, args.processes, Path(tmp), args.ticks, repeats=args.repeats)


if __name__ == "__main__":
    main()
