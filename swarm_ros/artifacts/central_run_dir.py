"""A central world's run directory (an algorithm whose world holds every robot: :mod:`swarm_ros.core.strips`):
summary.json and the algorithm's files, written whole or not at all (:func:`~swarm_ros.artifacts.run_dir.write_files`),
with the run's recording and bag moved in.

An algorithm with files of its own (the rubenstein algorithm's final.png) passes them to :func:`write_simulation`;
one with none takes it as its ``write_run`` as it is: metrics.csv (the engine's ``columns``, a row a tick) and
final_state.csv (every robot's arrays, a row a robot).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

from swarm_ros.artifacts.run_dir import write_files


def _number(value: float) -> int | float:
    return int(value) if float(value).is_integer() else float(value)


def metrics_csv(run: Any) -> str:
    """The run's metrics, a row a tick (``run.columns``): whole numbers without a point."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(run.columns)
    writer.writerows([_number(v) for v in row] for row in run.history.tolist())
    return buf.getvalue()


def robots_csv(run: Any) -> str:
    """Every robot's arrays as the run ended, a row a robot: ``id`` and each array's name."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["id", *run.robots._fields])
    writer.writerows([i, *(_number(a[i]) for a in run.robots)] for i in range(run.params.robots))
    return buf.getvalue()


def write_simulation(
    out: Path,
    run: Any,
    summary: dict,
    overwrite: bool = False,
    recording: Path | None = None,
    every: int | None = None,
    bag: Path | None = None,
    files: dict[str, Callable[[Path], object]] | None = None,
) -> Path:
    """A ``write_run`` (core.algorithm) of a central world's run: summary.json (saying how often ``recording`` holds
    the robots: ``every``, null without a recording) and ``files`` (with none, metrics.csv and final_state.csv)."""
    summary = {**summary, "recording_robots_every": every if recording is not None else None}
    if files is None:
        files = {
            "metrics.csv": lambda path: path.write_text(metrics_csv(run), encoding="utf-8"),
            "final_state.csv": lambda path: path.write_text(robots_csv(run), encoding="utf-8"),
        }
    return write_files(out, summary, files, overwrite=overwrite, recording=recording, bag=bag)
