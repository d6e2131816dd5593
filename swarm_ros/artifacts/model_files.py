"""The study's model's run files as text: metrics.csv (a row a tick) and final_state.csv (a row a robot), written
into the run directory by :func:`~swarm_ros.artifacts.run_dir.write_run` (the rubenstein algorithm's are
:mod:`~swarm_ros.artifacts.rubenstein.run_dir`'s)."""

from __future__ import annotations

import csv
import io
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from swarm_ros.core.state import SwarmState

FINAL_STATE_COLUMNS = ("id", "x", "y", "heading", "state")
FINAL_STATE_COLUMNS_3D = ("id", "x", "y", "z", "heading", "pitch", "state")  #: a 3D run's


def metrics_csv(history: np.ndarray) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    from swarm_ros.core.metrics import METRIC_COLUMNS  # the core's compiled modules load only when a run is written

    writer.writerow(METRIC_COLUMNS)
    writer.writerows(history.tolist())
    return buf.getvalue()


def final_state_csv(s: SwarmState) -> str:
    from swarm_ros.core.state import RobotState

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
