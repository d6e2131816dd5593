"""S world shards in one process (:mod:`swarm_ros.core.shards`): the split of the world's half of a tick run
end to end, passing between shards only their messages, for tests and for scripts/bench_shards.py."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from swarm_ros.core.metrics import Outcome
from swarm_ros.core.params import RunParams
from swarm_ros.core.regions import columns
from swarm_ros.core.rules import Decider, Decisions
from swarm_ros.core.shapes import Shape
from swarm_ros.core.shards import Part, ShardPlan, WorldShard
from swarm_ros.core.state import SwarmState
from swarm_ros.core.swarm_view import UNKNOWN


@dataclass
class ShardedRun:
    """A run of :func:`run_sharded`: what ``Simulation`` gives, and what each shard did.

    Attributes:
        history: the metrics of every tick (int64, columns ``METRIC_COLUMNS``), as ``Simulation.history``.
        state: every robot's final row (each moving robot's from the shard owning it), occupancy and frontier.
        outcome, losses: as ``Simulation``'s.
        seconds: per shard, the seconds of its world's work (claims, apply, routing, close) over the run.
        decide_seconds: per shard, the seconds its robots took to decide (a robot batch's work in the graph).
        rows_received: per shard, the rows it took from the others over the run.
        rows_applied: per shard, the rows of its own robots it applied over the run (what it would publish).
        rivals_received: per shard, the claims it took from the others over the run.
    """

    history: np.ndarray
    state: SwarmState
    outcome: Outcome | None
    losses: list[tuple[int, int]]
    seconds: np.ndarray
    decide_seconds: np.ndarray
    rows_received: np.ndarray
    rivals_received: np.ndarray
    rows_applied: np.ndarray


class ShardedWorld:
    """S world shards and their robots in one process, exchanging only the messages of the module's docstring;
    each shard's robots decide from its regional view, as a robot batch does. Counts each shard's seconds
    and what it received (:class:`ShardedRun`)."""

    def __init__(
        self, shape: Shape, params: RunParams, cuts: np.ndarray, removals: dict[int, np.ndarray] | None = None
    ) -> None:
        self.plan = ShardPlan(shape.world.radius, params.vision_radius, cuts)
        s = self.plan.shards
        self.shards = [WorldShard(shape, params, self.plan, k) for k in range(s)]
        self.deciders = [Decider(shape, params) for _ in range(s)]
        self.removals = removals or {}  # tick -> robots removed at its end (as a lost batch's)
        self.seconds, self.decide_seconds = np.zeros(s), np.zeros(s)
        self.rows, self.rivals = np.zeros(s, dtype=np.int64), np.zeros(s, dtype=np.int64)
        self.applied = np.zeros(s, dtype=np.int64)
        self.received: list[list[Part]] = []  # the last tick's parts, as each shard received them
        self.claims: list[list[Decisions]] = []  # the last tick's claims, as each shard received them

    @property
    def outcome(self) -> Outcome | None:
        return self.shards[0].outcome

    def step(self) -> None:
        """One tick: decide, exchange the claims, apply, exchange the rows and counts, close."""
        shards, clock, count = self.shards, time.perf_counter, range(self.plan.shards)
        tick = shards[0].tick + 1
        decisions, claims = [], []
        for k, sh in enumerate(shards):
            t0 = clock()
            decisions.append(self.deciders[k].decide(sh.state, sh.own_moving(), tick, sh.view.moving_ids()))
            t1 = clock()
            claims.append(sh.claims(decisions[k]))
            self.decide_seconds[k] += t1 - t0
            self.seconds[k] += clock() - t1
        self.claims = [[claims[i][k] for i in count if i != k] for k in count]
        parts, routed = [], []
        for k, sh in enumerate(shards):
            t0 = clock()
            gone = self.removals.get(tick)
            if gone is not None:  # its own of the robots removed at this tick's end
                gone = np.intersect1d(gone, decisions[k].ids)
            parts.append(sh.apply(decisions[k], self.claims[k], gone))
            routed.append(sh.routes(parts[k]))
            self.seconds[k] += clock() - t0
            self.rivals[k] += sum(int(r.ids.size) for r in self.claims[k])
            self.applied[k] += parts[k].ids.size
        self.received = [[routed[i][k] for i in count if i != k] for k in count]
        for k, sh in enumerate(shards):
            t0 = clock()
            sh.close(parts[k], self.received[k])
            self.seconds[k] += clock() - t0
            self.rows[k] += sum(int(q.ids.size) for q in self.received[k])

    def result(self) -> ShardedRun:
        first = self.shards[0]
        history = np.asarray(first.history, dtype=np.int64)
        return ShardedRun(
            history=history,
            state=_assemble(self.shards),
            outcome=first.outcome,
            losses=list(first.losses),
            seconds=self.seconds.copy(),
            decide_seconds=self.decide_seconds.copy(),
            rows_received=self.rows.copy(),
            rivals_received=self.rivals.copy(),
            rows_applied=self.applied.copy(),
        )


def run_sharded(
    shape: Shape,
    params: RunParams,
    cuts: np.ndarray,
    max_ticks: int | None = None,
    removals: dict[int, np.ndarray] | None = None,
) -> ShardedRun:
    """Run with the world split into ``len(cuts) + 1`` shards cut at ``cuts`` (x positions), in one process
    (:class:`ShardedWorld`). Gives ``Simulation(shape, params).run(max_ticks)``'s run; ``removals``: robots
    removed at the end of a tick (``Simulation.remove`` after that tick's ``step``), by tick."""
    world = ShardedWorld(shape, params, cuts, removals)
    left = float("inf") if max_ticks is None else max_ticks
    while world.outcome is None and left > 0:
        world.step()
        left -= 1
    return world.result()


def _assemble(shards: list[WorldShard]) -> SwarmState:
    """Every robot's row from the shard whose strips hold it (the shards agree on every stationary robot's row,
    and a moving robot, or one separated or removed while moving, is known for sure to its owner)."""
    whole = shards[0].state.copy()
    for sh in shards:
        s = sh.state
        cols = columns(s.x, sh.plan.radius)
        here = np.flatnonzero((s.state != UNKNOWN) & (cols >= sh.strip[0]) & (cols <= sh.strip[1]))
        for name in ("x", "y", "heading", "state", "z", "pitch"):
            if getattr(whole, name) is not None:
                getattr(whole, name)[here] = getattr(s, name)[here]
    return whole
