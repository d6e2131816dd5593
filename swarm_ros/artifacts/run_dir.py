"""A run's output directory: summary.json, metrics.csv, final_state.csv, final.png, convergence.png, recording.rrd.

Everything is written into a hidden temporary directory beside the target and renamed
into place at the end, so a run directory is either complete or absent. Number
formats are fixed (integers; floats as Python's shortest round-trip repr), so the same
run gives byte-identical files apart from ``wall_seconds``.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.errors import InputError, RunFailed
from swarm_ros.core.inputs import path_too_long, shown

if TYPE_CHECKING:
    from swarm_ros.core.params import RunParams

RUNS_DIR = Path("runs")
RECORDING_FILE = "recording.rrd"


class OutputError(InputError):
    """The output directory cannot be used."""


class RecordingError(RunFailed):
    """The recording file could not be written (a full disk, say); what is on disk of it is not whole. A run
    failure, not bad input: the command exits 1."""


def default_run_dir(shape: str, params: RunParams, now: datetime | None = None) -> Path:
    """``runs/<time>_<shape>_n<N>_v<R>_s<seed>`` under the current directory; under the rubenstein algorithm, which
    has no vision radius, ``runs/<time>_<shape>_n<N>_rubenstein_s<seed>``."""
    stamp = (now or datetime.now()).strftime("%Y%m%d-%H%M%S")
    setting = algorithm_of(params.algorithm).setting(params)
    return RUNS_DIR / f"{stamp}_{shape}_n{params.robots}_{setting}_s{params.seed}"


#: Everything a run directory holds: what :func:`write_run` writes, and ``logs`` (``swarm-ros run``).
BAG_DIR = "bag"  #: the rosbag2 of a ROS run, in its run directory
RUN_ENTRIES = frozenset(
    {"summary.json", "metrics.csv", "final_state.csv", "final.png", "convergence.png", RECORDING_FILE, "logs", BAG_DIR}
)
#: summary.json fields that mark a directory as a run directory this tool wrote.
_SUMMARY_MARKS = ("shape", "engine", "outcome", "convergence_tick", "seed", "robots")


def foreign_content(out: Path) -> str | None:
    """Why ``out`` is not a run directory that ``--overwrite`` may replace, or None if it is one.

    A run directory holds a summary.json with this tool's fields and nothing but the
    entries a run writes (:data:`RUN_ENTRIES`). Anything else, a file a user added
    included, makes it foreign: replacing it would delete what the tool did not write.
    """
    try:
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return "it holds no summary.json written by swarm-ros"
    if not isinstance(summary, dict) or any(k not in summary for k in _SUMMARY_MARKS):
        return "its summary.json was not written by swarm-ros"
    try:
        extra = sorted(e.name for e in out.iterdir() if e.name not in RUN_ENTRIES)
    except OSError as exc:
        return f"it cannot be listed ({exc.strerror or exc})"
    if extra:
        return f"it holds {extra[0]!r}, which no run writes"
    return None


MIB = 1024**2
#: Free space a run needs on its output's disk to start: its files take more (the star's run directory 2 MB, with
#: its bag 4 MB), and Rerun's file writer hangs, instead of failing, when a disk is full as it starts.
MIN_FREE = 8 * MIB


def check_out_dir(out: Path, overwrite: bool, free: int = MIN_FREE) -> None:
    """Fail early, before a run, if ``out`` cannot be written, or may not be replaced.

    ``overwrite`` replaces only a run directory this tool wrote (:func:`foreign_content`);
    nothing is touched here. Whether the directory that will receive the run (and, beside
    it, the partial recording and the logs) is writable is tried for real, with a
    temporary file made and removed at once: permission bits do not tell (root, /sys).

    Raises:
        OutputError: ``out`` exists (and is not an empty directory) without ``overwrite``,
            or with it but is not a run directory; is a file; its nearest existing
            ancestor is not a writable directory; or its disk has less than ``free`` bytes free.
    """
    check_name_length(out)
    check_links(out)
    if out.exists():
        if not out.is_dir():
            raise OutputError(f"{out}: exists and is not a directory")
        if any(out.iterdir()):
            if not overwrite:
                raise OutputError(f"{out}: output directory exists and is not empty (use --overwrite to replace it)")
            why = foreign_content(out)
            if why is not None:
                raise OutputError(
                    f"{out}: not a swarm-ros run directory ({why}); --overwrite replaces only run "
                    f"directories, so nothing was touched"
                )
    # Nothing is created here: the nearest existing ancestor must be a directory we may write.
    base = out.absolute().parent
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        raise OutputError(f"{base}: is not a directory, so {out} cannot be created")
    if not writable_dir(base):
        raise OutputError(f"{base}: directory is not writable, so {out} cannot be created")
    try:
        disk = os.statvfs(base)
        left = disk.f_bavail * disk.f_frsize
    except OSError:
        return
    if left < free:
        raise OutputError(
            f"{base}: {left / MIB:.1f} MiB free on its disk; a run needs at least {free // MIB} MiB "
            f"to start (its recording, bag and logs take more)"
        )


def check_links(out: Path) -> None:
    """Refuse an output path that is, or passes through, a symbolic link leading nowhere (a loop, or a link to
    something missing): nothing could be made there, and Python's own path resolution would raise on a loop.

    Raises:
        OutputError: one line naming the link.
    """
    for p in (out, *out.parents):  # as the user wrote it, so that the error names the link as they know it
        if p.is_symlink() and not p.exists():
            try:
                os.stat(p)
                why = "it cannot be followed"
            except OSError as exc:
                why = "a loop" if exc.errno == errno.ELOOP else "its target does not exist"
            raise OutputError(f"{shown(p)}: a symbolic link that leads nowhere ({why}), so {shown(out)} cannot be made")


#: Bytes a run adds to its directory's name for the names it makes beside it (``.<name>.logs-XXXXXXXX``), and
#: to its path for the files in it (``logs/world.checkpoint.json.XXXXXXXX``).
NAME_MARGIN = 20
PATH_MARGIN = 64


def check_name_length(out: Path) -> None:
    """Refuse an output directory whose name, with what a run adds to it, is longer than Linux takes.

    Raises:
        OutputError: the last name, a name on the way, or the whole path is too long.
    """
    why = path_too_long(out, NAME_MARGIN) or path_too_long(out / ("x" * PATH_MARGIN))
    if why:
        raise OutputError(f"{shown(out)}: cannot be the output directory ({why})")


def writable_dir(path: Path) -> bool:
    """Whether a file can be created in the directory ``path`` (tried with a temporary file, removed at once)."""
    try:
        with tempfile.NamedTemporaryFile(dir=path, prefix=".swarm_ros-probe-"):
            return True
    except OSError:
        return False


def _umask() -> int:
    """This process's umask, read without changing it (setting it to read it back would briefly open every file
    another thread creates meanwhile), from /proc; 0o022 where that cannot be read."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return 0o022


def public_mode(path: Path, directory: bool = False) -> None:
    """Give a file or directory made under a temporary name (``mkstemp``/``mkdtemp`` make them 0600/0700) the
    mode the user's umask gives everything else, before it is renamed into place."""
    path.chmod((0o777 if directory else 0o666) & ~_umask())


def summary_json(summary: dict) -> str:
    return json.dumps(summary, indent=2) + "\n"


def fill_summary(out: Path, restarted: Sequence[tuple[int, str]] = (), **values: object) -> bool:
    """Set fields of the run's ``summary.json`` that it holds as null (e.g. ``shutdown_seconds``, known only
    after the run directory was written), and add to its ``restarts`` those of the node processes
    ``restarted`` ((tick, name) per restart, as the launcher saw them) it lacks: a name's last restarts, at the
    launcher's ticks (at most the run's last), in tick order. Written to a fresh name and renamed over. Return
    whether it was (False: nothing to fill).

    Raises:
        OutputError: summary.json could not be read or written, and why (it is left as it was).
    """
    path, tmp = out / "summary.json", None
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
        fields = {key: value for key, value in values.items() if key in summary and summary[key] is None}
        listed = [r["node"] for r in summary.get("restarts", [])]
        late = [
            {"tick": min(tick, summary["convergence_tick"]), "node": name}
            for name in dict.fromkeys(n for _, n in restarted)
            for tick, _ in [r for r in restarted if r[1] == name][listed.count(name) :]
        ]
        if late:
            fields["restarts"] = sorted(summary["restarts"] + late, key=lambda r: r["tick"])
        if not fields:
            return False
        summary.update(fields)
        fd, tmp = tempfile.mkstemp(prefix=".summary.json.", dir=out)
        with open(fd, "w", encoding="utf-8") as f:
            f.write(summary_json(summary))
        public_mode(Path(tmp))
        Path(tmp).replace(path)
    except (OSError, ValueError, AttributeError, KeyError, TypeError) as exc:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)  # (a full disk: not left half-written beside it)
        raise OutputError(f"{path}: could not fill in {', '.join(values) or 'restarts'}: {exc}") from None
    return True


def partial_bag(out: Path) -> Path:
    """Where a run that stopped early leaves its bag, closed and readable: ``<out>.partial-bag``, beside ``out``
    (not ``.bag``: readers such as rosbags' AnyReader take a path ending in ``.bag`` for a ROS 1 bag)."""
    return out.parent / f"{out.name}.partial-bag"


def check_leftovers(out: Path) -> None:
    """Fail if an earlier run of ``out`` that stopped early left its recording or bag beside it.

    A new run would stream to the same names; what an earlier run left for the user is
    never replaced, so the new run is refused until the user moves or deletes it.

    Raises:
        OutputError: naming the file or directory left there.
    """
    for left in (partial_recording(out), partial_bag(out)):
        if left.exists() or left.is_symlink():
            raise OutputError(
                f"{left}: left by an earlier run of {out} that stopped early; move or delete it "
                f"first (a new run would write there, and never replaces it)"
            )


_CLAIMS: list = []  # (lock file, its path) of the run directories this process writes now


def claim_out_dir(out: Path) -> None:
    """Reserve ``out`` for this process until :func:`release_out_dirs` (or its exit), or fail at once if
    another swarm-ros command holds it.

    The lock is an exclusive ``flock`` on a file named after ``out``'s absolute path in
    the system's temporary directory (nothing is created beside ``out``); the kernel
    releases it when the process ends, however it ends. The file holds the holder's pid
    and command, for the message.

    Raises:
        OutputError: another command is writing ``out``.
    """
    import fcntl
    import hashlib
    import sys

    resolved = str(Path(os.path.abspath(out)).resolve())
    lock_dir = Path(tempfile.gettempdir()) / "swarm_ros-runs"
    path = lock_dir / (hashlib.sha256(resolved.encode()).hexdigest()[:32] + ".lock")
    while True:
        try:
            lock_dir.mkdir(exist_ok=True)
            f = open(path, "a+", encoding="utf-8")
        except OSError as exc:
            raise OutputError(f"{lock_dir}: cannot reserve {out} ({exc.strerror or exc})") from None
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            holder = " ".join(f.read().split()) or "another process"
            f.close()
            raise OutputError(
                f"{out}: another swarm-ros command is writing this run directory now ({holder})"
            ) from None
        try:
            same = os.stat(path).st_ino == os.fstat(f.fileno()).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        f.close()  # its holder released (and removed) it between our open and our lock: take the new one
    f.seek(0)
    f.truncate()
    f.write(f"pid {os.getpid()}: {' '.join(['swarm-ros', *sys.argv[1:]])}\n")
    f.flush()
    _CLAIMS.append((f, path))
    _sweep_stale_locks(lock_dir, path)


def _sweep_stale_locks(lock_dir: Path, own: Path) -> None:
    """Remove the lock files of commands that ended without removing theirs (SIGKILLed): any that no process
    holds locked. A command about to lock one that goes meanwhile retries with a new file (claim_out_dir)."""
    import fcntl

    for path in lock_dir.glob("*.lock"):
        if path == own:
            continue
        try:
            with open(path, "a+", encoding="utf-8") as f:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                if os.stat(path).st_ino == os.fstat(f.fileno()).st_ino:
                    path.unlink()  # while locked: as release_out_dirs does
        except OSError:
            continue  # held by a live command, or gone meanwhile


def release_out_dirs() -> None:
    """Give up this process's claims (:func:`claim_out_dir`), removing their lock files."""
    while _CLAIMS:
        f, path = _CLAIMS.pop()
        try:
            path.unlink()  # while still locked: a waiting claimant then sees another file and retries
        except OSError:
            pass
        f.close()


def partial_recording(out: Path) -> Path:
    """Where a run streams its recording while it goes on: ``<out>.partial.rrd``, beside ``out``.

    :func:`write_run` moves it into the run directory as ``recording.rrd``; a run that is
    interrupted, crashes or is killed leaves it here, readable up to that point.
    """
    return out.parent / f"{out.name}.partial.rrd"


def write_files(
    out: Path,
    summary: dict,
    files: dict[str, Callable[[Path], object]],
    overwrite: bool = False,
    recording: Path | None = None,
    bag: Path | None = None,
) -> Path:
    """Write summary.json and ``files`` (name -> a function that writes the file at the path it is given) into
    ``out``, whole or not at all (:func:`write_dir`), ``recording`` (a finished .rrd) moved in as ``recording.rrd``
    and ``bag`` (a finished rosbag2 directory, the graph's) as ``bag/``, each back where it was if the write fails:
    every algorithm's run directory. Returns ``out``.

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


def write_dir(
    out: Path, overwrite: bool, fill: Callable[[Path], None], restore: Callable[[Path], str] | None = None
) -> Path:
    """Make run directory ``out`` whole or not at all: ``fill`` fills a temporary one that takes its place after.

    Raises:
        OutputError: the directory cannot be written.
    """
    check_out_dir(out, overwrite, free=0)  # the run is over: what it writes now either fits or fails whole
    out = out.absolute()
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{out.parent}: cannot create output directory ({exc.strerror or exc})") from None
    try:  # fresh names: nothing that exists is ever replaced but ``out``, and only a run directory
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
        trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
    except OSError as exc:
        raise OutputError(f"{out}: cannot write run output ({exc.strerror or exc})") from None
    try:
        fill(tmp)
        public_mode(tmp, directory=True)
        if out.exists():
            out.rename(trash / out.name)
        tmp.rename(out)
    except OSError as exc:
        kept = restore(tmp) if restore is not None else ""
        raise OutputError(f"{out}: cannot write run output ({exc.strerror or exc}){kept}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(trash, ignore_errors=True)
    return out
