"""What the world's :class:`~swarm_ros.protocol.lockstep.Lockstep` says about the run (its /swarm/status), and
how it notices a silent process (the fallback to liveliness): two views of its state, kept apart from the
state machine itself as :class:`WorldStatus`, a base class of the lockstep's."""

from __future__ import annotations

import math
from collections import deque
from typing import TYPE_CHECKING

import numpy as np

from swarm_ros.core.errors import RunFailed
from swarm_ros.core.metrics import METRIC_COLUMNS, Outcome
from swarm_ros.core.state import RobotState
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.plan import MONITOR
from swarm_ros.protocol.status import RUNNING, STARTING, Status, restarts_text
from swarm_ros.protocol.world_losses import Down
from swarm_ros.protocol.world_port import DROWNED_S, FIRST_STALL_S, STALL_S, STILL_S

if TYPE_CHECKING:
    from swarm_ros.protocol.shard_exchange import RunView


class WorldStatus:
    """The lockstep's status and stall checks, as its methods (the fields they read are the lockstep's own,
    set in ``Lockstep.__init__``)."""

    sim: RunView
    rejections: Rejections
    started: bool
    ended_at: float | None
    start_time: float | None
    startup_seconds: float
    published_tick: int
    restarts: list[tuple[int, str]]
    lost: list[str]
    batch_names: list[str]
    down_since: dict[int, Down]
    monitor_down_since: float | None
    monitor_alive: bool
    monitor_tick: int
    window: int
    every: int
    queued: deque
    progress_at: float
    moved_at: float
    decided: np.ndarray
    pending: np.ndarray
    live: set[int]
    resent_at: dict[int, float]
    inflight: tuple[int, np.ndarray] | None

    # the lockstep's own (Lockstep defines them; a WorldStatus alone is not a lockstep)
    def hosts(self, ids: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def lose_batch(self, k: int, why: str) -> None:
        raise NotImplementedError

    def monitor_down(self, why: str) -> None:
        raise NotImplementedError

    def _awaits_monitor(self) -> bool:
        raise NotImplementedError

    def _send_snapshot(self, k: int) -> None:
        raise NotImplementedError

    def _orphans(self) -> np.ndarray:
        raise NotImplementedError

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
                    self.monitor_down(f"no metrics for {limit:g} s")
                elif now - self.progress_at >= DROWNED_S:
                    self._drowned("the monitor's metrics")
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
