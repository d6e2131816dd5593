"""A Rerun recording for an algorithm with no scene of its own (a central world's, :mod:`swarm_ros.core.strips`):
``world/robots``: every robot as a point where it stands, of its ``state``'s class (``state <k>``, a colour each) if
its arrays have one, every ``every`` ticks on the timeline ``tick``; ``metrics/<column>``: every tick's metrics
(metrics.csv's columns), sent at the end; ``events``: how the run ended. The rubenstein algorithm has its own
(:mod:`swarm_ros.artifacts.rubenstein.recording`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.artifacts.rerun_recording import TIMELINE, close_stream, open_stream

#: the colour of each state code, in turn (a state code past the last takes the colours again from the first)
PALETTE = np.array(
    [[158, 158, 158], [46, 158, 68], [74, 127, 214], [242, 142, 43], [225, 87, 89], [148, 103, 189]], dtype=np.uint8
)
ROBOTS, METRICS, EVENTS = "world/robots", "metrics", "events"


class CentralRecorder:
    """Writes ``path`` (an .rrd file, or None) and streams to a viewer as a run goes on (``log``), until
    :meth:`finish`."""

    def __init__(
        self, path: Path | None, run: Any, every: int = 1, spawn: bool = False, connect: str | None = None
    ) -> None:
        p = run.params
        self.path, self.every, self._last, self.ended = path, every, -1, False
        self.rec = open_stream(f"{run.shape.name} n{p.robots} {p.algorithm} s{p.seed}", path, spawn, connect)
        self.rec.log("world", rr.Transform3D(mat3x3=[[1, 0, 0], [0, -1, 0], [0, 0, 1]]), static=True)  # y up
        states = [rr.AnnotationInfo(id=k, label=f"state {k}", color=c.tolist()) for k, c in enumerate(PALETTE)]
        self.rec.log("world", rr.AnnotationContext(states), static=True)
        self.robots(run)

    def robots(self, run: Any) -> None:
        """Log the robots as they stand at ``run.tick``."""
        s = run.robots
        states = np.asarray(s.state, dtype=np.int64) % len(PALETTE) if "state" in s._fields else None
        self.rec.set_time(TIMELINE, sequence=run.tick)
        self.rec.log(ROBOTS, rr.Points2D(np.column_stack([s.x, s.y]), class_ids=states, radii=0.4))
        self._last = run.tick

    def log(self, run: Any) -> None:
        """Log the robots if due at ``run.tick`` (or the run is done)."""
        if run.tick % self.every == 0 or run.done:
            self.robots(run)

    def event(self, tick: int, text: str) -> None:
        """Log a text event (a restarted process) at ``tick``, unless the recording has ended."""
        if not self.ended:
            log_event(self.rec, tick, text)

    def finish(self, run: Any, outcome: str) -> None:
        """Log the last robots, the metrics of every tick and the outcome, and end the recording.

        Raises:
            RecordingError: the file could not be written whole (it is removed).
        """
        if run.tick != self._last:
            self.robots(run)
        self.ended = True
        end_recording(self.rec, self.path, run, outcome)


def log_event(rec: rr.RecordingStream, tick: int, text: str) -> None:
    """A text event (a restarted process) at ``tick``, on the events entity every recording shows."""
    rec.set_time(TIMELINE, sequence=tick)
    rec.log(EVENTS, rr.TextLog(text, level="WARN"))


def end_recording(rec: rr.RecordingStream, path: Path | None, run: Any, outcome: str) -> None:
    """Send a run's metrics of every tick (``metrics/<column>`` of its ``columns``) and its outcome (``events``), and
    end the recording ``rec`` of the file ``path`` (:func:`~swarm_ros.artifacts.rerun_recording.close_stream`).

    Raises:
        RecordingError: the file could not be written whole (it is removed).
    """
    history = run.history
    ticks = [rr.TimeColumn(TIMELINE, sequence=history[:, 0].astype(np.int64))]
    for k, name in enumerate(run.columns[1:], start=1):
        rec.send_columns(f"{METRICS}/{name}", indexes=ticks, columns=rr.Scalars.columns(scalars=history[:, k]))
    rec.set_time(TIMELINE, sequence=run.tick)
    rec.log(EVENTS, rr.TextLog(f"outcome: {outcome}", level="INFO"))
    close_stream(rec, path)


def open_recording(path: Path, run: Any, options: RecordingOptions) -> CentralRecorder | None:
    """The ``recording`` of a run of an algorithm with no scene of its own: to ``path`` if the options write a file,
    and a viewer; None if nothing is recorded."""
    if not options.active:
        return None
    every = options.every_for(run.params)
    return CentralRecorder(path if options.enabled else None, run, every, options.spawn, options.connect)
