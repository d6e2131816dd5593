#!/usr/bin/env python3
"""Benchmark the in-process engine on one core, under every rule set: robot-steps per second and tick cost.

A robot-step is one moving robot's decision at one tick, wandering or walking
(stationary robots cost nothing and are not counted). Cases, for each rule set
(paper, local, literal):

  * star, 1036 robots: the first 200 ticks, and a whole run;
  * a disc-shaped world at the star's density with 10,000 and 100,000 robots: the
    first 200 ticks;

and, under the default rule set (paper), tick cost against the number of moving robots
over the whole star run, with a least-squares fit ``cost = a + b * moving``.

Only ``Simulation.run()`` is timed (set-up and compilation are not), except in the
tick-cost table, which times each ``step()``. A case that runs for less than ``MIN_TIMED_S`` (the star's
first 200 ticks take about 30 ms) is run again from a fresh simulation of the same seed until it has run that
long, and its fastest repetition counts: measured once, one interruption by another process moved it by 20%.
Pinned to one CPU. Compare the numbers as ratios within one run: the machines are shared and noisy. Target
(issue 11): at least 3 M robot-steps/s for ``paper`` on the star.

``--before DIR`` measures every case instead in this tree and in DIR, another checkout
(``git archive <commit> | tar -x -C DIR``), alternating, ``--rounds`` times, each in a fresh
process started inside its tree (``scripts/alternate.py``): each tree's median rate, the ratio
this tree / DIR (median and range over the rounds), and per tree the cost of a robot-step at
100,000 robots against the star's first 200 ticks (issue 47's targets: every case at least
DIR's when DIR is ddd3674; 100,000 robots at most 1.3x the star's cost and at least 1.6x DIR's rate).

    .venv/bin/python scripts/bench_engine.py [--seeds 3] [--rules paper,local,literal] [--smoke]
    .venv/bin/python scripts/bench_engine.py --before /tmp/base [--rounds 3] [--seeds 3] [--rules paper]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.params import RULE_SETS  # here in trees from before core/darr_niazi too (--before)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from alternate import alternate, child_report, print_ratios

ROOT = Path(__file__).resolve().parent.parent

STAR_DENSITY = 1036 / 63**2  # robots per free patch in the default star run
MIN_TIMED_S = 0.3  #: seconds a case is timed for at least, over repetitions (its fastest counts)
MAX_REPEATS = 20


def disc_world(robots: int) -> Shape:
    """A disc of ``robots`` patches in a world where the robots have the star's density."""
    inner = int(np.ceil(np.sqrt(robots / STAR_DENSITY)))
    world = World(radius=(inner + 1) // 2 + 1)
    r = world.radius
    c = np.arange(-r, r + 1)
    x, y = np.meshgrid(c, c)
    d2 = (x * x + y * y).ravel()
    order = np.argsort(d2, kind="stable")[:robots]  # the `robots` patches nearest the origin
    mask = np.zeros(world.patch_count, dtype=bool)
    mask[order] = True
    return Shape(
        name=f"disc{robots}",
        mask=mask.reshape(world.size, world.size),
        world=world,
        source=f"bench disc of {robots} patches",
    )


def timed_run(sim: Simulation, ticks: int | None) -> tuple[float, int, int]:
    """Run ``ticks`` ticks (or to the end) with ``Simulation.run``; (seconds, ticks, robot-steps)."""
    start_row = sim.tick
    t0 = time.perf_counter()
    sim.run(max_ticks=ticks)
    secs = time.perf_counter() - t0
    moving = sim.history[start_row:-1, 4]  # robots moving at the end of tick t decide at tick t + 1
    return secs, sim.tick - start_row, int(moving.sum())


def best_run(make, seed: int, ticks: int | None) -> tuple[float, int, int]:
    """:func:`timed_run` of ``make(seed)``, repeated on a fresh simulation until ``MIN_TIMED_S`` have been timed
    (at most ``MAX_REPEATS`` times); the fastest repetition. A run is deterministic, so every repetition does the
    same work."""
    runs = [timed_run(make(seed), ticks)]
    while sum(r[0] for r in runs) < MIN_TIMED_S and len(runs) < MAX_REPEATS:
        runs.append(timed_run(make(seed), ticks))
    return min(runs, key=lambda r: r[0])


def timed_steps(sim: Simulation) -> tuple[np.ndarray, np.ndarray]:
    """Step to the end one ``step()`` at a time; per tick: seconds and robots that decided."""
    secs, moving = [], []
    clock = time.perf_counter
    while not sim.done:
        m = sim.metrics.moving
        t0 = clock()
        sim.step()
        secs.append(clock() - t0)
        moving.append(m)
    return np.array(secs), np.array(moving)


def cases(rules: str, star: Shape, discs: dict[int, Shape], first_ticks: int) -> list[tuple[str, object, int | None]]:
    """The cases of one rule set: (label, seed -> Simulation, ticks or None for the whole run)."""
    out: list[tuple[str, object, int | None]] = [
        (
            f"star 1036, first {first_ticks} ticks",
            lambda s: Simulation(star, RunParams(1036, seed=s, rules=rules)),
            first_ticks,
        ),
        ("star 1036, whole run", lambda s: Simulation(star, RunParams(1036, seed=s, rules=rules)), None),
    ]
    for n, shape in discs.items():
        out.append(
            (
                f"disc {n:,} (world {shape.world.size}^2), {first_ticks} ticks",
                lambda s, sh=shape, n=n: Simulation(sh, RunParams(n, seed=s, rules=rules)),
                first_ticks,
            )
        )
    return out


def measure(rule_sets: list[str], seeds: int, sizes: tuple[int, ...], first_ticks: int) -> dict[str, float]:
    """Every case's median robot-steps/s over ``seeds`` seeds, in whichever swarm_ros is on sys.path (the child of
    ``--before``)."""
    star, discs = Shape.load("star"), {n: disc_world(n) for n in sizes}
    out = {}
    for rules in rule_sets:
        Simulation(star, RunParams(robots=50, max_ticks=3, rules=rules)).run()  # load the kernels
        for label, make, ticks in cases(rules, star, discs, first_ticks):
            rates = sorted(steps / secs for secs, _, steps in (best_run(make, s, ticks) for s in range(1, seeds + 1)))
            out[f"{rules}, {label}"] = rates[len(rates) // 2]
    return out


def compare(before: Path, rounds: int, seeds: int, rule_sets: list[str], sizes, first_ticks: int) -> None:
    args = ["--measure", "--seeds", str(seeds), "--rules", ",".join(rule_sets)] + ["--smoke"] * (sizes == (2_000,))
    rates = alternate(Path(__file__).resolve(), args, {"this tree": ROOT, "before": before}, rounds)
    print(f"\nAgainst {before} ({rounds} rounds, alternating; M robot-steps/s, median of rounds):")
    print_ratios(rates, "this tree", "before")
    big = max(sizes)
    print(f"\nCost of a robot-step at {big:,} robots against the star's first {first_ticks} ticks (median of rounds):")
    for name, runs in rates.items():
        for rules in rule_sets:
            star = f"{rules}, star 1036, first {first_ticks} ticks"
            disc = next(case for case in runs[0] if case.startswith(f"{rules}, disc {big:,} "))
            ratio = sorted(r[star] / r[disc] for r in runs)
            print(f"  {name:<10} {rules:<8} {np.median(ratio):5.2f}x  ({ratio[0]:.2f}-{ratio[-1]:.2f})")


def report(label: str, secs: float, ticks: int, steps: int) -> float:
    rate = steps / secs
    print(
        f"{label:<34} {ticks:>7} ticks {steps:>12,} robot-steps {secs:8.3f} s "
        f"{rate / 1e6:8.2f} M robot-steps/s {ticks / secs:10,.0f} ticks/s"
    )
    return rate


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--seeds", type=int, default=3, help="repetitions of each case (median reported)")
    ap.add_argument("--rules", default=",".join(RULE_SETS), help="rule sets to measure (default: all)")
    ap.add_argument(
        "--smoke",
        action="store_true",
        help="one seed, small cases: checks the script runs (test_scripts.py); its numbers mean nothing",
    )
    ap.add_argument("--before", type=Path, help="another checkout: measure every case in both, alternating")
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds of --before")
    ap.add_argument("--measure", action="store_true", help=argparse.SUPPRESS)  # a child of --before
    args = ap.parse_args()
    rule_sets = [r for r in args.rules.split(",") if r]
    sizes, first_ticks = ((2_000,), 20) if args.smoke else ((10_000, 100_000), 200)
    if args.smoke:
        args.seeds = 1
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
        pinned = "pinned to 1 CPU"
    except (AttributeError, OSError):
        pinned = "not pinned"
    if args.measure:
        child_report(measure(rule_sets, args.seeds, sizes, first_ticks))
        return 0
    if args.before is not None:
        print(f"swarm_ros engine benchmark against {args.before} ({pinned}; median of {args.seeds} seeds a round)")
        compare(args.before, args.rounds, args.seeds, rule_sets, sizes, first_ticks)
        return 0
    star = Shape.load("star")
    for rules in rule_sets:  # compile / load the kernels
        Simulation(star, RunParams(robots=50, max_ticks=3, rules=rules)).run()
    smoke = "; --smoke: small cases, numbers that mean nothing" if args.smoke else ""
    print(f"swarm_ros engine benchmark ({pinned}; median of {args.seeds} seeds{smoke})")

    def median_case(label, make, ticks):
        runs = sorted((best_run(make, seed, ticks) for seed in range(1, args.seeds + 1)), key=lambda r: r[2] / r[0])
        return report(label, *runs[len(runs) // 2])

    discs = {n: disc_world(n) for n in sizes}
    results = {}
    for rules in rule_sets:
        print(f"\nrules {rules}:")
        rates = [median_case(label, make, ticks) for label, make, ticks in cases(rules, star, discs, first_ticks)]
        first, whole = rates[0], rates[1]
        per_size = {1036: first, **dict(zip(discs, rates[2:]))}
        print("  cost per robot-step across swarm sizes (first 200 ticks; flat = linear in N):")
        for n, rate in per_size.items():
            print(
                f"    {n:>7,} robots: {1e9 / rate:7.1f} ns per robot-step  ({per_size[1036] / rate:5.2f} x the star's)"
            )
        results[rules] = (first, whole)

    if "paper" in rule_sets:
        secs, moving = timed_steps(Simulation(star, RunParams(1036, seed=1)))
        print("\nTick cost vs moving robots, rules paper, star seed 1, one step() call per tick (so including")
        print("the Python call overhead that run() spreads over many ticks):")
        edges = [0, 25, 50, 100, 200, 400, 700, 1100]
        print(f"  {'moving robots':>15} {'ticks':>7} {'us/tick':>9} {'ns/robot-step':>14}")
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = (moving >= lo) & (moving < hi)
            if sel.any():
                print(
                    f"  {f'{lo}-{hi - 1}':>15} {sel.sum():>7} {1e6 * secs[sel].mean():9.1f} "
                    f"{1e9 * secs[sel].sum() / max(moving[sel].sum(), 1):14.1f}"
                )
        b, a = np.polyfit(moving, secs, 1)
        pred = a + b * moving
        r2 = 1 - ((secs - pred) ** 2).sum() / ((secs - secs.mean()) ** 2).sum()
        print(f"  least squares: cost = {1e6 * a:.2f} us + {1e9 * b:.1f} ns x moving  (R^2 = {r2:.3f})")
        target = 3e6
        print()
        for label, rate in zip(("first 200 ticks", "whole run"), results["paper"]):
            print(
                f"Target >= 3 M robot-steps/s, rules paper, star {label}: "
                f"{'MET' if rate >= target else 'NOT MET'} ({rate / 1e6:.2f} M)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
