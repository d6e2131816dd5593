"""What the world's :class:`~swarm_ros.protocol.lockstep.Lockstep` is configured by and talks to: its policy,
its timing, and the port the node around it implements (docs/faults.md); and a central world's watch on its peers
(:class:`Watch`), on the same timing."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

from swarm_ros.core.errors import RunFailed
from swarm_ros.core.params import node_defaults

if TYPE_CHECKING:
    import numpy as np

    from swarm_ros.core.rules import Decisions
    from swarm_ros.core.shard_parts import Part
    from swarm_ros.protocol.status import Status

STALL_S = 5.0  #: seconds without progress after which a silent batch or monitor counts as lost
FIRST_STALL_S = 30.0  #: the same before its first decisions or report (discovery may be slow)
#: seconds without progress after which the run fails, when what it waits for is alive (its liveliness
#: holds) but silent: its messages do not get through (a flood), or it hangs. Never removed for that.
DROWNED_S = 60.0
#: seconds without a tick published or a report received after which the run fails, whatever the liveliness
#: of its processes says (longer than any wait for a restart: ``restart_timeout`` is 30 s by default)
STILL_S = 120.0
#: seconds a batch lost for good (under ``on_batch_loss: remove``, or out of restarts) is still waited for before
#: its robots are removed: a world starved of CPU past the 1 s liveliness lease sees a live batch lapse, and the
#: batch's liveliness or decisions back within this make it a pause, not a loss (CI once removed a live batch's
#: robots so). A new process of the batch announcing itself meanwhile confirms the loss at once.
LOSS_CONFIRM_S = 2.0
FINAL_WAIT = 30.0  #: seconds to wait, after the end, for the monitor to catch up
LINGER = 1.0  #: at most this many seconds for the last messages to reach their readers before exiting
#: at most this many for the applied decisions to reach theirs (the monitor's bag): over UDP between four hosts the
#: decisions of 100,000 robots took seconds. Only a reader that died makes the world wait this long.
DECISIONS_LINGER = 5.0
#: seconds of wall time between two status messages while nothing else changes: ten a second, so that a
#: progress display can follow the run on them alone (it need not take the monitor's metrics of every tick)
STATUS_PERIOD = 0.1


_DEFAULT = node_defaults("world")  # declared once, in swarm_ros.core.params


@dataclass(frozen=True)
class Policy:
    """The world's own parameters (``swarm_ros.core.params.NODE_PARAMETERS["world"]``)."""

    monitor_window: int = _DEFAULT["monitor_window"]
    start_timeout: float = _DEFAULT["start_timeout"]
    on_batch_loss: str = _DEFAULT["on_batch_loss"]
    max_restarts: int = _DEFAULT["max_restarts"]
    restart_timeout: float = _DEFAULT["restart_timeout"]
    tick_rate: float = _DEFAULT["tick_rate"]
    record_every: int = _DEFAULT["record_every"]


class Logger(Protocol):
    """Where the lockstep's lines go: the node's logger (rclpy's), or a test's."""

    def info(self, text: str) -> None: ...
    def warn(self, text: str) -> None: ...


class WorldPort(Protocol):
    """What the lockstep asks of the node around it."""

    def watch_batch(self, k: int, name: str) -> None: ...  # batch k admitted: take its decisions, watch it
    def send_snapshot(self, k: int, tick: int, rows: np.ndarray) -> None: ...  # batch k's region, to start from
    # a tick: the decisions applied in it (None: none go out), the robots' rows (None: none go out at this tick),
    # the occupancy if `joined`, each batch's region's rows (None: none, a restored world's replay) and the tally
    # (None: none, record_every 1)
    def publish_tick(
        self,
        tick: int,
        rows: np.ndarray | None,
        joined: bool,
        applied: np.ndarray | None,
        regional: list[np.ndarray] | None,
        tally: np.ndarray | None,
    ) -> None: ...
    def publish_status(self, status: Status) -> None: ...  # the run's state
    # a tick's rows in this process's view (the first `published` of them its part for the monitor), the decisions
    # applied (None: none go out), its metrics, the messages kept for the peers and the tally (None: record_every
    # 1), durable before anything of the next tick goes out (swarm_ros.protocol.shard_save)
    def save_tick(
        self,
        tick: int,
        rows: np.ndarray,
        published: int,
        applied: np.ndarray | None,
        metrics: tuple[int, ...],
        sent: dict,
        tally: np.ndarray | None,
    ) -> None: ...
    # the exchange's sends to its peers (world shards; none for the world alone)
    def send_claims(self, peer: int, tick: int, claims: Decisions) -> None: ...
    def send_part(self, peer: int, tick: int, part: Part) -> None: ...
    def ask_again(self, peer: int) -> None: ...
    def save_book(self, book: dict) -> None: ...  # the bookkeeping beside the ticks (Lockstep.book)
    def monitor_reads_all(self) -> bool: ...  # the monitor's reader of every topic it records is matched
    def delivered(self) -> bool: ...  # every reader acknowledged the last status, rows and tallies
    def decisions_delivered(self) -> bool: ...  # every reader acknowledged the applied decisions
    def startup_seconds(self) -> float: ...  # from the start of the run's command (or this process) to now


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
