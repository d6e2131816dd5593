"""The rubenstein algorithm's robot batch: decides, each tick, for the robots of its strip of the cell grid
(:mod:`swarm_ros.core.strips`).

The cell list (:class:`~swarm_ros.core.rubenstein.rule.Cells`) has cells the size of the communication range C, and
a robot decides from the robots in the 3 x 3 cells around its own: the strips' columns are the cell columns. A batch
builds its own cell list from its area's robots alone, in ascending id order, on the grid of the world's, so each of
its robots visits the same neighbours in the same order as in one process, and decides the same.
"""

from __future__ import annotations

import numpy as np

from swarm_ros.core.strips import Strips

from .rule import JOINED, Cells, Decided, Robots, build_cells, clear_cells, decide_kernel, decided_for
from .run import RubensteinRun, anchor_capacity


class RubensteinBatch:
    """One robot batch: decides for the robots of its strip from the rows of its area alone.

    The robots' arrays it is given are indexed by robot id, but only its area's rows are read: the rest is never
    looked at (its cell list holds its area's robots only).
    """

    def __init__(self, run: RubensteinRun, strips: Strips, k: int) -> None:
        n = run.params.robots
        self.rule, self.bitmap, self.strips, self.k, self.grid = run.rule, run.bitmap, strips, k, run.grid
        c = run.cells
        self.cells = Cells(np.full(c.head.size, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64), *c[2:])
        self._out = decided_for(n)
        cap = anchor_capacity(run.params.comm_range)
        self._anchors = (np.empty(cap), np.empty(cap), np.empty(cap))

    def decide(self, tick: int, ids: np.ndarray, changed: np.ndarray | None, s: Robots) -> tuple[np.ndarray, Decided]:
        """Decide ``tick`` for the robots of the strip not joined from ``s`` (every robot's arrays, of which those of
        its area, ``ids``, ascending, hold their rows after ``tick - 1``; what ``changed`` in the tick is not
        needed: it decides from the whole area): their ids and decisions (position k robot k's)."""
        own = ids[self.strips.in_strip(self.grid.columns(s.x[ids]), self.k) & (s.state[ids] != JOINED)]
        build_cells(ids, s.x, s.y, self.cells)
        decide_kernel(own, s, self.rule, self.bitmap, self.cells, tick, self._out, *self._anchors)
        clear_cells(ids, s.x, s.y, self.cells)
        return own.copy(), Decided(*(a[: own.size].copy() for a in self._out))
