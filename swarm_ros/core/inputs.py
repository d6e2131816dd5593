"""Reading a user's input file with a size bound: shape files, parameter files, experiment files, results.

Every input file is read through :func:`read_bounded`, so a file that never ends (``/dev/zero``, a pipe
that keeps writing) or is far larger than any real input is refused in one line instead of filling the
machine's memory. Anything that can be read is taken: a regular file, ``/dev/null`` (empty), a named pipe
or a shell's process substitution (``<(cat plus.txt)``), each read once.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from swarm_ros.core.errors import InputError

KIB, MIB = 1024, 1024**2
#: Bounds, far above any real input of each kind: the largest built-in shape file is 5 kB, the study's
#: experiment file 1 kB, the protocol's results.csv (360 runs) 80 kB, the 3D box mesh 3 kB.
YAML_LIMIT = 1 * MIB  #: a parameter file or an experiment file
SHAPE_LIMIT = 64 * MIB  #: a text grid (a 5,000 x 5,000 world's is 25 MB) or a PNG image
MESH_LIMIT = 256 * MIB  #: an STL, OBJ or PLY mesh
RESULTS_LIMIT = 1024 * MIB  #: an experiment's results.csv (about 220 bytes a run)


def size_words(n: int) -> str:
    """``1 MiB``, ``64 MiB``, ``512 KiB``: a bound as a user reads it."""
    return f"{n // MIB} MiB" if n >= MIB and n % MIB == 0 else f"{n // KIB} KiB" if n % KIB == 0 else f"{n} bytes"


def read_bounded(path: Path, limit: int, what: str, error: type[InputError]) -> bytes:
    """The bytes of ``path``, read once, or ``error`` in one line naming the file.

    Args:
        path: a file, ``/dev/null``, a named pipe or a ``/dev/fd/N`` of the shell (not a directory).
        limit: the most bytes accepted (a reader that yields more is refused after ``limit + 1``).
        what: the kind of file, for the message (``shape file``, ``parameter file``, ...).

    Raises:
        error: no such file, a directory, unreadable, or larger than ``limit``.
    """
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise error(f"{path}: no such {what}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    if stat.S_ISDIR(mode):
        raise error(f"{path}: is a directory, not a {what}")
    try:
        if stat.S_ISFIFO(mode):
            data = _read_pipe(path, limit, what, error)
        else:
            with open(path, "rb") as f:
                data = f.read(limit + 1)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc})") from None
    if len(data) > limit:
        raise error(f"{path}: larger than {size_words(limit)}, more than any {what} needs")
    return data


#: How long a named pipe may keep its reader waiting for a first byte (or its end) before it is refused: a pipe no
#: one writes to would otherwise hold the command until Ctrl-C.
PIPE_WAIT = 5.0


def _read_pipe(path: Path, limit: int, what: str, error: type[InputError]) -> bytes:
    """A named pipe's (or the shell's ``<(...)``) bytes, up to ``limit + 1``; ``error`` if nothing (not even its
    end) comes within :data:`PIPE_WAIT` seconds. Opened without blocking, so a pipe with no writer cannot hold the
    open either; once a byte or the end is there, read to the end as from a file."""
    import select

    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        poller = select.poll()
        poller.register(fd, select.POLLIN | select.POLLHUP)
        if not poller.poll(int(PIPE_WAIT * 1000)):
            raise error(f"{path}: a named pipe no one writes to (nothing came in {PIPE_WAIT:g} s)")
        os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=False) as f:
            return f.read(limit + 1)
    finally:
        os.close(fd)


NAME_MAX, PATH_MAX = 255, 4096  #: Linux's longest file name and path, in bytes


def path_too_long(path: Path | str, margin: int = 0) -> str:
    """Why ``path`` is longer than Linux takes, or "" if it is not; ``margin``: bytes a caller adds to its last
    name for the names it makes beside it (a run's ``.<name>.logs-XXXXXXXX``)."""
    path = Path(path)
    longest = max((len(os.fsencode(name)) for name in path.parts), default=0)
    if longest > NAME_MAX:
        return f"a name in the path is {longest} bytes long, more than the {NAME_MAX} Linux takes"
    last = len(os.fsencode(path.name))
    if last + margin > NAME_MAX:
        return (
            f"its name is {last} bytes long; at most {NAME_MAX - margin} fit, since a run makes names "
            f"{margin} bytes longer beside it"
        )
    if len(os.fsencode(os.path.abspath(path))) + margin > PATH_MAX:
        return f"the path is longer than the {PATH_MAX} bytes Linux takes"
    return ""


def shown(path: Path | str, width: int = 60) -> str:
    """``path`` for a message: whole, or its first ``width`` characters and ``...`` if it is longer."""
    text = str(path)
    return text if len(text) <= width else text[:width] + "..."
