"""A rubenstein run's directory: summary.json, metrics.csv, final_state.csv and final.png, written whole or not at
all (:func:`~swarm_ros.artifacts.run_dir.write_files`)."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from swarm_ros.artifacts.central_run_dir import write_simulation as write_central
from swarm_ros.core.rubenstein.rule import STATE_NAMES
from swarm_ros.core.rubenstein.run import COLUMNS, RubensteinRun

FINAL_COLUMNS = ("id", "x", "y", "heading", "state", "gradient", "estimate_x", "estimate_y", "localized")


def metrics_csv(run: RubensteinRun) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in run.history.tolist():
        writer.writerow([*(int(v) for v in row[:-1]), row[-1]])
    return buf.getvalue()


def final_state_csv(run: RubensteinRun) -> str:
    s = run.robots
    lines = [",".join(FINAL_COLUMNS)]
    for i in range(s.x.size):
        g = int(s.g[i]) if s.g[i] < 1 << 40 else ""
        est = (repr(float(s.ex[i])), repr(float(s.ey[i]))) if s.est[i] else ("", "")
        lines.append(
            f"{i},{float(s.x[i])!r},{float(s.y[i])!r},{float(s.heading[i])!r},{STATE_NAMES[s.state[i]]},{g},"
            f"{est[0]},{est[1]},{int(s.loc[i])}"
        )
    return "\n".join(lines) + "\n"


def save_final_png(run: RubensteinRun, path: Path) -> None:
    """The shape's pixels, and each robot where it ended, coloured by state, with its estimate's offset."""
    import numpy as np
    from matplotlib.collections import EllipseCollection, LineCollection, PatchCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    f, s = run.frame, run.robots
    fig = Figure(figsize=(7, 7))
    ax = fig.add_subplot()
    rows, cols = f.mask.shape
    pixels = [
        Rectangle((f.x0 + c * f.pixel, f.y0 + r * f.pixel), f.pixel, f.pixel)
        for r in range(rows)
        for c in range(cols)
        if f.mask[r, c]
    ]
    ax.add_collection(PatchCollection(pixels, facecolor="#e4e4e4", edgecolor="none"))
    colours = np.array(["#9e9e9e", "#4a7fd6", "#f28e2b", "#e15759", "#2e9e44"])
    # one artist for all the discs and one for all the estimates' offsets: a swarm of any size draws in one pass
    ax.add_collection(
        EllipseCollection(
            1.0,
            1.0,
            0.0,
            units="xy",
            offsets=np.column_stack([s.x, s.y]),
            offset_transform=ax.transData,
            facecolors=colours[s.state],
            edgecolors="k",
            linewidths=0.2,
        )
    )
    est = np.flatnonzero(s.est)
    segments = np.stack([np.column_stack([s.x[est], s.y[est]]), np.column_stack([s.ex[est], s.ey[est]])], axis=1)
    ax.add_collection(LineCollection(list(segments), colors="#b0009b", linewidths=0.6))
    ax.set_title(f"{run.shape.name}, {run.params.robots} robots (rubenstein): {run.outcome}, tick {run.tick}")
    ax.set_aspect("equal")
    ax.autoscale_view()
    fig.savefig(path, dpi=100)


def write_simulation(
    out: Path,
    run: RubensteinRun,
    summary: dict,
    overwrite: bool = False,
    recording: Path | None = None,
    every: int | None = None,
    bag: Path | None = None,
) -> Path:
    """A rubenstein run's directory (core.algorithm's part ``write_run``): a central world's
    (:func:`~swarm_ros.artifacts.central_run_dir.write_simulation`), with its metrics.csv, final_state.csv and
    final.png."""
    files = {
        "metrics.csv": lambda path: path.write_text(metrics_csv(run), encoding="utf-8"),
        "final_state.csv": lambda path: path.write_text(final_state_csv(run), encoding="utf-8"),
        "final.png": lambda path: save_final_png(run, path),
    }
    return write_central(out, run, summary, overwrite, recording, every, bag, files)
