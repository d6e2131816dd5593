"""A run's output directory: summary.json, metrics.csv, final_state.csv, final.png, convergence.png, recording.rrd.

Everything is written into a hidden temporary directory beside the target and renamed
into place at the end, so a run directory is either complete or absent. Number
formats are fixed (integers; floats as Python's shortest round-trip repr), so the same
run gives byte-identical files apart from ``wall_seconds``.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
from datetime import datetime
from pathlib import Path

from dataclasses import dataclass

import numpy as np

from .core.engine import Simulation
from .core.errors import SwarmError
from .core.metrics import METRIC_COLUMNS, Outcome, TickMetrics
from .core.params import RunParams
from .core.shapes import Shape
from .core.state import RobotState, SwarmState

RUNS_DIR = Path("runs")
FINAL_STATE_COLUMNS = ("id", "x", "y", "heading", "state")
RECORDING_FILE = "recording.rrd"


class OutputError(SwarmError):
    """The output directory cannot be used."""


@dataclass(frozen=True)
class RunRecord:
    """What a finished run leaves behind, whichever engine ran it.

    Attributes:
        shape, params: what was run.
        state: the swarm at the last tick.
        history: metrics of every tick, tick 0 first (int64, columns ``METRIC_COLUMNS``).
        outcome: how the run ended.
        summary: the summary.json record (:func:`swarm_ros.core.metrics.run_summary`).
    """

    shape: Shape
    params: RunParams
    state: SwarmState
    history: np.ndarray
    outcome: Outcome
    summary: dict

    @property
    def final(self) -> TickMetrics:
        return TickMetrics(*self.history[-1].tolist())

    @staticmethod
    def of(sim: Simulation, wall_seconds: float, stopped: Outcome | None = None) -> RunRecord:
        """The record of an in-process run: finished, or ``stopped`` (interrupted) at its current tick."""
        summary = sim.summary(wall_seconds=wall_seconds, stopped=stopped)
        return RunRecord(shape=sim.shape, params=sim.params, state=sim.state, history=sim.history,
                         outcome=Outcome(summary["outcome"]), summary=summary)


def default_run_dir(shape: str, robots: int, vision: float, seed: int, now: datetime | None = None) -> Path:
    """``runs/<time>_<shape>_n<N>_v<R>_s<seed>`` under the current directory."""
    stamp = (now or datetime.now()).strftime("%Y%m%d-%H%M%S")
    return RUNS_DIR / f"{stamp}_{shape}_n{robots}_v{vision:g}_s{seed}"


def check_out_dir(out: Path, overwrite: bool) -> None:
    """Fail early, before a run, if ``out`` cannot be written.

    Raises:
        OutputError: ``out`` exists (and is not an empty directory) without ``overwrite``,
            is a file, or its nearest existing ancestor is not a writable directory.
    """
    if out.exists():
        if not out.is_dir():
            raise OutputError(f"{out}: exists and is not a directory")
        if any(out.iterdir()) and not overwrite:
            raise OutputError(f"{out}: output directory exists and is not empty (use --overwrite to replace it)")
    # Nothing is created here: the nearest existing ancestor must be a directory we may write.
    base = out.absolute().parent
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        raise OutputError(f"{base}: is not a directory, so {out} cannot be created")
    if not os.access(base, os.W_OK | os.X_OK):
        raise OutputError(f"{base}: directory is not writable, so {out} cannot be created")


def metrics_csv(history: np.ndarray) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(METRIC_COLUMNS)
    writer.writerows(history.tolist())
    return buf.getvalue()


def final_state_csv(s: SwarmState) -> str:
    labels = [st.label for st in RobotState]
    lines = [",".join(FINAL_STATE_COLUMNS)]
    for i, (x, y, h, st) in enumerate(zip(s.x.tolist(), s.y.tolist(), s.heading.tolist(), s.state.tolist())):
        lines.append(f"{i},{x!r},{y!r},{h!r},{labels[st]}")
    return "\n".join(lines) + "\n"


def summary_json(summary: dict) -> str:
    return json.dumps(summary, indent=2) + "\n"


def partial_recording(out: Path) -> Path:
    """Where a run streams its recording while it goes on: ``<out>.partial.rrd``, beside ``out``.

    :func:`write_run` moves it into the run directory as ``recording.rrd``; a run that is
    interrupted, crashes or is killed leaves it here, readable up to that point.
    """
    return out.parent / f"{out.name}.partial.rrd"


def write_run(out: Path, record: RunRecord, overwrite: bool = False, recording: Path | None = None) -> Path:
    """Write the run's files into ``out`` atomically (temp dir + rename). Returns ``out``.

    ``recording``, a finished .rrd file, is moved in as ``recording.rrd`` (and back if
    the write fails).

    Raises:
        OutputError: the directory cannot be written.
    """
    from .plots import save_convergence_png, save_final_png

    check_out_dir(out, overwrite)
    out = out.absolute()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{out.parent}: cannot create output directory ({exc.strerror or exc})") from None
    tmp = out.parent / f".{out.name}.tmp-{os.getpid()}"
    trash = out.parent / f".{out.name}.old-{os.getpid()}"
    try:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        (tmp / "summary.json").write_text(summary_json(record.summary), encoding="utf-8")
        (tmp / "metrics.csv").write_text(metrics_csv(record.history), encoding="utf-8")
        (tmp / "final_state.csv").write_text(final_state_csv(record.state), encoding="utf-8")
        save_final_png(record, tmp / "final.png")
        save_convergence_png(record, tmp / "convergence.png")
        if recording is not None:
            recording.rename(tmp / RECORDING_FILE)
        if out.exists():
            out.rename(trash)
        tmp.rename(out)
    except OSError as exc:
        kept = ""
        if recording is not None and (tmp / RECORDING_FILE).exists():
            (tmp / RECORDING_FILE).rename(recording)
        if recording is not None and recording.exists():
            kept = f"; the recording is kept in {recording}"
        raise OutputError(f"{out}: cannot write run output ({exc.strerror or exc}){kept}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(trash, ignore_errors=True)
    return out
