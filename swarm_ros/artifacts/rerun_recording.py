"""A run's Rerun recording, written the same way by both engines.

The in-process engine (``swarm-ros simulate``) and the ROS 2 monitor node both hand a
:class:`Recorder` the swarm's state and metrics as they go; for the same run they log
the same data. What it logs, on one timeline ``tick``, is :mod:`swarm_ros.artifacts.rerun_scene`'s to say.

Data is buffered for :data:`BATCH_TICKS` ticks and sent as columns
(:meth:`rerun.RecordingStream.send_columns`), about five times cheaper than one
``log`` call per tick. The file is streamed while the run goes on, so a run that is
killed still leaves what was sent up to then; :meth:`Recorder.close` (also on errors
and Ctrl-C) sends the rest and writes the file's footer.
"""

from __future__ import annotations

import os
import shutil
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from swarm_ros.artifacts.rerun_scene import EVENTS, FILLED, FREE, METRICS, OCCUPANCY, ROBOTS, blueprint, log_scene
from swarm_ros.artifacts.run_dir import RecordingError
from swarm_ros.core.darr_niazi.state import SwarmState
from swarm_ros.core.errors import ParameterError
from swarm_ros.core.metrics import METRIC_COLUMNS, TickMetrics
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape

APP_ID = "swarm_ros"
TIMELINE = "tick"
BATCH_TICKS = 64  #: ticks of robots and metrics buffered before they are sent

DISK_FULL = "no space left on device"


def write_failure(path: Path | None, exc: BaseException | None = None) -> str:
    """Why rerun could not write ``path``, in words: the disk is full, if it is (rerun's own error does not say)."""
    if path is not None and _disk_full(path):
        return DISK_FULL
    text = str(exc or "").strip()
    return text.splitlines()[0] if text else "a write failed; was the disk full?"


def _disk_full(path: Path) -> bool:
    """Whether the disk ``path`` is written on has no free block left."""
    try:
        return os.statvfs(path.parent).f_bavail == 0
    except OSError:
        return False


#: seconds a recording's file may stay the same size on a full disk, while rerun closes it, before the close is
#: taken as stuck (:meth:`Recorder.close`)
STUCK_S = 1.0

#: How an RRD file ends once it was closed whole: its footer's magic, then a 4-byte version.
_RRD_FOOTER_MAGIC = b"RRF2FOOT"


def _ends_whole(path: Path) -> bool:
    """Whether the RRD file at ``path`` ends with its footer (``rerun rrd verify`` refuses one without). The footer is
    written last, by the time ``disconnect()`` returns."""
    try:
        with open(path, "rb") as f:
            f.seek(max(f.seek(0, os.SEEK_END) - 12, 0))
            return f.read(12)[:8] == _RRD_FOOTER_MAGIC
    except OSError:
        return False


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
                removed.
        """
        if self._closed:
            return
        self._closed = True
        self.flush()
        stuck = not self._disconnect()
        if self.path is None or (not stuck and _ends_whole(self.path)):
            return
        why = write_failure(self.path)
        self.path.unlink(missing_ok=True)  # no reader could trust it, and it would block the next run
        raise RecordingError(f"{self.path}: the recording could not be written whole ({why}); it is removed")

    def _disconnect(self) -> bool:
        """Disconnect: rerun writes what is queued and the file's footer, last, and closes it. False if it is stuck.

        Once the disk filled under rerun's file writer, ``disconnect()`` sometimes never returns (seen in CI: the
        monitor was killed in it, and left a recording without its footer). It runs in a thread of its own here;
        a file that stays the same size for :data:`STUCK_S` on a disk with no free block will not be finished.
        """
        done = threading.Event()

        def disconnect() -> None:
            self.rec.disconnect()
            done.set()

        threading.Thread(target=disconnect, name="rerun-disconnect", daemon=True).start()
        size, since = -1, time.monotonic()
        while not done.wait(0.05):
            if self.path is None:
                continue  # a viewer only: nothing on this disk to give up on
            now = self.path.stat().st_size if self.path.exists() else -1
            if now != size:
                size, since = now, time.monotonic()
            elif time.monotonic() - since > STUCK_S and _disk_full(self.path):
                return False
        return True

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


def open_stream(
    name: str, path: Path | None, spawn: bool = False, connect: str | None = None, layout: rrb.Blueprint | None = None
) -> rr.RecordingStream:
    """A recording called ``name``, streaming to the file ``path`` (if any) and to a viewer (``spawn`` one, or the
    one at ``connect``), with the default blueprint ``layout``.

    Raises:
        RecordingError: the file cannot be written at all (a full disk).
    """
    rec = rr.RecordingStream(APP_ID)
    rec.send_recording_name(name)
    sinks: list = []
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)  # the run is starting: runs/ may not exist yet
        sinks.append(rr.FileSink(str(path)))
    if spawn:
        connect = connect or spawn_viewer()
    if connect:
        sinks.append(rr.GrpcSink(connect))
    try:
        rec.set_sinks(*sinks, default_blueprint=layout)
    except RuntimeError as exc:
        rec.disconnect()
        if path is not None:
            path.unlink(missing_ok=True)  # made just now by the file sink, and empty
        raise RecordingError(f"{path}: cannot write the recording ({write_failure(path, exc)})") from None
    return rec


#: Seconds a spawned viewer has to answer on its port, and to stay up after it does (without a display it binds
#: its port, then exits).
SPAWN_WAIT, SPAWN_SETTLE = 10.0, 1.0


def spawn_viewer(port: int = 9876, exe: str | None = None) -> str | None:
    """Start a Rerun viewer (the ``rerun`` beside this Python, else on PATH), detached, its output discarded, and
    return its URL once it answers; None, said in one line on stderr, if it exits (e.g. with no display) or
    does not answer within :data:`SPAWN_WAIT` seconds."""
    import socket
    import subprocess
    import time

    beside = Path(sys.executable).with_name("rerun")
    exe = exe or (str(beside) if beside.exists() else shutil.which("rerun"))
    warning = (
        "swarm-ros: warning: the Rerun viewer {}; going on without it (open the recording afterwards: "
        "rerun <run>/recording.rrd)"
    )
    if exe is None:
        print(warning.format("is not installed (no 'rerun' beside Python or on PATH)"), file=sys.stderr, flush=True)
        return None
    viewer = subprocess.Popen(
        [exe, f"--port={port}", "--memory-limit=75%", "--expect-data-soon"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # detached: it outlives the run, and a Ctrl-C of it
    deadline, answered = time.monotonic() + SPAWN_WAIT, None
    while viewer.poll() is None and time.monotonic() < deadline:
        if answered is None:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
                answered = time.monotonic()
            except OSError:
                pass
        elif time.monotonic() - answered > SPAWN_SETTLE:
            return f"rerun+http://127.0.0.1:{port}/proxy"
        time.sleep(0.05)
    if viewer.poll() is None:
        viewer.kill()
        print(warning.format(f"did not answer on port {port} within {SPAWN_WAIT:g} s"), file=sys.stderr, flush=True)
    else:
        print(warning.format(f"exited at once (status {viewer.returncode}; no display?)"), file=sys.stderr, flush=True)
    return None
