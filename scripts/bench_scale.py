#!/usr/bin/env python3
"""The graph at scale: disc shapes of 10,000 robots and more, at the star's density, K = 1, 2, 4 against
the in-process engine.

A disc of N patches (N robots) in a world whose area holds N robots at the star's density
(1,036 robots in a 65 x 65 world): radius 100 for 10,000. Each run stops after ``--ticks``
ticks. Printed per engine: seconds of the run (tick 0 to its end) and of the whole command,
median and range over ``--repeats``, and each node's CPU per tick (its CPU from "ready" to
"done" in its log, the monitor's to its "last tick" line, over the ticks); then the bytes of rows
each batch took from its area and changes topics per tick (its log's last line), and K against the smallest K
as ratios.
``--bare`` turns the recording and the bag off. docs/benchmarks.md ("At scale") discusses the numbers.

``--projection`` also prints, for each size and K, the tick time the graph would take on K hosts with one
core per process: the world's CPU per tick (the slowest world shard's with ``--world-shards``) plus the
slowest batch's plus the transport's part of a tick, or the monitor's CPU per tick if that is longer (the
monitor runs beside the lockstep, up to ``monitor_window`` ticks behind). CPU per tick is each node's as
measured in the runs above (median over ``--repeats``); the transport's part is measured here too, by a
bare rclpy lockstep (scripts/bench_bare.py) of K batches exchanging messages of the measured sizes (the
largest batch's region rows a tick, its share of the moving robots' decisions) and doing nothing else;
with S shards, each shard's K / S batches, plus two rounds (claims, parts) of a shard with its S - 1 peers
trading the most part rows and claims a shard took from them (its log's count of each).
On this 2-core machine every process of a K = 8 graph shares two cores, so each one's CPU per tick is
measured under contention: the projection says what the code's per-process work allows, not what this
machine shows.

``--before DIR`` runs an A/B instead: each K's graph from this tree and from DIR (an older commit's tree,
``git archive <commit> | tar -x -C DIR``) in turn, ``--repeats`` rounds, each run from inside its own tree
(``python -m swarm_ros`` imports the working directory's package before PYTHONPATH's); it prints each round,
the medians, and the graph's summed CPU a tick of this tree against DIR's, round by round.

    .venv/bin/python scripts/bench_scale.py [--robots 10000 50000] [--processes 1 2 4] [--ticks 300] [--bare]
        [--world-shards S]
        [--repeats 3] [--projection] [--before DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: the tree this script belongs to: its commands run there, so `python -m swarm_ros` imports this tree's package
#: (the working directory comes first on the import path, before PYTHONPATH): an older tree's copy of this
#: script, run from anywhere, measures that tree (an A/B of two commits)
ROOT = Path(__file__).resolve().parents[1]

STAR_DENSITY = 1036 / 65**2  #: robots per patch of the star's world
_CPU = re.compile(r"\[(\w+)\]: (ready|last tick|done), .* \((\d+\.\d+) s of CPU[,)]")
_RECEIVED = re.compile(r"received (\d+) bytes of rows on ")


def disc_file(robots: int, folder: Path) -> tuple[Path, int]:
    """A text shape file of a disc of about ``robots`` patches, and the world radius for it."""
    r = math.sqrt(robots / math.pi)
    half = math.ceil(r) + 1
    yy, xx = np.mgrid[-half : half + 1, -half : half + 1]
    mask = xx**2 + yy**2 <= r * r
    path = folder / f"disc{robots}.txt"
    path.write_text("".join("".join("#" if v else "." for v in row) + "\n" for row in mask))
    return path, round(math.sqrt(robots / STAR_DENSITY) / 2)


def disc_flags(robots: int, tmp: Path, ticks: int, seed: int) -> tuple[list[str], int]:
    """A run of the disc of ``robots`` (:func:`disc_file`, written into ``tmp``) as flags, and its world radius."""
    shape, radius = disc_file(robots, tmp)
    flags = ["--shape", str(shape), "--world-radius", str(radius), "--seed", str(seed), "--max-ticks", str(ticks)]
    return flags, radius


#: the commands' environment, as on a user's machine: Python writes its bytecode caches (a shell that sets
#: PYTHONDONTWRITEBYTECODE would have every process compile each module changed since its cache from source)
USER_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def _swarm(args: list[str], tree: Path = ROOT) -> float:
    """Seconds of ``swarm-ros ARGS`` run from ``tree`` (whose package it imports: the working directory's)."""
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "swarm_ros", *args, "--quiet", "--overwrite"],
        capture_output=True,
        text=True,
        cwd=tree,
        env=USER_ENV,
    )
    if done.returncode != 0:
        sys.exit(f"bench_scale: swarm-ros {args[0]} failed: {done.stderr.strip()[-500:]}")
    return time.perf_counter() - t0


def imported_from(tree: Path) -> Path | None:
    """Where ``python -m swarm_ros`` run from ``tree`` takes the package from (it must be ``tree``), or None."""
    code = "import pathlib, swarm_ros; print(pathlib.Path(swarm_ros.__file__).resolve().parent.parent)"
    where = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tree)
    return Path(where.stdout.strip()) if where.returncode == 0 else None


def compare(before: Path, robots: int, k: int, world_shards: int, ticks: int, rounds: int, tmp: Path, bare: bool):
    """A/B of two trees: the graph run from each tree in turn (this one and ``before``, the order alternating by
    round), ``rounds`` rounds; each node's CPU per tick and the run's seconds, per round and as medians."""
    trees = {"this tree": ROOT, "before": before.resolve()}
    for name, tree in trees.items():
        source = imported_from(tree)
        if source != tree:
            sys.exit(f"bench_scale: {name} ({tree}) imports swarm_ros from {source or 'nowhere'}, not from itself")
    flags, _ = disc_flags(robots, tmp, ticks, 1)
    flags += ["--processes", str(k), "--world-shards", str(min(world_shards, k))]
    flags += ["--no-recording", "--no-bag"] if bare else []
    got: dict[str, list[tuple[float, dict[str, float]]]] = {name: [] for name in trees}
    print(f"\n{robots:,} robots, {label(k, world_shards)}, {ticks} ticks, seed 1, {rounds} alternating rounds")
    for r in range(rounds):
        for name, tree in list(trees.items())[:: 1 if r % 2 == 0 else -1]:
            out = tmp / f"ab-{r}-{name.replace(' ', '-')}"
            _swarm(["run", *flags, "--out", str(out)], tree)
            cpu = node_cpu(out / "logs", ticks)
            got[name].append((json.loads((out / "summary.json").read_text())["wall_seconds"], cpu))
            print(f"  round {r + 1} {name:<9} run {got[name][-1][0]:.2f} s   " + _cpu_text(cpu))
    for name, runs in got.items():
        nodes = runs[-1][1]
        cpu = {node: statistics.median(c[node] for _, c in runs if node in c) for node in nodes}
        print(f"{name:<9} median  run {_spread([w for w, _ in runs])} s   " + _cpu_text(cpu))
    ratio = [sum(a[1].values()) / sum(b[1].values()) for a, b in zip(got["this tree"], got["before"])]
    print("the graph's summed CPU a tick, this tree against before, per round: " + ", ".join(f"{x:.2f}" for x in ratio))


def _cpu_text(cpu: dict[str, float]) -> str:
    return ", ".join(f"{node} {ms:.1f}" for node, ms in cpu.items())


def cpu_lines(logs: Path) -> dict[str, dict[str, float]]:
    """Per node of a run's logs: its process's CPU seconds at its 'ready', 'last tick' and 'done' lines."""
    cpu: dict[str, dict[str, float]] = {}
    for log in logs.glob("*.log"):
        for m in _CPU.finditer(log.read_text(errors="replace")):
            cpu.setdefault(m[1], {})[m[2]] = float(m[3])
    return cpu


def node_cpu(logs: Path, ticks: int) -> dict[str, float]:
    """Milliseconds of CPU per tick of each node, between its 'ready' line and its 'last tick' line (the
    monitor's, before it writes the run directory) or else its 'done' line."""
    cpu = cpu_lines(logs)
    return {
        node: 1000 * (c.get("last tick", c.get("done", 0.0)) - c["ready"]) / ticks
        for node, c in sorted(cpu.items())
        if "ready" in c and "done" in c
    }


def received(logs: Path, ticks: int) -> dict[str, float]:
    """Bytes of rows each batch took from its area and changes topics per tick (the 'received ...' line of its log)."""
    out = {}
    for log in sorted(logs.glob("robot_batch_*.log")):
        m = _RECEIVED.search(log.read_text(errors="replace"))
        if m:
            out[log.stem] = int(m[1]) / ticks
    return out


_PEERS = re.compile(r"received (\d+) part rows and (\d+) claims from its peers")


def peer_rows(logs: Path, ticks: int) -> tuple[float, float]:
    """The most part rows and the most claims a world shard took from its peers per tick (its log's 'received
    ...' line); (0, 0) without shards."""
    found = [_PEERS.search(log.read_text(errors="replace")) for log in sorted(logs.glob("world_shard_*.log"))]
    rows = [int(m[1]) / ticks for m in found if m]
    claims = [int(m[2]) / ticks for m in found if m]
    return max(rows, default=0.0), max(claims, default=0.0)


def moving_per_tick(run: Path) -> float:
    """Moving robots per tick of a run (metrics.csv, the ticks before the last): the decisions a tick takes."""
    with (run / "metrics.csv").open() as f:
        header = f.readline().strip().split(",")
        col = header.index("moving")
        moving = [int(line.split(",")[col]) for line in f]
    return statistics.fmean(moving[:-1] or moving)


def project(robots: int, measured: dict, sim_tick_ms: float, ticks: int, world_shards: int = 1) -> list[str]:
    """The projection's rows for one size (see the module's docstring); ``measured``: K -> (CPU per tick of
    each node, largest bytes of rows a batch took per tick, moving robots per tick, the most part rows and the
    most claims a world shard took from its peers per tick). With S world shards the world's part is the
    slowest shard's CPU, and the transport adds the shards' two exchange rounds a tick (claims, then parts),
    each taken as a bare lockstep of one shard with its S - 1 peers, each peer sending its share of those."""
    import bench_bare

    lines = []
    for k, (cpu, largest, moving, (part_rows, claims)) in measured.items():
        batches = [ms for node, ms in cpu.items() if node.startswith("robot_batch")]
        worlds = [ms for node, ms in cpu.items() if node.startswith("world")]
        world, batch, monitor = max(worlds, default=0.0), max(batches, default=0.0), cpu.get("monitor", 0.0)
        shards = min(world_shards, k)
        transport = 1000 * bench_bare.bare_fixed(
            -(-k // shards),
            max(1, round(largest / ROBOT_ROW_BYTES)),
            max(1, round(moving / k)),
            min(ticks, 100),
            90 + k,
        )
        if shards > 1:
            rows, rivals = (max(1, round(n / (shards - 1))) for n in (part_rows, claims))
            transport += 1000 * bench_bare.bare_fixed(shards - 1, rivals, rivals, min(ticks, 100), 80 + k)
            transport += 1000 * bench_bare.bare_fixed(shards - 1, rows, rows, min(ticks, 100), 80 + k)
        tick = max(world + batch + transport, monitor)
        lines.append(
            f"{robots:>9,} {k:>3} {shards:>3} {world:>8.1f} {batch:>8.1f} {monitor:>8.1f} {transport:>10.1f} "
            f"{tick:>10.1f} {sim_tick_ms:>11.1f} {tick / sim_tick_ms:>7.1f}x"
        )
    return lines


PROJECTION_HEAD = (
    f"{'robots':>9} {'K':>3} {'S':>3} {'world':>8} {'batch':>8} {'monitor':>8} {'transport':>10} "
    f"{'projected':>10} {'in-process':>11} {'ratio':>8}"
)
ROBOT_ROW_BYTES = 40  #: bytes of a /swarm/robots row, the bare lockstep's row (a region row is 29)


def _spread(values: list[float]) -> str:
    return f"{statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})"


def label(k: int, world_shards: int) -> str:
    """A graph run's row label: its K, and its S if it has world shards."""
    return f"ROS 2 graph, K = {k}" + f", S = {min(world_shards, k)}" * (world_shards > 1)


def scale(
    sizes: list[int],
    processes: list[int],
    tmp: Path,
    ticks: int = 300,
    seed: int = 1,
    repeats: int = 1,
    bare: bool = False,
    projection: bool = False,
    world_shards: int = 1,
) -> None:
    extra = ["--no-recording"] if bare else []  # simulate writes no bag
    graph_extra = ["--no-bag"] if bare else []
    projected: list[str] = []
    for robots in sizes:
        common, radius = disc_flags(robots, tmp, ticks, seed)
        common += extra
        print(
            f"\n{robots:,} robots (disc, world radius {radius}), {ticks} ticks, seed {seed}, "
            f"{'no recording, no bag' if bare else 'recording and bag on'}, median (min-max) of {repeats}"
        )
        print(f"{'engine':<22} {'run s':>18} {'command s':>18} {'vs in-process':>14}   CPU per tick of each node (ms)")
        sim_runs, sim_whole = [], []
        for _ in range(repeats):
            sim_whole.append(_swarm(["simulate", *common, "--out", str(tmp / f"sim{robots}")]))
            sim_runs.append(json.loads((tmp / f"sim{robots}" / "summary.json").read_text())["wall_seconds"])
        sim_run = statistics.median(sim_runs)
        print(f"{'in-process':<22} {_spread(sim_runs):>18} {_spread(sim_whole):>18} {1:>13.1f}x")
        medians, traffic, measured = {}, {}, {}
        for k in processes:
            out = tmp / f"run{robots}-{k}"
            runs, whole, cpus = [], [], []
            for _ in range(repeats):
                shards = ["--world-shards", str(min(world_shards, k))]
                whole.append(_swarm(["run", *common, *graph_extra, "--processes", str(k), *shards, "--out", str(out)]))
                runs.append(json.loads((out / "summary.json").read_text())["wall_seconds"])
                cpus.append(node_cpu(out / "logs", ticks))
            medians[k] = statistics.median(runs)
            cpu_ms = {node: statistics.median(c[node] for c in cpus if node in c) for node in cpus[-1]}
            cpu = ", ".join(f"{node} {ms:.1f}" for node, ms in cpu_ms.items())
            print(
                f"{label(k, world_shards):<22} {_spread(runs):>18} {_spread(whole):>18} "
                f"{medians[k] / sim_run:>13.1f}x   {cpu}"
            )
            traffic[k] = received(out / "logs", ticks)
            measured[k] = (
                cpu_ms,
                max(traffic[k].values(), default=0.0),
                moving_per_tick(out),
                peer_rows(out / "logs", ticks),
            )
        print("bytes of rows each batch received per tick (its area and changes topics, the last run):")
        for k, per in traffic.items():
            print(
                f"  K = {k}: "
                + ", ".join(f"{name} {b / 1e3:,.1f} kB" for name, b in per.items())
                + (f"; largest {max(per.values()) / 1e3:,.1f} kB" if per else "")
            )
        for k, (*_, (part_rows, claims)) in measured.items():
            if part_rows or claims:
                print(f"  K = {k}: a world shard took at most {part_rows:,.0f} part rows, {claims:,.0f} claims a tick")
        first = processes[0]
        for k in processes[1:]:
            ratio = max(traffic[k].values()) / max(traffic[first].values()) if traffic[k] and traffic[first] else 0
            largest = [max(measured[j][0].values()) for j in (first, k)]
            print(
                f"K = {k} against K = {first}: run time {medians[k] / medians[first]:.2f}x, "
                f"largest bytes received per batch {ratio:.2f}x, largest CPU per tick of a process "
                f"{largest[1] / largest[0]:.2f}x"
            )
        if projection:
            projected += project(robots, measured, 1000 * sim_run / ticks, ticks, world_shards)
    if projection:
        print(
            "\nprojected tick on K hosts, one core per process (ms): world + slowest batch + transport, or the "
            "monitor if longer"
        )
        print(PROJECTION_HEAD)
        print("\n".join(projected))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10_000])
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--ticks", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--bare", action="store_true", help="--no-recording --no-bag on every run")
    parser.add_argument(
        "--projection",
        action="store_true",
        help="also project the tick on K hosts from each process's CPU and the transport's part",
    )
    parser.add_argument("--world-shards", type=int, default=1, help="world shards S of every graph run (at most its K)")
    parser.add_argument(
        "--before",
        type=Path,
        help="an older tree (git archive <commit> | tar -x -C DIR): an A/B of each K against it, --repeats rounds",
    )
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_bare
    with tempfile.TemporaryDirectory() as tmp:
        if args.before is not None:
            for robots in args.robots:
                for k in args.processes:
                    compare(args.before, robots, k, args.world_shards, args.ticks, args.repeats, Path(tmp), args.bare)
            return
        scale(
            args.robots,
            args.processes,
            Path(tmp),
            args.ticks,
            repeats=args.repeats,
            bare=args.bare,
            projection=args.projection,
            world_shards=args.world_shards,
        )


if __name__ == "__main__":
    main()
