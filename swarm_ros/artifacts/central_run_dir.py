"""A central world's run directory (an algorithm whose world holds every robot: :mod:`swarm_ros.core.strips`):
summary.json and the algorithm's files, written whole or not at all (:func:`~swarm_ros.artifacts.run_dir.write_dir`),
with the run's recording and bag moved in.

An algorithm with files of its own (the rubenstein algorithm's final.png) passes them to :func:`write_central_run`;
one with none takes :func:`write_simulation` as its ``write_run``: metrics.csv (the engine's ``columns``, a row a
tick) and final_state.csv (every robot's arrays, a row a robot).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

from swarm_ros.artifacts.run_dir import BAG_DIR, RECORDING_FILE, summary_json, write_dir


def write_central_run(
    out: Path,
    summary: dict,
    files: dict[str, Callable[[Path], object]],
    overwrite: bool = False,
    recording: Path | None = None,
    bag: Path | None = None,
) -> Path:
    """Write summary.json and ``files`` (name -> a function that writes the file at the path it is given) into
    ``out``, atomically, ``recording`` (a finished .rrd) moved in as ``recording.rrd`` and ``bag`` (a finished
    rosbag2 directory, the graph's) as ``bag/`` (each back where it was if the write fails). Returns ``out``.

    Raises:
        OutputError: the directory cannot be written.
    """

    def fill(tmp: Path) -> None:
        (tmp / "summary.json").write_text(summary_json(summary), encoding="utf-8")
        for name, write in files.items():
            write(tmp / name)
        if recording is not None:
            recording.rename(tmp / RECORDING_FILE)
        if bag is not None:
            bag.rename(tmp / BAG_DIR)

    def restore(tmp: Path) -> str:
        if recording is not None and (tmp / RECORDING_FILE).exists():
            (tmp / RECORDING_FILE).rename(recording)
        if bag is not None and (tmp / BAG_DIR).exists():
            (tmp / BAG_DIR).rename(bag)
        return f"; the recording is kept in {recording}" if recording is not None and recording.exists() else ""

    return write_dir(out, overwrite, fill, restore)


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
    return write_central_run(out, summary, files, overwrite=overwrite, recording=recording, bag=bag)
