"""How fast the graph recovers from a SIGKILL of each kind of node process, and what the fault costs the run.

    .venv/bin/python scripts/bench_faults.py [--trials 3] [--at 1000] [--smoke]

Each trial runs ``swarm-ros run`` on the star (rules local, seed 5, 3,604 ticks, K = 3, recording and bag on,
the README's defaults) once without a fault, then once for each node kind with that process SIGKILLed once the
world has saved tick ``--at``. Reported per kind, as median (min-max) over the trials:

- kill -> moving: from the SIGKILL until the run moves again: the monitor's bag holds a tick past the one it held
  50 ms after the kill (its /clock, written as it takes each tick's metrics; a restarted monitor's bag is a new
  one). The world runs on up to ``monitor_window`` ticks without the monitor, then waits.
- slowdown: the faulted command's wall time over the unfaulted one's, in the same trial.
- same: metrics.csv and final_state.csv byte-identical to the unfaulted run's.

Then, as before, the launcher itself is killed: the time until none of its node processes is alive (they get
SIGHUP from the kernel through PR_SET_PDEATHSIG).

First, in this process, what being restartable costs: the world's checkpoint of the star's run (saved every
1,000 ticks), and the monitor's bag writes of a tick, without and with making them durable (a 12-kB rows
message).
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RUN = ["--shape", "star", "--seed", "5", "--rules", "local", "--processes", "3", "--quiet"]
KINDS = ("robot_batch_1", "world", "monitor")


def _nodes(out: Path) -> dict[str, int]:
    found = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            cmd = (proc / "cmdline").read_bytes().decode(errors="replace")
            state = (proc / "stat").read_text().split(")")[-1].split()[0]
        except OSError:
            continue
        if f".{out.name}.logs-" in cmd and str(out.parent) in cmd and state != "Z":
            m = re.search(r"__node:=(\w+)", cmd)
            if m:
                found[m.group(1)] = int(proc.name)
    return found


def _held(out: Path) -> int:
    """The last tick the run's monitor holds durably in its bag (its /clock); -1 before tick 0."""
    from swarm_ros.ros.bag_writer import held_tick

    return held_tick(out.parent.glob(f".{out.name}.bag-*"))


def _wait(out: Path, above: int, timeout: float = 180) -> float:
    """Poll the monitor's bag until it holds a tick past ``above``; return time.monotonic() then."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if _held(out) > above:
            return time.monotonic()
        time.sleep(0.005)
    raise SystemExit(f"the run never passed tick {above}")


def one_run(base: Path, name: str, victim: str | None, at: int) -> tuple[float, float | None, Path]:
    """(command seconds, kill -> moving seconds or None, run directory)."""
    out = base / name
    began = time.monotonic()
    launcher = subprocess.Popen(
        [sys.executable, "-m", "swarm_ros", "run", *RUN, "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    moving = None
    if victim is not None:
        _wait(out, at - 1)
        pid = _nodes(out)[victim]
        os.kill(pid, signal.SIGKILL)
        killed = time.monotonic()
        # where the run stops: what was under way when the process died lands within moments (the world
        # applies a tick whose decisions were in, a record in flight arrives); a restart takes over a second
        time.sleep(0.05)
        moving = _wait(out, _held(out)) - killed
    _, err = launcher.communicate(timeout=600)
    if launcher.returncode != 0:
        raise SystemExit(f"{name}: run failed: {err.strip()}")
    return time.monotonic() - began, moving, out


def launcher_trial(base: Path, at: int = 300) -> float:
    out = base / "launcher"
    launcher = subprocess.Popen(
        [sys.executable, "-m", "swarm_ros", "run", *RUN, "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    _wait(out, at)
    pids = list(_nodes(out).values())
    launcher.kill()
    killed = time.monotonic()
    while time.monotonic() - killed < 20:
        alive = [
            p
            for p in pids
            if Path(f"/proc/{p}").exists() and Path(f"/proc/{p}/stat").read_text().split(")")[-1].split()[0] != "Z"
        ]
        if not alive:
            break
        time.sleep(0.005)
    took = time.monotonic() - killed
    launcher.wait()
    return took


def tick_costs(base: Path, ticks: int = 3000) -> tuple[float, float, float]:
    """Microseconds per tick: the world's checkpoint of the star's run at tick 1,000 over the 1,000 ticks between
    saves; the monitor's bag writes of a tick without and with making them durable."""
    from swarm_ros.core.algorithm import algorithm_of
    from swarm_ros.core.params import Settings
    from swarm_ros.protocol import central_checkpoint as checkpoint
    from swarm_ros.protocol.plan import CentralTopics
    from swarm_ros.ros import graph as msgs
    from swarm_ros.ros.bag_writer import BagRecorder, central_topics

    shape, params = Settings(shape="star", seed=5, rules="local").resolve()
    run = algorithm_of(params.algorithm).hook("engine")(shape, params)
    run.run(max_ticks=1000)
    saves = max(1, ticks // 300)
    began = time.perf_counter()
    for _ in range(saves):
        checkpoint.save(base / "world.checkpoint", run, {0: "robot_batch_0"}, np.array([0, run.grid.nx]))
    write = (time.perf_counter() - began) / saves / checkpoint.SAVE_TICKS * 1e6
    bag, out, topics = (
        BagRecorder(base / "run", recorded=central_topics(params.algorithm)),
        [],
        CentralTopics.of(params.algorithm),
    )
    for durable in (False, True):
        began = time.perf_counter()
        for _ in range(ticks):
            bag.write(topics.robots, bytes(12_000))
            bag.write(topics.metrics, bytes(200))
            bag.write(msgs.CLOCK, bytes(20))
            if durable:
                bag.durable()
        out.append((time.perf_counter() - began) / ticks * 1e6)
    bag.close()
    return write, out[0], out[1]


def _same(a: Path, b: Path) -> bool:
    return all((a / f).read_bytes() == (b / f).read_bytes() for f in ("metrics.csv", "final_state.csv"))


def _spread(values: list[float], fmt: str = "{:.2f}") -> str:
    return f"{fmt.format(statistics.median(values))} ({fmt.format(min(values))}-{fmt.format(max(values))})"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--at", type=int, default=1000, help="kill once the monitor's bag holds this tick")
    parser.add_argument(
        "--smoke",
        action="store_true",
        help="a batch killed in runs of 400 ticks, once: checks the script runs (test_scripts.py); no real numbers",
    )
    args = parser.parse_args()
    if args.smoke:
        RUN.extend(["--max-ticks", "400"])
        args.trials, args.at = 1, 100
    kinds = KINDS[:1] if args.smoke else KINDS  # --smoke: a robot batch only
    back: dict[str, list[float]] = {k: [] for k in kinds}
    slow: dict[str, list[float]] = {k: [] for k in kinds}
    same: dict[str, list[bool]] = {k: [] for k in kinds}
    plain, exits = [], []
    with tempfile.TemporaryDirectory(prefix="swarm_ros-bench-faults-") as tmp:
        write, bag, durable = tick_costs(Path(tmp), 100 if args.smoke else 3000)
    print(
        f"per tick: the world's checkpoint {write:.1f} us; the monitor's bag {bag:.1f} us, made durable "
        f"{durable:.1f} us",
        flush=True,
    )
    for trial in range(args.trials):
        with tempfile.TemporaryDirectory(prefix="swarm_ros-bench-faults-") as tmp:
            base = Path(tmp)
            seconds, _, ref = one_run(base, "plain", None, args.at)
            plain.append(seconds)
            for kind in kinds:
                took, moving, out = one_run(base, kind, kind, args.at)
                back[kind].append(moving)
                slow[kind].append(took / seconds)
                same[kind].append(_same(ref, out))
            exits.append(launcher_trial(base, min(300, args.at)))
        print(
            f"trial {trial + 1}: plain {seconds:.2f} s; "
            + "; ".join(f"{k} back in {back[k][-1]:.2f} s, x{slow[k][-1]:.2f}" for k in kinds),
            flush=True,
        )
    print(
        f"\nstar, rules local, seed 5, K = 3, recording and bag on{'; --smoke: 400 ticks' if args.smoke else ''}; "
        f"kill once the bag holds tick {args.at}; "
        f"{args.trials} trials; unfaulted command {_spread(plain)} s"
    )
    print(f"{'killed':>14} {'kill -> moving s':>22} {'slowdown':>22} {'same':>6}")
    for k in kinds:
        print(f"{k:>14} {_spread(back[k]):>22} {_spread(slow[k], '{:.2f}x'):>22} {'yes' if all(same[k]) else 'NO':>6}")
    print(
        f"node exit after the launcher's SIGKILL: {_spread(exits)} s (target < 2 s: "
        f"{'MET' if max(exits) < 2 else 'NOT MET'})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
