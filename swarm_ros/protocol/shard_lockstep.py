"""A world shard's coordination of the graph, as a plain class: the world's :class:`Lockstep` for the robot
batches in the shard's strips, each tick closed with the other shards through a :class:`ShardExchange`.

With ``--world-shards S`` the world's work is split by region (docs/protocol.md, "World shards"): shard i
owns the strips of consecutive robot batches (:func:`~swarm_ros.core.regions.shard_batches`). It admits those
batches, checks their decisions as the world does, and hands them to its exchange, which settles claims near
its borders with the neighbouring shards and closes the tick from every shard's counts. Once a tick is
closed it publishes what the world would have, for its part: its batches' region rows, its robots' rows and
applied decisions for the monitor, which joins the S parts of each tick. Everything else, admission, the
monitor window, lost batches and their removal, a restarted batch or monitor, is :class:`Lockstep`'s own
code, reading the shard's replica through :class:`ShardSim`.

A restarted shard goes on from its save (:class:`ShardSave`, written at every close before anything of the
next tick is sent): it sends its peers its kept messages again and asks for theirs, sends its batches a
snapshot, and publishes again the ticks the monitor has not confirmed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

import numpy as np

from swarm_ros.core.errors import ContractError, Rejected, RunFailed
from swarm_ros.core.metrics import METRIC_COLUMNS, TickMetrics
from swarm_ros.core.regions import columns
from swarm_ros.core.replica import UNKNOWN
from swarm_ros.core.rules import Decisions
from swarm_ros.core.shard_parts import Part
from swarm_ros.core.shards import WorldShard
from swarm_ros.core.state import IS_MOVING, STATE_COUNT
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.hosting import Hosting, route, snapshot
from swarm_ros.protocol.lockstep import Lockstep
from swarm_ros.protocol.rows import decision_rows, decisions_of, robot_rows, state_rows
from swarm_ros.protocol.shard_exchange import ShardExchange
from swarm_ros.protocol.shard_save import ShardSave
from swarm_ros.protocol.world_port import Logger, Policy, WorldPort

_LOCALIZED = METRIC_COLUMNS.index("localized")


def _joined(first: np.ndarray, then: np.ndarray) -> np.ndarray:
    """Rows of one layout one after the other, in that layout (``np.concatenate`` may repack records)."""
    out = np.empty(first.size + then.size, dtype=first.dtype)
    out[: first.size], out[first.size :] = first, then
    return out


def _first_of(n: int, ids: list[np.ndarray], values: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The robots of ``ids`` (arrays of distinct ids below ``n``) in ascending order, and the value each has in
    the first array that holds it (``np.unique(..., return_index=True)``'s answer, in time linear in ``n``: the
    sort took a shard over 1 ms a tick at 50,000 robots)."""
    held = np.zeros(n, dtype=bool)
    value = np.empty(n, dtype=np.result_type(*values))
    for these, their in zip(reversed(ids), reversed(values)):  # the first array's values written last
        held[these] = True
        value[these] = their
    every = np.flatnonzero(held)
    return every, value[every]


class ShardHosting(Hosting):
    """A shard's map of its strips to its batches: a batch wholly outside them is another shard's."""

    def __init__(self, radius: int, vision_radius: float, own: tuple[int, int]) -> None:
        super().__init__(radius, vision_radius)
        self.own = own

    def holds(self, strip: tuple[int, int]) -> bool:
        """Whether a batch hosting ``strip`` is this shard's (False: another shard's).

        Raises:
            Rejected: a strip across the shard's border: no shard can admit it.
        """
        first, last = self.own
        if strip[0] >= first and strip[1] <= last:
            return True
        if strip[1] < first or strip[0] > last:
            return False
        raise Rejected("columns of another shard", f"{self.text(strip)} crosses the border of {self.text(self.own)}")

    def covered(self) -> int:
        """Columns hosted: of the shard's strips, by its admitted batches; the others' columns count as covered
        (their shards admit their batches)."""
        return int((self.host >= 0).sum()) + self.width - (self.own[1] - self.own[0] + 1)


class ShardSim:
    """What :class:`Lockstep` reads of its ``Simulation``, from a shard: the last tick closed, the shard's replica
    (exact in its area), the metrics every shard holds, and its own moving robots."""

    def __init__(self, exchange: ShardExchange) -> None:
        self.exchange, self.shard = exchange, exchange.shard
        self.shape, self.params = self.shard.shape, self.shard.params

    @property
    def tick(self) -> int:
        return self.exchange.tick

    @property
    def done(self) -> bool:
        return self.shard.outcome is not None

    @property
    def outcome(self):
        return self.shard.outcome

    @property
    def state(self):
        return self.shard.state

    @property
    def history(self) -> list[tuple[int, ...]]:
        return self.shard.history

    @property
    def losses(self) -> list[tuple[int, int]]:
        return self.shard.losses

    @property
    def metrics(self) -> TickMetrics:
        return TickMetrics(*self.shard.history[-1])

    def moving_ids(self) -> np.ndarray:
        return self.shard.own_moving()


class ShardNodePort(WorldPort, Protocol):
    """What a :class:`ShardLockstep` asks of its node: the world's port, the exchange's sends, and the save."""

    def send_claims(self, peer: int, tick: int, claims: Decisions) -> None: ...
    def send_part(self, peer: int, tick: int, part: Part) -> None: ...
    def ask_again(self, peer: int) -> None: ...
    # the tick's rows in the shard's view (the first ``published`` its part), the kept messages and its tally (None:
    # record_every 1), durable before
    # anything of the next tick goes out (swarm_ros.protocol.shard_save)
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


class ShardLockstep(Lockstep):
    """Shard ``shard.index``'s lockstep (see the module's docstring); the port of its own exchange."""

    def __init__(
        self,
        shard: WorldShard,
        node_name: str,
        policy: Policy,
        port: ShardNodePort,
        logger: Logger,
        rejections: Rejections,
        clock: Callable[[], float] = time.monotonic,
        created: float | None = None,
    ) -> None:
        self.exchange = ShardExchange(shard, self, rejections)
        super().__init__(ShardSim(self.exchange), policy, port, logger, rejections, clock, created)  # type: ignore[arg-type]
        self.shard, self.node_name, self.shard_port = shard, node_name, port
        self.hosting = self.own_hosting = ShardHosting(shard.plan.radius, shard.params.vision_radius, shard.strip)
        self.inflight: tuple[int, np.ndarray] | None = None  # (tick, applied rows) handed to the exchange
        self.removing = np.empty(0, dtype=np.int64)  # the pending robots removed at the in-flight tick's end
        self.losses_booked = 0  # the shard's losses the bookkeeping saved holds
        self.removed_now = np.empty(0, dtype=np.int64)  # the pending robots removed at the last tick's end
        self.removals: list[tuple[int, np.ndarray]] = []  # (tick, robots removed at its end), every shard alike
        self.deferred: list[tuple[int, str]] = []  # batches to remove once the in-flight tick is closed

    # -- admission ------------------------------------------------------------------
    def announce(self, name: str, incarnation: int, strip: tuple[int, int]) -> None:
        """As :meth:`Lockstep.announce`, for a batch in this shard's strips; another shard's is not this one's."""
        if name in self.batch_names or self.own_hosting.holds(strip):
            super().announce(name, incarnation, strip)

    def maybe_start(self) -> None:
        """Tick 0 once this shard's batches host its strips and the monitor is there (as the world starts)."""
        if not self.starting():
            return
        self.log.info(f"{self.node_name}: its strips hosted by {len(self.batch_names)} batches: tick 0")
        own = self._own()
        rows = state_rows(own, self.sim.state)
        rest = np.setdiff1d(np.arange(self.shard.params.robots), own, assume_unique=True)  # unknown ones as unknown
        table = _joined(rows, state_rows(rest, self.sim.state))
        self.save_book()  # first: a save that holds a tick has the bookkeeping beside it
        tally = self._tally()
        self.shard_port.save_tick(0, table, rows.size, None, self.shard.history[0], {}, tally)
        for k in range(len(self.batch_names)):
            self._send_snapshot(k)
        self._emit(0, rows, False, None, None, save=False, tally=tally)

    def _tally(self) -> np.ndarray | None:
        """As :meth:`Lockstep._tally`: the robots in this shard's strips, by state."""
        if self.every == 1:
            return None
        return np.bincount(self.sim.state.state[self._own()], minlength=STATE_COUNT).astype(np.int64)

    def _recorded_rows(self) -> np.ndarray:
        """As :meth:`Lockstep._recorded_rows`: every robot standing in this shard's strips."""
        return state_rows(self._own(), self.sim.state)

    def _own(self) -> np.ndarray:
        """The robots this shard reports at tick 0 and at every tick it records: every one standing in its strips
        (moving robots: those it owns; stationary and removed ones: every shard knows them, this one has the
        strips they stand in)."""
        s = self.sim.state
        known = np.flatnonzero(s.state != UNKNOWN)
        return known[self._in_strips(s.x[known])]

    def _in_strips(self, x: np.ndarray) -> np.ndarray:
        cols = columns(x, self.shard.plan.radius)
        return (cols >= self.shard.strip[0]) & (cols <= self.shard.strip[1])

    def _send_snapshot(self, k: int, rows: np.ndarray | None = None) -> None:
        """Batch ``k``'s region at the last tick closed, from the shard's replica (which holds it)."""
        s = self.sim.state
        rows = state_rows(np.flatnonzero(s.state != UNKNOWN), s)
        self.port.send_snapshot(k, self.sim.tick, snapshot(rows, self.hosting.area(k), self.hosting.radius))

    # -- ticks ----------------------------------------------------------------------
    def decisions(self, k: int, tick: int, rows: np.ndarray) -> None:
        """As :meth:`Lockstep.decisions`; those of the tick being closed with the peers are repeats."""
        if self.inflight is not None and tick == self.inflight[0]:
            return
        super().decisions(k, tick, rows)

    def _maybe_advance(self, tick: int) -> None:
        """Hand the tick to the exchange once every own moving robot not being removed has decided (one at a
        time: the next once this one is closed)."""
        if self.inflight is not None or not self.started or self.sim.done or self.queued:
            return
        expected = self.shard.own_count - len(self._standing()) - len(self._orphans())
        if self.received > expected:
            raise RunFailed(f"tick {tick}: {self.received} decisions for {expected} moving robots")
        if self.received == expected:
            self._advance(self.sim.tick + 1)

    def _advance(self, tick: int) -> None:
        s = self.sim.state
        parts = [decisions_of(tick, r) for r in self.parts]
        standing = self._standing()
        if standing.size:
            parts.append(Decisions.standing(s, standing, tick))
        orphans = self._orphans()
        if orphans.size:
            parts.append(self.decider.decide(s, orphans, tick))
        decisions = Decisions.concatenate(parts) if parts else Decisions.standing(s, np.empty(0, np.int64), tick)
        self.parts, self.received = [], 0
        self.decided[decisions.ids] = False
        self.inflight = (tick, decision_rows(decisions))
        self.removing = self.pending
        try:
            self.exchange.own_decisions(decisions, self.pending if self.pending.size else None)
        except ContractError as exc:
            raise RunFailed(f"{self.node_name}, tick {tick}: {exc}") from None

    # -- the exchange's port --------------------------------------------------------
    def send_claims(self, peer: int, tick: int, claims: Decisions) -> None:
        self.shard_port.send_claims(peer, tick, claims)

    def send_part(self, peer: int, tick: int, part: Part) -> None:
        self.shard_port.send_part(peer, tick, part)

    def ask_again(self, peer: int) -> None:
        self.shard_port.ask_again(peer)

    def closed(self, tick: int, part: Part, sent: dict) -> None:
        """Tick ``tick`` is closed: save, then publish this shard's part of it (and go on to the next)."""
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
        every, cols = _first_of(self.sim.params.robots, ids, before)
        areas = [self.hosting.area(k) for k in range(len(self.batch_names))]
        changed = self._region_rows(every, received)
        regional = route(changed, cols, areas, self.hosting.radius)
        reported = np.zeros(self.sim.params.robots, dtype=bool)  # the monitor's part: no overlap
        reported[part.ids] = True
        reported[gone[self._in_strips(s.x[gone])]] = True
        mine = reported[every]
        rows = changed[mine]
        h = shard.history
        joined = gone.size > 0 or len(h) < 2 or h[-1][_LOCALIZED] != h[-2][_LOCALIZED] or bool(part.removing.size)
        if booked:  # robots removed, pending no longer: beside the tick before it is saved
            self.save_book()
        out, sent_applied, tally = self.outgoing(tick, rows, applied)
        # saved: what goes out first (the rows that changed, every robot in its strips, or none), then the rest of
        # what changed in its view
        if out is None or out is rows:
            table, published = _joined(rows, changed[~mine]), 0 if out is None else rows.size
        else:
            table, published = _joined(out, changed[~np.isin(changed["id"], out["id"])]), out.size
        self.shard_port.save_tick(tick, table, published, sent_applied, h[-1], sent, tally)
        self.queued.append((tick, out, joined, sent_applied, regional, tally))
        for k, why in self.deferred:  # batches lost while the tick was with the peers: their robots as they are now
            super()._remove_batch(k, why)
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

    def _remove_batch(self, k: int, why: str) -> None:
        """As :meth:`Lockstep._remove_batch`, between ticks: while a tick is with the peers, its robots may still
        cross into another shard's strips, so the removal waits for the tick's close."""
        if self.inflight is not None:
            self.down_since.pop(k, None)  # confirmed: no longer waited for, nor removed again at the next poll
            if all(k != d for d, _ in self.deferred):
                self.deferred.append((k, why))
        else:
            super()._remove_batch(k, why)

    def check_stalls(self, now: float) -> None:
        """As :meth:`Lockstep.check_stalls`; while the tick is with the peers, the batches are not waited for (a
        peer that never answers stops the run after ``STILL_S``; its process is restarted by the launcher)."""
        if self.inflight is not None:
            self.progress_at = now
        super().check_stalls(now)

    def poll(self) -> None:
        """As :meth:`Lockstep.poll`; and a shard whose own robots are none goes on by itself."""
        super().poll()
        self._maybe_advance(self.sim.tick + 1)

    def _flush(self) -> None:
        super()._flush()
        if not self.queued:
            self._maybe_advance(self.sim.tick + 1)

    # -- saves ----------------------------------------------------------------------
    def book(self) -> dict:
        """The lockstep's bookkeeping, with the robots pending removal and every robot removed so far."""
        return {
            **super().book(),
            # with the robots just removed: a save of the tick before (its next tick's write cut off) removes them
            # again; one of this tick knows they are removed (restore keeps only those still moving)
            "pending": np.union1d(self.pending, self.removed_now).tolist(),
            "removals": [[t, ids.tolist()] for t, ids in self.removals],
        }

    def restore(self, saved: ShardSave, incarnation: int) -> None:  # type: ignore[override]
        """Go on from ``saved`` (a process of this shard before this one wrote it): its exchange sends its peers
        the kept messages again and asks for theirs, its batches get a snapshot, the monitor the ticks it has
        not confirmed."""
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
            self.shard_port.ask_again(j)
        self.log.warn(f"{self.node_name} restarted: going on from tick {tick} of its save")
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
