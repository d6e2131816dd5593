"""The world's loss policy: a robot batch or the monitor lost (its liveliness lapsed, or it stalled).

A lost batch is waited for (``restart_timeout``) while it has restarts left under ``on_batch_loss:
restart``, and its robots are removed otherwise, once the loss is confirmed (``LOSS_CONFIRM_S``): the moving
robots in its strip, at the end of the next tick, after which the world decides for the robots that move into
the strip. A lost monitor is waited for as long; the ticks are held back meanwhile, as while it is behind, then
the swarm goes on without it. docs/faults.md says the policy in full.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from swarm_ros.core.errors import RunFailed
from swarm_ros.protocol.hosting import Hosting
from swarm_ros.protocol.plan import MONITOR
from swarm_ros.protocol.world_port import LOSS_CONFIRM_S, Logger, Policy

if TYPE_CHECKING:
    from swarm_ros.protocol.shard_exchange import RunView


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


class WorldLosses:
    """The lockstep's handling of lost processes, as its methods (the fields they read and write are the
    lockstep's own, set in ``Lockstep.__init__``)."""

    sim: RunView
    policy: Policy
    log: Logger
    clock: Callable[[], float]
    hosting: Hosting
    batch_names: list[str]
    restart_counts: list[int]
    live: set[int]
    lapsed: set[int]
    respawned: dict[int, tuple[int, int]]
    down_since: dict[int, Down]
    removed_batches: set[int]
    lost: list[str]
    started: bool
    pending: np.ndarray
    parts: list[np.ndarray]
    received: int
    inflight: tuple[int, np.ndarray] | None
    deferred: list[tuple[int, str]]
    monitor_alive: bool
    monitor_down_since: float | None
    window: int

    # the lockstep's own (Lockstep defines them)
    def publish_status(self, note: str = "") -> None:
        raise NotImplementedError

    def save_book(self) -> None:
        raise NotImplementedError

    def maybe_start(self) -> None:
        raise NotImplementedError

    def _respawn(self, k: int) -> None:
        raise NotImplementedError

    def _maybe_advance(self, tick: int) -> None:
        raise NotImplementedError

    def _flush(self) -> None:
        raise NotImplementedError

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
        self.parts = [r[~np.isin(r["id"], self.pending)] for r in self.parts]
        self.received = sum(r.size for r in self.parts)
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
