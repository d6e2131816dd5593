"""Ctrl-C and SIGTERM as a flag, checked at safe points, instead of an exception raised anywhere;
and the age of a process (for the launcher's and the nodes' timelines).

A KeyboardInterrupt can land in the middle of any statement: halfway through sending a
recording's buffered columns, say, or inside a ROS callback, where rclpy turns it into a
bare RuntimeError. Loops that must stop cleanly (the ROS nodes, ``swarm-ros simulate``)
install a :class:`StopFlag` and check ``signum`` between units of work.
"""

from __future__ import annotations

import os
import signal
import time

EXIT_INTERRUPTED = 130  #: the exit status of a command or node stopped by Ctrl-C or SIGTERM (128 + SIGINT)


class InterruptSaid(KeyboardInterrupt):
    """A Ctrl-C that a command has already told the user about (what was kept, how to resume)."""


class StopFlag:
    """Records SIGINT or SIGTERM instead of raising; ``signum`` is 0 until one arrives.

    Use as a context manager to restore the previous handlers on exit.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # SIGHUP: the terminal, or the launcher, is gone

    def __init__(self) -> None:
        import threading

        self.signum = 0
        # Python runs signal handlers in the main thread only: elsewhere (a Dask worker's task) the flag stays 0
        main = threading.current_thread() is threading.main_thread()
        self._previous = {sig: signal.signal(sig, self._set) for sig in self.SIGNALS} if main else {}

    def _set(self, signum: int, frame: object) -> None:
        self.signum = signum

    def restore(self) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def __enter__(self) -> StopFlag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.restore()


#: Set by ``swarm-ros run`` in each node's environment: the launcher's pid, which the node dies with
#: (the kernel sends it SIGHUP when the launcher dies).
PARENT_ENV = "SWARM_ROS_LAUNCHER_PID"


def run_age() -> float:
    """Seconds from the start of ``swarm-ros run`` (its process, if it is this process's parent), else from the
    start of this process, to now."""
    parent = os.environ.get(PARENT_ENV, "")
    if parent.isdigit() and int(parent) == os.getppid():
        age = process_age(int(parent))
        if age == age:  # not NaN
            return age
    return process_age()


def process_age(pid: int | str = "self") -> float:
    """Seconds since process ``pid`` (this one by default) started, interpreter start-up included,
    to the kernel's 10 ms; NaN where that cannot be read (no such process, not Linux)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()
        started = int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22, starttime, after the command name
        return time.clock_gettime(time.CLOCK_BOOTTIME) - started
    except (OSError, ValueError, IndexError):
        return float("nan")  # not Linux
