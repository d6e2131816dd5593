"""What of each tick the world (or a world shard) sends the monitor: a part of
:class:`~swarm_ros.protocol.lockstep.Lockstep`.

With ``record_every`` 1 (the default up to 10,000 robots) it is every tick's changed rows and applied decisions,
and the monitor counts each tick from its view. Above, the rows would bound a large run by the monitor, which
takes, checks and records every one of them: the world sends instead, every tick, a *tally* (the run's robots by
state; with world shards, shard 0 alone sends it, from the metrics every shard holds), from which the monitor counts
the tick, and every ``record_every``-th tick and at the last, every robot's row (a shard: those in its strips) and
that tick's decisions, which the monitor checks against the tally and records.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from swarm_ros.core.metrics import SEEDS, TickMetrics
from swarm_ros.core.regions import columns
from swarm_ros.core.state import STATE_COUNT, RobotState
from swarm_ros.core.swarm_view import UNKNOWN
from swarm_ros.protocol.rows import state_rows

if TYPE_CHECKING:
    from swarm_ros.core.shards import WorldShard
    from swarm_ros.protocol.shard_exchange import RunView


def state_counts(metrics: TickMetrics, seeds: int, removed: int) -> np.ndarray:
    """The robots in each :class:`~swarm_ros.core.state.RobotState` (codes in order) at the end of ``metrics``'
    tick, given the seeds still in the run (robots 0-3) and the robots removed so far: the inverse of
    :func:`~swarm_ros.core.metrics.tick_metrics`."""
    counts = np.zeros(STATE_COUNT, dtype=np.int64)
    counts[RobotState.SEED], counts[RobotState.LOCALIZED] = seeds, metrics.localized - seeds
    counts[RobotState.SEPARATED] = metrics.stationary - metrics.localized
    counts[RobotState.REMOVED], counts[RobotState.WALKING] = removed, metrics.walking
    counts[RobotState.MOVING_INSIDE] = metrics.inside
    counts[RobotState.MOVING_OUTSIDE] = metrics.moving - metrics.inside - metrics.walking
    return counts


class WorldRecords:
    """The lockstep's choice of what goes to the monitor (see the module's docstring)."""

    sim: RunView
    shard: WorldShard
    every: int  #: record_every, resolved: the robots' rows go to the monitor every this many ticks

    def records(self, tick: int) -> bool:
        """Whether tick ``tick``'s robots' rows go to the monitor (the recording, the bag): every tick when
        ``every`` is 1, else every ``every``-th tick and the last."""
        return tick % self.every == 0 or (tick == self.sim.tick and self.sim.done)

    def outgoing(
        self, tick: int, rows: np.ndarray, applied: np.ndarray | None
    ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """What of the tick just applied (``rows``: the robots that changed) goes to the monitor: (robot rows or
        None, applied decisions or None, tally or None). With ``every`` = 1, the changed rows and the decisions;
        above, the tally every tick, and at a tick that :meth:`records`, every robot's row (this process's part)
        and the decisions."""
        if self.every == 1:
            return rows, applied, None
        if not self.records(tick):
            return None, None, self._tally()
        return self._recorded_rows(), applied, self._tally()

    def resent(self, tick: int, rows: np.ndarray, tally: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """What a restarted process sends again of a saved tick (its checkpoint ring's ``rows`` and ``tally``):
        (robot rows or None, tally or None), as :meth:`outgoing` sent them."""
        if self.every == 1:
            return rows, None
        return (rows if self.records(tick) else None), (tally if self.shard.index == 0 else None)

    def _tally(self) -> np.ndarray | None:
        """The run's robots by state at the tick just closed, from world process 0 only (every world process holds
        the run's metrics and its removed robots alike), or None (another process; the rows go out every tick)."""
        if self.every == 1 or self.shard.index != 0:
            return None
        seeds = SEEDS - int(self.shard.removed[:SEEDS].sum())
        return state_counts(self.sim.metrics, seeds, self.sim.removed)

    def _recorded_rows(self) -> np.ndarray:
        """Every robot's row in this process's strips (the world's: every robot's) at the tick just closed."""
        return state_rows(self._own(), self.sim.state)

    def _own(self) -> np.ndarray:
        """The robots this process reports at tick 0 and at every tick it records: every one standing in its strips
        (moving robots: those it owns; stationary and removed ones: every shard knows them, this one has the
        strips they stand in)."""
        s = self.sim.state
        known = np.flatnonzero(s.state != UNKNOWN)
        return known[self._in_strips(s.x[known])]

    def _in_strips(self, x: np.ndarray) -> np.ndarray:
        cols = columns(x, self.shard.plan.radius)
        return (cols >= self.shard.strip[0]) & (cols <= self.shard.strip[1])
