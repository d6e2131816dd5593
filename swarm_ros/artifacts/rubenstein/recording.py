"""A rubenstein run's Rerun recording: the shape, and every robot every ``every`` ticks, on the timeline ``tick``
(``swarm-ros simulate --algorithm rubenstein``; to the run's ``recording.rrd`` and/or a live viewer).

Entities (y up, lengths in robot diameters):

* ``world/shape``: the shape's pixels (static);
* ``world/robots``: each robot's disc where it truly is, coloured by its state (:data:`STATE_COLOURS`);
* ``world/gradient``: a dot on each robot coloured by its gradient (a cycle of :data:`RING_COLOURS`, so the
  rings of the gradient show as bands; grey while unknown);
* ``world/estimates``: an arrow from each robot that has a position estimate to that estimate;
* ``metrics/<column>``: every tick's metrics (the run's ``metrics.csv`` columns), sent at the end;
* ``events``: how the run ended.

Robots are buffered for :data:`BATCH` logged ticks and sent as columns.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

from swarm_ros.artifacts.central_recording import end_recording, log_event
from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.artifacts.rerun_recording import TIMELINE, open_stream
from swarm_ros.core.rubenstein.rule import UNKNOWN_G
from swarm_ros.core.rubenstein.run import RubensteinRun

BATCH = 64
#: start, wait_to_move, move_while_outside, move_while_inside, joined_shape
STATE_COLOURS = np.array(
    [[158, 158, 158], [74, 127, 214], [242, 142, 43], [225, 87, 89], [46, 158, 68]], dtype=np.uint8
)
RING_COLOURS = np.array(
    [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37], [240, 120, 40]], dtype=np.uint8
)
_UNKNOWN = np.array([200, 200, 200], dtype=np.uint8)
ROBOTS, GRADIENT, ESTIMATES, SHAPE, METRICS, EVENTS = (
    "world/robots",
    "world/gradient",
    "world/estimates",
    "world/shape",
    "metrics",
    "events",
)


class RubensteinRecorder:
    """Writes ``path`` (an .rrd file) as a rubenstein run goes on; :meth:`finish` sends the metrics and ends it."""

    def __init__(
        self, path: Path | None, run: RubensteinRun, every: int = 1, spawn: bool = False, connect: str | None = None
    ) -> None:
        self.path, self.every = path, every
        self._last, self.ended = -1, False
        self._ticks: list[int] = []
        self._pos: list[np.ndarray] = []
        self._state: list[np.ndarray] = []
        self._g: list[np.ndarray] = []
        self._from: list[np.ndarray] = []
        self._to: list[np.ndarray] = []
        p = run.params
        self.rec = open_stream(f"{run.shape.name} n{p.robots} rubenstein s{p.seed}", path, spawn, connect)
        f = run.frame
        rows, cols = np.nonzero(f.mask)
        mins = np.stack([f.x0 + cols * f.pixel, f.y0 + rows * f.pixel], axis=1)
        self.rec.log("world", rr.Transform3D(mat3x3=[[1, 0, 0], [0, -1, 0], [0, 0, 1]]), static=True)  # y up
        self.rec.log(
            SHAPE,
            rr.Boxes2D(mins=mins, sizes=np.full_like(mins, f.pixel), colors=[228, 228, 228], draw_order=0.0),
            static=True,
        )
        self.rec.log(ROBOTS, rr.Points2D.from_fields(radii=0.5, draw_order=1.0), static=True)
        self.rec.log(GRADIENT, rr.Points2D.from_fields(radii=0.18, draw_order=2.0), static=True)
        self.robots(run)

    def due(self, tick: int) -> bool:
        return tick % self.every == 0

    def robots(self, run: RubensteinRun) -> None:
        """Buffer the robots as they are at ``run.tick``."""
        s = run.robots
        self._last = run.tick
        self._ticks.append(run.tick)
        self._pos.append(np.stack([s.x, s.y], axis=1))
        self._state.append(STATE_COLOURS[s.state])
        known = s.g < UNKNOWN_G
        g = np.where(known, s.g, 0) % len(RING_COLOURS)
        self._g.append(np.where(known[:, None], RING_COLOURS[g], _UNKNOWN))
        est = s.est.astype(bool)
        self._from.append(np.stack([s.x[est], s.y[est]], axis=1))
        self._to.append(np.stack([s.ex[est] - s.x[est], s.ey[est] - s.y[est]], axis=1))
        if len(self._ticks) >= BATCH:
            self._send()

    def _send(self) -> None:
        if not self._ticks:
            return
        index = [rr.TimeColumn(TIMELINE, sequence=self._ticks)]
        lengths = [len(p) for p in self._pos]
        pos = np.concatenate(self._pos)
        self.rec.send_columns(
            ROBOTS,
            indexes=index,
            columns=rr.Points2D.columns(positions=pos, colors=np.concatenate(self._state)).partition(lengths),
        )
        self.rec.send_columns(
            GRADIENT,
            indexes=index,
            columns=rr.Points2D.columns(positions=pos, colors=np.concatenate(self._g)).partition(lengths),
        )
        arrows = rr.Arrows2D.columns(origins=np.concatenate(self._from), vectors=np.concatenate(self._to))
        self.rec.send_columns(ESTIMATES, indexes=index, columns=arrows.partition([len(a) for a in self._from]))
        self._ticks, self._pos, self._state, self._g, self._from, self._to = [], [], [], [], [], []

    def log(self, run: RubensteinRun) -> None:
        """Buffer the robots if due at ``run.tick`` (or the run is done)."""
        if self.due(run.tick) or run.done:
            self.robots(run)

    def event(self, tick: int, text: str) -> None:
        """Log a text event (a restarted process) at ``tick``, unless the recording has ended."""
        if not self.ended:
            log_event(self.rec, tick, text)

    def finish(self, run: RubensteinRun, outcome: str) -> None:
        """Send what is buffered, the metrics of every tick and the outcome, and end the file.

        Raises:
            RecordingError: the file could not be written whole (it is removed).
        """
        if run.tick != self._last:
            self.robots(run)
        self._send()
        self.ended = True
        end_recording(self.rec, self.path, run, outcome)


def open_recording(path: Path, run: RubensteinRun, options: RecordingOptions) -> RubensteinRecorder | None:
    """The recording of an in-process rubenstein run (core.algorithm's part ``recording``): to ``path`` if the
    options write a file, and a viewer; None if nothing is recorded."""
    if not options.active:
        return None
    every = options.every_for(run.params)
    path_or_none = path if options.enabled else None
    return RubensteinRecorder(path_or_none, run, every=every, spawn=options.spawn, connect=options.connect)
