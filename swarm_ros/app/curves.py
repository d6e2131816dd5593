"""The curves of an experiment's first runs, kept so that the report draws them without running them again.

For each grid point's repetition 0 that it runs in process, an experiment writes ``curves/<run>.csv`` beside
results.csv, before the run's row goes into results.csv: ``tick,empty``, the shape's empty patches (a
rubenstein run's uncovered pixels) at tick 0, at every tick the count changes, and at the last tick; the count
holds from one row to the next (a step curve, a few hundred rows where a 1,024-robot rubenstein run has 170,000
ticks). The report (panel (d) of a shape's figure) reads it, or, for a run without one (run over the ROS 2 graph,
or by an older swarm_ros), runs the run again in process, checks it against its row and keeps its curve.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from swarm_ros.app.results_file import EXPERIMENT_AXES

CURVES_DIR = "curves"
CURVE = "curve"  #: the key of a run's step curve in the row an in-process worker returns (not a results.csv column)


def curve_name(row: dict) -> str:
    """The file name of a run's curve, from its coordinates (as results.csv's rows give them)."""
    axes = [f"{a}-{row[a]:g}" if isinstance(row[a], float) else f"{a}-{row[a]}" for a in EXPERIMENT_AXES if row[a]]
    parts = [str(row["shape"]), f"n{row['robots']}", *axes, f"r{row['repetition']}"]
    return "_".join(parts).replace("/", "-").replace("=", "-") + ".csv"


def curve_of(run) -> np.ndarray:
    """(tick, empty) of every tick of a finished in-process run: its engine's ``empty_curve()`` (a
    ``Simulation``'s empty patches, a ``RubensteinRun``'s uncovered pixels)."""
    return run.empty_curve()


def steps(curve: np.ndarray) -> np.ndarray:
    """The rows of a (tick, value) curve where the value changes, the first and the last."""
    keep = np.ones(len(curve), dtype=bool)
    keep[1:] = curve[1:, 1] != curve[:-1, 1]
    keep[-1] = True
    return curve[keep]


def write_curve(out: Path, row: dict, curve: np.ndarray) -> None:
    """Write a run's step curve (:func:`steps`) into ``out``/curves, whole or not at all."""
    folder = out / CURVES_DIR
    folder.mkdir(exist_ok=True)
    path = folder / curve_name(row)
    part = folder / f".{path.name}.tmp"
    lines = "".join(f"{int(t)},{int(v)}\n" for t, v in curve.tolist())
    part.write_text(f"tick,empty\n{lines}", encoding="utf-8")
    os.replace(part, path)


def read_curve(out: Path, row: dict) -> np.ndarray | None:
    """A run's step curve as written by :func:`write_curve`, or None if there is none (or it does not read)."""
    path = out / CURVES_DIR / curve_name(row)
    try:
        curve = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, dtype=float)
    except (OSError, ValueError):
        return None
    return curve if curve.shape[1:] == (2,) and len(curve) else None
