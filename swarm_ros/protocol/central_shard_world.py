"""World shard i's half of a central world's run in the graph (``--world-shards S``), as plain code: the batches of
its strips only, the robots of its columns and halo (:class:`~swarm_ros.core.central_shards.CentralShard`), and a
tick settled with its peers (:class:`~swarm_ros.core.central_shards.CentralExchange`) once its batches' decisions
are in. The rest of the world's logic is :class:`~swarm_ros.protocol.central_world.CentralWorld`'s, as the one
world's: the monitor's reach, records (each shard's of its own robots; shard 0 sends the metrics, the same on every
shard), liveliness, a still run, the end, and a checkpoint (:mod:`~swarm_ros.protocol.central_checkpoint`), which
also holds the robots the shard holds: a restarted shard process goes on from it, its peers waiting for it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from swarm_ros.core.central_shards import BORDER, DECIDING, CentralExchange, CentralShard, concat
from swarm_ros.core.errors import ContractError, Rejected, RunFailed

from .central_lockstep import CentralLockstep
from .central_rows import Wire
from .plan import shard_name


class ShardLockstep(CentralLockstep):
    """A :class:`CentralLockstep` for world shard ``shard.index``: ``port`` sends its messages to its peers
    (``send_border``, ``send_shared``, ``send_rows``: :class:`~swarm_ros.core.central_shards.ShardPort`)."""

    def __init__(self, shard: CentralShard, wire: Wire, port: Any, ahead: int = 2) -> None:
        super().__init__(shard.run, wire)
        self.shard, self.expected, self.port = shard, shard.strips, port
        self.shard_index = shard.index
        self.exchange = CentralExchange(shard, self, ahead)

    @property
    def batches(self) -> int:
        return self.expected.batches

    @property
    def mine(self) -> list[int]:
        """The batches it serves: those of its strips."""
        return list(self.shard.batches)

    def recorded(self) -> np.ndarray:
        """Its own robots: each shard's record holds those."""
        return self.shard.own

    def announce(self, name: str, strip: tuple[int, int]) -> list[int]:
        """As :meth:`CentralLockstep.announce`, for its batches: another shard's batch's strip is not its concern.

        Raises:
            Rejected: a strip that is no batch's of the run, or of one of its batches another node announced.
        """
        k = next((k for k in range(self.expected.batches) if self.expected.strip(k) == tuple(strip)), None)
        if k is None:
            raise Rejected("strip", f"{name}'s columns {strip[0]}..{strip[1]} are no batch's strip of the run")
        if k not in self.shard.batches:
            return []
        if self.hosts.get(k, name) != name:
            raise Rejected("strip", f"{name} announced the strip of {self.hosts[k]}")
        self.hosts[k] = name
        if self.started:
            return [k]
        if len(self.hosts) < len(self.mine):
            return []
        self.strips, self.started = self.expected, True
        return self.mine

    def kept(self) -> dict[str, np.ndarray]:
        """The robots it holds (its columns' and its halo's), and its batches removed: saved with the run."""
        return {**super().kept(), "present": self.shard.present}

    def resume(self, hosts: dict[int, str], cuts: np.ndarray, kept: dict[str, np.ndarray], before: int = -1) -> None:
        """As :meth:`CentralLockstep.resume`, holding the robots it held, its exchanges on from the run's tick.

        Raises:
            RunFailed: a checkpoint that is not of this shard of this run.
        """
        if not np.array_equal(cuts, self.expected.cuts) or set(hosts) != set(self.mine) or "present" not in kept:
            raise RunFailed("the world shard's checkpoint is not of this shard of this run")
        try:
            self.shard.restore(kept["present"])
        except ContractError as exc:
            raise RunFailed(f"the world shard's checkpoint is not of this run ({exc})") from exc
        super().resume(hosts, cuts, kept, before)
        self.exchange.restart()
        for tick, ids in self.removing:  # (saved as they were removed: at the end of the tick it goes on deciding)
            if tick == self.exchange.tick:
                self.exchange.leave(ids)

    def holding(self) -> np.ndarray:
        """The robots it holds: its columns' and its halo's."""
        return self.shard.holding()

    def _columns(self) -> np.ndarray:
        """Every robot's column as its arrays hold it now (its peers' rows come in after its tick is closed)."""
        return self.run.grid.columns(self.run.robots.x)

    def awaited(self) -> list[str]:
        """Its batches whose decisions are not in yet, or, once they are, the peer shards whose messages of the tick
        it waits for, by node name."""
        peers = self.exchange.awaited()
        return [shard_name(j) for j in peers] if self.exchange.phase != DECIDING else super().awaited()

    def own(self, k: int) -> np.ndarray:
        deciding = self.shard.run.deciding(self.shard.present)
        return deciding[self.expected.in_strip(self.run.grid.columns(self.run.robots.x[deciding]), k)]

    def decisions(self, k: int, tick: int, rows: np.ndarray) -> bool:
        """As :meth:`CentralLockstep.decisions`; those of a tick its batches' decisions went to the peers for
        already are a repeat (a restarted process's batch answers twice: from its topic's history, and anew). Those of
        a later tick than the one it settles with its peers were not asked for yet (its run's tick moves on as it
        settles, before the peers close the tick): the process before's, up to its next save, or a fault.

        Raises:
            Rejected: as :meth:`CentralLockstep.decisions`, and decisions of a tick not asked for yet.
        """
        if tick == self.exchange.tick and self.exchange.phase != DECIDING:
            return False
        if self.started and tick > self.exchange.tick:
            if tick <= self.before:
                return False  # sent to the process before this one, which had got further
            raise Rejected("stale tick", f"decisions for tick {tick}; the shard is settling tick {self.exchange.tick}")
        return super().decisions(k, tick, rows)

    # -- batches removed (lost for good) --------------------------------------------------------------------
    def can_remove(self) -> bool:
        """Whether a batch can be removed now: not while its shared rows of the tick being settled are out and the
        tick not closed (every shard must hear of the robots that leave with those rows)."""
        return self.exchange.phase in (DECIDING, BORDER)

    def remove_batch(self, k: int) -> np.ndarray:
        """As :meth:`CentralLockstep.remove_batch`: the robots leave at the end of the tick being settled, every
        shard told with its shared rows (:meth:`~swarm_ros.core.central_shards.CentralExchange.leave`)."""
        if k in self.removed or k not in self.shard.batches or self.strips is None:
            return np.empty(0, dtype=np.int64)
        ids = self.own(k)
        self.exchange.leave(ids)
        self.removing.append((self.exchange.tick, ids))
        self._host_locally(k)
        if k not in self.decided and self.exchange.phase == DECIDING:
            self._decide_locally(k, whole=True)
        return ids

    def settle(self) -> bool:
        """Its batches' decisions are in: to its peers; the tick settles when theirs are in (``on_settled``)."""
        ids, decided = concat([self.decided[k] for k in self.mine])
        self.decided.clear()
        self.exchange.decided(self.run.tick + 1, ids, decided)
        return False

    # -- the exchange's port, and what comes from the peers ---------------------------------------------------
    def send_border(self, peer: int, tick: int, ids: np.ndarray, decided: Any) -> None:
        self.port.send_border(peer, tick, self.wire.decision_rows(ids, decided))

    def send_shared(self, tick: int, ids: np.ndarray, rows: Any, counts: np.ndarray, leaving: np.ndarray) -> None:
        self.port.send_shared(tick, self.wire.rows(ids, self.run.robots), np.concatenate([counts, leaving]))

    def send_rows(self, peer: int, tick: int, ids: np.ndarray, rows: Any) -> None:
        self.port.send_rows(peer, tick, self.wire.rows(ids, self.run.robots))

    def closed(self, tick: int) -> None:
        self.removing = [(t, ids) for t, ids in self.removing if t > tick]
        self.on_settled()

    def border(self, peer: int, tick: int, rows: np.ndarray) -> None:
        """Shard ``peer``'s decisions of tick ``tick`` for robots in this shard's halo.

        Raises:
            Rejected: rows that fail the wire's checks, or a message the exchange refuses.
        """
        self.wire.check_rows(self.run, rows, tick)
        self.exchange.border(peer, tick, *self.wire.decisions_of(rows))

    def shared(self, peer: int, tick: int, rows: np.ndarray, values: np.ndarray) -> None:
        """Shard ``peer``'s rows every shard shares, and its counts, of tick ``tick``, then its robots that leave at
        the tick's end (``values``: the counts, then those ids).

        Raises:
            Rejected: as :meth:`border`; counts out of bounds, or robots that leave that are not the peer's.
        """
        self.wire.check_rows(self.run, rows, tick)
        n = self.shard.run.counts(np.empty(0, dtype=np.int64)).size
        counts, leaving = values[:n], values[n:]
        if counts.size != n or np.any(counts < 0):
            raise Rejected("bad number", f"counts {counts.tolist()}")
        if leaving.size and (
            leaving[0] < 0 or leaving[-1] >= self.run.params.robots or np.any(np.diff(leaving) <= 0)
            or np.intersect1d(leaving, self.shard.own).size
        ):  # fmt: skip
            raise Rejected("bad ids", "robots that leave must be ascending ids of the peer's own robots")
        self.exchange.shared(peer, tick, *self.wire.robots_of(rows), counts, leaving)

    def rows(self, peer: int, tick: int, rows: np.ndarray) -> None:
        """Shard ``peer``'s robots in this shard's columns or halo after tick ``tick``.

        Raises:
            Rejected: as :meth:`border`.
        """
        self.wire.check_rows(self.run, rows, tick)
        self.exchange.rows(peer, tick, *self.wire.robots_of(rows))
