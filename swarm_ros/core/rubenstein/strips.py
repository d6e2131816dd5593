"""A rubenstein run split among K robot batches, as the ROS 2 graph is to run it: by strips of the cell grid.

The cell list (:class:`~swarm_ros.core.rubenstein.rule.Cells`) has cells the size of the communication
range C, and a robot decides from the robots in the 3 x 3 cells around its own. So the world is cut
into K strips of whole cell columns (:func:`strips_for`: as many robots in each at the start as whole
columns allow); batch k decides for the robots not joined whose cell, at the last
tick, lies in its strip, and it needs the robots of its *area*: its strip and one cell column either
side (the halo, C wide). It builds its own cell list from those robots alone, in ascending id order, on
the grid of the world's, so each of its robots visits the same neighbours in the same order as in one
process, and decides the same. The world holds every robot: it sends each batch its area's robots
as they stand after a tick, takes every batch's decisions for the next, and settles them
(:meth:`~swarm_ros.core.rubenstein.run.RubensteinRun.settle`) as the in-process engine does.

A batch's work a tick is its area's robots and their neighbours, never the whole swarm's. A batch
keeps nothing between ticks that the world does not send it again, so a restarted batch decides as
the one it replaces would have.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm_ros.core.errors import ParameterError
from swarm_ros.core.regions import parse_cuts

from .rule import JOINED, Cells, Decided, Robots, build_cells, clear_cells, decide_kernel, decided_for
from .run import RubensteinRun, anchor_capacity, robots_at_start


@dataclass(frozen=True)
class Strips:
    """K strips of whole cell columns: strip k is the columns ``cuts[k]`` to ``cuts[k + 1] - 1``."""

    cuts: np.ndarray  #: int64, K + 1 ascending column numbers, the first 0 and the last the grid's width

    @staticmethod
    def balanced(start_columns: np.ndarray, columns: int, batches: int) -> Strips:
        """``batches`` strips of whole columns holding, at the start, as nearly equal numbers of robots as
        whole columns allow (``start_columns``: each robot's cell column at tick 0), each at least one column
        wide. The robots not joined are the ones that decide, and for most of a run most of them wait in the
        pack, so this shares most of the deciding.

        Raises:
            ParameterError: more batches than columns.
        """
        if not 1 <= batches <= columns:
            raise ParameterError(f"processes must be between 1 and the {columns} cell columns, got {batches}")
        held = np.cumsum(np.bincount(start_columns, minlength=columns))
        cuts = [0]
        for k in range(1, batches):
            at = int(np.searchsorted(held, k * held[-1] / batches)) + 1  # columns before it hold k/K of them
            cuts.append(min(max(at, cuts[-1] + 1), columns - (batches - k)))
        return Strips(np.array([*cuts, columns], dtype=np.int64))

    @staticmethod
    def cut(at: np.ndarray, cells: Cells, batches: int) -> Strips:
        """``batches`` strips cut at ``at`` (K - 1 ascending x positions in d, ``region_cuts``): strip k starts at the
        cell column that holds cut k - 1.

        Raises:
            ParameterError: not K - 1 cuts, or cuts that leave a strip without a cell column.
        """
        if at.size != batches - 1:
            raise ParameterError(f"region_cuts gives {at.size} cuts; {batches} batches need {batches - 1}")
        starts = np.floor((at - cells.x0) / cells.side).astype(np.int64)
        cuts = np.concatenate([[0], starts, [cells.nx]]).astype(np.int64)
        if (np.diff(cuts) < 1).any():
            end = cells.x0 + cells.nx * cells.side
            raise ParameterError(
                f"region_cuts {at.tolist()} leave a strip with no cell column (the grid's {cells.nx} columns, "
                f"{cells.side:g} d wide, span x = {cells.x0:g} to {end:g} d)"
            )
        return Strips(cuts)

    @staticmethod
    def tiling(strips: list[tuple[int, int]], columns: int) -> Strips | None:
        """The strips ``strips`` ((first, last) cell columns, in any order) make, if they tile the ``columns``
        columns of the grid with no gap or overlap; None if they do not (yet)."""
        ordered = sorted(strips)
        if not ordered or ordered[0][0] != 0 or ordered[-1][1] != columns - 1:
            return None
        if any(before[1] + 1 != after[0] for before, after in zip(ordered, ordered[1:])):
            return None
        return Strips(np.array([first for first, _ in ordered] + [columns], dtype=np.int64))

    @property
    def batches(self) -> int:
        return self.cuts.size - 1

    def strip(self, k: int) -> tuple[int, int]:
        """The first and last cell column of strip k."""
        return int(self.cuts[k]), int(self.cuts[k + 1]) - 1

    def area(self, k: int) -> tuple[int, int]:
        """The first and last cell column of batch k's area: its strip and the halo column either side."""
        first, last = self.strip(k)
        return max(first - 1, 0), min(last + 1, int(self.cuts[-1]) - 1)

    def in_strip(self, columns: np.ndarray, k: int) -> np.ndarray:
        """Which of the robots in cell ``columns`` lie in strip k."""
        first, last = self.strip(k)
        return (columns >= first) & (columns <= last)

    def in_area(self, columns: np.ndarray, k: int) -> np.ndarray:
        """Which of the robots in cell ``columns`` lie in batch k's area."""
        first, last = self.area(k)
        return (columns >= first) & (columns <= last)


def cell_columns(x: np.ndarray, cells: Cells) -> np.ndarray:
    """The cell column of each x (as the kernels find a robot's cell)."""
    return np.clip(np.floor((x - cells.x0) / cells.side).astype(np.int64), 0, cells.nx - 1)


def strips_for(run: RubensteinRun, batches: int, region_cuts: str = "") -> Strips:
    """The run's strips for ``batches`` batches: cut at ``region_cuts`` (x positions in d, :meth:`Strips.cut`), or,
    with none, :meth:`Strips.balanced` over its robots at tick 0 (every process that knows the run's parameters
    finds the same).

    Raises:
        ParameterError: cuts or a batch count the grid cannot be cut by.
    """
    if region_cuts:
        return Strips.cut(parse_cuts(region_cuts), run.cells, batches)
    return Strips.balanced(cell_columns(robots_at_start(run.params).x, run.cells), run.cells.nx, batches)


def area_of(run: RubensteinRun, strips: Strips, k: int) -> np.ndarray:
    """The ids of the robots in batch k's area, as they stand at the run's tick (what the world sends it)."""
    return np.flatnonzero(strips.in_area(cell_columns(run.robots.x, run.cells), k))


class RubensteinBatch:
    """One robot batch: decides for the robots of its strip from the rows of its area alone.

    Its arrays are indexed by robot id, but only its area's rows are written and read a tick: the
    rest is never looked at (its cell list holds its area's robots only).
    """

    def __init__(self, run: RubensteinRun, strips: Strips, k: int) -> None:
        n = run.params.robots
        self.rule, self.bitmap, self.strips, self.k = run.rule, run.bitmap, strips, k
        self.robots = Robots(*(np.zeros(n, dtype=a.dtype) for a in run.robots))
        c = run.cells
        self.cells = Cells(np.full(c.head.size, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64), *c[2:])
        self._out = decided_for(n)
        cap = anchor_capacity(run.params.comm_range)
        self._anchors = (np.empty(cap), np.empty(cap), np.empty(cap))

    def decide(self, tick: int, ids: np.ndarray, rows: Robots) -> tuple[np.ndarray, Decided]:
        """Take the rows of the area's robots ``ids`` (ascending) as they stood after ``tick - 1`` and decide
        ``tick`` for the robots of the strip not joined: their ids and decisions (position k robot k's)."""
        s = self.robots
        for mine, theirs in zip(s, rows):
            mine[ids] = theirs
        own = ids[self.strips.in_strip(cell_columns(s.x[ids], self.cells), self.k) & (s.state[ids] != JOINED)]
        build_cells(ids, s.x, s.y, self.cells)
        decide_kernel(own, s, self.rule, self.bitmap, self.cells, tick, self._out, *self._anchors)
        clear_cells(ids, s.x, s.y, self.cells)
        return own.copy(), Decided(*(a[: own.size].copy() for a in self._out))


def run_batched(run: RubensteinRun, batches: int, max_ticks: int | None = None, region_cuts: str = "") -> Strips:
    """Run ``run`` to its end (or ``max_ticks`` more ticks) with its robots' decisions made by ``batches``
    :class:`RubensteinBatch` es (cut at ``region_cuts``, if given), each sent only its area's rows; the result equals
    ``run.run()``'s. Returns the strips."""
    strips = strips_for(run, batches, region_cuts)
    hosts = [RubensteinBatch(run, strips, k) for k in range(batches)]
    left = max_ticks
    while run.outcome is None and (left is None or left > 0):
        tick = run.tick + 1
        parts = []
        for k, host in enumerate(hosts):
            ids = area_of(run, strips, k)
            parts.append(host.decide(tick, ids, Robots(*(a[ids] for a in run.robots))))
        run.settle(parts)
        left = None if left is None else left - 1
    return strips
