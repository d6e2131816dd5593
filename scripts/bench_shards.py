#!/usr/bin/env python3
"""The world's half of a tick split into world shards (swarm_ros.core.shards): each shard's work per tick,
for S = 1, 2, 4, 8 shards, against the one world that does it all today.

Disc shapes at the star's density (as scripts/bench_scale.py), ``--ticks`` ticks, seed 1, strips cut where
each starts with as many robots. For each size, in one process:

* ``world apply``: ``Simulation.apply`` of each tick, given the tick's decisions (what the graph's one world
  process runs per tick besides its messages);
* ``in-process``: ``Simulation.run`` (the fast engine: decide and apply, compiled);
* for each S, ``run_sharded``: every shard's world work per tick (exchanging claims, applying its robots'
  decisions, routing its rows, taking the others' and closing the tick), the largest and the sum over the
  shards, the rows and rival claims a shard receives per tick, the rows the busiest shard applies per tick
  (its own robots': what a shard process would publish, seal and save, where the one world does all of
  them), and whether the run equals ``Simulation``'s.

Each shard runs in turn in this one process, so its seconds are its own work, measured without the other
shards competing for the cores. Median (min-max) over ``--repeats``. docs/benchmarks.md ("World shards") quotes
the output.

    .venv/bin/python scripts/bench_shards.py [--robots 10000 50000 100000] [--shards 1 2 4 8] [--ticks 100]
        [--repeats 3] [--smoke]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_scale import disc_file

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.regions import balanced_cuts
from swarm_ros.core.rules import Decider
from swarm_ros.core.sharded_run import run_sharded
from swarm_ros.core.state import initial_state


def _spread(values: list[float], digits: int = 2) -> str:
    return f"{statistics.median(values):.{digits}f} ({min(values):.{digits}f}-{max(values):.{digits}f})"


def world_apply_ms(shape: Shape, params: RunParams, ticks: int) -> tuple[float, Simulation]:
    """Milliseconds per tick of ``Simulation.apply`` (the decisions made outside the timing); the run after."""
    sim, decider = Simulation(shape, params), Decider(shape, params)
    spent = 0.0
    while sim.outcome is None and sim.tick < ticks:
        moving = sim.moving_ids()
        decisions = decider.decide(sim.state, moving, sim.tick + 1, moving)
        t0 = time.perf_counter()
        sim.apply(decisions)
        spent += time.perf_counter() - t0
    return 1000 * spent / max(sim.tick, 1), sim


def in_process_ms(shape: Shape, params: RunParams, ticks: int) -> float:
    sim = Simulation(shape, params)
    t0 = time.perf_counter()
    sim.run(max_ticks=ticks)
    return 1000 * (time.perf_counter() - t0) / max(sim.tick, 1)


def bench(sizes: list[int], shard_counts: list[int], ticks: int, repeats: int, tmp: Path) -> None:
    for robots in sizes:
        path, radius = disc_file(robots, tmp)
        shape = Shape.load(path, World(radius=radius))
        params = RunParams(robots=robots, seed=1)
        x0 = initial_state(shape, robots, params.seed).x[4:]
        print(
            f"\n{robots:,} robots (disc, world radius {radius}), {ticks} ticks, seed 1, median (min-max) of {repeats}"
        )
        applies, runs = [], []
        for _ in range(repeats):
            ms, reference = world_apply_ms(shape, params, ticks)
            applies.append(ms)
            runs.append(in_process_ms(shape, params, ticks))
        print(f"  one world, Simulation.apply per tick (ms)   {_spread(applies)}")
        print(f"  in-process engine, run() per tick (ms)      {_spread(runs)}")
        head = "shards  largest shard ms/tick   sum of shards ms/tick  largest/one world  rows in/tick  claims in/tick"
        print(f"  {head}  own rows/tick  same run")
        largest_at: dict[int, float] = {}
        own_at: dict[int, float] = {}  # the rows the largest shard applies (and would publish) per tick
        for s in shard_counts:
            cuts = balanced_cuts(x0, radius, s)
            largest, total, rows, rivals, own, same = [], [], 0.0, 0.0, 0.0, True
            for _ in range(repeats):
                run = run_sharded(shape, params, cuts, max_ticks=ticks)
                t = max(int(run.history[-1, 0]), 1)
                per = 1000 * run.seconds / t
                largest.append(float(per.max()))
                total.append(float(per.sum()))
                rows, rivals = float(run.rows_received.max()) / t, float(run.rivals_received.max()) / t
                own = float(run.rows_applied.max()) / t
                same &= bool(np.array_equal(run.history, reference.history)) and run.outcome == reference.outcome
                same &= bool(np.array_equal(run.state.state, reference.state.state))
            largest_at[s] = statistics.median(largest)
            own_at[s] = own
            print(
                f"  {s:>6}  {_spread(largest):>21}  {_spread(total):>21}  "
                f"{largest_at[s] / statistics.median(applies):>16.2f}x  {rows:>12,.0f}  {rivals:>14,.1f}  "
                f"{own:>13,.0f}  "
                f"{'identical' if same else 'DIFFERENT'}"
            )
        first = shard_counts[0]
        for s in shard_counts[1:]:
            print(
                f"  largest shard, S = {s} against S = {first}: {largest_at[s] / largest_at[first]:.2f}x of the work, "
                f"{own_at[s] / own_at[first]:.2f}x of the rows it applies"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10_000, 50_000, 100_000])
    parser.add_argument("--shards", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--ticks", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--smoke", action="store_true", help="2,000 robots, 20 ticks, S = 1 and 2, once")
    args = parser.parse_args()
    if args.smoke:
        args.robots, args.shards, args.ticks, args.repeats = [2_000], [1, 2], 20, 1
    if min(args.robots) < 100 or min(args.shards) < 1 or args.ticks < 1 or args.repeats < 1:
        parser.error("--robots at least 100, --shards, --ticks and --repeats at least 1")
    with tempfile.TemporaryDirectory() as tmp:
        bench(args.robots, args.shards, args.ticks, args.repeats, Path(tmp))
    print(f"\nwhole bench: {time.process_time():.1f} s of CPU; cores shared with whatever else runs: see the spread")


if __name__ == "__main__":
    main()
