#!/usr/bin/env python3
"""Benchmark compiling the numba kernels: each algorithm's alone, and both side by side as scripts/setup.sh does.

Each measurement is a fresh process that compiles into an empty cache of its own (``NUMBA_CACHE_DIR`` set to a
new temporary directory, so the tree's own cache is neither read nor touched): ``compile_kernels(algorithm)``
timed inside the process (import excluded), and the process's CPU. Cases, ``--rounds`` rounds, in turn:

  * darr-niazi alone (the study's model: its 2D and 3D kernels);
  * rubenstein alone;
  * both at once, one process each (what scripts/setup.sh runs): the wall time of the pair.

With ``--colcon``, it also builds the package with colcon (``.venv-colcon``, which scripts/setup.sh makes) from a
copy of this tree that holds the kernels' cache (run ``python -m swarm_ros.core.kernels`` first), and times
``ros2 launch swarm_ros swarm.launch.py shape:=rectangle processes:=2`` (442 robots, K = 2) twice from it: the
first launch after the build, then the second. Before the cache travelled with the package, the first compiled
every kernel again.

    .venv/bin/python scripts/bench_compile.py [--rounds 3] [--colcon]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ALGORITHMS = ("darr-niazi", "rubenstein")
_CHILD = (
    "import sys, time\n"
    "from swarm_ros.core.kernels import compile_kernels\n"
    "t = time.perf_counter(); compile_kernels(sys.argv[1]); print(time.perf_counter() - t)\n"
)


def _start(algorithm: str, cache: Path) -> subprocess.Popen:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-c", _CHILD, algorithm], env=env, cwd=ROOT, stdout=subprocess.PIPE, text=True
    )


def compile_round() -> dict[str, tuple[float, float]]:
    """One round: (seconds, CPU seconds) of each algorithm alone, then of both side by side (wall, summed CPU)."""
    out = {}
    for algorithm in ALGORITHMS:
        with tempfile.TemporaryDirectory() as cache:
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            proc = _start(algorithm, Path(cache))
            took = float(proc.communicate()[0].strip().splitlines()[-1])
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
        out[algorithm] = (took, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    with tempfile.TemporaryDirectory() as cache:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        began = time.perf_counter()
        procs = [_start(a, Path(cache)) for a in ALGORITHMS]
        for p in procs:
            p.communicate()
        took = time.perf_counter() - began
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    out["both, side by side"] = (took, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return out


def colcon_launches(launch: str) -> list[tuple[float, bool]]:
    """Build a workspace with colcon from a copy of this tree (sources and kernel cache, as the tests build it), then
    run ``ros2 launch swarm_ros swarm.launch.py <launch>`` twice from it (ROS 2's command-line tools, installed
    into .venv as the tests install them): (seconds, whether it said it compiled) of each."""
    sys.path.insert(0, str(ROOT / "test"))
    from ros2_tools import Ros2, build_workspace, install_ros2_tools  # the tests' own, so both build alike

    install_ros2_tools()
    out = []
    with tempfile.TemporaryDirectory() as ws:
        install = build_workspace(Path(ws) / "ws")
        home = Path(ws) / "home"
        home.mkdir()
        shell = Ros2(install, home, 180 + os.getpid() % 20)
        for k in range(2):
            began = time.perf_counter()
            done = shell.run(f"ros2 launch swarm_ros swarm.launch.py {launch} out_dir:={home / f'run{k}'}", timeout=600)
            took = time.perf_counter() - began
            if done.returncode != 0:
                raise SystemExit(f"ros2 launch failed: {(done.stdout + done.stderr)[-1500:]}")
            out.append((took, "compiling the" in done.stdout + done.stderr))
        shell.run("ros2 daemon stop", timeout=30)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--colcon", action="store_true", help="also time the first start after a colcon build")
    args = parser.parse_args()
    results: dict[str, list[tuple[float, float]]] = {}
    print(f"compiling the kernels into an empty cache, {args.rounds} rounds (seconds; CPU seconds)")
    for r in range(args.rounds):
        one = compile_round()
        print(f"  round {r + 1}: " + ", ".join(f"{k} {s:.1f} ({c:.1f} CPU)" for k, (s, c) in one.items()))
        for k, v in one.items():
            results.setdefault(k, []).append(v)
    for k, values in results.items():
        wall = [w for w, _ in values]
        cpu = [c for _, c in values]
        print(
            f"{k:<20} median {statistics.median(wall):.1f} s ({min(wall):.1f}-{max(wall):.1f}); "
            f"CPU {statistics.median(cpu):.1f} s ({min(cpu):.1f}-{max(cpu):.1f})"
        )
    if args.colcon:
        launch = "shape:=rectangle processes:=2"
        (first, compiled), (second, again) = colcon_launches(launch)
        said = {True: "compiled the kernels", False: "compiled nothing"}
        print(f"ros2 launch {launch}, after a colcon build of this tree:")
        print(f"  first  {first:.1f} s ({said[compiled]})")
        print(f"  second {second:.1f} s ({said[again]}); first / second {first / second:.2f}")


if __name__ == "__main__":
    main()
