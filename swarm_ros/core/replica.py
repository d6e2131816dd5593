"""A copy of the world's state rebuilt from what the world broadcasts, for robot batches and the monitor.

The distributed engine's world publishes, after each tick, one row per robot whose
row changed in that tick (at tick 0, every robot): id, state, x, y, heading. Only
moving robots change, so those rows are exactly the robots that decided in the tick.
A :class:`Replica` applies the rows in tick order and keeps the occupancy and frontier
grids in step, so after tick t it holds the same :class:`~swarm_ros.core.state.SwarmState`
as the world: a robot batch decides from it, the monitor counts it.
"""

from __future__ import annotations

import numba
import numpy as np

from swarm_ros.core.arbitration import occupy, vacate
from swarm_ros.core.rules import patch_index
from swarm_ros.core.shapes import Shape
from swarm_ros.core.state import IS_MOVING, NO_ROBOT, RobotState, SwarmState, frontier_blocks_of, has_repeats

_SEED, _LOCALIZED = np.int8(RobotState.SEED), np.int8(RobotState.LOCALIZED)
_REMOVED = np.int8(RobotState.REMOVED)
UNKNOWN = np.int8(-1)  #: state of a robot before the tick-0 rows arrive


@numba.njit(cache=True)
def _apply_rows(ids, new_state, new_x, new_y, new_heading, x, y, heading, state, occupancy, frontier, blocks,
                shape, radius, size):
    """Write the rows into the state arrays; occupy the patch of every robot that became stationary-localized,
    free the patch of every localized robot that was removed.

    Returns the number of rows that were rejected (-1 per row whose id is out of range
    or whose localized patch is not an empty shape patch), else 0.
    """
    n = state.size
    for k in range(ids.size):
        i = ids[k]
        if i < 0 or i >= n:
            return k + 1
        was = state[i]
        st = new_state[k]
        if was == _REMOVED and st != _REMOVED:
            return k + 1  # removed robots never come back
        if st == _REMOVED and (was == _SEED or was == _LOCALIZED):
            vacate(patch_index(x[i], y[i], radius, size), occupancy, frontier, blocks, shape, size)
        x[i] = new_x[k]
        y[i] = new_y[k]
        heading[i] = new_heading[k]
        state[i] = st
        if (st == _SEED or st == _LOCALIZED) and was != _SEED and was != _LOCALIZED:
            p = patch_index(x[i], y[i], radius, size)
            if not shape[p] or occupancy[p] >= 0:
                return k + 1
            occupy(p, i, occupancy, frontier, blocks, shape, size)
    return 0


class Replica:
    """The swarm's state as seen through the world's per-tick rows.

    Attributes:
        state: the rebuilt :class:`SwarmState`; ``state.tick`` is -1 until tick 0 arrives.
    """

    def __init__(self, shape: Shape, robots: int) -> None:
        world = shape.world
        self.shape = shape
        self._radius, self._size = world.radius, world.size
        self._shape = shape.mask.ravel().copy()
        self.state = self._empty(robots)

    def _empty(self, robots: int) -> SwarmState:
        world = self.shape.world
        frontier = np.zeros(world.patch_count, dtype=bool)
        return SwarmState(
            x=np.zeros(robots), y=np.zeros(robots), heading=np.zeros(robots),
            state=np.full(robots, UNKNOWN, dtype=np.int8),
            occupancy=np.full(world.patch_count, NO_ROBOT, dtype=np.int32),
            frontier=frontier, frontier_blocks=frontier_blocks_of(frontier, world.size), tick=-1)

    def load(self, tick: int, ids: np.ndarray, state: np.ndarray, x: np.ndarray, y: np.ndarray,
             heading: np.ndarray) -> None:
        """Start again from a snapshot: every robot's row at ``tick`` (how a restarted robot batch catches up).

        The occupancy and frontier are rebuilt from the rows, so the replica equals one
        that applied every tick's rows from tick 0 to ``tick``.

        Raises:
            ValueError: as :meth:`update` for tick 0; the replica is then unusable.
        """
        if tick < 0:
            raise ValueError(f"a snapshot of tick {tick}")
        self.state = self._empty(self.state.robots)
        self.state.tick = -1
        self._apply(0, ids, state, x, y, heading)  # the checks of a tick-0 message: every robot once
        self.state.tick = tick

    @property
    def tick(self) -> int:
        return self.state.tick

    def update(self, tick: int, ids: np.ndarray, state: np.ndarray, x: np.ndarray, y: np.ndarray,
               heading: np.ndarray) -> None:
        """Apply the rows of ``tick``, which must be the tick after the last one applied.

        Raises:
            ValueError: a tick was skipped or repeated, tick 0 does not cover every robot,
                an id is out of range, a state code is unknown, or a robot localizes on a
                patch that is not an empty shape patch. The replica is then unusable.
        """
        if tick != self.state.tick + 1:
            raise ValueError(f"rows for tick {tick} arrived after tick {self.state.tick}")
        self._apply(tick, ids, state, x, y, heading)

    def _apply(self, tick: int, ids: np.ndarray, state: np.ndarray, x: np.ndarray, y: np.ndarray,
               heading: np.ndarray) -> None:
        s = self.state
        ids = np.asarray(ids, dtype=np.int64)
        state = np.asarray(state, dtype=np.int8)
        if tick == 0 and (ids.size != s.robots or not np.array_equal(np.sort(ids), np.arange(s.robots))):
            raise ValueError(f"tick 0 must hold every robot once ({s.robots}), got {ids.size} rows")
        if state.size and (state.min() < 0 or state.max() > max(RobotState)):
            raise ValueError(f"unknown robot state code in the rows of tick {tick}")
        bad = _apply_rows(ids, state, np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64),
                          np.asarray(heading, dtype=np.float64), s.x, s.y, s.heading, s.state, s.occupancy,
                          s.frontier, s.frontier_blocks, self._shape, self._radius, self._size)
        if bad:
            raise ValueError(f"tick {tick}: row {bad - 1} (robot {ids[bad - 1]}) is out of range, "
                             f"localizes on a patch that is not an empty shape patch, or returns after removal")
        s.tick = tick

    def inconsistent(self, tick: int, ids: np.ndarray, state: np.ndarray, x: np.ndarray, y: np.ndarray) -> str | None:
        """Why the rows of ``tick`` cannot be the world's next ones (None if they can), changing nothing.

        Checks what :meth:`update` would otherwise find half-way through, leaving the replica
        unusable: the tick follows the last one; tick 0 holds every robot once; after tick 0,
        only robots that were moving change, except that any robot may be removed, once; a
        robot that localizes does so on a frontier patch, one robot per patch. Ids and state
        codes must be in range (:mod:`swarm_ros.protocol.checks` checks them first).
        """
        s = self.state
        if tick != s.tick + 1:
            return f"rows for tick {tick} after tick {s.tick}"
        ids = np.asarray(ids, dtype=np.int64)
        if tick == 0:
            if ids.size != s.robots or not np.array_equal(np.sort(ids), np.arange(s.robots)):
                return f"tick 0 must hold every robot once ({s.robots}), got {ids.size} rows"
            return None
        before, after = s.state[ids], np.asarray(state, dtype=np.int8)
        moving = IS_MOVING[before]
        if (~moving & ((after != _REMOVED) | (before == _REMOVED))).any():
            return "a robot that was not moving changed"
        joins = moving & ((after == _LOCALIZED) | (after == _SEED))
        if joins.any():
            px = np.floor(np.asarray(x)[joins] + 0.5).astype(np.int64) + self._radius
            py = np.floor(np.asarray(y)[joins] + 0.5).astype(np.int64) + self._radius
            if px.min() < 0 or py.min() < 0 or px.max() >= self._size or py.max() >= self._size:
                return "a robot localizes outside the world"
            p = py * self._size + px
            if not s.frontier[p].all() or has_repeats(p):
                return "a robot localizes off the frontier, or two on one patch"
        return None

    def moving_ids(self) -> np.ndarray:
        """Ids of the moving robots, ascending."""
        return self.state.moving_ids()
