"""The world's coordination of the graph, as a plain class: no rclpy, an injectable clock.

:class:`Lockstep` owns the run's state (a ``Simulation``) and decides everything the world node
does: which robot batches are admitted, when tick 0 starts, when a tick's decisions are all in
and the tick is applied (with the in-process engine's own ``Simulation.apply``), how far it may
run ahead of the monitor, and what happens when a batch or the monitor is lost. The node feeds
it checked messages and liveliness changes; it answers through a :class:`WorldPort`. Unit tests
drive it with a fake port and clock (test/test_lockstep.py); docs/protocol.md and docs/faults.md describe the
protocol and its fault policy.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable

import numpy as np

from swarm_ros.core.engine import Simulation
from swarm_ros.core.errors import ContractError, Rejected, RunFailed
from swarm_ros.core.params import auto_every
from swarm_ros.core.rules import Decider, Decisions
from swarm_ros.core.state import IS_MOVING
from swarm_ros.protocol.checks import Rejections, decisions_allowed
from swarm_ros.protocol.hosting import Hosting, snapshot
from swarm_ros.protocol.plan import BATCHES, MONITOR
from swarm_ros.protocol.rows import decision_rows, decisions_of, state_rows
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
from swarm_ros.protocol.world_restore import Saved, WorldRestore
from swarm_ros.protocol.world_status import WorldStatus


class Lockstep(WorldLosses, WorldStatus, WorldRestore, WorldRecords):  # a base's stand-ins come after it
    """Admission, ticks and the monitor window of one run (see the module's docstring); its status and stall
    checks (:class:`WorldStatus`), its bookkeeping and restore (:class:`WorldRestore`), its loss policy
    (:class:`WorldLosses`)."""

    def __init__(
        self,
        sim: Simulation,
        policy: Policy,
        port: WorldPort,
        logger: Logger,
        rejections: Rejections,
        clock: Callable[[], float] = time.monotonic,
        created: float | None = None,
    ) -> None:
        self.sim, self.policy, self.port, self.log, self.rejections, self.clock = (
            sim,
            policy,
            port,
            logger,
            rejections,
            clock,
        )
        n = sim.params.robots
        self.window = policy.monitor_window  # 0 while there is no monitor to wait for
        self.period = 1.0 / policy.tick_rate if policy.tick_rate else 0.0  # seconds between ticks published, at least
        self.every = policy.record_every or auto_every(n)  # the robots' rows to the monitor (WorldRecords)
        self.paced_at = -math.inf  # clock() from which the next tick may be published (tick_rate)
        self.hosting = Hosting(sim.shape.world.radius, sim.params.vision_radius)  # which batch hosts which strip
        self.decider = Decider(sim.shape, sim.params)  # the world's own, for the strips of batches removed for good
        self.batch_names: list[str] = []
        self.restart_counts: list[int] = []  # per batch
        self.incarnations: list[int] = []  # per batch: the newest process's incarnation heard of
        self.down_since: dict[int, Down] = {}  # batches lost and waited for: since when, how long, why
        self.removed_batches: set[int] = set()
        self.respawned: dict[int, tuple[int, int]] = {}  # batch -> strip: re-announced with no higher incarnation
        self.lapsed: set[int] = set()  # batches whose liveliness lapsed since their last accepted announcement
        self.live: set[int] = set()  # batches whose liveliness holds (DDS reports a writer of theirs alive)
        self.resent_at: dict[int, float] = {}  # batch -> clock() its snapshot was last sent again (check_stalls)
        self.restarts: list[tuple[int, str]] = []  # (tick, node) of every restart: batches, the world, the monitor
        self.known: dict[int, int] = {}  # restored: batch -> incarnation of the process the world before knew
        self.restored = False  # this world went on from a checkpoint (a process before it was lost)
        self.monitor_nonce = ""  # the tag nonce of the monitor process whose metrics came last
        self.monitor_down_since: float | None = None  # the monitor lost and waited for: since when
        self.started_wall = 0.0  # time.time() at tick 0 (a restored world's wall_seconds count from it)
        self.lost: list[str] = []  # batches (and the monitor) lost for good
        self.started = False
        self.created = clock() if created is None else created  # start_timeout counts from here
        self.parts: list[np.ndarray] = []  # decision rows received for the coming tick
        self.received = 0
        self.decided = np.zeros(n, dtype=bool)  # robots whose decision for the coming tick is in
        self.pending = np.empty(0, dtype=np.int64)  # robots of lost batches, removed at the end of the next tick
        self.queued: deque = deque()  # (tick, rows, joined, applied, parts, tally) held while the monitor is behind
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

    # -- admission ------------------------------------------------------------------
    def announce(self, name: str, incarnation: int, strip: tuple[int, int]) -> None:
        """A batch's announcement of its strip (checked as a message): admit it, or take it as a restarted process.

        Raises:
            Rejected: columns another batch hosts, another strip than before, or a new batch after tick 0.
        """
        if name in self.batch_names:
            self._reannounced(self.batch_names.index(name), strip, incarnation)
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
        if incarnation:  # restarted before the world heard from the processes before it
            self._reannounced(k, strip, incarnation)
        if covered == self.hosting.width:
            self.maybe_start()

    def hosts(self, ids: np.ndarray) -> np.ndarray:
        return self.hosting.hosts(self.sim.state.x[ids])  # the batch hosting each robot now (its strip's)

    def _reannounced(self, k: int, strip: tuple[int, int], incarnation: int, respawn: bool = False) -> None:
        """A batch announced again: its process was restarted. Send it the current tick to start from."""
        name = self.batch_names[k]
        if self.known.get(k) == incarnation:  # the process the world before this one knew: nothing new
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

    def _send_snapshot(self, k: int, rows: np.ndarray | None = None) -> None:
        """Batch ``k``'s region at the current tick (``rows``: every robot's, if at hand)."""
        rows = state_rows(np.arange(self.sim.state.robots), self.sim.state) if rows is None else rows
        self.port.send_snapshot(k, self.sim.tick, snapshot(rows, self.hosting.area(k), self.hosting.radius))

    def starting(self) -> bool:
        """Whether tick 0 goes out now (it is then marked started): once batches host every column and the
        monitor is there (so the run never stalls for it); without a monitor to wait for (``monitor_window: 0``),
        or one not seen within ``FIRST_STALL_S``, at once."""
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
        """Tick 0 when :meth:`starting` says so: snapshots to the batches, the tick to the monitor."""
        if not self.starting():
            return
        self.log.info(
            f"all robots hosted by {len(self.batch_names)} batches{' and the monitor' * bool(self.window)}: tick 0"
        )
        rows = state_rows(np.arange(self.sim.state.robots), self.sim.state)
        self.save_book()  # first: a checkpoint that holds a tick has the bookkeeping beside it
        tally = self._tally()
        self.port.checkpoint(0, rows, None, self.sim.history[0], -1, tally)  # before the snapshots: they tell of tick 0
        for k in range(len(self.batch_names)):
            self._send_snapshot(k, rows)
        self._emit(0, rows, False, None, save=False, tally=tally)

    # -- ticks ----------------------------------------------------------------------
    @property
    def over(self) -> bool:
        """Whether the run has ended (decisions still arriving answer the tick after the last)."""
        return self.started and self.sim.done

    def decisions(self, k: int, tick: int, rows: np.ndarray) -> None:
        """Batch ``k``'s decisions for ``tick``: taken whole once checked
        (:func:`swarm_ros.protocol.checks.decisions_allowed`).

        Raises:
            Rejected: the check failed; nothing was taken.
            RunFailed: more decisions than moving robots (a gap in the checks).
        """
        if self.over:
            return  # answers to the tick after the last: the run is over
        if not self.started:
            raise Rejected("before tick 0")
        if self.restored and tick <= self.sim.tick:
            return  # sent to the world before this one: the batches' histories hand them over again
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
        """Apply the tick once every moving robot that is not being removed or decided by the world has decided;
        then the ticks that await no batch (only the world's own robots move), while nothing is queued."""
        while not self.sim.done:
            expected = self.sim.metrics.moving - len(self._standing()) - len(self._orphans())
            if self.received > expected:
                raise RunFailed(f"tick {tick}: {self.received} decisions for {expected} moving robots")
            if self.received < expected:
                return
            self._advance(tick)
            if self.queued:
                return  # the monitor is behind: poll() goes on once it has caught up
            tick += 1

    def _standing(self) -> np.ndarray:  # moving robots of lost batches: they stand still one tick, then go
        return self.pending[IS_MOVING[self.sim.state.state[self.pending]]]

    def _orphans(self) -> np.ndarray:  # moving robots in the strips of batches removed for good: the world's
        return self.hosting.orphans(self.sim.state.x, self.sim.moving_ids, self.removed_batches, self.pending)

    def _advance(self, tick: int) -> None:
        parts = [decisions_of(tick, r) for r in self.parts]
        standing = self._standing()
        s = self.sim.state
        if standing.size:
            parts.append(Decisions.standing(s, standing, tick))
        orphans = self._orphans()
        if orphans.size:
            parts.append(self.decider.decide(s, orphans, tick))
        decisions = Decisions.concatenate(parts)
        applied = decision_rows(decisions)
        deciders = np.sort(decisions.ids)
        before = self.hosting.before(s, deciders)  # their rows before the tick: for the region rows
        self.parts, self.received = [], 0
        self.decided[deciders] = False
        localized_before, losses_before = self.sim.metrics.localized, len(self.sim.losses)
        try:
            self.sim.apply(decisions)
        except ContractError as exc:
            raise RunFailed(f"tick {tick}: {exc}") from None
        if self.pending.size:
            count = self.sim.remove(self.pending)
            self.log.warn(f"tick {tick}: removed the {count} robots of lost batches")
            self.pending = np.empty(0, dtype=np.int64)
        if len(self.sim.losses) != losses_before:  # scheduled failures, or a lost batch's robots
            self.save_book()
        s = self.sim.state
        removed = self.sim.last_removed  # the deciders changed, and failed robots
        ids = np.union1d(deciders, removed) if removed.size else deciders
        joined = self.sim.metrics.localized != localized_before or removed.size > 0
        self._emit(tick, state_rows(ids, s), joined, applied, (deciders, before))

    def _emit(
        self,
        tick: int,
        rows: np.ndarray | None,
        joined: bool,
        applied: np.ndarray | None,
        moved: tuple[np.ndarray | None, tuple | None] | None = (None, None),
        save: bool = True,
        tally: np.ndarray | None = None,
    ) -> None:
        """Checkpoint a tick (``save``: ``rows``, those that changed, become what goes to the monitor,
        :meth:`outgoing`), then publish it now, or queue it while the monitor is more than ``window`` ticks
        behind; ``moved``: (ids, their rows before) for the region rows, None: none (a restored world's, which
        passes what it published: ``rows`` None at a tick whose rows were not, and its ``tally``)."""
        parts = None
        if moved is not None:
            assert rows is not None  # a new tick's changed rows
            parts = self.hosting.route(rows, moved[0], moved[1], self.sim.state)
        if save:
            assert rows is not None
            out, applied, tally = self.outgoing(tick, rows, applied)
            saved = rows if out is None else out  # at a recorded tick every robot's row: those changed among them
            self.port.checkpoint(tick, saved, applied, self.sim.history[tick], -1 if out is not None else 0, tally)
            rows = out
        self.queued.append((tick, rows, joined, applied, parts, tally))
        self._flush()

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
        while self.queued and not self._awaits_monitor():
            if self.period:  # tick_rate: each tick goes out at least a period after the one before
                now = self.clock()
                if now < self.paced_at:
                    return  # poll() goes on
                self.paced_at = now + self.period
            tick, rows, joined, applied, parts, tally = self.queued.popleft()
            self.port.publish_tick(tick, rows, joined, applied, parts, tally)
            self.progress_at = self.moved_at = self.clock()
            self.published_tick = tick
            if tick == self.sim.tick and self.sim.done:
                self._announce_end()
            elif tick == 0:
                self.publish_status()

    def _announce_end(self) -> None:
        m = self.sim.metrics
        self.ended_at = self.clock()
        self.publish_status()
        assert self.sim.outcome is not None  # called once the run has ended
        self.log.info(f"run ended: {self.sim.outcome.value} at tick {m.tick}, {m.localized} localized")

    def metrics(self, tick: int, nonce: str = "") -> None:
        """The monitor's report of ``tick`` (checked: a tick this world published), from the monitor process
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
        """The bookkeeping a restarted world needs besides the ticks (:mod:`swarm_ros.protocol.world_restore`)."""
        if self.started:
            self.port.save_book(self.book())

    def restore(self, saved: Saved, incarnation: int) -> None:
        """Go on from the checkpoint a world process before this one wrote (:func:`restore`), then send every
        batch a snapshot of the saved tick, and the ticks after the monitor's last report again."""
        self.restore_saved(saved, incarnation)
        for k in range(len(self.batch_names)):
            if k not in self.removed_batches:
                self._send_snapshot(k)
        for t in sorted(t for t in saved.ring if t > saved.monitor_tick or t == saved.tick):
            rows, applied, tally = saved.ring[t]
            out, again = self.resent(t, rows, tally)
            self._emit(t, out, t == saved.tick, applied, None, save=False, tally=again)
        self.publish_status()

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
        elif self.removed_batches and not self.queued and not self.received and not self.sim.done:
            self._maybe_advance(self.sim.tick + 1)  # a tick only the world's own robots decide in
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
