"""The study's model's run directory: metrics.csv (a row a tick), final_state.csv (a row a robot), final.png and
convergence.png beside summary.json, the recording and the bag, written whole or not at all by
:func:`~swarm_ros.artifacts.run_dir.write_files`, every algorithm's writer (the rubenstein algorithm's files are
:mod:`~swarm_ros.artifacts.rubenstein.run_dir`'s)."""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from swarm_ros.artifacts.run_dir import write_files

if TYPE_CHECKING:
    from swarm_ros.core.darr_niazi.engine import Simulation
    from swarm_ros.core.darr_niazi.run_result import RunRecord
    from swarm_ros.core.darr_niazi.state import SwarmState

FINAL_STATE_COLUMNS = ("id", "x", "y", "heading", "state")
FINAL_STATE_COLUMNS_3D = ("id", "x", "y", "z", "heading", "pitch", "state")  #: a 3D run's


def metrics_csv(history: np.ndarray) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    from swarm_ros.core.darr_niazi.metrics import (
        METRIC_COLUMNS,  # the core's compiled modules load only when a run is written
    )

    writer.writerow(METRIC_COLUMNS)
    writer.writerows(history.tolist())
    return buf.getvalue()


def final_state_csv(s: SwarmState) -> str:
    from swarm_ros.core.darr_niazi.state import RobotState

    labels = [st.label for st in RobotState]
    if s.z is not None and s.pitch is not None:
        lines = [",".join(FINAL_STATE_COLUMNS_3D)]
        for i, (x, y, z, h, p, st) in enumerate(
            zip(s.x.tolist(), s.y.tolist(), s.z.tolist(), s.heading.tolist(), s.pitch.tolist(), s.state.tolist())
        ):
            lines.append(f"{i},{x!r},{y!r},{z!r},{h!r},{p!r},{labels[st]}")
        return "\n".join(lines) + "\n"
    lines = [",".join(FINAL_STATE_COLUMNS)]
    for i, (x, y, h, st) in enumerate(zip(s.x.tolist(), s.y.tolist(), s.heading.tolist(), s.state.tolist())):
        lines.append(f"{i},{x!r},{y!r},{h!r},{labels[st]}")
    return "\n".join(lines) + "\n"


def write_simulation(
    out: Path,
    sim: Simulation,
    summary: dict,
    overwrite: bool = False,
    recording: Path | None = None,
    every: int | None = None,
    bag: Path | None = None,
) -> Path:
    """:func:`write_run` of an in-process run of the study's model and its summary (core.algorithm's part
    ``write_run``)."""
    from swarm_ros.core.darr_niazi.run_result import RunRecord
    from swarm_ros.core.metrics import Outcome

    record = RunRecord(sim.shape, sim.params, sim.state, sim.history, Outcome(summary["outcome"]), summary)
    return write_run(out, record, overwrite=overwrite, recording=recording, bag=bag, robots_every=every)


def write_run(
    out: Path,
    record: RunRecord,
    overwrite: bool = False,
    recording: Path | None = None,
    bag: Path | None = None,
    robots_every: int | None = None,
) -> Path:
    """Write a run of the study's model into ``out`` (:func:`write_files`): summary.json, metrics.csv,
    final_state.csv, final.png and convergence.png, the ``recording`` and the ``bag``. ``robots_every``: the
    recording holds every robot's pose every this many ticks; summary.json says so (``recording_robots_every``,
    null without a recording); a run's ``bag`` holds every robot's row as often (``bag_robots_every``, written
    with a bag only).

    Raises:
        OutputError: the directory cannot be written.
    """

    def pictures(path: Path, save: str) -> None:
        from swarm_ros.artifacts.darr_niazi import plots  # matplotlib: only when a run is written

        getattr(plots, save)(record, path)

    summary = {**record.summary, "recording_robots_every": robots_every if recording is not None else None}
    if bag is not None:
        summary["bag_robots_every"] = robots_every
    files: dict[str, Callable[[Path], object]] = {
        "metrics.csv": lambda path: path.write_text(metrics_csv(record.history), encoding="utf-8"),
        "final_state.csv": lambda path: path.write_text(final_state_csv(record.state), encoding="utf-8"),
        "final.png": lambda path: pictures(path, "save_final_png"),
        "convergence.png": lambda path: pictures(path, "save_convergence_png"),
    }
    return write_files(out, summary, files, overwrite=overwrite, recording=recording, bag=bag)
