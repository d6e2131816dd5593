"""The Fast DDS shared-memory files of a run's processes in /dev/shm: which a process holds, and removing
those no live process uses any more (after a run, or a test session). Plain files and /proc: no ROS import."""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

SHM_DIR = Path("/dev/shm")


def shm_locks(pid: int | str) -> set[str]:
    """The Fast DDS shared-memory lock files (``/dev/shm/fastrtps_*_el``) process ``pid`` has open now."""
    found: set[str] = set()
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return found
    for fd in fds:
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith(f"{SHM_DIR}/fastrtps_") and target.endswith("_el"):
            found.add(target)
    return found


def in_use(paths: set[str], besides: frozenset[int] = frozenset()) -> set[str]:
    """Those of ``paths`` that a live process (other than the pids ``besides``) has mapped or open (every
    process's /proc maps and fds)."""
    used: set[str] = set()
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit() or int(proc.name) in besides:
            continue
        try:
            with open(proc / "maps", encoding="utf-8", errors="replace") as f:
                for line in f:
                    path = line.rstrip("\n").partition(" /")[2]
                    if path and f"/{path}".removesuffix(" (deleted)") in paths:
                        used.add(f"/{path}".removesuffix(" (deleted)"))
            for fd in os.listdir(proc / "fd"):
                target = os.readlink(proc / "fd" / fd)
                if target in paths:
                    used.add(target)
        except OSError:
            continue  # gone meanwhile, or not ours to read
    return used


def clean_shm(lock_files: set[str], besides: frozenset[int] = frozenset()) -> list[str]:
    """Remove the Fast DDS shared-memory files behind ``lock_files`` that no live process uses; return them.

    Each segment ``/dev/shm/fastrtps_X`` (a participant's, or a port ``fastrtps_portN``)
    comes with a lock file ``fastrtps_X_el`` that its owner keeps locked, and a port with a
    semaphore ``sem.fastrtps_X_mutex``. A lock file we can lock ourselves has no live
    owner left (Fast DDS's own ``fastdds shm clean`` reasons the same way). A port whose
    owner ended normally removes its lock file but keeps the segment while another process
    still counts as its user, and a SIGKILLed process always does: so a port of this run's
    processes is left behind by every process that talked to a killed one. Such files go
    when no live process has them mapped or open (read from /proc), whatever their lock
    file says; only the files of ``lock_files``, which this run's processes held, are
    looked at. The processes ``besides`` do not count as users: the launcher's own node, shut down
    before it tidies up, leaves Fast DDS's process-wide cache of segments mapped, a killed peer's too.
    """
    groups = []
    for el in sorted(lock_files):
        segment = el.removesuffix("_el")
        try:
            with open(el, "rb") as f:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)  # released at close: we only look
        except FileNotFoundError:
            pass  # its owner removed it: the segment may remain
        except OSError:
            continue  # locked: a live process owns it
        groups.append((segment, el, str(SHM_DIR / f"sem.{Path(segment).name}_mutex")))
    used = in_use({path for group in groups for path in group}, besides) if groups else set()
    removed = []
    for group in groups:
        if used.intersection(group):
            continue
        for path in group:
            try:
                os.unlink(path)
                removed.append(path)
            except FileNotFoundError:
                pass
    return removed


def _registry() -> Path:
    """This user's list of the Fast DDS files each live ``swarm-ros run`` has seen its processes hold: one file per
    launcher, named by its pid (in the temporary directory, made private)."""
    import tempfile

    return Path(tempfile.gettempdir()) / f"swarm_ros-{os.getuid()}" / "shm"


def register(pid: int, lock_files: set[str]) -> None:
    """Record (replacing its last record) the lock files launcher ``pid``'s processes have held, so that a later run
    can tidy them if this launcher is SIGKILLed before it does (:func:`tidy_dead_runs`)."""
    folder = _registry()
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        part = folder / f".{pid}.tmp"
        part.write_text("".join(f"{f}\n" for f in sorted(lock_files)), encoding="utf-8")
        part.replace(folder / f"{pid}.list")
    except OSError:
        pass  # a full disk or a read-only /tmp: only the tidying after a SIGKILL misses them


def unregister(pid: int) -> None:
    """Drop launcher ``pid``'s record: it has tidied its own files."""
    try:
        (_registry() / f"{pid}.list").unlink(missing_ok=True)
    except OSError:
        pass  # not ours to remove: a later run finds it and tidies nothing a live process holds


def tidy_dead_runs() -> list[str]:
    """Remove the Fast DDS files that launchers no longer alive recorded (:func:`register`) and no live process
    holds (:func:`clean_shm`); drop their records. Any ``swarm-ros run`` calls it as it starts, so what a SIGKILLed
    one left in /dev/shm lasts only until the next run, whatever its output directory. Only files a record lists,
    and only Fast DDS lock files in /dev/shm among them, are looked at."""
    removed: list[str] = []
    try:
        records = sorted(_registry().glob("*.list"))
    except OSError:
        return removed
    for record in records:
        pid = record.stem
        if not pid.isdigit() or Path(f"/proc/{pid}").exists():
            continue  # that launcher is alive (or its pid was taken again: left for a later run)
        try:
            listed = record.read_text(encoding="utf-8", errors="replace").split()
        except OSError:
            continue
        removed += clean_shm(
            {
                f
                for f in listed
                if Path(f).parent == SHM_DIR and Path(f).name.startswith("fastrtps_") and f.endswith("_el")
            }
        )
        record.unlink(missing_ok=True)
    return removed


def half_made_ports(shm_dir: Path | None = None) -> list[str]:
    """The Fast DDS port segments (``fastrtps_port*``) in ``shm_dir`` (/dev/shm) that a process died making: empty,
    without the lock file their maker adds once it is done, and held by no live process (a maker at work holds its
    file open). Every participant that opens such a port, in any ROS 2 process on the host, waits for it for ever
    (docs/faults.md)."""
    empty = []
    try:
        ports = list((shm_dir or SHM_DIR).glob("fastrtps_port*"))
    except OSError:
        return []
    for port in ports:
        try:
            if not port.name.endswith("_el") and port.stat().st_size == 0 and not Path(f"{port}_el").exists():
                empty.append(str(port))
        except OSError:
            continue  # gone meanwhile
    return sorted(set(empty) - in_use(set(empty))) if empty else []
