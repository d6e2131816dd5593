#!/usr/bin/env python3
"""How a 3D run's convergence time depends on the world's size: the torus and the box at their voxel
counts, rules paper, vision 1, seeds 1-10, in worlds of radius 13 (10 for the box), 20 and 32.

The density (robots per free voxel) falls with the cube of the radius; docs/results.md
("Three dimensions") uses this table to compare 3D times with 2D ones at a like density.

    .venv/bin/python scripts/study_3d_density.py [--seeds 10]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from swarm_ros.core import RunParams, Shape, Simulation, World

CASES = (("torus", (13, 20, 32)), ("box", (10, 20, 32)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="runs per case (seeds 1..N)")
    ap.add_argument(
        "--smoke",
        action="store_true",
        help="two seeds of the smallest torus: checks the script runs (test/test_scripts.py); its numbers mean nothing",
    )
    args = ap.parse_args()
    cases = (("torus", (13,)),) if args.smoke else CASES
    if args.smoke:
        args.seeds = 2
    print(f"| shape | world | robots per free voxel | mean time (ticks), n = {args.seeds} | 95% half-width |")
    print("|---|---|---:|---:|---:|")
    from scipy import stats

    for name, radii in cases:
        for radius in radii:
            shape = Shape.load(name, World(radius))
            ticks = []
            for seed in range(1, args.seeds + 1):
                sim = Simulation(shape, RunParams(robots=shape.patches, seed=seed))
                sim.run()
                ticks.append(sim.tick)
            t = np.array(ticks, dtype=float)
            half = stats.t.ppf(0.975, t.size - 1) * t.std(ddof=1) / np.sqrt(t.size) if t.size > 1 else float("nan")
            print(
                f"| {name} | {shape.world.describe()} | {shape.patches / shape.free_patches:.3f} | "
                f"{t.mean():.0f} | {half:.0f} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
