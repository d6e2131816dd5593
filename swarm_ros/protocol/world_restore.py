"""A restarted world process goes on from its save (:mod:`swarm_ros.protocol.shard_save`).

:meth:`WorldRestore.book` is what the lockstep writes beside the ticks when its bookkeeping changes;
:meth:`WorldRestore.restore` puts a saved tick and that bookkeeping back into a fresh
:class:`~swarm_ros.protocol.lockstep.Lockstep` (a :class:`WorldRestore`), which then sends what a reader may
have lost with the process before: to its peers (world shards) the messages it kept for them, and asks for
theirs; to every batch a snapshot of the saved tick (a batch that had it ignores it); and the ticks from the one
after the monitor's last report up to the saved one, again (a reader that had them ignores them). The batches'
decisions for the next tick are in their writers' histories, which DDS hands to the new process's readers; so
are their announcements and the monitor's last metrics. The run then goes on as if nothing had happened: a
tick's decisions are a pure function of the state.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable

import numpy as np

from swarm_ros.core.errors import ContractError, RunFailed
from swarm_ros.core.replica import UNKNOWN
from swarm_ros.core.shards import WorldShard
from swarm_ros.core.state import IS_MOVING
from swarm_ros.protocol.hosting import Hosting
from swarm_ros.protocol.plan import MONITOR
from swarm_ros.protocol.shard_exchange import RunView, ShardExchange
from swarm_ros.protocol.shard_save import ShardSave
from swarm_ros.protocol.world_port import Logger, WorldPort


class WorldRestore:
    """The lockstep's bookkeeping and its restore, as its methods (the fields they read and write are the
    lockstep's own, set in ``Lockstep.__init__``)."""

    sim: RunView
    shard: WorldShard
    exchange: ShardExchange
    node_name: str
    port: WorldPort
    log: Logger
    clock: Callable[[], float]
    hosting: Hosting
    batch_names: list[str]
    restart_counts: list[int]
    incarnations: list[int]
    known: dict[int, int]
    restarts: list[tuple[int, str]]
    lost: list[str]
    removed_batches: set[int]
    monitor_nonce: str
    started: bool
    restored: bool
    started_wall: float
    start_time: float | None
    startup_seconds: float
    monitor_tick: int
    window: int
    pending: np.ndarray
    removed_now: np.ndarray
    removals: list[tuple[int, np.ndarray]]
    losses_booked: int
    queued: deque

    # the lockstep's own (Lockstep defines them)
    def save_book(self) -> None:
        raise NotImplementedError

    def _send_snapshot(self, k: int) -> None:
        raise NotImplementedError

    def _flush(self) -> None:
        raise NotImplementedError

    def publish_status(self, note: str = "") -> None:
        raise NotImplementedError

    def resent(self, tick: int, rows: np.ndarray, tally: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        raise NotImplementedError

    def book(self) -> dict:
        """The lockstep's bookkeeping, as JSON data: with the robots pending removal (and those just removed: a
        save of the tick before, its next tick's write cut off, removes them again; one of this tick knows they
        are removed) and every robot removed so far, by tick."""
        return {
            "batches": self.batch_names,
            "strips": [list(strip) for strip in self.hosting.strips],
            "restart_counts": self.restart_counts,
            "incarnations": self.incarnations,
            "restarts": [[t, n] for t, n in self.restarts],
            "lost": self.lost,
            "removed_batches": sorted(self.removed_batches),
            "losses": [[t, n] for t, n in self.sim.losses],
            "started_wall": self.started_wall,
            "startup_seconds": self.startup_seconds,
            "monitor_nonce": self.monitor_nonce,
            "pending": np.union1d(self.pending, self.removed_now).tolist(),
            "removals": [[t, ids.tolist()] for t, ids in self.removals],
        }

    def restore_book(self, b: dict, tick: int, monitor_tick: int, incarnation: int, node: str) -> None:
        """Take the bookkeeping ``b`` saved with ``tick`` (the monitor had reported ``monitor_tick``) by the
        process of ``node`` (the world, or a world shard) before this one, and watch the batches again;
        ``incarnation`` counts that node's processes before this one."""
        self.batch_names = list(b["batches"])
        self.hosting.restore(b["strips"])
        self.restart_counts, self.incarnations = list(b["restart_counts"]), list(b["incarnations"])
        self.known = dict(enumerate(self.incarnations))
        self.restarts = [(int(t), str(n)) for t, n in b["restarts"]]
        self.restarts += [(tick, node)] * max(1, incarnation - sum(n == node for _, n in self.restarts))
        self.lost, self.removed_batches = list(b["lost"]), set(b["removed_batches"])
        self.monitor_nonce = str(b["monitor_nonce"])
        self.started, self.restored = True, True
        self.started_wall = float(b["started_wall"])
        self.start_time = self.clock() - max(0.0, time.time() - self.started_wall)
        self.startup_seconds = float(b["startup_seconds"])
        self.monitor_tick = monitor_tick
        if MONITOR in self.lost:
            self.window = 0
        for k, name in enumerate(self.batch_names):
            self.port.watch_batch(k, name)

    def restore(self, saved: ShardSave, incarnation: int) -> None:
        """Go on from ``saved`` (a process of this node before this one wrote it; ``incarnation`` counts those
        processes: one killed before it wrote anything is a restart too, at the same tick): its exchange sends its
        peers the kept messages again and asks for theirs, its batches get a snapshot, the monitor the ticks it has
        not confirmed.

        Raises:
            RunFailed: the save does not make a consistent swarm.
        """
        b = saved.book
        try:
            self.exchange.restore(saved.exchange)
        except ContractError as exc:
            raise RunFailed(f"{self.node_name}: its save of tick {saved.exchange.shard.tick}: {exc}") from None
        tick = self.sim.tick
        self.restore_book(b, tick, saved.monitor_tick, incarnation, self.node_name)
        state = self.shard.state.state[saved.pending]
        self.pending = saved.pending[(state != UNKNOWN) & IS_MOVING[np.where(state == UNKNOWN, 0, state)]]
        self.losses_booked = len(self.shard.losses)
        self.removals = [(int(t), np.asarray(ids, np.int64)) for t, ids in b["removals"] if t <= tick]
        for j in self.exchange.peers:
            self.port.ask_again(j)
        self.log.warn(
            f"{self.node_name} restarted: going on from tick {tick} of its save "
            f"({len(self.batch_names)} batches, restarts so far {len(self.restarts) - 1})"
        )
        self.save_book()
        for k in range(len(self.batch_names)):
            if k not in self.removed_batches:
                self._send_snapshot(k)
        for t in sorted(t for t in saved.ring if t > self.monitor_tick or t == tick):
            rows, applied, tally = saved.ring[t]
            out, again = self.resent(t, rows, tally)
            self.queued.append((t, out, t == tick, applied, None, again))
        self._flush()
        self.publish_status()
