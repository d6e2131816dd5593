"""The study's model's Rerun recording, written the same way by both engines.

The in-process engine (``swarm-ros simulate``) and the ROS 2 monitor node both hand a
:class:`Recorder` the swarm's state and metrics as they go; for the same run they log
the same data. What it logs, on one timeline ``tick``, is :mod:`swarm_ros.artifacts.darr_niazi.scene`'s to say.

Data is buffered for :data:`BATCH_TICKS` ticks and sent as columns
(:meth:`rerun.RecordingStream.send_columns`), about five times cheaper than one
``log`` call per tick. :meth:`Recorder.close` (also on errors and Ctrl-C) sends the rest and ends the stream
(:func:`~swarm_ros.artifacts.rerun_recording.close_stream`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from swarm_ros.artifacts.darr_niazi.scene import EVENTS, FILLED, FREE, METRICS, OCCUPANCY, ROBOTS, blueprint, log_scene
from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.artifacts.rerun_recording import TIMELINE, close_stream, open_stream
from swarm_ros.core.darr_niazi.metrics import METRIC_COLUMNS, TickMetrics
from swarm_ros.core.darr_niazi.state import SwarmState
from swarm_ros.core.errors import ParameterError
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape

if TYPE_CHECKING:
    from swarm_ros.core.darr_niazi.engine import Simulation

BATCH_TICKS = 64  #: ticks of robots and metrics buffered before they are sent


class Recorder:
    """Writes one run to ``path`` (and optionally to a live viewer).

    Example:
        >>> with Recorder(Path("run.rrd"), sim.shape, sim.params) as rec:
        ...     rec.metrics(sim.history)
        ...     rec.robots(sim.state)
        ...     while not sim.done:
        ...         sim.step()
        ...         rec.metrics(sim.history[-1:])
        ...         rec.robots(sim.state, force=sim.done)
        ...     rec.outcome(sim.outcome.value, sim.metrics)

    Args:
        path: the .rrd file to stream to, or None for no file.
        shape, params: the run.
        every: log the robots (and occupancy) every ``every``-th tick; 1 = every tick.
        spawn: start a Rerun viewer and stream to it too.
        connect: URL of a running viewer to stream to too (``rerun+http://host:9876/proxy``).
    """

    def __init__(
        self,
        path: Path | None,
        shape: Shape,
        params: RunParams,
        *,
        every: int = 1,
        spawn: bool = False,
        connect: str | None = None,
    ) -> None:
        if every < 1:
            raise ParameterError(f"every must be >= 1, got {every}")
        self.path, self.every = path, every
        self._world = shape.world
        self._solid = shape.world.dims == 3
        self._robot_ticks: list[int] = []
        self._positions: list[np.ndarray] = []
        self._classes: list[np.ndarray] = []
        self._image_ticks: list[int] = []
        self._images: list[np.ndarray] = []
        self._metric_rows: list[np.ndarray] = []
        self._metric_count = 0
        self._filled: np.ndarray | None = None
        self._last_robot_tick = -1
        self._closed = False
        name = f"{shape.name} n{params.robots} v{params.vision_radius:g} s{params.seed}"
        self.rec = open_stream(name, path, spawn, connect, blueprint(shape.world.dims))
        log_scene(self.rec, shape, params, self.every)

    # -- logging ----------------------------------------------------------------
    def due(self, tick: int) -> bool:
        """Whether the robots of ``tick`` are to be logged (every k-th tick)."""
        return tick % self.every == 0

    def robots(self, state: SwarmState, force: bool = False) -> None:
        """Log the robots (and the occupancy, if it changed) at ``state.tick`` if due or ``force``d."""
        tick = state.tick
        if tick == self._last_robot_tick or not (force or self.due(tick)):
            return
        self._last_robot_tick = tick
        self._robot_ticks.append(tick)
        axes = (state.x, state.y, state.z) if self._solid else (state.x, state.y)
        xy = np.empty((state.x.size, len(axes)), dtype=np.float32)
        for k, a in enumerate(axes):
            xy[:, k] = a
        self._positions.append(xy)
        self._classes.append(state.state.astype(np.uint16))
        filled = state.occupancy >= 0
        if self._filled is None or not np.array_equal(filled, self._filled):
            self._filled = filled
            self._image_ticks.append(tick)
            if self._solid:  # the filled voxels' centres
                self._images.append(
                    np.stack(self._world.patch_coords(np.flatnonzero(filled)), axis=1).astype(np.float32)
                )
            else:
                self._images.append(np.where(filled, FILLED, FREE).astype(np.uint8))
        if len(self._robot_ticks) >= BATCH_TICKS:
            self._send_robot_columns()

    def metrics(self, rows: np.ndarray | Sequence[TickMetrics]) -> None:
        """Log metric rows (columns ``METRIC_COLUMNS``, tick first), any number at once."""
        rows = np.asarray(rows, dtype=np.int64).reshape(-1, len(METRIC_COLUMNS))
        if rows.size:
            self._metric_rows.append(rows.copy())
            self._metric_count += rows.shape[0]
            if self._metric_count >= BATCH_TICKS:
                self._send_metric_columns()

    def outcome(self, text: str, final: TickMetrics) -> None:
        """Log how the run ended (an outcome, or ``interrupted`` / ``failed``) as a text event at ``final.tick``."""
        self.flush()
        self.rec.set_time(TIMELINE, sequence=final.tick)
        line = (
            f"{text} at tick {final.tick}: {final.localized} localized, {final.empty_patches} empty "
            f"patches, {final.moving} moving"
        )
        level = {"interrupted": "WARN", "failed": "ERROR"}.get(text, "INFO")
        self.rec.log(EVENTS, rr.TextLog(line, level=level))

    def event(self, tick: int, text: str, level: str = "WARN") -> None:
        """Log a text event (e.g. a restarted process) at ``tick``."""
        self.rec.set_time(TIMELINE, sequence=tick)
        self.rec.log(EVENTS, rr.TextLog(text, level=level))

    def flush(self) -> None:
        """Send everything buffered."""
        self._send_robot_columns()
        self._send_metric_columns()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Send what is buffered, write the file's footer and disconnect; safe to call twice.

        Raises:
            RecordingError: the file could not be written whole (a full disk): it ends without its footer; it is
                removed (:func:`~swarm_ros.artifacts.rerun_recording.close_stream`).
        """
        if self._closed:
            return
        self._closed = True
        self.flush()
        close_stream(self.rec, self.path)

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals --------------------------------------------------------------
    def _send_robot_columns(self) -> None:
        if not self._robot_ticks:
            return
        lengths = [p.shape[0] for p in self._positions]
        points = rr.Points3D if self._solid else rr.Points2D
        columns = points.columns(
            positions=np.concatenate(self._positions), class_ids=np.concatenate(self._classes)
        ).partition(lengths)
        self.rec.send_columns(ROBOTS, indexes=[rr.TimeColumn(TIMELINE, sequence=self._robot_ticks)], columns=columns)
        self._robot_ticks, self._positions, self._classes = [], [], []
        if self._image_ticks:
            if self._solid:
                boxes = rr.Boxes3D.columns(centers=np.concatenate(self._images)).partition(
                    [len(c) for c in self._images]
                )
            else:
                boxes = rr.SegmentationImage.columns(buffer=self._images)
            self.rec.send_columns(
                OCCUPANCY, indexes=[rr.TimeColumn(TIMELINE, sequence=self._image_ticks)], columns=boxes
            )
            self._image_ticks, self._images = [], []

    def _send_metric_columns(self) -> None:
        if not self._metric_rows:
            return
        rows = np.concatenate(self._metric_rows)
        self._metric_rows, self._metric_count = [], 0
        ticks = rr.TimeColumn(TIMELINE, sequence=rows[:, 0])
        for k, name in enumerate(METRIC_COLUMNS[1:], start=1):
            self.rec.send_columns(
                f"{METRICS}/{name}", indexes=[ticks], columns=rr.Scalars.columns(scalars=rows[:, k].astype(np.float64))
            )


class SimulationRecording:
    """The recording of an in-process run of the study's model (core.algorithm's part ``recording``): the
    metrics of every tick and the robots every ``every``-th tick and at the end, as the run goes."""

    def __init__(self, recorder: Recorder, sim: Simulation) -> None:
        self.recorder, self.every = recorder, recorder.every
        recorder.metrics(sim.history)
        recorder.robots(sim.state)
        self._logged = sim.tick

    def log(self, sim: Simulation) -> None:
        """Log the ticks run since the last call: their metrics, and the robots if due (or the run is done)."""
        self.recorder.metrics(sim.history[self._logged + 1 :])
        self.recorder.robots(sim.state, force=sim.done)
        self._logged = sim.tick

    def event(self, tick: int, text: str) -> None:
        """Log a text event (a restarted process) at ``tick``, unless the recording has ended."""
        if not self.recorder.closed:
            self.recorder.event(tick, text)

    def finish(self, sim: Simulation, outcome: str) -> None:
        """Log the robots at the end if not yet (a graph's monitor is told its last record before the outcome), the
        outcome, and end the file.

        Raises:
            RecordingError: the file could not be written whole (it is removed).
        """
        self.recorder.robots(sim.state, force=sim.done)
        self.recorder.outcome(outcome, sim.metrics)
        self.recorder.close()


def open_recording(path: Path, sim: Simulation, options: RecordingOptions) -> SimulationRecording | None:
    """The recording of ``sim`` to ``path`` (if the options write a file) and a viewer, or None if nothing is
    recorded."""
    if not options.active:
        return None
    every = options.every_for(sim.params)
    recorder = Recorder(
        path if options.enabled else None, sim.shape, sim.params, every=every, spawn=options.spawn,
        connect=options.connect,
    )  # fmt: skip
    return SimulationRecording(recorder, sim)
