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

Then the cost of the Rerun recording (issue 4): ``swarm-ros run`` with K = 2 and
``swarm-ros simulate``, each with and without ``--no-recording``, alternately, best of
``--repeats``. Target: the recording slows ``swarm-ros run`` by at most 25%.

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

RULES: dict[str, str] = {"rules": "paper"}  #: rule set and switch overrides of every run (set from the flags)


def in_process(seed: int, repeats: int) -> tuple[int, float, float]:
    """(ticks, best seconds with run(), best seconds with step() per tick) for the star."""
    shape = Shape.load("star")
    params = RunParams(robots=shape.patches, seed=seed, **RULES)
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


def command(seed: int, out: Path, *args: str, record: bool = False) -> tuple[int, float, float]:
    """Run ``swarm-ros ARGS`` on the star: (ticks, run seconds from summary.json, whole command seconds)."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "swarm_ros.cli", *args, "--shape", "star", "--seed", str(seed),
                           *[a for k, v in RULES.items() for a in (f"--{k}", v)],
                           "--out", str(out), "--overwrite", "--quiet", *([] if record else ["--no-recording"])],
                          capture_output=True, text=True)
    whole = time.perf_counter() - t0
    if done.returncode != 0:
        sys.exit(f"bench_ros: swarm-ros {args[0]} failed: {done.stderr.strip()}")
    summary = json.loads((out / "summary.json").read_text())
    return summary["convergence_tick"], summary["wall_seconds"], whole


def over_graph(seed: int, processes: int, out: Path, record: bool = False) -> tuple[int, float, float]:
    """(ticks, run seconds as the monitor measured them, whole command seconds)."""
    return command(seed, out, "run", "--processes", str(processes), record=record)


def recording_cost(seed: int, repeats: int, tmp: Path) -> None:
    """Print run and command seconds with and without the recording (alternating; best of ``repeats``)."""
    cases = {("run", False): [], ("run", True): [], ("simulate", False): [], ("simulate", True): []}
    for r in range(repeats):
        for record in ((False, True) if r % 2 == 0 else (True, False)):
            cases[("run", record)].append(over_graph(seed, 2, tmp / f"rec-run-{r}", record=record))
            cases[("simulate", record)].append(command(seed, tmp / f"rec-sim-{r}", "simulate", record=record))
    best = {key: (min(g[1] for g in got), min(g[2] for g in got)) for key, got in cases.items()}
    size = (tmp / "rec-run-0" / "recording.rrd").stat().st_size
    print(f"\nRerun recording, star, best of {repeats} (recording.rrd {size / 1e6:.1f} MB)")
    print(f"{'command':<34} {'run s':>8} {'command s':>10}")
    for (what, record), (secs, whole) in best.items():
        label = f"swarm-ros {what}" + (" (K = 2)" if what == "run" else "") + (", recording" if record else
                                                                                ", --no-recording")
        print(f"{label:<34} {secs:>8.3f} {whole:>10.2f}")
    for what in ("run", "simulate"):
        (off, off_whole), (on, on_whole) = best[(what, False)], best[(what, True)]
        print(f"recording slows swarm-ros {what:<9}: run {100 * (on / off - 1):+.0f}%, "
              f"command {100 * (on_whole / off_whole - 1):+.0f}%")
    (off, off_whole), (on, on_whole) = best[("run", False)], best[("run", True)]
    worst = max(on / off, on_whole / off_whole)
    print(f"Target: the recording slows swarm-ros run by <= 25%: {'MET' if worst <= 1.25 else 'NOT MET'} "
          f"(worst of run and command time: {100 * (worst - 1):+.0f}%)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=2, help="runs per case; the best is kept")
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--rules", default="paper", help="rule set of every run (default: paper)")
    parser.add_argument("--crowding", help="override the crowding switch (e.g. disc, for the reading before "
                                           "rule sets: --rules local --crowding disc)")
    args = parser.parse_args()
    RULES["rules"] = args.rules
    if args.crowding:
        RULES["crowding"] = args.crowding

    ticks, fast, stepped = in_process(args.seed, args.repeats)
    fast_rate, step_rate = ticks / fast, ticks / stepped
    print(f"star, 1036 robots, seed {args.seed}, rules {' '.join(f'{k} {v}' for k, v in RULES.items())}: "
          f"{ticks} ticks")
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
    with tempfile.TemporaryDirectory() as tmp:
        recording_cost(args.seed, max(args.repeats, 3), Path(tmp))


if __name__ == "__main__":
    main()
