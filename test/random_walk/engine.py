"""The random walk: a walking robot on a shape cell next to (4-way) a stopped robot stops; any other steps a cell in a
random direction unless the grid's edge, a robot there or a lower id asking for the cell holds it back."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from swarm_ros.core.errors import ContractError
from swarm_ros.core.grid import CellMap
from swarm_ros.core.metrics import Outcome
from swarm_ros.core.params import RUN_PARAMETER
from swarm_ros.core.rng import uniform_array
from swarm_ros.core.strips import StripGrid

NAME, STREAM = "random-walk", 100
STEPS = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])  #: a step's (dx, dy), by its draw


class Robots(NamedTuple):
    x: np.ndarray  #: the robot's cell column
    y: np.ndarray  #: its cell row
    state: np.ndarray  #: 0 walking, 1 stopped


class Batch:
    """Decides for the walking robots of strip k (all of them with no strips) from its area's robots alone."""

    def __init__(self, run: RandomWalk, strips, k: int) -> None:
        self.mask, self.seed, self.strips, self.k, self.grid = run.mask, run.params.seed, strips, k, run.grid

    def decide(self, tick: int, ids: np.ndarray, changed, robots: Robots) -> tuple[np.ndarray, Robots]:
        (rows, cols), area = self.mask.shape, Robots(*(a[ids] for a in robots))  # (the robots it sees: ids)
        stopped = np.zeros((rows + 2, cols + 2), dtype=bool)  # a border of cells that never hold a robot
        stopped[area.y[area.state == 1] + 1, area.x[area.state == 1] + 1] = True
        mine = (area.state == 0) & (self.strips is None or self.strips.in_strip(self.grid.columns(area.x), self.k))
        x, y = area.x[mine], area.y[mine]
        stop = self.mask[y, x] & np.any([stopped[y + 1 + dy, x + 1 + dx] for dx, dy in STEPS], axis=0)
        step = STEPS[(uniform_array(self.seed, ids[mine], tick, STREAM) * 4).astype(np.int64)]
        tx = np.where(stop, x, np.clip(x + step[:, 0], 0, cols - 1))
        ty = np.where(stop, y, np.clip(y + step[:, 1], 0, rows - 1))
        return ids[mine], Robots(tx, ty, stop.astype(np.int8))


class RandomWalk:
    """The in-process engine, and the central world's :class:`~swarm_ros.core.strips.CentralRun`."""

    columns = ("tick", "stopped", "walking", "covered")

    def __init__(self, shape, params) -> None:
        self.shape, self.params, self.mask = shape, params, np.asarray(shape.mask, dtype=bool)
        rows, cols = self.mask.shape
        first = int(np.flatnonzero(self.mask)[0])
        others = np.random.default_rng(params.seed).permutation(np.delete(np.arange(rows * cols), first))
        cells = np.concatenate([[first], others[: params.robots - 1]])
        self.robots = Robots(cells % cols, cells // cols, (np.arange(params.robots) == 0).astype(np.int8))
        self.grid, self.tick, self.outcome = StripGrid(-0.5, 2.0, (cols + 1) // 2, "cells"), 0, None  # 2 cells wide
        self._rows = [[0, *self.counts(np.arange(params.robots)).tolist()]]

    history = property(lambda self: np.array(self._rows, dtype=float))  #: a row of ``columns`` a tick
    done = property(lambda self: self.outcome is not None)
    seen_by_all = staticmethod(lambda state: state < 0)  #: none: a walker sees only its neighbours
    progress = lambda self: (int(self._rows[-1][3]), int(self.mask.sum()), {"tick": str(self.tick)})
    empty_curve = lambda self: np.stack([self.history[:, 0], self.mask.sum() - self.history[:, 3]], axis=1)
    saved = lambda self: {**self.robots._asdict(), "history": self.history}  # a checkpoint's arrays

    def cell_map(self) -> CellMap:  # the shape's cells, and those a stopped robot stands on
        filled, s = np.zeros_like(self.mask), self.robots
        filled[s.y[s.state == 1], s.x[s.state == 1]] = True
        return CellMap(self.mask, filled & self.mask, 1.0, (-0.5, -0.5))

    def deciding(self, among: np.ndarray | None = None) -> np.ndarray:
        ids = np.arange(self.params.robots) if among is None else among
        return ids[self.robots.state[ids] == 0]

    def counts(self, ids: np.ndarray) -> np.ndarray:
        s, stopped = self.robots, self.robots.state[ids] == 1
        covered = np.count_nonzero(stopped & self.mask[s.y[ids], s.x[ids]])
        return np.array([stopped.sum(), ids.size - stopped.sum(), covered], dtype=np.int64)

    def run(self, max_ticks: int | None = None) -> Outcome | None:
        everyone = np.arange(self.params.robots)
        while self.outcome is None and (max_ticks is None or max_ticks > 0):
            self.settle([Batch(self, None, 0).decide(self.tick + 1, everyone, None, self.robots)])
            max_ticks = None if max_ticks is None else max_ticks - 1
        return self.outcome

    def settle(self, decided: list[tuple[np.ndarray, Robots]]) -> Outcome | None:
        ids = np.concatenate([p[0] for p in decided])
        if self.outcome is not None or not np.array_equal(np.sort(ids), self.deciding()):
            raise ContractError(f"tick {self.tick + 1}: not one decision for each walking robot")
        d = Robots(*(np.concatenate([p[1][f] for p in decided]) for f in range(3)))
        self.settle_shard(ids, d, ids[:0], Robots(*(a[:0] for a in d)), everyone := np.arange(self.params.robots))
        return self.close_shard(ids[:0], d, self.counts(everyone))

    def settle_shard(self, own, decided: Robots, halo, halo_decided: Robots, present: np.ndarray) -> np.ndarray:
        """Stops; steps onto cells free at the start, the lowest id first (a grant reads two cells: one column)."""
        s, ids = self.robots, np.concatenate([own, halo])
        tx, ty, stop = (np.concatenate(f) for f in zip(decided, halo_decided))
        taken = np.zeros(self.mask.shape, dtype=bool)
        taken[s.y[present], s.x[present]] = True
        asks, cell = np.flatnonzero((stop == 0) & ~taken[ty, tx]), ty * self.mask.shape[1] + tx
        asks = asks[np.lexsort((ids[asks], cell[asks]))]
        first, go = np.ones(asks.size, dtype=bool), np.zeros(ids.size, dtype=bool)
        first[1:] = np.diff(cell[asks]) != 0
        go[asks[first]] = True
        k = np.arange(own.size)
        s.x[own], s.y[own], s.state[own] = np.where(go[k], tx[k], s.x[own]), np.where(go[k], ty[k], s.y[own]), stop[k]
        return own[:0]  # nothing every shard shares but the counts

    def close_shard(self, _joined: np.ndarray, _rows: Robots, counts: np.ndarray) -> Outcome | None:
        self.tick += 1
        self._rows.append([self.tick, *counts.tolist()])
        stopped, walking, covered = counts.tolist()
        if covered == self.mask.sum():
            self.outcome = Outcome.COMPLETE if walking == 0 else Outcome.COMPLETE_WITH_EXTRAS
        elif walking == 0 or self.tick >= self.params.max_ticks:
            self.outcome = Outcome.INCOMPLETE if walking == 0 else Outcome.TIMEOUT
        return self.outcome

    def load(self, tick: int, robots: Robots, history: np.ndarray, outcome: Outcome | None = None) -> None:
        for mine, theirs in zip(self.robots, robots):
            mine[:] = theirs
        self.tick, self.outcome, self._rows = tick, outcome, history.tolist()

    def restore(self, tick: int, arrays: dict[str, np.ndarray]) -> None:  # another run's: ValueError, in load
        self.load(tick, Robots(*(arrays[f] for f in Robots._fields)), arrays["history"][: tick + 1])


def summary_of(run: RandomWalk, wall_seconds: float, stopped: Outcome | None = None) -> dict:
    """Its summary.json, in the study's results.csv columns: a stopped robot is a localized one."""
    outcome, cells, (_, done, walking, covered) = run.outcome or stopped, int(run.mask.sum()), run._rows[-1]
    mine = {k: v for k, v in run.params.as_dict().items() if RUN_PARAMETER[k].algorithm in ("", NAME)}
    counts = {"localized": int(done), "unlocalized": int(walking), "empty_patches": cells - int(covered)}
    return {"shape": run.shape.name, "shape_patches": cells, **mine, "world_radius": run.shape.world.radius,
            "engine": "inprocess", "outcome": str(outcome), "convergence_tick": run.tick, **counts, "separated": 0,
            "lost_robots": 0, "convergence_rate": 0.0, "coverage": covered / cells, "fill_50_tick": None,
            "fill_90_tick": None, "wall_seconds": wall_seconds}  # fmt: skip
