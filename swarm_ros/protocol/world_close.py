"""What a world process does once its exchange has closed a tick (:meth:`WorldClose.closed`): a part of
:class:`~swarm_ros.protocol.lockstep.Lockstep`.

It saves the tick, then queues what goes out of it: each of its batches' region rows (the robots that changed in
its view: its own robots' rows, the peers' robots that crossed into its area, the robots removed), its part of
the robots' rows and applied decisions for the monitor (the robots in its strips: for the world, every robot),
and whether the occupancy changed. The world alone has no peers, and its view is the whole swarm.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from swarm_ros.core.metrics import METRIC_COLUMNS
from swarm_ros.core.regions import columns
from swarm_ros.core.replica import UNKNOWN
from swarm_ros.core.rules import Decisions
from swarm_ros.core.shard_parts import Part
from swarm_ros.protocol.hosting import route, stood
from swarm_ros.protocol.rows import robot_rows, state_rows

if TYPE_CHECKING:
    from swarm_ros.core.shards import WorldShard
    from swarm_ros.protocol.hosting import Hosting
    from swarm_ros.protocol.shard_exchange import RunView
    from swarm_ros.protocol.world_port import Logger, WorldPort

_LOCALIZED = METRIC_COLUMNS.index("localized")


def joined(first: np.ndarray, then: np.ndarray) -> np.ndarray:
    """Rows of one layout one after the other, in that layout (``np.concatenate`` may repack records)."""
    out = np.empty(first.size + then.size, dtype=first.dtype)
    out[: first.size], out[first.size :] = first, then
    return out


def first_of(n: int, ids: list[np.ndarray], values: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The robots of ``ids`` (arrays of distinct ids below ``n``) in ascending order, and the value each has in
    the first array that holds it (``np.unique(..., return_index=True)``'s answer, in time linear in ``n``: the
    sort took a shard over 1 ms a tick at 50,000 robots)."""
    given = [(these, their) for these, their in zip(ids, values) if these.size]
    if len(given) == 1 and (given[0][0][1:] > given[0][0][:-1]).all():  # one array, ascending: itself
        return given[0]
    held = np.zeros(n, dtype=bool)
    value = np.empty(n, dtype=np.result_type(*values))
    for these, their in zip(reversed(ids), reversed(values)):  # the first array's values written last
        held[these] = True
        value[these] = their
    every = np.flatnonzero(held)
    return every, value[every]


def members(ids: np.ndarray, among: np.ndarray) -> np.ndarray:
    """Which of ``ids`` are in ``among`` (both ascending, distinct): ``np.isin`` by binary search."""
    if not among.size:
        return np.zeros(ids.size, dtype=bool)
    if among.size == ids.size and np.array_equal(among, ids):
        return np.ones(ids.size, dtype=bool)
    return among[np.minimum(np.searchsorted(among, ids), among.size - 1)] == ids


class WorldClose:
    """The lockstep's close of a tick, as its methods (the fields they read and write are the lockstep's own,
    set in ``Lockstep.__init__``)."""

    shard: WorldShard
    sim: RunView
    hosting: Hosting
    port: WorldPort
    log: Logger
    batch_names: list[str]
    inflight: tuple[int, np.ndarray] | None
    before: tuple[np.ndarray, ...]
    pending: np.ndarray
    removing: np.ndarray
    removed_now: np.ndarray
    removals: list[tuple[int, np.ndarray]]
    losses_booked: int
    deferred: list[tuple[int, str]]
    queued: deque

    # the lockstep's own (Lockstep and its other bases define them)
    def save_book(self) -> None:
        raise NotImplementedError

    def _flush(self) -> None:
        raise NotImplementedError

    def _remove_batch(self, k: int, why: str) -> None:
        raise NotImplementedError

    def _in_strips(self, x: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def outgoing(
        self, tick: int, rows: np.ndarray, applied: np.ndarray | None
    ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        raise NotImplementedError

    def closed(self, tick: int, part: Part, sent: dict[int, tuple[list[Decisions], list[Part] | None]]) -> None:
        """Tick ``tick`` is closed (the exchange's port): save, then queue this process's part of it for
        publishing (and go on to the next)."""
        shard, s = self.shard, self.sim.state
        assert self.inflight is not None and self.inflight[0] == tick  # the exchange closes what it was given
        applied = self.inflight[1]
        self.inflight = None
        booked = len(shard.losses) != self.losses_booked or bool(self.removing.size)
        if len(shard.losses) != self.losses_booked:  # robots removed in this tick: which, for the save
            self.losses_booked = len(shard.losses)
            known = np.concatenate([ids for _, ids in self.removals]) if self.removals else np.empty(0, np.int64)
            self.removals.append((tick, np.setdiff1d(np.flatnonzero(shard.removed), known)))
        if self.removing.size:
            self.log.warn(f"tick {tick}: removed the {self.removing.size} robots of lost batches")
            self.pending = np.setdiff1d(self.pending, self.removing)
            self.removed_now, self.removing = self.removing, np.empty(0, dtype=np.int64)
        gone = shard.gone_stationary
        received = shard.received
        ids = [part.ids, gone] + ([received.ids] if received is not None else [])
        before = [part.before, columns(s.x[gone], shard.plan.radius)] + (
            [received.before] if received is not None else []
        )
        every, cols = first_of(self.sim.params.robots, ids, before)
        areas = [self.hosting.area(k) for k in range(len(self.batch_names))]
        changed = self._region_rows(every, received)
        moved = ~stood(self.before, s, every)  # a decider whose row is the same goes to no batch again
        regional = route(changed[moved], cols[moved], areas, self.hosting.radius)
        # the monitor's part (no overlap with another shard's): its own robots, and those removed in its strips
        ours = np.union1d(part.ids, gone[self._in_strips(s.x[gone])]) if gone.size else part.ids
        mine = members(every, ours)
        whole = bool(mine.all())  # the world alone: every row is its own
        rows = changed if whole else changed.take(np.flatnonzero(mine))
        h = shard.history
        joins = gone.size > 0 or len(h) < 2 or h[-1][_LOCALIZED] != h[-2][_LOCALIZED] or bool(part.removing.size)
        if booked:  # robots removed, pending no longer: beside the tick before it is saved
            self.save_book()
        out, sent_applied, tally = self.outgoing(tick, rows, applied)
        # saved: what goes out first (the rows that changed, every robot in its strips, or none), then the rest of
        # what changed in its view
        if out is None or out is rows:
            rest = changed[:0] if whole else changed.take(np.flatnonzero(~mine))
            table, published = (joined(rows, rest) if rest.size else rows), 0 if out is None else rows.size
        else:
            table, published = joined(out, changed[~np.isin(changed["id"], out["id"])]), out.size
        self.port.save_tick(tick, table, published, sent_applied, h[-1], sent, tally)
        self.queued.append((tick, out, joins, sent_applied, regional, tally))
        for k, why in self.deferred:  # batches lost while the tick was with the peers: their robots as they are now
            self._remove_batch(k, why)
        self.deferred = []
        self._flush()  # and on to the next tick

    def _region_rows(self, ids: np.ndarray, received: Part | None) -> np.ndarray:
        """The rows of robots ``ids`` after the tick: from the replica, or, for a peer's robot that left this
        shard's area in the tick (forgotten by the replica), from the peer's part."""
        rows = state_rows(ids, self.sim.state)
        gone = np.flatnonzero(self.sim.state.state[ids] == UNKNOWN)
        if gone.size and received is not None:
            order = np.argsort(received.ids)
            at = order[np.searchsorted(received.ids, ids[gone], sorter=order)]
            solid = (received.z, received.pitch) if received.z.size else (None, None)
            rows[gone] = robot_rows(at, received.state, received.x, received.y, received.heading, *solid)
            rows["id"][gone] = ids[gone]
        return rows
