#!/usr/bin/env python3
"""Benchmark the engine in 3D, and 2D against the release before 3D: robot-steps per second on one core.

A robot-step is one moving robot's decision at one tick (as in ``scripts/bench_engine.py``).

3D cases, for each rule set: the torus (1348 robots, the default 65^3 world), its first
2,000 ticks and its whole run; and a ball world at the torus's density with 10,000 robots,
its first 200 ticks. The median of ``--seeds`` seeds.

``--before DIR`` also measures 2D in this tree and in DIR, another checkout (the release
before the 3D model: ``git worktree add /tmp/before d168d39``), alternating, ``--rounds``
times: the star (1036 robots) under each rule set, its first 200 ticks and its whole run,
each in a fresh process pinned to one CPU. It reports each tree's median rate and the
ratio this tree / DIR (median and range over the rounds): the 3D model must leave 2D
within 10% of its speed. Compare ratios within one run: the machines are shared and noisy.

    .venv/bin/python scripts/bench_3d.py [--seeds 3] [--before /tmp/before --rounds 5] [--smoke]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from alternate import alternate, child_report, print_ratios

ROOT = Path(__file__).resolve().parent.parent
RULES = ("paper", "local", "literal")


def _pin() -> str:
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
        return "pinned to 1 CPU"
    except (AttributeError, OSError):
        return "not pinned"


def _timed(sim, ticks: int | None) -> tuple[float, int, int]:
    start = sim.tick
    t0 = time.perf_counter()
    sim.run(max_ticks=ticks)
    secs = time.perf_counter() - t0
    return secs, sim.tick - start, int(sim.history[start:-1, 4].sum())  # moving at t decide at t + 1


def measure_2d(seeds: int) -> dict[str, float]:
    """Median robot-steps/s of the star cases in whichever swarm_ros is on sys.path (child process)."""
    from swarm_ros.core import RunParams, Shape, Simulation

    star = Shape.load("star")
    out = {}
    for rules in RULES:
        Simulation(star, RunParams(robots=50, max_ticks=3, rules=rules)).run()  # load the kernels
        for label, ticks in (("first 200", 200), ("whole run", None)):
            rates = sorted(
                steps / secs
                for secs, _, steps in (
                    _timed(Simulation(star, RunParams(1036, seed=s, rules=rules)), ticks) for s in range(1, seeds + 1)
                )
            )
            out[f"{rules}, star {label}"] = rates[len(rates) // 2]
    return out


def ball_world(robots: int, density: float):
    """A ball of ``robots`` voxels in a 3D world where the robots have ``density`` per free voxel."""
    from swarm_ros.core import Shape, World

    side = int(np.ceil((robots / density) ** (1 / 3)))
    world = World((side + 1) // 2 + 1, 3)
    c = np.arange(-world.radius, world.radius + 1)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    order = np.argsort((x * x + y * y + z * z).ravel(), kind="stable")[:robots]
    mask = np.zeros(world.patch_count, dtype=bool)
    mask[order] = True
    return Shape(name=f"ball{robots}", mask=mask.reshape(world.grid_shape), world=world, source="bench ball")


def bench_3d(seeds: int, smoke: bool = False) -> None:
    from swarm_ros.core import RunParams, Shape, Simulation

    torus = Shape.load("torus")
    balls, ticks = (1_000, 20) if smoke else (10_000, 200)
    ball = ball_world(balls, torus.patches / torus.free_patches)
    cases = [("torus 1348, first 2000 ticks", torus, 1348, 2000), ("torus 1348, whole run", torus, 1348, None)]
    cases = cases[:1] if smoke else cases
    cases.append((f"ball {balls:,} (world {ball.world.size}^3), {ticks} ticks", ball, balls, ticks))
    for rules in RULES[:1] if smoke else RULES:
        Simulation(torus, RunParams(robots=50, max_ticks=3, rules=rules)).run()
        print(f"\nrules {rules}:")
        for label, shape, robots, ticks in cases:
            runs = sorted(
                (_timed(Simulation(shape, RunParams(robots, seed=s, rules=rules)), ticks) for s in range(1, seeds + 1)),
                key=lambda r: r[2] / r[0],
            )
            secs, n, steps = runs[len(runs) // 2]
            print(
                f"  {label:<38} {n:>7} ticks {steps:>12,} robot-steps {secs:8.3f} s "
                f"{steps / secs / 1e6:7.2f} M robot-steps/s"
            )


def compare_2d(before: Path, rounds: int, seeds: int) -> None:
    rates = alternate(
        Path(__file__).resolve(), ["--measure-2d", "--seeds", str(seeds)], {"this tree": ROOT, "before": before}, rounds
    )
    print(f"\n2D against {before} ({rounds} rounds, alternating; M robot-steps/s, median of rounds):")
    print_ratios(rates, "this tree", "before")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="seeds per case (median reported)")
    ap.add_argument("--before", type=Path, help="a checkout of the release before 3D: compare 2D speed with it")
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds of the 2D comparison")
    ap.add_argument("--measure-2d", action="store_true", help=argparse.SUPPRESS)  # a child of --before
    ap.add_argument(
        "--smoke",
        action="store_true",
        help="one seed, small cases: checks the script runs (test_scripts.py); its numbers mean nothing",
    )
    args = ap.parse_args()
    if args.smoke:
        args.seeds = 1
    pinned = _pin()
    if args.measure_2d:
        child_report(measure_2d(args.seeds))  # the tree measured, which the parent checks, and its rates
        return 0
    smoke = "; --smoke: small cases, numbers that mean nothing" if args.smoke else ""
    print(f"swarm_ros 3D engine benchmark ({pinned}; median of {args.seeds} seeds{smoke})")
    bench_3d(args.seeds, args.smoke)
    if args.before is not None:
        compare_2d(args.before, args.rounds, args.seeds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
