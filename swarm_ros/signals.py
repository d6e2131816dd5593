"""Ctrl-C and SIGTERM as a flag, checked at safe points, instead of an exception raised anywhere.

A KeyboardInterrupt can land in the middle of any statement: halfway through sending a
recording's buffered columns, say, or inside a ROS callback, where rclpy turns it into a
bare RuntimeError. Loops that must stop cleanly (the ROS nodes, ``swarm-ros simulate``)
install a :class:`StopFlag` and check ``signum`` between units of work.
"""

from __future__ import annotations

import signal


class StopFlag:
    """Records SIGINT or SIGTERM instead of raising; ``signum`` is 0 until one arrives.

    Use as a context manager to restore the previous handlers on exit.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # SIGHUP: the terminal, or the launcher, is gone

    def __init__(self) -> None:
        self.signum = 0
        self._previous = {sig: signal.signal(sig, self._set) for sig in self.SIGNALS}

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
