"""A restarted world process goes on from its checkpoint (:mod:`swarm_ros.protocol.checkpoint`).

:meth:`WorldRestore.book` is what the lockstep writes beside the ticks when its bookkeeping changes;
:meth:`WorldRestore.restore_saved` puts a saved tick and that bookkeeping back into a fresh
:class:`~swarm_ros.protocol.lockstep.Lockstep` (a :class:`WorldRestore`), which then
sends what a reader may have lost with the world before: to every batch a snapshot of the
saved tick (a batch that had it ignores it), and the ticks from the one after the monitor's
last report up to the saved one, again (a reader that had them ignores them). The batches'
decisions for the next tick are in their writers' histories, which DDS hands to the new
world's readers; so are their announcements and the monitor's last metrics. The run then
goes on as if nothing had happened: a tick's decisions are a pure function of the state.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from swarm_ros.core.engine import Simulation
from swarm_ros.core.errors import ContractError, RunFailed
from swarm_ros.core.metrics import Outcome, TickMetrics, outcome_of
from swarm_ros.core.state import RobotState
from swarm_ros.protocol.checkpoint import Saved
from swarm_ros.protocol.hosting import Hosting
from swarm_ros.protocol.plan import MONITOR, WORLD
from swarm_ros.protocol.rows import pose_of
from swarm_ros.protocol.world_port import Logger, WorldPort

__all__ = ["Saved", "WorldRestore"]


class WorldRestore:
    """The lockstep's bookkeeping and its restore, as its methods (the fields they read and write are the
    lockstep's own, set in ``Lockstep.__init__``)."""

    sim: Simulation
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

    def save_book(self) -> None:  # the lockstep's own (Lockstep defines it)
        raise NotImplementedError

    def book(self) -> dict:
        """The lockstep's bookkeeping, as JSON data."""
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
        }

    def _saved_outcome(self, history: np.ndarray, robots: np.ndarray) -> Outcome | None:
        """The outcome after the saved tick, from its metrics (separated robots mean the shape completed with
        extras: the end check of a swarm whose left-overs are separated reads as complete)."""
        m = TickMetrics(*history[-1].tolist())
        if (robots["state"] == RobotState.SEPARATED).any():
            return Outcome.COMPLETE_WITH_EXTRAS
        alive = int((robots["state"] != RobotState.REMOVED).sum())
        return outcome_of(m, self.sim.shape.patches, alive, self.sim.params.max_ticks)

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

    def restore_saved(self, saved: Saved, incarnation: int) -> None:
        """Put ``saved`` into this lockstep (fresh, not started): its state and bookkeeping. The lockstep then sends
        again what readers may lack (module doc, :meth:`~swarm_ros.protocol.lockstep.Lockstep.restore`).
        ``incarnation`` counts the world's processes before this one: one killed before it wrote anything is a
        restart too, at the same tick.

        Raises:
            RunFailed: the checkpoint does not make a consistent swarm, or its bookkeeping is missing.
        """
        b, rows = saved.book, saved.robots
        if "batches" not in b:
            raise RunFailed("the checkpoint's bookkeeping is missing")
        tick = saved.tick
        pose = pose_of(rows)
        try:
            self.sim.restore(
                tick,
                pose["x"],
                pose["y"],
                pose["heading"],
                rows["state"],
                saved.history,
                [tuple(x) for x in b["losses"]],
                self._saved_outcome(saved.history, rows),
                pose.get("z"),
                pose.get("pitch"),
            )
        except ContractError as exc:
            raise RunFailed(f"the checkpoint of tick {tick}: {exc}") from None
        self.restore_book(b, tick, saved.monitor_tick, incarnation, WORLD)
        self.save_book()
        self.log.warn(
            f"world restarted: going on from tick {tick} of its checkpoint "
            f"({len(self.batch_names)} batches, restarts so far {len(self.restarts) - 1})"
        )
