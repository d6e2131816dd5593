"""``swarm-ros simulate`` under the rubenstein algorithm (Rubenstein et al.'s Kilobot self-assembly)."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from swarm_ros.app.summary_print import print_kilobot_summary
from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape
from swarm_ros.core.signals import EXIT_INTERRUPTED, StopFlag

#: the recording logs the robots every this many ticks unless told (a robot steps 0.05 d a tick by default, and a
#: run lasts tens of thousands of ticks)
RECORD_EVERY = 20


def simulate_kilobot(
    args: argparse.Namespace,
    shape: Shape,
    params: RunParams,
    out: Path,
    options: RecordingOptions,
    prog: str,
    every: int,
) -> int:
    """``simulate`` under the rubenstein algorithm: its in-process engine, with a progress bar and a recording."""
    from tqdm import tqdm

    from swarm_ros.artifacts.kilobot_recording import KilobotRecorder
    from swarm_ros.artifacts.kilobot_run import write_kilobot_run
    from swarm_ros.artifacts.run_dir import partial_recording
    from swarm_ros.core.metrics import Outcome
    from swarm_ros.core.rubenstein.run import KilobotRun, summary_of
    from swarm_ros.core.rubenstein.tick_checks import check_tick, snapshot

    start = time.perf_counter()
    rrd = partial_recording(out) if options.enabled else None
    recorder = None
    with StopFlag() as stop:
        run = KilobotRun(shape, params)
        if options.active:
            log_every = options.every or RECORD_EVERY
            recorder = KilobotRecorder(rrd, run, every=log_every, spawn=options.spawn, connect=options.connect)
            every = log_every
        try:
            with tqdm(
                total=run.pixels, unit="pixel", desc="covered", disable=True if args.quiet else None, file=sys.stderr
            ) as bar:
                while not run.done and not stop.signum:
                    if args.check:  # tick by tick, each checked (core/rubenstein/tick_checks.py)
                        prev, covered = snapshot(run), run.metrics["covered"]
                        run.step()
                        check_tick(prev, covered, run)
                    else:
                        run.run(every - run.tick % every)
                    if run.tick % every and not run.done:
                        continue
                    if recorder is not None:
                        recorder.robots(run)
                    m = run.metrics
                    bar.update(int(m["covered"]) - bar.n)
                    bar.set_postfix(tick=str(run.tick), joined=str(int(m["joined"])), refresh=False)
        except BaseException:
            if recorder is not None:  # the recording so far, ended whole where the run failed
                recorder.close(run, "failed")
            raise
    stopped = Outcome.INTERRUPTED if not run.done else None
    summary = summary_of(run, time.perf_counter() - start, stopped)
    if recorder is not None:
        recorder.close(run, summary["outcome"])
    summary["recording_robots_every"] = recorder.every if recorder is not None and rrd is not None else None
    out = write_kilobot_run(out, run, summary, overwrite=args.overwrite, recording=rrd)
    if stopped is not None:
        print(f"{prog}: interrupted at tick {run.tick}; the run so far is in {out}", file=sys.stderr)
        return EXIT_INTERRUPTED
    if not args.quiet:
        print_kilobot_summary(summary, out)
    return 0
