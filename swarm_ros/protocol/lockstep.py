"""The world's coordination of the graph, as a plain class: no rclpy, an injectable clock.

:class:`Lockstep` is one world process's: the world's, or world shard i's of S (``--world-shards``); the world
is the shard with no peers, and runs the same code. It holds its :class:`~swarm_ros.core.shards.WorldShard`
(the run's state in its area) inside a :class:`~swarm_ros.protocol.shard_exchange.ShardExchange` (its exchanges
with its peers: none for the world, which closes each tick at once), and decides everything its node does:
which robot batches it admits (those in its strips), when tick 0 starts, when a tick's decisions are all in
and the tick goes to the exchange, what it publishes once the tick is closed, how far it
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
from typing import NamedTuple

import numpy as np

from swarm_ros.core.errors import ContractError, Rejected, RunFailed
from swarm_ros.core.metrics import METRIC_COLUMNS, Outcome, TickMetrics, progress_of
from swarm_ros.core.params import auto_every
from swarm_ros.core.regions import columns
from swarm_ros.core.rules import Decider, Decisions
from swarm_ros.core.shard_parts import Part
from swarm_ros.core.shards import WorldShard
from swarm_ros.core.state import IS_MOVING, RobotState
from swarm_ros.core.swarm_view import UNKNOWN
from swarm_ros.protocol.checks import Rejections, decisions_allowed
from swarm_ros.protocol.hosting import Hosting, poses, route, snapshot, stood
from swarm_ros.protocol.plan import BATCHES, MONITOR
from swarm_ros.protocol.rows import decision_rows, decisions_of, robot_rows, state_rows
from swarm_ros.protocol.shard_exchange import RunView, ShardExchange
from swarm_ros.protocol.shard_save import ShardSave
from swarm_ros.protocol.status import RUNNING, STARTING, Status, progress_values, restarts_text
from swarm_ros.protocol.world_port import (
    DECISIONS_LINGER,
    DROWNED_S,
    FINAL_WAIT,
    FIRST_STALL_S,
    LINGER,
    LOSS_CONFIRM_S,
    STALL_S,
    STATUS_PERIOD,
    STILL_S,
    Logger,
    Policy,
    WorldPort,
)
from swarm_ros.protocol.world_records import WorldRecords


class Down(NamedTuple):
    """A lost batch the world waits for: since when (its clock), for how long, and what to say if it is not back."""

    since: float
    limit: float
    why: str  # why it was lost
    confirming: bool  # lost for good once the wait is over (no restart is awaited)

    def expired(self) -> str:
        """What to say when its robots are removed for being away too long."""
        waited = f"not back within {self.limit:g} s"
        return f"{self.why}; {waited}" if self.confirming else waited


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


class Lockstep(WorldRecords):
    """One world process's coordination (see the module's docstring): admission, ticks, the monitor window, the close
    of a tick, status and stall checks, bookkeeping and restore, and the loss policy; what of each tick goes to the
    monitor is :class:`WorldRecords`'. The port of its own exchange."""

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
        self.monitor_nonce = ""  # the tag nonce of the monitor process whose held report came last
        self.monitor_down_since: float | None = None  # the monitor lost and waited for: since when
        self.started_wall = 0.0  # time.time() at tick 0 (a restored process's wall_seconds count from it)
        self.lost: list[str] = []  # batches (and the monitor) lost for good
        self.started = False
        self.created = clock() if created is None else created  # start_timeout counts from here
        self.decision_rows: list[np.ndarray] = []  # decision rows received for the coming tick
        self.received = 0
        self.decided = np.zeros(n, dtype=bool)  # robots whose decision for the coming tick is in
        self.pending = np.empty(0, dtype=np.int64)  # robots of lost batches, removed at the end of a coming tick
        self.queued: deque = deque()  # (tick, rows, joined, applied, regional, tally) held while the monitor is behind
        self.monitor_tick = -1
        self.monitor_alive = False
        self.published_tick = -1
        self.progress_at = clock()  # the last tick published or more reported held (or a stall dealt with)
        self.moved_at = self.progress_at  # the last tick published or more reported held
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
        """Batch ``k``'s region at the last tick closed, from the view (which holds it)."""
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
        self.decision_rows.append(rows)
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
        each = [decisions_of(tick, r) for r in self.decision_rows]
        standing = self._standing()
        if standing.size:
            each.append(Decisions.standing(s, standing, tick))
        orphans = self._orphans()
        if orphans.size:
            each.append(self.decider.decide(s, orphans, tick))
        decisions = Decisions.concatenate(each) if each else Decisions.standing(s, np.empty(0, np.int64), tick)
        self.decision_rows, self.received = [], 0
        self.decided[decisions.ids] = False
        self.inflight = (tick, decision_rows(decisions))
        # their rows before the tick (closed(): the region rows); the deciders are its own robots (the shard checks)
        self.before = poses(s, self.shard.own_moving())
        self.removing = self.pending
        try:
            self.exchange.own_decisions(decisions, self.pending if self.pending.size else None)
        except ContractError as exc:
            raise RunFailed(f"{self.node_name}, tick {tick}: {exc}") from None

    # -- the exchange's port: its sends go to the node; closed() is below, with the close of a tick ---------
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

    def held(self, tick: int, nonce: str = "") -> None:
        """The monitor's report that its bag holds ``tick`` (checked: a tick this process published, or -1), from
        the monitor process whose tags carry ``nonce``: a new one after another is a restarted monitor."""
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
        """The bookkeeping a restarted process needs besides the ticks (``restore``, below)."""
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

    # -- a closed tick: saved, then what goes out of it queued (each batch's region rows, this process's part of the
    # robots' rows and applied decisions for the monitor, whether the occupancy changed); the world alone has no
    # peers, and its view is the whole swarm
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
        """The rows of robots ``ids`` after the tick: from the view, or, for a peer's robot that left this
        shard's area in the tick (forgotten by the view), from the peer's part."""
        rows = state_rows(ids, self.sim.state)
        gone = np.flatnonzero(self.sim.state.state[ids] == UNKNOWN)
        if gone.size and received is not None:
            order = np.argsort(received.ids)
            at = order[np.searchsorted(received.ids, ids[gone], sorter=order)]
            solid = (received.z, received.pitch) if received.z.size else (None, None)
            rows[gone] = robot_rows(at, received.state, received.x, received.y, received.heading, *solid)
            rows["id"][gone] = ids[gone]
        return rows

    # -- what it says about the run (/swarm/status), and how it notices a silent process (the fallback to liveliness)
    def status(self, note: str = "") -> Status:
        """The run's state now: outcome, the last published tick and its counts, restarts and lost processes."""
        tick = max(self.published_tick, 0)
        sim, warn = self.sim, bool(note or self.lost or self.down_since or self.monitor_down_since is not None)
        if not self.started:
            outcome, message = STARTING, "waiting for robot batches"
        elif self.ended_at is not None:
            assert sim.outcome is not None  # the run has ended
            outcome = sim.outcome.value
            message = f"{outcome} at tick {tick}"
            warn = warn or sim.outcome not in (Outcome.COMPLETE, Outcome.COMPLETE_WITH_EXTRAS)
        else:
            outcome, message = RUNNING, note or RUNNING
        values: dict[str, object] = {
            "rules": sim.params.ruleset.label,
            "robots": sim.params.robots,
            "record_every": self.every,  # the monitor checks it is told the same
        }
        if self.started:
            m = sim.history[min(tick, sim.tick)]
            values.update({key: int(m[METRIC_COLUMNS.index(key)]) for key in ("localized", "moving", "walking")})
            values.update(progress_values(progress_of(TickMetrics(*m), sim.shape.patches)))  # at the tick published
            values["startup_seconds"] = f"{self.startup_seconds:.3f}"
        if self.ended_at is not None:
            values["separated"] = int((sim.state.state == RobotState.SEPARATED).sum())
            assert self.start_time is not None  # set at tick 0, before any end
            values["wall_seconds"] = f"{self.ended_at - self.start_time:.3f}"
        values["restarts"] = restarts_text(self.restarts)
        values["rejected_messages"] = self.rejections.total
        values["rejected"] = self.rejections.text()
        values["lost"] = ",".join(self.lost)
        values["waiting_for"] = ",".join(
            [self.batch_names[k] for k in sorted(self.down_since)] + [MONITOR] * (self.monitor_down_since is not None)
        )
        return Status(tick=tick, outcome=outcome, message=message, warn=warn, values=values)

    def check_stalls(self, now: float) -> None:
        """The fallback to liveliness (a process lost before DDS matched its liveliness topic): a batch
        whose robots have not decided, or a monitor that has not reported, for ``STALL_S`` is lost.
        Before the first decisions or report, while discovery may still be going on, the limit is
        ``FIRST_STALL_S``. One whose liveliness holds is not lost for its silence (its messages may be
        drowned by a flood): it is waited for, and after ``DROWNED_S`` the run fails.

        Whatever the liveliness says, a run that has not moved (no tick published, no report) for
        ``STILL_S`` fails: liveliness that comes and goes (a transport that has stopped delivering)
        would otherwise keep the rules above from ever firing.

        While a tick is with the peers (world shards), the batches are not waited for (a peer that never answers
        stops the run after ``STILL_S``; its process is restarted by the launcher).

        Raises:
            RunFailed: a batch or the monitor alive but silent for ``DROWNED_S``; the run still for ``STILL_S``.
        """
        if self.inflight is not None:
            self.progress_at = now
        if not self.started or self.sim.done:
            return
        if now - self.moved_at >= STILL_S:
            waiting = ", ".join(self.batch_names[k] for k in sorted(self.down_since)) or "no lost process"
            dropped = self.rejections.text() or "nothing"
            raise RunFailed(
                f"the run has not moved for {STILL_S:g} s at tick {self.sim.tick} (waiting for: {waiting}; "
                f"messages dropped: {dropped}): its messages do not get through"
            )
        if self.queued:  # held for the monitor, or for tick_rate (nothing is awaited then: at most 1 s)
            if not self._awaits_monitor():
                return
            limit = STALL_S if self.monitor_tick >= 0 else FIRST_STALL_S
            if self.window and now - self.progress_at >= limit:
                if not self.monitor_alive:
                    self.monitor_down(f"nothing more held for {limit:g} s")
                elif now - self.progress_at >= DROWNED_S:
                    self._drowned("the monitor's held reports")
            return
        limit = STALL_S if self.sim.tick > 0 else FIRST_STALL_S
        if now - self.progress_at < limit:
            return
        moving = self.sim.moving_ids()
        # not awaited from any batch: the robots being removed, and those in removed batches' strips (the world
        # decides them as it applies the tick): counted, they made a removed batch (alive again after a stall)
        # the silent one, and the silent batch's snapshot went to it instead
        missing = np.setdiff1d(moving[~self.decided[moving]], np.union1d(self.pending, self._orphans()))
        silent = np.unique(self.hosts(missing)).tolist()
        for k in silent:
            if k not in self.live:
                self.lose_batch(k, f"no decisions for {limit:g} s")
        alive = [k for k in silent if k in self.live]
        if not alive:
            self.progress_at = now
            return
        if now - self.progress_at >= DROWNED_S:
            self._drowned(f"the decisions of {', '.join(self.batch_names[k] for k in alive)}")
        # Alive but silent: the rows it decides from may never have reached it (CI once saw a restarted world's
        # snapshot to a batch that had missed the last rows not arrive, and the run waited 60 s for nothing). The
        # current tick's snapshot again, once a STALL_S: a batch that has the tick ignores it.
        for k in alive:
            if now - self.resent_at.get(k, -math.inf) >= STALL_S:
                self.resent_at[k] = now
                self._send_snapshot(k)

    def _drowned(self, what: str) -> None:
        dropped = self.rejections.text() or "nothing"
        raise RunFailed(
            f"{what} did not arrive for {DROWNED_S:g} s at tick {self.sim.tick}, though the process is "
            f"alive: its messages do not get through, or it hangs (messages dropped: {dropped})"
        )

    # -- its bookkeeping beside the ticks, and a restarted process's restore from its save
    # (swarm_ros.protocol.shard_save): it sends again what a reader may have lost with the process before; a tick's
    # decisions are a pure function of the state, so the run goes on as if nothing had happened
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

    # -- the loss policy: a lost batch is waited for (restart_timeout) while it has restarts left under on_batch_loss:
    # restart, and its robots removed otherwise once the loss is confirmed (LOSS_CONFIRM_S); a lost monitor is waited
    # for as long, the ticks held back meanwhile, then the swarm goes on without it (docs/faults.md)
    def batch_liveliness(self, k: int, alive: int, not_alive: int) -> None:
        """Batch ``k``'s liveliness changed: ``alive`` writers alive, ``not_alive`` lapsed."""
        if alive > 0 and k not in self.live:  # from now on a loss is noticed by liveliness, not the fallback
            self.log.info(f"{self.batch_names[k]} is alive (liveliness)")
        if alive > 0:
            self.live.add(k)
        else:
            self.live.discard(k)
        if alive == 0 and not_alive > 0:
            self.lapsed.add(k)
            self.lose_batch(k, "liveliness lapsed")
        elif alive > 0 and k in self.respawned and self.started:  # a respawned process is up
            self._respawn(k)
        elif alive > 0 and k in self.down_since:  # a process of this batch is alive (again)
            self.down_since.pop(k)

    def lose_batch(self, k: int, why: str) -> None:
        """Batch ``k``'s process is gone (or stalled). Wait for it to come back, or remove its robots once the loss
        is confirmed (:data:`LOSS_CONFIRM_S`)."""
        name = self.batch_names[k]
        if k in self.removed_batches or k in self.down_since or self.sim.done:
            return
        p, tick = self.policy, self.sim.tick
        if not self.started or (p.on_batch_loss == "restart" and self.restart_counts[k] < p.max_restarts):
            self.down_since[k] = Down(self.clock(), p.restart_timeout, why, False)
            self.log.warn(
                f"{name} lost ({why}) at tick {tick}: waiting up to {p.restart_timeout:g} s for "
                f"it to restart (restarts so far: {self.restart_counts[k]} of {p.max_restarts})"
            )
            self.publish_status(f"waiting for {name}")
            if k in self.respawned and self.started:  # its new process announced itself already
                self._respawn(k)
            return
        self.down_since[k] = Down(self.clock(), LOSS_CONFIRM_S, why, True)
        self.log.warn(
            f"{name} lost ({why}) at tick {tick}: its robots are removed unless it is back within {LOSS_CONFIRM_S:g} s"
        )
        self.publish_status(f"waiting for {name}")

    def confirm_loss(self, k: int, why: str) -> bool:
        """Remove batch ``k``'s robots now if it is lost for good and only waited for to confirm it (a new process
        of it announced itself: the one before is gone). Whether it was."""
        down = self.down_since.get(k)
        if down is None or not down.confirming:
            return False
        self._remove_batch(k, f"{down.why}; {why}")
        return True

    def expire_losses(self, now: float) -> None:
        """Remove the robots of the batches not back within their wait.

        Raises:
            RunFailed: a batch lost before tick 0 did not come back within ``restart_timeout``.
        """
        for k, down in list(self.down_since.items()):
            if now - down.since <= down.limit:
                continue
            if not self.started:
                raise RunFailed(
                    f"{self.batch_names[k]} was lost before the run started and did not come back "
                    f"within {down.limit:g} s (restart_timeout)"
                )
            self._remove_batch(k, down.expired())

    def _remove_batch(self, k: int, why: str) -> None:
        """Remove batch ``k``'s robots, the moving robots in its strip, at the end of the next tick (robots lost
        for good); from then on the world decides for the robots that move into the strip. Between ticks: while a
        tick is with the peers (world shards), its robots may still cross into another shard's strips, so the
        removal waits for the tick's close."""
        self.down_since.pop(k, None)  # confirmed: no longer waited for, nor removed again at the next poll
        if self.inflight is not None:
            if all(k != d for d, _ in self.deferred):
                self.deferred.append((k, why))
            return
        name = self.batch_names[k]
        ids = self.hosting.orphans(self.sim.state.x, self.sim.moving_ids, {k}, self.pending)
        self.removed_batches.add(k)
        self.lost.append(name)
        self.save_book()
        self.pending = np.union1d(self.pending, ids)
        # decisions it sent for this tick before it was lost no longer count either
        self.decision_rows = [r[~np.isin(r["id"], self.pending)] for r in self.decision_rows]
        self.received = sum(r.size for r in self.decision_rows)
        tick = self.sim.tick
        self.log.warn(
            f"{name} lost ({why}) at tick {tick}: its {ids.size} robots are removed at the end of tick {tick + 1}"
        )
        self.publish_status(f"lost {name}")
        self._maybe_advance(tick + 1)  # the lost robots' decisions are no longer awaited

    def monitor_liveliness(self, alive: int, not_alive: int) -> None:
        self.monitor_alive = alive > 0
        if self.monitor_alive:
            self.monitor_down_since = None
            self.maybe_start()
        if alive == 0 and not_alive > 0:
            self.monitor_down("liveliness lapsed")
        elif alive > 0 and MONITOR in self.lost:  # it was only starved of CPU for a moment
            self.lost.remove(MONITOR)
            self.window = self.policy.monitor_window
            self.log.warn(f"the monitor is back at tick {self.sim.tick}")
            self.publish_status()

    def monitor_down(self, why: str) -> None:
        """The monitor's process is gone: wait up to ``restart_timeout`` for a new one, holding the ticks
        back as while it is behind (they stay in the topics' histories for it), then go on without it."""
        if MONITOR in self.lost or self.monitor_down_since is not None:
            return
        self.monitor_down_since = self.clock()
        self.log.warn(
            f"the monitor was lost ({why}) at tick {self.sim.tick}: waiting up to "
            f"{self.policy.restart_timeout:g} s for it to restart"
        )
        self.publish_status("waiting for the monitor")

    def _lose_monitor(self, why: str) -> None:
        if MONITOR in self.lost:
            return
        self.lost.append(MONITOR)
        self.save_book()
        self.window = 0  # nobody to wait for: run on
        self.log.warn(f"the monitor was lost ({why}) at tick {self.sim.tick}; the swarm goes on without it")
        self.publish_status("lost the monitor")
        self._flush()
