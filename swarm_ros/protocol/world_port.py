"""A central world's watch on its peers' processes (:class:`Watch`), and its timing (docs/faults.md)."""

from __future__ import annotations

from swarm_ros.core.errors import RunFailed

STALL_S = 5.0  #: seconds a batch process never seen alive is waited for before it counts as lost
#: seconds without a tick published or a report received after which the run fails, whatever the liveliness
#: of its processes says
STILL_S = 120.0
#: seconds a batch lost for good (under ``on_batch_loss: remove``, or out of restarts) is still waited for before
#: its robots are removed: a world starved of CPU past the 1 s liveliness lease sees a live batch lapse, and the
#: batch's liveliness or decisions back within this make it a pause, not a loss (CI once removed a live batch's
#: robots so). A new process of the batch announcing itself meanwhile confirms the loss at once.
LOSS_CONFIRM_S = 2.0
LINGER = 1.0  #: at most this many seconds for the last messages to reach their readers before exiting
#: seconds of wall time between two status messages while nothing else changes: ten a second, so that a
#: progress display can follow the run on them alone (it need not take the monitor's metrics of every tick)
STATUS_PERIOD = 0.1


class Watch:
    """What the world knows of its peers' processes, and whether the run still moves.

    Each batch and the monitor hold a silent writer whose DDS liveliness lapses when its process dies or stalls. A
    lapsed peer is only waited for (a launcher starts its process again, and the new one takes the run up where it
    is); it is named in the status, so a run started by hand says what it waits for. Whatever the liveliness says, a
    run whose world has neither sent a tick nor heard the monitor hold a further record for ``STILL_S`` fails: a peer
    started by hand that died, or a transport that stopped delivering, would otherwise keep it waiting for ever."""

    def __init__(self, now: float) -> None:
        self.moved_at = now  #: when a tick last went out, or the monitor last reported more held
        self.seen: set[str] = set()  #: the peers whose liveliness was ever seen
        self.lapsed: set[str] = set()  #: the peers whose liveliness lapsed and has not come back

    def liveliness(self, name: str, alive: int, not_alive: int) -> str | None:
        """Peer ``name``'s liveliness changed (``alive`` writers alive, ``not_alive`` lapsed): what to log, if any."""
        if alive > 0:
            back, first = name in self.lapsed, name not in self.seen
            self.seen.add(name)
            self.lapsed.discard(name)
            return f"{name} is alive (liveliness)" if first else f"{name} is back (liveliness)" if back else None
        if not_alive > 0 and name not in self.lapsed:
            self.lapsed.add(name)
            return f"{name} was lost (liveliness lapsed): the run waits for it"
        return None

    def replaced(self, name: str) -> None:
        """A new process of peer ``name`` announced itself: it is not the one whose liveliness lapsed."""
        self.lapsed.discard(name)

    def unheard(self, name: str) -> None:
        """Peer ``name``'s new process was never seen alive, and is silent: it counts as lapsed."""
        self.lapsed.add(name)

    def moved(self, now: float) -> None:
        self.moved_at = now

    def still(self, now: float) -> bool:
        """Whether the run has not moved for ``STILL_S``: it fails then (:meth:`failure`)."""
        return now - self.moved_at >= STILL_S

    def failure(self, tick: int, awaited: list[str], dropped: str) -> RunFailed:
        """The error of a run still at ``tick``, waiting for the peers ``awaited``, with ``dropped`` messages."""
        waits = ", ".join(f"{n} (liveliness lapsed)" if n in self.lapsed else n for n in awaited) or "nothing"
        return RunFailed(
            f"the run has not moved for {STILL_S:g} s at tick {tick} (waiting for: {waits}; messages dropped: "
            f"{dropped or 'nothing'}): its processes are gone or their messages do not get through"
        )
