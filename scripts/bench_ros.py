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

Then where a command's time goes (issue 13): for K = 1, 2, 4, with the recording and the
bag on (the defaults), the seconds from the command's start to each milestone, read from
the launcher's clock (``logs/launcher.log``) and the nodes' logs: node processes started,
every node ready (imports, warm-up), tick 0 (all participants discovered and matched),
the last tick, the run directory written, every node process gone, the command done.
Target: the star, K = 2, whole command under 4 s (median of ``--repeats``).

Then the README's command against ``simulate`` (issue 45): ``swarm-ros run --shape star`` and ``swarm-ros
simulate --shape star``, alternating, at least 5 pairs, with each command's CPU and the run's by node. Target: the
first within 1.5x of the second.

Then (``rosstart``) what a process pays to be a ROS node at all, in fresh processes with a run's DDS settings:
importing rclpy, its first node (the DDS participant), 12 endpoints. Every node process of the graph pays it.

Then the cost of the bag (issue 13): ``swarm-ros run`` with K = 2 with and without
``--no-bag``, alternately. Target: the bag slows the ``swarm-ros run`` command by at most 15%
(the run's own time, tick 0 to the outcome, is printed too).

Then the cost of the Rerun recording (issue 4): ``swarm-ros run`` with K = 2 and
``swarm-ros simulate``, each with and without ``--no-recording``, alternately, best of
``--repeats``. Target: the recording slows ``swarm-ros run`` by at most 25%.

Then (issue 23) a flood on every topic of a run (scripts/bench_flood.py, ``--flood-rates``):
the run must end with exit 0 and files byte-identical to ``simulate``'s; its slowdown is
printed. With ``--only scale``, disc shapes of ``--scale-robots`` robots at the star's density,
K = 1, 2, 4 against the in-process engine, with each node's CPU per tick
(scripts/bench_scale.py). The speed part runs, alternately with the graph, a bare rclpy
lockstep of the same message sizes (scripts/bench_bare.py), the transport's floor: target,
the graph at >= 40% of its ticks/s with K = 2.

    .venv/bin/python scripts/bench_ros.py [--seed 1] [--repeats 2] [--processes 1 2 4] [--only ...]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from swarm_ros.core import RunParams, Shape, Simulation

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_run import timed
from bench_scale import USER_ENV, cpu_lines

#: the tree this script belongs to: its commands run there, so `python -m swarm_ros` imports this tree's package
#: (the working directory comes first on the import path, before PYTHONPATH): an older tree's copy of this
#: script, run from anywhere, measures that tree (an A/B of two commits)
ROOT = Path(__file__).resolve().parents[1]

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
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "swarm_ros",
            *args,
            "--shape",
            "star",
            "--seed",
            str(seed),
            *[a for k, v in RULES.items() for a in (f"--{k}", v)],
            "--out",
            str(out),
            "--overwrite",
            "--quiet",
            *([] if record else ["--no-recording"]),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=USER_ENV,
    )
    whole = time.perf_counter() - t0
    command.started_at = time.time() - whole  # the epoch of the start, for milestones()
    if done.returncode != 0:
        sys.exit(f"bench_ros: swarm-ros {args[0]} failed: {done.stderr.strip()}")
    summary = json.loads((out / "summary.json").read_text())
    return summary["convergence_tick"], summary["wall_seconds"], whole


def over_graph(seed: int, processes: int, out: Path, record: bool = False, *extra: str) -> tuple[int, float, float]:
    """(ticks, run seconds (the world's tick 0 to its outcome), whole command seconds)."""
    return command(seed, out, "run", "--processes", str(processes), *extra, record=record)


#: (milestone, where it is logged: a log file of the run's logs/ and what its line says)
MILESTONES = (
    ("node processes started", "launcher.log", "started world"),
    ("every node ready", "*.log", "ready, "),
    ("tick 0 (discovered, matched)", "world.log", ": tick 0"),
    ("last tick", "world.log", "run ended"),
    ("run directory written", "monitor.log", "run written"),
    ("every node process gone", "launcher.log", "all node processes gone"),
)
_STAMP = re.compile(r"^(?:\[\w+\] )?\[(\d+\.\d+)\]")


def milestones(out: Path, started_at: float, whole: float) -> list[float]:
    """Seconds from the command's start to each of :data:`MILESTONES` (the last of several lines), then the end."""
    got = []
    for _, pattern, text in MILESTONES:
        stamps = [
            float(m[1])
            for log in (out / "logs").glob(pattern)
            for line in log.read_text(errors="replace").splitlines()
            if text in line and (m := _STAMP.match(line))
        ]
        if not stamps:
            sys.exit(f"bench_ros: no '{text}' in {out / 'logs' / pattern}")
        got.append(max(stamps) - started_at)
    return got + [whole]


def breakdown(seed: int, processes: list[int], repeats: int, tmp: Path) -> dict[int, list[float]]:
    """Print the median seconds to each milestone for each K; return {K: medians}."""
    names = [name for name, _, _ in MILESTONES] + ["command done"]
    medians, all_runs = {}, {}
    for k in processes:
        runs = all_runs[k] = []
        for r in range(repeats):
            out = tmp / f"steps-k{k}-{r}"
            _, _, whole = over_graph(seed, k, out, True)
            runs.append(milestones(out, command.started_at, whole))
        medians[k] = [statistics.median(run[i] for run in runs) for i in range(len(names))]
    print(
        f"\nWhere a command's time goes: the star, recording and bag on, seconds from the command's start "
        f"(median of {repeats})"
    )
    print(f"{'milestone':<30}" + "".join(f"{f'K = {k}':>9}" for k in processes))
    for i, name in enumerate(names):
        print(f"{name:<30}" + "".join(f"{medians[k][i]:>9.2f}" for k in processes))
    for k in processes:  # the spread of what a user waits for
        wholes = sorted(run[-1] for run in all_runs[k])
        print(
            f"command, K = {k}, over {len(wholes)} runs: min {wholes[0]:.2f} s, median "
            f"{statistics.median(wholes):.2f} s, max {wholes[-1]:.2f} s"
        )
    if 2 in medians:
        whole = medians[2][-1]
        print(
            f"Target: the star with K = 2, recording on, whole command under 4 s: "
            f"{'MET' if whole < 4 else 'NOT MET'} ({whole:.2f} s)"
        )
    return medians


def readme_command(repeats: int, tmp: Path) -> float:
    """The README's main command against ``simulate`` of the same run, back to back and alternating (the star,
    the defaults: K = 2, recording and bag on), ``repeats`` pairs; print each, the medians and their ratio.
    Target (issue 45): the README's command within 1.5x of simulate's. Return the ratio of the medians.

    Each command's CPU (user and system, its processes' and their children's: the launcher and every node) is
    printed too: on a machine of 2 cores a command cannot take less than half its CPU.

    As a user runs them: with Python's bytecode caches written (``PYTHONDONTWRITEBYTECODE`` is dropped from the
    commands' environment; with it set, every module changed since its cache was written is compiled from
    source in every process, the run's five more often than simulate's one), after one untimed pair that
    writes them and fills numba's cache."""
    exe = [sys.executable, "-m", "swarm_ros"]
    env = USER_ENV
    for command in ("run", "simulate"):
        subprocess.run(
            [*exe, command, "--shape", "star", "--out", str(tmp / f"readme-{command}-warm"), "--quiet"],
            capture_output=True,
            cwd=ROOT,
            env=env,
        )
    times: dict[str, list[float]] = {"run": [], "simulate": []}
    cpu: dict[str, list[float]] = {"run": [], "simulate": []}
    nodes: dict[str, list[float]] = {}  # each node process's CPU up to its exit, from its "done" line
    print("\nThe README's command against simulate, the star with the defaults, back to back (seconds)")
    for r in range(repeats):
        for command in ("run", "simulate") if r % 2 == 0 else ("simulate", "run"):
            argv = [*exe, command, "--shape", "star", "--out", str(tmp / f"readme-{command}-{r}"), "--quiet"]
            took, used, _ = timed(argv, env, ROOT)
            times[command].append(took)
            cpu[command].append(used)
            if command == "run":
                for name, lines in cpu_lines(tmp / f"readme-{command}-{r}" / "logs").items():
                    if "done" in lines:
                        nodes.setdefault(name, []).append(lines["done"])
        print(
            f"  pair {r + 1}: run {times['run'][-1]:.2f} ({cpu['run'][-1]:.2f} s of CPU), "
            f"simulate {times['simulate'][-1]:.2f} ({cpu['simulate'][-1]:.2f} s of CPU)"
        )
    med = {c: statistics.median(t) for c, t in times.items()}
    for c, t in times.items():
        c_cpu = cpu[c]
        print(
            f"{c:<9} median {med[c]:.2f} s ({min(t):.2f}-{max(t):.2f}) over {len(t)}; "
            f"CPU median {statistics.median(c_cpu):.2f} s ({min(c_cpu):.2f}-{max(c_cpu):.2f})"
        )
    if nodes:
        own = statistics.median(cpu["run"]) - sum(statistics.median(v) for v in nodes.values())
        print(
            "run's CPU by process (medians, s): "
            + ", ".join(f"{name} {statistics.median(v):.2f}" for name, v in sorted(nodes.items()))
            + f"; the launcher and what the nodes spent after their last line {own:.2f}"
        )
    ratio = med["run"] / med["simulate"]
    print(f"Target: swarm-ros run within 1.5x of simulate: {'MET' if ratio <= 1.5 else 'NOT MET'} ({ratio:.2f}x)")
    return ratio


def bag_cost(seed: int, repeats: int, tmp: Path) -> None:
    """Print run and command seconds with and without the bag (K = 2, recording on; alternating; median)."""
    cases: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
    for r in range(repeats):
        for bag in (False, True) if r % 2 == 0 else (True, False):
            out = tmp / f"bag-{bag}-{r}"
            _, secs, whole = over_graph(seed, 2, out, True, *([] if bag else ["--no-bag"]))
            cases[bag].append((secs, whole))
    med = {
        bag: (statistics.median(s for s, _ in got), statistics.median(w for _, w in got)) for bag, got in cases.items()
    }
    bag_dir = tmp / "bag-True-0" / "bag"
    size = sum(f.stat().st_size for f in bag_dir.iterdir())
    print(f"\nThe bag (bag/, rosbag2 MCAP), star, K = 2, median of {repeats}: {size / 1e6:.1f} MB")
    print(f"{'command':<34} {'run s':>8} {'command s':>10}")
    for bag in (False, True):
        label = "swarm-ros run" + (" (bag)" if bag else " --no-bag")
        print(f"{label:<34} {med[bag][0]:>8.3f} {med[bag][1]:>10.2f}")
    (off, off_whole), (on, on_whole) = med[False], med[True]
    print(
        f"bag slows swarm-ros run: run {100 * (on / off - 1):+.0f}%, command {100 * (on_whole / off_whole - 1):+.0f}%"
    )
    # The command is what a user waits for. The bag's cost is a fixed ~0.2 s of the monitor's CPU (opening
    # rosbags' type store, closing the file), spent while the world runs: on a 1-second run the run time
    # swings by tens of percent either way with it (measured -23% and +28% on the same code).
    cost = on_whole / off_whole
    print(
        f"Target: the bag slows the swarm-ros run command by <= 15%: {'MET' if cost <= 1.15 else 'NOT MET'} "
        f"({100 * (cost - 1):+.0f}%)"
    )


def recording_cost(seed: int, repeats: int, tmp: Path) -> None:
    """Print run and command seconds with and without the recording (alternating; best of ``repeats``)."""
    cases = {("run", False): [], ("run", True): [], ("simulate", False): [], ("simulate", True): []}
    for r in range(repeats):
        for record in (False, True) if r % 2 == 0 else (True, False):
            cases[("run", record)].append(over_graph(seed, 2, tmp / f"rec-run-{r}", record=record))
            cases[("simulate", record)].append(command(seed, tmp / f"rec-sim-{r}", "simulate", record=record))
    best = {key: (min(g[1] for g in got), min(g[2] for g in got)) for key, got in cases.items()}
    size = (tmp / "rec-run-0" / "recording.rrd").stat().st_size
    print(f"\nRerun recording, star, best of {repeats} (recording.rrd {size / 1e6:.1f} MB)")
    print(f"{'command':<34} {'run s':>8} {'command s':>10}")
    for (what, record), (secs, whole) in best.items():
        label = (
            f"swarm-ros {what}"
            + (" (K = 2)" if what == "run" else "")
            + (", recording" if record else ", --no-recording")
        )
        print(f"{label:<34} {secs:>8.3f} {whole:>10.2f}")
    for what in ("run", "simulate"):
        (off, off_whole), (on, on_whole) = best[(what, False)], best[(what, True)]
        print(
            f"recording slows swarm-ros {what:<9}: run {100 * (on / off - 1):+.0f}%, "
            f"command {100 * (on_whole / off_whole - 1):+.0f}%"
        )
    (off, off_whole), (on, on_whole) = best[("run", False)], best[("run", True)]
    worst = max(on / off, on_whole / off_whole)
    print(
        f"Target: the recording slows swarm-ros run by <= 25%: {'MET' if worst <= 1.25 else 'NOT MET'} "
        f"(worst of run and command time: {100 * (worst - 1):+.0f}%)"
    )


def speed(seed: int, repeats: int, processes: list[int]) -> None:
    """Print the graph's ticks/s (recording and bag on, as a user runs it) against the in-process engine and
    against a bare rclpy lockstep of the same message sizes (scripts/bench_bare.py), alternated in this session."""
    import bench_bare
    from bench_scale import node_cpu

    ticks, fast, stepped = in_process(seed, repeats)
    fast_rate, step_rate = ticks / fast, ticks / stepped
    print(
        f"star, 1036 robots, seed {seed}, {' '.join(f'{k} {v}' for k, v in RULES.items())}: "
        f"{ticks} ticks; the graph with recording and bag on; median (min-max) of {repeats}"
    )
    print(f"{'engine':<34} {'ticks/s':>22} {'vs run()':>9} {'vs bare':>8} {'command s':>18}")
    print(f"{'in-process, run()':<34} {fast_rate:>22,.0f} {1:>8.1f}x")
    print(f"{'in-process, step() per tick':<34} {step_rate:>22,.0f} {step_rate / fast_rate:>8.3f}x")
    spread = lambda xs, f="{:,.0f}": f"{f.format(statistics.median(xs))} ({f.format(min(xs))}-{f.format(max(xs))})"
    medians, shares = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for k in processes:
            graph, bare, wholes, cpus = [], [], [], []
            for r in range(repeats):
                got = over_graph(seed, k, Path(tmp) / f"k{k}-{r}", True)
                if got[0] != ticks:
                    sys.exit(f"bench_ros: the graph ran {got[0]} ticks, the in-process engine {ticks}")
                graph.append(ticks / got[1])
                wholes.append(got[2])
                cpus.append(node_cpu(Path(tmp) / f"k{k}-{r}" / "logs", ticks))
                bare_ticks, secs = bench_bare.bare(seed, k, 95 + k)
                bare.append(bare_ticks / secs)
            medians[k], shares[k] = statistics.median(graph), statistics.median(graph) / statistics.median(bare)
            print(
                f"{f'ROS 2 graph, K = {k}':<34} {spread(graph):>22} {medians[k] / fast_rate:>8.4f}x "
                f"{shares[k]:>7.0%} {spread(wholes, '{:.2f}'):>18}"
            )
            bare_rate = statistics.median(bare)
            print(f"{f'bare rclpy lockstep, K = {k}':<34} {spread(bare):>22} {bare_rate / fast_rate:>8.4f}x")
            per_node = {n: statistics.median(c[n] for c in cpus) for n in cpus[0]}
            print(
                f"{'':<6}a tick: {1000 / medians[k]:.2f} ms of the graph, {1000 / bare_rate:.2f} ms of the bare "
                f"lockstep; CPU per tick (ms, from 'ready' to 'done', the end included): "
                + ", ".join(f"{n} {ms:.2f}" for n, ms in per_node.items())
            )
            if k == 2:
                whole2 = statistics.median(wholes)
    if 2 in medians:
        r2 = medians[2]
        print(f"Target >= 500 ticks/s with K = 2: {'MET' if r2 >= 500 else 'NOT MET'} ({r2:,.0f})")
        print(
            f"Target >= 40% of the bare lockstep's ticks/s with K = 2: {'MET' if shares[2] >= 0.4 else 'NOT MET'} "
            f"({shares[2]:.0%})"
        )
        print(f"Target: the whole command under 4 s with K = 2: {'MET' if whole2 < 4 else 'NOT MET'} ({whole2:.2f} s)")


_ROS_START = """
import time
c0, t0 = time.process_time(), time.perf_counter()
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
c1, t1 = time.process_time(), time.perf_counter()
rclpy.init()
node = Node("bench_ros_start")
c2, t2 = time.process_time(), time.perf_counter()
for k in range(6):
    node.create_subscription(PointCloud2, f"/bench_ros_start/in{k}", lambda m: None, 10)
    node.create_publisher(PointCloud2, f"/bench_ros_start/out{k}", 10)
c3, t3 = time.process_time(), time.perf_counter()
print(c1 - c0, c2 - c1, c3 - c2, t1 - t0, t2 - t1, t3 - t2)
"""


def ros_start(repeats: int) -> None:
    """What a process pays to be a ROS node at all, with a run's DDS settings, in a fresh process each time
    (``repeats``, median): importing rclpy and a message package, the first node (its DDS participant), and
    12 endpoints (a world's or monitor's order of magnitude). Each node process of the graph pays it;
    ``simulate`` does not."""
    from swarm_ros.app.processes import DomainLock
    from swarm_ros.ros.dds import apply_dds_defaults

    lock = DomainLock()
    env = dict(os.environ, ROS_DOMAIN_ID=str(lock.domain_id))
    apply_dds_defaults(env)
    runs = []
    try:
        for _ in range(repeats):
            done = subprocess.run([sys.executable, "-c", _ROS_START], env=env, capture_output=True, text=True)
            if done.returncode != 0:
                raise SystemExit(f"the ROS start-up measurement failed: {done.stderr.strip()[-500:]}")
            runs.append([float(v) for v in done.stdout.split()])
    finally:
        lock.close()
    med = [statistics.median(r[k] for r in runs) for k in range(6)]
    print(f"\nWhat a process pays to be a ROS node (a fresh process, a run's DDS settings; median of {repeats}, s)")
    steps = ("import rclpy and a message package", "the first node (its DDS participant)", "12 endpoints")
    for k, what in enumerate(steps):
        print(f"  {what:<40} CPU {med[k]:.3f}   wall {med[k + 3]:.3f}")
    print(f"  {'in all':<40} CPU {sum(med[:3]):.3f}   wall {sum(med[3:]):.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=2, help="runs per case; the best is kept")
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--rules", default="paper", help="rule set of every run (default: paper)")
    parser.add_argument(
        "--only",
        choices=("speed", "breakdown", "readme", "rosstart", "bag", "recording", "flood", "scale"),
        nargs="+",
        help="run only these parts (default: all)",
    )
    parser.add_argument(
        "--crowding",
        help="override the crowding switch (e.g. disc, for the reading before "
        "rule sets: --rules local --crowding disc)",
    )
    parser.add_argument(
        "--flood-rates",
        type=int,
        nargs="+",
        default=[1000, 2500, 5000],
        help="messages per second on each topic (flood part)",
    )
    parser.add_argument(
        "--hog",
        action="store_true",
        help="measure beside one CPU-bound process (python -c 'while 1: pass'), as on a shared machine",
    )
    parser.add_argument(
        "--scale-robots",
        type=int,
        nargs="+",
        default=[10_000],
        help="robots of the disc shapes (scale part, not run by default)",
    )
    args = parser.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench_bare, bench_flood, bench_scale
    RULES["rules"] = args.rules
    if args.crowding:
        RULES["crowding"] = args.crowding

    parts = set(args.only or ("speed", "breakdown", "readme", "rosstart", "bag", "recording", "flood"))
    if args.hog:  # one core kept busy for the whole bench, stopped at its end however it ends
        import atexit

        hog = subprocess.Popen([sys.executable, "-c", "while 1: pass"])
        atexit.register(hog.kill)
        print("beside one CPU-bound process (--hog)")
    if "speed" in parts:
        speed(args.seed, args.repeats, args.processes)
    if "rosstart" in parts:
        ros_start(max(args.repeats, 5))
    with tempfile.TemporaryDirectory() as tmp:
        if "breakdown" in parts:
            breakdown(args.seed, args.processes, max(args.repeats, 3), Path(tmp))
        if "readme" in parts:
            readme_command(max(args.repeats, 5), Path(tmp))
        if "bag" in parts:
            bag_cost(args.seed, max(args.repeats, 3), Path(tmp))
        if "recording" in parts:
            recording_cost(args.seed, max(args.repeats, 3), Path(tmp))
        if "flood" in parts:
            import bench_flood

            bench_flood.flood(args.flood_rates, Path(tmp))
        if "scale" in parts:
            import bench_scale

            bench_scale.scale(args.scale_robots, args.processes, Path(tmp))


if __name__ == "__main__":
    main()
