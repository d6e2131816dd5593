"""A central world cut into S world shards (:mod:`swarm_ros.core.strips`): each shard holds the robots of a run of
consecutive batches' strips (its own columns) and of one column either side (its halo), never the whole swarm's,
and the run is the one world's, exactly.

A shard's engine (the algorithm's, a :class:`ShardedRun`) holds every robot's arrays, of which
only the robots it holds (``present``) are read. A tick, for shard s:

1. its batches decide from the robots of their areas, which lie in its own columns and its halo;
2. every shard sends each other the decisions of its own deciding robots that lie in the other's halo (*border*):
   a grant reads the decisions of the robots within one column;
3. it settles and applies its own robots' moves (the engine's ``settle_shard``), and names those whose rows change
   what every shard shares (the rubenstein algorithm's: the robots that joined, which cover pixels and enter the
   running counts);
4. every shard sends every other those rows and its counts; each closes the tick alike (``close_shard``: the shared
   state, the tick's metrics and the end, the same on every shard);
5. every shard sends each other the rows of its robots now in the other's own columns or halo: robots that crossed
   into the other's columns are handed over, and the other's halo is what its neighbours' robots are now.

A robot moves less than a column a tick, and a decision or a grant reads the robots within one column, so each shard
decides, settles and closes as the one world does. :func:`run_sharded` runs S shards end to end in one process,
passing between them only those messages, for tests.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from .regions import shard_batches
from .strips import CentralRun, Strips


class ShardedRun(CentralRun, Protocol):
    """What an engine gives beside :class:`~swarm_ros.core.strips.CentralRun` to run in world shards."""

    def counts(self, ids: np.ndarray) -> np.ndarray: ...  # robots ``ids``' share of the tick's counts (summed)

    def settle_shard(self, own: np.ndarray, decided: Any, halo: np.ndarray, halo_decided: Any, present: np.ndarray):
        """Settle and apply its ``own`` deciding robots' moves against every robot ``present`` (its halo's decided
        too); the ids of its robots whose rows change what every shard shares."""
        ...

    def close_shard(self, shared: np.ndarray, rows: Any, counts: np.ndarray) -> Any:
        """Close the tick alike on every shard: the ``shared`` robots' ``rows`` in, the summed ``counts``; the
        outcome."""
        ...


def _take(robots: Any, ids: np.ndarray | slice) -> Any:
    """The rows of robots ``ids`` of every robot's arrays ``robots`` (a NamedTuple of arrays)."""
    return type(robots)(*(a[ids] for a in robots))


def _concat(parts: list[tuple[np.ndarray, Any]]) -> tuple[np.ndarray, Any]:
    """(ids, rows) of several, in ascending id order."""
    ids = np.concatenate([p[0] for p in parts]).astype(np.int64)
    order = np.argsort(ids, kind="stable")
    rows = type(parts[0][1])(*(np.concatenate(f)[order] for f in zip(*(p[1] for p in parts))))
    return ids[order], rows


class CentralShard:
    """World shard ``shard`` of ``shards``: the strips of its batches (:func:`~swarm_ros.core.regions.shard_batches`)
    and one column either side. ``run``: its engine, at tick 0 (every robot's rows then true)."""

    def __init__(self, run: ShardedRun, strips: Strips, shard: int, shards: int) -> None:
        self.run, self.strips = run, strips
        self.batches = shard_batches(shard, shards, strips.batches)
        self.first = int(strips.cuts[self.batches[0]])
        self.last = int(strips.cuts[self.batches[-1] + 1]) - 1
        self.present = self._within(np.arange(run.params.robots), self.first - 1, self.last + 1)

    def _within(self, ids: np.ndarray, first: int, last: int) -> np.ndarray:
        columns = self.run.grid.columns(self.run.robots.x[ids])
        return ids[(columns >= first) & (columns <= last)]

    @property
    def own(self) -> np.ndarray:
        """Its robots: those present in its own columns, ascending."""
        return self._within(self.present, self.first, self.last)

    def area(self, k: int) -> np.ndarray:
        """The robots of batch k's area (one of its batches), ascending: what the shard sends it."""
        first, last = self.strips.area(k)
        return self._within(self.present, first, last)

    def border(self, other: CentralShard, ids: np.ndarray) -> np.ndarray:
        """Which of robots ``ids`` (its own) lie in ``other``'s halo."""
        columns = self.run.grid.columns(self.run.robots.x[ids])
        return (columns == other.first - 1) | (columns == other.last + 1)

    def reach(self, other: CentralShard, ids: np.ndarray) -> np.ndarray:
        """Which of robots ``ids`` (its own) lie in ``other``'s own columns or halo."""
        columns = self.run.grid.columns(self.run.robots.x[ids])
        return (columns >= other.first - 1) & (columns <= other.last + 1)

    def receive(self, mine: np.ndarray, rows: list[tuple[np.ndarray, Any]]) -> None:
        """After a tick: it holds its robots ``mine`` still within reach, and the peers' robots ``rows`` (ids,
        every array's rows) they sent it (:meth:`reach`)."""
        kept = self._within(mine, self.first - 1, self.last + 1)
        parts = [(kept, _take(self.run.robots, kept)), *rows]
        ids, got = _concat(parts)
        for a, b in zip(self.run.robots, got):
            a[ids] = b
        self.present = ids


def run_sharded(
    make_run: Callable[[], ShardedRun],
    batch: Callable[[ShardedRun, Strips, int], Any],
    shards: int,
    batches: int,
    max_ticks: int | None = None,
    region_cuts: str = "",
) -> list[CentralShard]:
    """Run a central world as ``shards`` world shards of ``batches`` batches (``batch(run, strips, k)`` gives batch
    k, as the algorithm's wire does), from ``make_run()`` (a fresh engine, one per shard), to its end or
    ``max_ticks`` ticks, passing between shards only their messages. Returns the shards: each one's engine has the
    run's metrics and outcome, and the rows of its own robots."""
    from .strips import strips_for

    runs = [make_run() for _ in range(shards)]
    strips = strips_for(runs[0], batches, region_cuts)
    world = [CentralShard(runs[s], strips, s, shards) for s in range(shards)]
    hosts = {k: batch(w.run, strips, k) for w in world for k in w.batches}
    left = max_ticks
    while world[0].run.outcome is None and (left is None or left > 0):
        tick = world[0].run.tick + 1
        decided = []
        for w in world:  # 1. the batches decide; what each shard's own deciding robots decided
            parts = [hosts[k].decide(tick, ids, _take(w.run.robots, ids)) for k in w.batches for ids in [w.area(k)]]
            decided.append(_concat(parts))
        border = [[(ids[keep], _take(d, keep)) for o, (ids, d) in enumerate(decided) if o != s
                   for keep in [world[o].border(w, ids)]] for s, w in enumerate(world)]  # fmt: skip
        mine = [w.own for w in world]  # 2. the border's decisions, and who owns which robot, before any moves
        joined, counts = [], []
        for s, w in enumerate(world):  # 3. settle and apply its own
            halo, halo_decided = _concat([(decided[s][0][:0], _take(decided[s][1], slice(0, 0))), *border[s]])
            ids = w.run.settle_shard(decided[s][0], decided[s][1], halo, halo_decided, w.present)
            joined.append((ids, _take(w.run.robots, ids)))
            counts.append(w.run.counts(mine[s]))
        shared, total = _concat(joined), np.sum(counts, axis=0)
        for w in world:  # 4. the shared rows and the counts in: the tick closes alike on every shard
            w.run.close_shard(*shared, total)
        sent = [[(ids[keep], _take(w.run.robots, ids[keep])) for ids in [mine[s]] for keep in [w.reach(o, ids)]]
                for s, w in enumerate(world) for o in world]  # fmt: skip
        for s, w in enumerate(world):  # 5. handovers and halos
            w.receive(mine[s], [sent[o * shards + s][0] for o in range(shards) if o != s])
        left = None if left is None else left - 1
    return world
