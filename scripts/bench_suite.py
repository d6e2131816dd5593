#!/usr/bin/env python3
"""The test suite's own time: pytest's count and seconds for the whole suite, one tier of it, or a few test files.

    .venv/bin/python scripts/bench_suite.py [--clone] [--tier unit|process] [--repeats 2] [--hog] [-- pytest args]

``--clone`` measures what CI runs: a ``git clone`` of this checkout's HEAD in a temporary directory, its
``scripts/setup.sh`` (timed too), then the suite there; without it, this tree and its ``.venv``. Each repeat runs
``.venv/bin/python -m pytest`` as the README does (pytest.ini's two workers) and prints pytest's own figure: the
tests passed and failed, and its seconds. ``--hog`` keeps one core busy for the whole bench (a Python busy loop): a
loaded machine, for the suite's waits. ROS 2's command-line tools count in only if ``SWARM_ROS_ROS2_CLI`` names them,
as for the tests. Each repeat's pytest output goes to a log file; the logs are removed at the end unless a run
failed (then the script says where they are and exits 1). Ctrl-C stops the run under way and exits 130.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
COUNTS = re.compile(r"(\d+) (passed|failed|errors?)")
SECONDS = re.compile(r" in ([\d.]+)s\b")


def summary_of(log: str) -> tuple[int, int, float]:
    """(passed, failed or errored, pytest's seconds) from pytest's last summary line in ``log``."""
    for line in reversed(log.splitlines()):
        took = SECONDS.search(line)
        if took:
            counts = {kind: int(n) for n, kind in COUNTS.findall(line)}
            failed = counts.get("failed", 0) + counts.get("error", 0) + counts.get("errors", 0)
            return counts.get("passed", 0), failed, float(took.group(1))
    raise ValueError("pytest printed no summary line")


def _run(argv: list[str], cwd: Path, log: Path) -> int:
    """Run ``argv`` in a session of its own, its output into ``log``; on Ctrl-C stop the whole session (SIGINT,
    then SIGKILL after 1 s) and raise KeyboardInterrupt."""
    with open(log, "w") as out:
        proc = subprocess.Popen(argv, cwd=cwd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            return proc.wait()
        except KeyboardInterrupt:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(timeout=1)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
            raise


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clone", action="store_true", help="a fresh clone of HEAD, set up by scripts/setup.sh")
    parser.add_argument("--tier", choices=("unit", "process"), help="only the tests of this marker")
    parser.add_argument("--repeats", type=int, default=1, help="runs of the suite, one after another (default 1)")
    parser.add_argument("--hog", action="store_true", help="keep one core busy throughout")
    parser.add_argument("pytest_args", nargs="*", help="more pytest arguments (after --)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats {args.repeats}: at least 1")
    work = Path(tempfile.mkdtemp(prefix="swarm_ros-bench-suite-"))
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if args.hog else None
    failed_any = False
    try:
        tree = HERE
        if args.clone:
            tree = work / "clone"
            subprocess.run(["git", "clone", "-q", str(HERE), str(tree)], check=True, timeout=300)
            began = time.perf_counter()
            if _run(["bash", "scripts/setup.sh"], tree, work / "setup.log") != 0:
                raise SystemExit(f"bench_suite: scripts/setup.sh failed in the clone (log: {work / 'setup.log'})")
            print(f"setup: {time.perf_counter() - began:.0f} s (scripts/setup.sh in a fresh clone)", flush=True)
        python = tree / ".venv" / "bin" / "python"
        if not python.is_file():
            raise SystemExit(f"bench_suite: {python} is not there: run scripts/setup.sh first, or pass --clone")
        command = [str(python), "-m", "pytest", "-q", "-p", "no:cacheprovider"]
        command += ["-m", args.tier] if args.tier else []
        what = f"pytest{' -m ' + args.tier if args.tier else ''} {' '.join(args.pytest_args)}".strip()
        print(f"{what} in {tree}{', one core kept busy' if hog else ''}; ROS 2 CLI tools: "
              f"{os.environ.get('SWARM_ROS_ROS2_CLI') or 'none'}", flush=True)  # fmt: skip
        times = []
        for i in range(1, args.repeats + 1):
            print(f"run {i} of {args.repeats}: started {time.strftime('%H:%M:%S')}", file=sys.stderr, flush=True)
            log = work / f"pytest-{i}.log"
            code = _run([*command, *args.pytest_args], tree, log)
            try:
                passed, failed, seconds = summary_of(log.read_text(errors="replace"))
            except ValueError:
                raise SystemExit(f"bench_suite: run {i}: pytest exited {code} without a summary (log: {log})") from None
            failed_any |= failed > 0 or code != 0
            times.append(seconds)
            print(f"run {i}: {passed} passed, {failed} failed, {seconds:.0f} s ({seconds / 60:.1f} min)", flush=True)
        if len(times) > 1:
            print(f"median {statistics.median(times):.0f} s ({min(times):.0f}-{max(times):.0f})")
    except SystemExit:
        failed_any = True  # keep the logs it names
        raise
    except KeyboardInterrupt:
        print("bench_suite: interrupted", file=sys.stderr)
        return 130
    finally:
        if hog is not None:
            hog.kill()
            hog.wait()
        if failed_any:
            print(f"bench_suite: the logs are in {work}", file=sys.stderr)
        else:
            shutil.rmtree(work, ignore_errors=True)
    return 1 if failed_any else 0


if __name__ == "__main__":
    sys.exit(main())
