"""``swarm-ros simulate``: one driver for every algorithm. It runs the algorithm's in-process engine to its end, or
to Ctrl-C or SIGTERM, with a progress bar, ``--check``'s per-tick checks and a recording, and writes the run
directory; the algorithm supplies the engine and its hooks (core.algorithm): ``checked_step``, ``recording``,
``summary``, ``write_run`` and ``print_summary``.

An engine is what core.algorithm's ``engine`` says: ``run(max_ticks)``, ``step()``, ``tick``, ``done`` and
``progress()`` (the cells filled so far, the cells to fill, and a few words for the bar).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.core.algorithm import Algorithm, algorithm_of
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape
from swarm_ros.core.signals import EXIT_INTERRUPTED, StopFlag

PROGRESS_TICKS = 200  #: ticks between progress-bar updates


def simulate(
    args: argparse.Namespace, shape: Shape, params: RunParams, out: Path, options: RecordingOptions, prog: str
) -> int:
    """Run ``params``' algorithm in this process and write the run directory ``out``; the command's exit status."""
    from swarm_ros.artifacts.run_dir import partial_recording
    from swarm_ros.core.metrics import Outcome

    algorithm = algorithm_of(params.algorithm)
    start = time.perf_counter()
    stopped = recorder = None
    rrd = partial_recording(out)
    # Ctrl-C or SIGTERM, from here on: the run so far (tick 0 at least) becomes an 'interrupted' run directory
    with StopFlag() as stop:
        run = algorithm.hook("engine")(shape, params)
        recorder = algorithm.hook("recording")(rrd, run, options) if options.active else None
        try:
            _run_with_progress(run, algorithm, args.check, args.quiet, recorder, stop)
        except BaseException:
            if recorder is not None and finished_whole(recorder, run, "failed"):
                note_partial(rrd, options, prog)
            raise
        if stop.signum and not run.done:
            stopped = Outcome.INTERRUPTED
    summary = algorithm.hook("summary")(run, wall_seconds=time.perf_counter() - start, stopped=stopped)
    if recorder is not None:  # a recording that could not be written whole (a full disk) fails the command here
        recorder.finish(run, summary["outcome"])
    recorded = rrd if options.enabled else None
    every = recorder.every if recorder is not None and recorded is not None else None
    out = algorithm.hook("write_run")(out, run, summary, overwrite=args.overwrite, recording=recorded, every=every)
    if stopped is not None:
        print(f"{prog}: interrupted at tick {run.tick}; the run so far is in {out}", file=sys.stderr)
        return EXIT_INTERRUPTED
    if not args.quiet:
        algorithm.hook("print_summary")(summary, out, shape.dims)
    return 0


def _run_with_progress(
    run: Any, algorithm: Algorithm, check: bool, quiet: bool, recorder: Any, stop: StopFlag | None = None
) -> None:
    """Run ``run`` to its end (or until ``stop`` is set) with a progress bar, each tick checked if ``check`` and
    logged to ``recorder`` as it falls due."""
    from tqdm import tqdm

    checked_step = algorithm.hook("checked_step") if check else None
    done, total, words = run.progress()
    with tqdm(
        total=total,
        initial=done,
        unit=algorithm.progress_unit,
        desc=algorithm.progress_what,
        disable=True if quiet else None,
        file=sys.stderr,
        dynamic_ncols=True,
    ) as bar:
        while not run.done and not (stop and stop.signum):
            if checked_step is not None:
                checked_step(run)
            elif recorder is not None:  # stop on every tick whose robots are logged
                run.run(max_ticks=min(PROGRESS_TICKS, recorder.every - run.tick % recorder.every))
            else:
                run.run(max_ticks=PROGRESS_TICKS)
            if recorder is not None:
                recorder.log(run)
            done, total, words = run.progress()
            bar.update(done - bar.n)
            bar.set_postfix(words, refresh=False)


def finished_whole(recorder: Any, run: Any, outcome: str) -> bool:
    """End the recording of a run that failed; False if it could not be written whole (it is then removed)."""
    from swarm_ros.artifacts.run_dir import RecordingError

    try:
        recorder.finish(run, outcome)
    except RecordingError:
        return False
    return True


def note_partial(rrd: Path, options: RecordingOptions, prog: str) -> None:
    """Tell where the recording of a run that stopped early is."""
    if options.enabled and rrd.exists():
        print(f"{prog}: the recording so far is in {rrd}", file=sys.stderr)
