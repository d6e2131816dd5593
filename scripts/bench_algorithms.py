#!/usr/bin/env python3
"""Benchmark the in-process engine's two algorithms on the star with 1,024 robots: robot-steps per second.

A robot-step is one robot's decision at one tick: under the study's model (darr-niazi) a moving
robot's (stationary robots cost nothing there), under rubenstein every robot not yet joined (a
waiting robot also recomputes its gradient and its position estimate from its neighbours each
tick). Cases, one seed each, ``--rounds`` rounds alternating the two:

  * darr-niazi, star, 1,024 robots: the whole run;
  * rubenstein, star, 1,024 robots: ``--ticks`` ticks from tick 0 (the start-up, then the first
    edge-followers: a whole run lasts tens of thousands of ticks).

Only ``run()`` is timed (set-up and compilation are not). Pinned to one CPU. Prints each case's
robot-steps per second per round, the median and the range, and the ticks per second.

``--before DIR`` measures both cases instead in this tree and in DIR, another checkout (``git archive <commit> |
tar -x -C DIR``), alternating, ``--rounds`` times, each in a fresh process started inside its tree
(``scripts/alternate.py``): each tree's median rate and the ratio this tree / DIR (median and range).

    .venv/bin/python scripts/bench_algorithms.py [--rounds 3] [--ticks 4000] [--smoke]
    .venv/bin/python scripts/bench_algorithms.py --before /tmp/base [--rounds 7]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

from pathlib import Path

from alternate import alternate, child_report, print_ratios

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.core.params import RUBENSTEIN

try:
    from swarm_ros.core.rubenstein.run import COLUMNS, RubensteinRun
except ImportError:  # a tree before the class's rename (--before): the same engine under its old name
    from swarm_ros.core.rubenstein.run import COLUMNS
    from swarm_ros.core.rubenstein.run import KilobotRun as RubensteinRun

ROOT = Path(__file__).resolve().parent.parent

ROBOTS = 1024


def darr_niazi(shape: Shape) -> tuple[float, int, int]:
    """(seconds, ticks, robot-steps) of a whole run of the study's model."""
    sim = Simulation(shape, RunParams(ROBOTS, seed=1))
    t0 = time.perf_counter()
    sim.run()
    secs = time.perf_counter() - t0
    return secs, sim.tick, int(sim.history[:-1, 4].sum())  # moving at the end of tick t decide at t + 1


def rubenstein(shape: Shape, ticks: int) -> tuple[float, int, int]:
    """(seconds, ticks, robot-steps) of the first ``ticks`` ticks of a rubenstein run."""
    run = RubensteinRun(shape, RunParams(ROBOTS, algorithm=RUBENSTEIN, seed=1))
    t0 = time.perf_counter()
    run.run(ticks)
    secs = time.perf_counter() - t0
    h = run.history
    deciding = h[:-1, COLUMNS.index("moving")] + h[:-1, COLUMNS.index("waiting")]
    return secs, run.tick, int(deciding.sum())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--ticks", type=int, default=4000, help="rubenstein ticks timed (default 4000)")
    parser.add_argument("--smoke", action="store_true", help="one round of 300 ticks: that the bench runs (CI)")
    parser.add_argument("--before", type=Path, help="another checkout: measure both cases in both, alternating")
    parser.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)  # a child of --before
    args = parser.parse_args()
    if args.smoke:
        args.rounds, args.ticks = 1, 300
    if args.before is not None:
        print(f"The two algorithms, this tree against {args.before}, {args.rounds} alternating rounds (1 CPU)")
        flags = ["--measure", "--ticks", str(args.ticks)]
        rates = alternate(Path(__file__).resolve(), flags, {"this tree": ROOT, "before": args.before}, args.rounds)
        print(f"M robot-steps/s, median of {args.rounds} rounds:")
        print_ratios(rates, "this tree", "before")
        return 0
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    except (AttributeError, OSError):
        pass
    shape = Shape.load("star")
    Simulation(shape, RunParams(50, max_ticks=3)).run()  # load the kernels
    RubensteinRun(shape, RunParams(50, algorithm=RUBENSTEIN, max_ticks=3)).run()
    if args.measure:  # one round of each, for --before
        (secs, _, steps), (ksecs, _, ksteps) = darr_niazi(shape), rubenstein(shape, args.ticks)
        child_report({"darr-niazi, whole run": steps / secs, f"rubenstein, ticks 1-{args.ticks}": ksteps / ksecs})
        return 0
    results: dict[str, list[tuple[float, int, int]]] = {"darr-niazi": [], "rubenstein": []}
    for r in range(args.rounds):
        order = ("darr-niazi", "rubenstein") if r % 2 == 0 else ("rubenstein", "darr-niazi")
        for name in order:
            results[name].append(darr_niazi(shape) if name == "darr-niazi" else rubenstein(shape, args.ticks))
    print(f"In-process engine, star, {ROBOTS:,} robots, 1 CPU, {args.rounds} rounds (M robot-steps/s):")
    print(f"  {'algorithm':<12} {'timed':<28} {'per round':<28} {'median':>7}  {'ticks/s':>9}")
    for name, runs in results.items():
        rates = [steps / secs / 1e6 for secs, _, steps in runs]
        ticks_s = statistics.median(t / s for s, t, _ in runs)
        timed = "whole run" if name == "darr-niazi" else f"ticks 1-{args.ticks}"
        timed += f" ({runs[0][1]:,} ticks)"
        print(
            f"  {name:<12} {timed:<28} {', '.join(f'{x:.2f}' for x in rates):<28} "
            f"{statistics.median(rates):>7.2f}  {ticks_s:>9,.0f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
