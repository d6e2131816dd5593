#!/usr/bin/env python3
"""A run under a flood on every topic (scripts/flood.py), against the same run alone and ``simulate``.

The rectangle with rules ``local``, seed 4, K = 2, recording and bag on: the run of the issue
in which a flood of 40,050 messages once wrote a wrong outcome. For each rate (messages per
second on each topic), flood processes start first (one per 2,500 messages/s on each topic:
one Python process cannot publish much more on 15 topics), then ``swarm-ros run``; the
floods stop when it ends. Printed per rate: the rate the floods reached on the slowest
topic, the run's exit status, whether metrics.csv and final_state.csv are byte-identical to
``simulate``'s, the messages the world and the monitor dropped, and the run's and the
command's seconds against the run alone.

    .venv/bin/python scripts/bench_flood.py [--rates 1000 2500 5000] [--smoke]
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from swarm_ros.app.processes import DomainLock

FLOOD = Path(__file__).resolve().parent / "flood.py"
FLAGS = ["--shape", "rectangle", "--rules", "local", "--seed", "4"]
PER_PROCESS = 2500  #: messages per second on each topic, at most, from one flood process


def _run(out: Path, domain: int) -> tuple[int, float, str]:
    t0 = time.perf_counter()
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "swarm_ros",
            "run",
            *FLAGS,
            "--processes",
            "2",
            "--domain-id",
            str(domain),
            "--out",
            str(out),
            "--quiet",
        ],
        capture_output=True,
        text=True,
    )
    return done.returncode, time.perf_counter() - t0, done.stderr.strip().splitlines()[-1] if done.stderr else ""


def flooded(rate: int, out: Path) -> dict:
    """One run under a flood of ``rate`` messages/s on each topic (0: alone)."""
    lock = DomainLock()
    n = math.ceil(rate / PER_PROCESS) if rate else 0
    floods = [
        subprocess.Popen(
            [sys.executable, str(FLOOD), "--domain-id", str(lock.domain_id), "--rate", str(rate / n)],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        for _ in range(n)
    ]
    try:
        if floods:
            time.sleep(1.5)
        code, whole, err = _run(out, lock.domain_id)
    finally:
        for f in floods:
            f.send_signal(signal.SIGINT)
        reports = [json.loads(f.communicate(timeout=60)[0].strip().splitlines()[-1]) for f in floods]
        lock.close()
    reached: dict[str, float] = {}
    for report in reports:
        for topic, r in report["rate_per_topic"].items():
            reached[topic] = reached.get(topic, 0) + r
    got = {
        "rate": rate,
        "code": code,
        "whole": whole,
        "error": err,
        "reached": min(reached.values()) if reached else 0,
        "topics": len(reached),
        "sent": sum(r["total"] for r in reports),
    }
    if code == 0:
        summary = json.loads((out / "summary.json").read_text())
        got.update(run=summary["wall_seconds"], rejected=summary["rejected_messages"])
    return got


def flood(rates: list[int], tmp: Path) -> None:
    ref = tmp / "flood-ref"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "swarm_ros",
            "simulate",
            *FLAGS,
            "--out",
            str(ref),
            "--quiet",
            "--no-recording",
            "--overwrite",
        ],
        check=True,
    )
    print("\nA flood on every topic: rectangle, rules local, seed 4, K = 2, recording and bag on")
    print(
        f"{'asked/s':>8} {'reached/s':>10} {'topics':>6} {'sent':>10} {'exit':>5} {'same':>5} {'run s':>7} "
        f"{'command s':>10} {'dropped (world, monitor)':>26}"
    )
    alone = None
    for rate in [0, *rates]:
        out = tmp / f"flood-{rate}"
        got = flooded(rate, out)
        same = got["code"] == 0 and all(
            (ref / f).read_bytes() == (out / f).read_bytes() for f in ("metrics.csv", "final_state.csv")
        )
        if rate == 0:
            alone = got
        dropped = f"{got['rejected']['world']:,}, {got['rejected']['monitor']:,}" if "rejected" in got else got["error"]
        print(
            f"{rate:>8,} {got['reached']:>10,.0f} {got['topics']:>6} {got['sent']:>10,} {got['code']:>5} "
            f"{'yes' if same else 'NO':>5} {got.get('run', float('nan')):>7.2f} {got['whole']:>10.2f} "
            f"{dropped:>26}"
        )
        if rate and got["code"] == 0 and alone and alone["code"] == 0:
            print(
                f"{'':>8} slowdown: run {got['run'] / alone['run']:.1f}x, command {got['whole'] / alone['whole']:.1f}x"
            )
        if got["code"] == 0 and not same:
            print("  A WRONG RESULT: exit 0 with files that differ from simulate's")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rates", type=int, nargs="+", default=[1000, 2500, 5000])
    parser.add_argument(
        "--smoke",
        action="store_true",
        help="runs of 300 ticks at 200 messages/s: checks the script runs (test_scripts.py); its numbers mean nothing",
    )
    args = parser.parse_args()
    if args.smoke:
        FLAGS.extend(["--max-ticks", "300"])
        args.rates = [200]
    with tempfile.TemporaryDirectory() as tmp:
        flood(args.rates, Path(tmp))


if __name__ == "__main__":
    main()
