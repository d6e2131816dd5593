"""How a run is recorded, the same for both engines (CLI flags, monitor parameters).

Apart from the recordings (:mod:`swarm_ros.artifacts.rerun_recording`) so that the launcher can read the
options without loading Rerun, which only the process that records needs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from swarm_ros.core.errors import ParameterError
from swarm_ros.core.params import RECORD_EVERY, auto_every

if TYPE_CHECKING:
    from swarm_ros.core.params import RunParams

_URL_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")


@dataclass(frozen=True)
class RecordingOptions:
    """How a run is recorded; the same for both engines (CLI flags, monitor parameters).

    Attributes:
        enabled: write recording.rrd (default on).
        every: log the robots every ``every``-th tick (>= 1); 0: :func:`auto_every` of the run.
        spawn: start a viewer and stream to it live.
        connect: stream live to the viewer at this URL.
    """

    enabled: bool = True
    every: int = 0
    spawn: bool = False
    connect: str | None = None

    def __post_init__(self) -> None:
        RECORD_EVERY.check(self.every)
        if self.connect and not self.connect.startswith(_URL_SCHEMES):
            raise ParameterError(
                f"viewer URL must start with one of {', '.join(_URL_SCHEMES)}, "
                f"got {self.connect!r} (e.g. rerun+http://127.0.0.1:9876/proxy)"
            )

    def reachable(self, timeout: float = 1.0) -> RecordingOptions:
        """These options, without ``connect`` if no viewer answers there (said in one line on stderr).

        Rerun would otherwise retry for about ten seconds and print its own errors; the
        recording file does not depend on the viewer, so the run goes on without it.
        """
        if not self.connect:
            return self
        import socket
        import sys
        from urllib.parse import urlsplit

        try:
            url = urlsplit(self.connect)
            host, port = url.hostname or "127.0.0.1", url.port or 9876
        except ValueError as exc:
            raise ParameterError(f"viewer URL {self.connect!r}: {exc}") from None
        try:
            socket.create_connection((host, port), timeout=timeout).close()
            return self
        except OSError as exc:
            print(
                f"swarm-ros: warning: no Rerun viewer answers at {self.connect} ({exc.strerror or exc}); "
                f"going on without it",
                file=sys.stderr,
                flush=True,
            )
            return replace(self, connect=None)

    def every_for(self, params: RunParams) -> int:
        """The robots are logged every this many ticks in a run of ``params``."""
        return self.every or auto_every(params)

    @property
    def active(self) -> bool:
        """Whether anything is recorded at all (to a file or a viewer)."""
        return self.enabled or self.spawn or bool(self.connect)
