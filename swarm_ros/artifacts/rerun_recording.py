"""Every algorithm's Rerun recording starts and ends here: a stream to the run's ``recording.rrd`` and a viewer
(:func:`open_stream`, on the timeline :data:`TIMELINE`), ended whole or removed on a full disk
(:func:`close_stream`), and a viewer spawned for it (:func:`spawn_viewer`). What a recording shows is its
algorithm's (the study's model: :mod:`swarm_ros.artifacts.darr_niazi.recording`; the rubenstein algorithm's:
:mod:`swarm_ros.artifacts.rubenstein.recording`; a plain one: :mod:`swarm_ros.artifacts.central_recording`).

The file is streamed while the run goes on, so a run that is killed still leaves what was sent up to then.
"""

from __future__ import annotations

import os
import shutil
import sys
import threading
import time
from pathlib import Path

import rerun as rr
import rerun.blueprint as rrb

from swarm_ros.artifacts.run_dir import RecordingError

APP_ID = "swarm_ros"
TIMELINE = "tick"

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
#: taken as stuck (:func:`close_stream`)
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


def close_stream(rec: rr.RecordingStream, path: Path | None) -> None:
    """End the recording ``rec`` that streams to the file ``path`` (or None: a viewer only): rerun writes what is
    queued and the file's footer, last, and closes it. Every algorithm's recording ends here.

    Once the disk filled under rerun's file writer, ``disconnect()`` sometimes never returns (seen in CI: the
    monitor was killed in it, and left a recording without its footer). It runs in a thread of its own here; a
    file that stays the same size for :data:`STUCK_S` on a disk with no free block will not be finished.

    Raises:
        RecordingError: the file could not be written whole (a full disk): it ends without its footer; it is
            removed, since no reader could trust it and it would block the next run.
    """
    done = threading.Event()

    def disconnect() -> None:
        rec.disconnect()
        done.set()

    threading.Thread(target=disconnect, name="rerun-disconnect", daemon=True).start()
    size, since, stuck = -1, time.monotonic(), False
    while not done.wait(0.05):
        if path is None:
            continue  # a viewer only: nothing on this disk to give up on
        now = path.stat().st_size if path.exists() else -1
        if now != size:
            size, since = now, time.monotonic()
        elif time.monotonic() - since > STUCK_S and _disk_full(path):
            stuck = True
            break
    if path is None or (not stuck and _ends_whole(path)):
        return
    why = write_failure(path)
    path.unlink(missing_ok=True)
    raise RecordingError(f"{path}: the recording could not be written whole ({why}); it is removed")


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
