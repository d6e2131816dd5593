"""The world's coordination of the graph, as a plain class: no rclpy, an injectable clock.

:class:`Lockstep` is one world process's: the world's, or world shard i's of S (``--world-shards``); the world
is the shard with no peers, and runs the same code. It holds its :class:`~swarm_ros.core.shards.WorldShard`
(the run's state in its area) inside a :class:`~swarm_ros.protocol.shard_exchange.ShardExchange` (its exchanges
with its peers: none for the world, which closes each tick at once), and decides everything its node does:
which robot batches it admits (those in its strips), when tick 0 starts, when a tick's decisions are all in
and the tick goes to the exchange, what it publishes once the tick is closed (:class:`WorldClose`), how far it
may run ahead of the monitor, and what happens when a batch or the monitor is lost. The node feeds it checked
messages and liveliness changes; it answers through a :class:`WorldPort`. Unit tests drive it with a fake port
and clock (test/test_lockstep.py for the world, test/test_shard_lockstep.py for S shards over fake channels);
docs/protocol.md and docs/faults.md describe the protocol and its fault policy.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable

import numpy as np

from swarm_ros.core.errors import ContractError, Rejected, RunFailed
from swarm_ros.core.params import auto_every
from swarm_ros.core.replica import UNKNOWN
from swarm_ros.core.rules import Decider, Decisions
from swarm_ros.core.shard_parts import Part
from swarm_ros.core.shards import WorldShard
from swarm_ros.core.state import IS_MOVING
from swarm_ros.protocol.checks import Rejections, decisions_allowed
from swarm_ros.protocol.hosting import Hosting, poses, snapshot
from swarm_ros.protocol.plan import BATCHES, MONITOR
from swarm_ros.protocol.rows import decision_rows, decisions_of, state_rows
from swarm_ros.protocol.shard_exchange import RunView, ShardExchange
from swarm_ros.protocol.world_close import WorldClose, joined
from swarm_ros.protocol.world_losses import Down, WorldLosses
from swarm_ros.protocol.world_port import (
    DECISIONS_LINGER,
    FINAL_WAIT,
    FIRST_STALL_S,
    LINGER,
    STATUS_PERIOD,
    Logger,
    Policy,
    WorldPort,
)
from swarm_ros.protocol.world_records import WorldRecords
from swarm_ros.protocol.world_restore import WorldRestore
from swarm_ros.protocol.world_status import WorldStatus


class Lockstep(WorldLosses, WorldRecords, WorldStatus, WorldRestore, WorldClose):  # a base's stand-ins after it
    """Admission, ticks and the monitor window of one world process (see the module's docstring); its close of a
    tick (:class:`WorldClose`), status and stall checks (:class:`WorldStatus`), bookkeeping and restore
    (:class:`WorldRestore`), loss policy (:class:`WorldLosses`) and records for the monitor (:class:`WorldRecords`);
    the port of its own exchange."""

    def __init__(
        self,
        shard: WorldShard,
        node_name: str,
        policy: Policy,
        port: WorldPort,
        logger: Logger,
        rejections: Rejections,
        clock: Callable[[], float] = time.monotonic,
        created: float | None = None,
    ) -> None:
        self.exchange = ShardExchange(shard, self, rejections)
        self.shard, self.node_name, self.sim = shard, node_name, RunView(self.exchange)
        self.policy, self.port, self.log, self.rejections, self.clock = policy, port, logger, rejections, clock
        n = shard.params.robots
        self.window = policy.monitor_window  # 0 while there is no monitor to wait for
        self.period = 1.0 / policy.tick_rate if policy.tick_rate else 0.0  # seconds between ticks published, at least
        self.every = policy.record_every or auto_every(shard.params)  # the robots' rows to the monitor (WorldRecords)
        self.paced_at = -math.inf  # clock() from which the next tick may be published (tick_rate)
        # which batch hosts which of this process's strips (another shard's batches are not this one's)
        self.hosting = Hosting(shard.plan.radius, shard.params.vision_radius, shard.strip)
        self.decider = Decider(shard.shape, shard.params)  # its own, for the strips of batches removed for good
        self.batch_names: list[str] = []
        self.restart_counts: list[int] = []  # per batch
        self.incarnations: list[int] = []  # per batch: the newest process's incarnation heard of
        self.down_since: dict[int, Down] = {}  # batches lost and waited for: since when, how long, why
        self.removed_batches: set[int] = set()
        self.respawned: dict[int, tuple[int, int]] = {}  # batch -> strip: re-announced with no higher incarnation
        self.lapsed: set[int] = set()  # batches whose liveliness lapsed since their last accepted announcement
        self.live: set[int] = set()  # batches whose liveliness holds (DDS reports a writer of theirs alive)
        self.resent_at: dict[int, float] = {}  # batch -> clock() its snapshot was last sent again (check_stalls)
        self.restarts: list[tuple[int, str]] = []  # (tick, node) of every restart: batches, world processes, monitor
        self.known: dict[int, int] = {}  # restored: batch -> incarnation of the process the one before knew
        self.restored = False  # this process went on from a save (a process before it was lost)
        self.monitor_nonce = ""  # the tag nonce of the monitor process whose metrics came last
        self.monitor_down_since: float | None = None  # the monitor lost and waited for: since when
        self.started_wall = 0.0  # time.time() at tick 0 (a restored process's wall_seconds count from it)
        self.lost: list[str] = []  # batches (and the monitor) lost for good
        self.started = False
        self.created = clock() if created is None else created  # start_timeout counts from here
        self.parts: list[np.ndarray] = []  # decision rows received for the coming tick
        self.received = 0
        self.decided = np.zeros(n, dtype=bool)  # robots whose decision for the coming tick is in
        self.pending = np.empty(0, dtype=np.int64)  # robots of lost batches, removed at the end of a coming tick
        self.queued: deque = deque()  # (tick, rows, joined, applied, regional, tally) held while the monitor is behind
        self.monitor_tick = -1
        self.monitor_alive = False
        self.published_tick = -1
        self.progress_at = clock()  # the last tick published or metrics received (or a stall dealt with)
        self.moved_at = self.progress_at  # the last tick published or metrics received
        self.status_at = -1.0
        self.start_time: float | None = None
        self.startup_seconds = float("nan")
        self.ended_at: float | None = None
        self.finished = False  # the end is out and delivered (or given up on): the node may exit
        self.inflight: tuple[int, np.ndarray] | None = None  # (tick, applied rows) handed to the exchange
        self.before: tuple[np.ndarray, ...] = (np.empty(0, dtype=np.int64),)  # the deciders' rows (hosting.poses)
        self.removing = np.empty(0, dtype=np.int64)  # the pending robots removed at the in-flight tick's end
        self.losses_booked = 0  # the losses the bookkeeping saved holds
        self.removed_now = np.empty(0, dtype=np.int64)  # the pending robots removed at the last tick's end
        self.removals: list[tuple[int, np.ndarray]] = []  # (tick, robots removed at its end), every shard alike
        self.deferred: list[tuple[int, str]] = []  # batches to remove once the in-flight tick is closed
        self.advancing = self.again = False  # inside _maybe_advance; asked again from inside it

    # -- admission ------------------------------------------------------------------
    def announce(self, name: str, incarnation: int, strip: tuple[int, int]) -> None:
        """A batch's announcement of its strip (checked as a message): admit it, or take it as a restarted process.
        A batch in another shard's strips is that shard's.

        Raises:
            Rejected: columns another batch hosts, a strip across this shard's border, another strip than before,
                or a new batch after tick 0.
        """
        if name in self.batch_names:
            self._reannounced(self.batch_names.index(name), strip, incarnation)
            return
        if not self.hosting.holds(strip):
            return
        if self.started:
            raise Rejected("new batch after tick 0", f"'{name}'")
        k = self.hosting.admit(name, strip, self.batch_names)
        self.batch_names.append(name)
        self.restart_counts.append(0)
        self.incarnations.append(0)
        self.port.watch_batch(k, name)
        covered = self.hosting.covered()
        self.log.info(f"{name} hosts {self.hosting.text(strip)}; {covered}/{self.hosting.width} columns covered")
        if incarnation:  # restarted before this process heard from the processes before it
            self._reannounced(k, strip, incarnation)
        if covered == self.hosting.width:
            self.maybe_start()

    def hosts(self, ids: np.ndarray) -> np.ndarray:
        return self.hosting.hosts(self.sim.state.x[ids])  # the batch hosting each robot now (its strip's)

    def _reannounced(self, k: int, strip: tuple[int, int], incarnation: int, respawn: bool = False) -> None:
        """A batch announced again: its process was restarted. Send it the current tick to start from."""
        name = self.batch_names[k]
        if self.known.get(k) == incarnation:  # the process the one before this one knew: nothing new
            del self.known[k]
            return
        if self.started and self.confirm_loss(k, "a new process of it announced itself"):
            return  # lost for good: its robots are removed, and the new process is not taken
        if incarnation <= self.incarnations[k]:
            # The same process again, an older one's announcement, or a new process that a launcher
            # without restart counting (ros2 launch's respawn) started: that one is taken once the
            # batch is known to be lost, now or when its liveliness lapses.
            if respawn or (self.started and (k in self.down_since or k in self.lapsed)):
                incarnation = self.incarnations[k] + 1
            else:
                self.respawned[k] = strip
                return
        if tuple(strip) != self.hosting.strips[k]:
            raise Rejected("columns of another batch", f"'{name}' announced another strip than before")
        if k in self.removed_batches or self.sim.done:
            self.log.warn(f"ignored a new announcement of {name}: its robots are removed or the run is over")
            return
        tick = self.sim.tick if self.started else 0
        self.respawned.pop(k, None)
        self.lapsed.discard(k)
        self.restart_counts[k] += incarnation - self.incarnations[k]
        self.restarts += [(tick, name)] * (incarnation - self.incarnations[k])
        self.incarnations[k] = incarnation
        self.down_since.pop(k, None)
        self.log.warn(
            f"{name} is back (restart {self.restart_counts[k]}) at tick {tick}"
            + ("; sending it a snapshot" if self.started else "")
        )
        if self.started:
            self._send_snapshot(k)
            self.save_book()
        self.publish_status()

    def _respawn(self, k: int) -> None:
        """Take batch ``k``'s process that announced itself without a higher incarnation as its restart."""
        try:
            self._reannounced(k, self.respawned[k], self.incarnations[k], respawn=True)
        except Rejected as fault:
            self.rejections.drop(BATCHES, fault)

    def _send_snapshot(self, k: int) -> None:
        """Batch ``k``'s region at the last tick closed, from the replica (which holds it)."""
        s = self.sim.state
        rows = state_rows(np.flatnonzero(s.state != UNKNOWN), s)
        self.port.send_snapshot(k, self.sim.tick, snapshot(rows, self.hosting.area(k), self.hosting.radius))

    def starting(self) -> bool:
        """Whether tick 0 goes out now (it is then marked started): once batches host every column of this
        process's strips and the monitor is there (so the run never stalls for it); without a monitor to wait
        for (``monitor_window: 0``), or one not seen within ``FIRST_STALL_S``, at once."""
        if self.started or self.hosting.covered() < self.hosting.width:
            return False
        if self.window and not (self.monitor_alive and self.port.monitor_reads_all()) and MONITOR not in self.lost:
            if self.clock() - self.created < FIRST_STALL_S:
                return False
            liveliness = "its liveliness seen" if self.monitor_alive else "no liveliness"
            readers = "its readers all found" if self.port.monitor_reads_all() else "not all its readers found"
            self._lose_monitor(f"not seen within {FIRST_STALL_S:g} s: {liveliness}, {readers}")
        self.started, self.start_time, self.started_wall = True, self.clock(), time.time()
        self.startup_seconds = self.port.startup_seconds()
        return True

    def maybe_start(self) -> None:
        """Tick 0 when :meth:`starting` says so: the save, snapshots to the batches, the tick to the monitor."""
        if not self.starting():
            return
        monitor = " and the monitor" * bool(self.window)
        self.log.info(
            f"{self.node_name}: its strips hosted by {len(self.batch_names)} batches{monitor}: tick 0 "
            f"({time.process_time():.2f} s of CPU)"
        )
        own = self._own()
        rows = state_rows(own, self.sim.state)
        rest = np.setdiff1d(np.arange(self.shard.params.robots), own, assume_unique=True)  # unknown ones as unknown
        self.save_book()  # first: a save that holds a tick has the bookkeeping beside it
        tally = self._tally()
        self.port.save_tick(
            0, joined(rows, state_rows(rest, self.sim.state)), rows.size, None, self.shard.history[0], {}, tally
        )
        for k in range(len(self.batch_names)):
            self._send_snapshot(k)
        self.queued.append((0, rows, False, None, None, tally))
        self._flush()

    # -- ticks ----------------------------------------------------------------------
    @property
    def over(self) -> bool:
        """Whether the run has ended (decisions still arriving answer the tick after the last)."""
        return self.started and self.sim.done

    def decisions(self, k: int, tick: int, rows: np.ndarray) -> None:
        """Batch ``k``'s decisions for ``tick``: taken whole once checked
        (:func:`swarm_ros.protocol.checks.decisions_allowed`); those of the tick being closed with the peers are
        repeats.

        Raises:
            Rejected: the check failed; nothing was taken.
            RunFailed: more decisions than moving robots (a gap in the checks).
        """
        if self.over or (self.inflight is not None and tick == self.inflight[0]):
            return  # answers to the tick after the last, or repeats
        if not self.started:
            raise Rejected("before tick 0")
        if self.restored and tick <= self.sim.tick:
            return  # sent to the process before this one: the batches' histories hand them over again
        if k in self.removed_batches:
            raise Rejected("removed batch", f"{self.batch_names[k]}'s robots were removed; the world decides its strip")
        decisions_allowed(rows, tick, self.sim, self.hosts, k, self.decided, self.batch_names[k])
        if self.pending.size:  # a lost batch's last words (or a stalled one's, resumed) do not count
            if not (rows := rows[~np.isin(rows["id"], self.pending)]).size:
                return
        self.decided[rows["id"]] = True
        self.down_since.pop(k, None)  # a batch deciding is not lost
        self.parts.append(rows)
        self.received += rows.size
        self._maybe_advance(tick)

    def _maybe_advance(self, tick: int) -> None:
        """Hand the tick to the exchange once every own moving robot that is not being removed or decided by this
        process has decided (one at a time: the next once this one is closed, and nothing is queued). A world
        alone closes it at once, and goes on while only its own robots move: in this loop, not deeper each tick
        (a close asks for the next tick from inside this call)."""
        if self.advancing:
            self.again = True
            return
        self.advancing = True
        try:
            self.again = True
            while self.again:
                self.again = False
                if self.inflight is not None or not self.started or self.sim.done or self.queued:
                    return
                expected = self.shard.own_count - len(self._standing()) - len(self._orphans())
                if self.received > expected:
                    raise RunFailed(f"tick {tick}: {self.received} decisions for {expected} moving robots")
                if self.received == expected:
                    tick = self.sim.tick + 1
                    self._advance(tick)
        finally:
            self.advancing = False

    def _standing(self) -> np.ndarray:  # moving robots of lost batches: they stand still one tick, then go
        return self.pending[IS_MOVING[self.sim.state.state[self.pending]]]

    def _orphans(self) -> np.ndarray:  # moving robots in the strips of batches removed for good: its own to decide
        return self.hosting.orphans(self.sim.state.x, self.sim.moving_ids, self.removed_batches, self.pending)

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
        # their rows before the tick (WorldClose: the region rows); the deciders are its own robots (the shard checks)
        self.before = poses(s, self.shard.own_moving())
        self.removing = self.pending
        try:
            self.exchange.own_decisions(decisions, self.pending if self.pending.size else None)
        except ContractError as exc:
            raise RunFailed(f"{self.node_name}, tick {tick}: {exc}") from None

    # -- the exchange's port: its sends go to the node; closed() is WorldClose's ----------------------
    def send_claims(self, peer: int, tick: int, claims: Decisions) -> None:
        self.port.send_claims(peer, tick, claims)

    def send_part(self, peer: int, tick: int, part: Part) -> None:
        self.port.send_part(peer, tick, part)

    def ask_again(self, peer: int) -> None:
        self.port.ask_again(peer)

    def _awaits_monitor(self) -> bool:
        """Whether the next tick queued waits for the monitor to catch up (it is more than ``window`` ahead)."""
        return bool(self.queued) and self.window > 0 and self.queued[0][0] - self.monitor_tick > self.window

    def wake_in(self) -> float | None:
        """Seconds until the next tick queued may be published under ``tick_rate`` (the node polls by then);
        None: nothing waits for the clock."""
        if not self.period or not self.queued or self._awaits_monitor():
            return None
        return max(0.0, self.paced_at - self.clock())

    def _flush(self) -> None:
        """Publish the ticks queued, as far as the monitor window and ``tick_rate`` allow; then on to the next."""
        while self.queued and not self._awaits_monitor():
            if self.period:  # tick_rate: each tick goes out at least a period after the one before
                now = self.clock()
                if now < self.paced_at:
                    return  # poll() goes on
                self.paced_at = now + self.period
            tick, rows, joined_, applied, regional, tally = self.queued.popleft()
            self.port.publish_tick(tick, rows, joined_, applied, regional, tally)
            self.progress_at = self.moved_at = self.clock()
            self.published_tick = tick
            if tick == self.sim.tick and self.sim.done:
                self._announce_end()
            elif tick == 0:
                self.publish_status()
        if not self.queued:
            self._maybe_advance(self.sim.tick + 1)

    def _announce_end(self) -> None:
        m = self.sim.metrics
        self.ended_at = self.clock()
        self.publish_status()
        assert self.sim.outcome is not None  # called once the run has ended
        self.log.info(
            f"run ended: {self.sim.outcome.value} at tick {m.tick}, {m.localized} localized "
            f"({time.process_time():.2f} s of CPU)"
        )

    def metrics(self, tick: int, nonce: str = "") -> None:
        """The monitor's report of ``tick`` (checked: a tick this process published), from the monitor process
        whose tags carry ``nonce``: a new one after another is a restarted monitor."""
        if nonce != self.monitor_nonce:
            if self.monitor_nonce and self.started:
                self.restarts.append((self.sim.tick, MONITOR))
                self.log.warn(f"the monitor is back (a new process) at tick {self.sim.tick}")
            self.monitor_nonce = nonce
            self.save_book()
            self.publish_status()
        if tick > self.monitor_tick:
            self.monitor_tick = tick
            self.progress_at = self.moved_at = self.clock()
            self._flush()

    def save_book(self) -> None:
        """The bookkeeping a restarted process needs besides the ticks (:mod:`swarm_ros.protocol.world_restore`)."""
        if self.started:
            self.port.save_book(self.book())

    # -- status -----------------------------------------------------------------------
    def publish_status(self, note: str = "") -> None:
        self.status_at = self.clock()
        self.port.publish_status(self.status(note))

    # -- the clock --------------------------------------------------------------------
    def poll(self) -> None:
        """Between messages: timeouts, stalls, the periodic status, and whether the node may exit.

        Raises:
            RunFailed: batches did not cover the robots within ``start_timeout``, or a batch lost
                before tick 0 did not come back within ``restart_timeout``.
        """
        now, p = self.clock(), self.policy
        self.check_stalls(now)
        if self.monitor_down_since is not None and now - self.monitor_down_since > p.restart_timeout:
            self.monitor_down_since = None
            self._lose_monitor(f"not back within {p.restart_timeout:g} s")
        self.expire_losses(now)
        if not self.sim.done and now - self.status_at >= STATUS_PERIOD:
            self.publish_status()
        if not self.started and now - self.created > p.start_timeout:
            dropped = f"; dropped: {self.rejections.text()}" if self.rejections.total else ""
            raise RunFailed(
                f"robot batches cover {self.hosting.covered()} of {self.hosting.width} columns after "
                f"{p.start_timeout:g} s (start_timeout){dropped}"
            )
        if self.period and self.queued:
            self._flush()  # a tick held for tick_rate, due now
        if not self.started:
            self.maybe_start()
        else:
            self._maybe_advance(self.sim.tick + 1)  # a tick only its own robots decide in, or none of its own
        if self.ended_at is not None:
            caught_up = self.window == 0 or self.monitor_tick >= self.sim.tick
            # the end is out once every reader acknowledged the last status and rows, and the applied decisions (a
            # run's bag is whole only with them, and over a slow link they can still be on their way when the
            # monitor has counted the last tick); a reader that died never does, so wait at most LINGER for the
            # first, DECISIONS_LINGER for the second
            waited = now - self.ended_at
            out = (self.port.delivered() or waited > LINGER) and (
                self.port.decisions_delivered() or waited > DECISIONS_LINGER
            )
            if (caught_up and out) or waited > FINAL_WAIT:
                self.finished = True
