"""A copy of the world's state rebuilt from the rows the world sends, for the study's model's robot batches.

The world sends, after each tick, one row per robot whose row changed in that tick (at tick 0,
every robot): id, state, x, y, heading (3D: and z, pitch). Only moving robots change, so those
rows are exactly the robots that decided in the tick. A :class:`SwarmView` applies the rows in
tick order and keeps the occupancy and frontier grids in step, so after tick t it holds the same
:class:`~swarm_ros.core.darr_niazi.state.SwarmState` as the world.

A robot batch keeps a *regional* view (``area``: the columns of its strip and halo,
:class:`swarm_ros.core.strips.Strips`): it receives the rows of the robots in that area, the
rows of robots that left it, and every robot's change to a stationary state. It holds
every stationary robot (so the occupancy and frontier are whole) and the moving robots
in its area; a moving robot whose row takes it out of the area is forgotten (state
:data:`UNKNOWN`) until a row brings it back.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from swarm_ros.core.darr_niazi.arbitration import occupy, vacate
from swarm_ros.core.darr_niazi.kernel_state import Robots, grid_of, robots_of
from swarm_ros.core.darr_niazi.rules2d import cell_index
from swarm_ros.core.darr_niazi.state import IS_MOVING, NO_ROBOT, RobotState, SwarmState, frontier_blocks_of
from swarm_ros.core.errors import ContractError
from swarm_ros.core.shapes import Shape

_SEED, _LOCALIZED = np.int8(RobotState.SEED), np.int8(RobotState.LOCALIZED)
_REMOVED, _SEPARATED = np.int8(RobotState.REMOVED), np.int8(RobotState.SEPARATED)
UNKNOWN = np.int8(-1)  #: state of a robot before the tick-0 rows arrive, or (regional) outside the area


@numba.njit(cache=True)
def _apply_rows(ids, rows, robots, grid, first, last):
    """Write ``rows`` (a :class:`~swarm_ros.core.darr_niazi.kernel_state.Robots` of the rows' poses and states, row k
    robot ``ids[k]``'s) into ``robots``; occupy in ``grid`` the patch of every robot that became stationary-localized,
    free the patch of every localized robot that was removed; forget (:data:`UNKNOWN`) a moving robot whose
    column is outside ``first``..``last``.

    Returns the number of rows that were rejected (-1 per row whose id is out of range
    or whose localized patch is not an empty shape patch), else 0.
    """
    new_state, new_x, new_y, new_z, new_heading, new_pitch = (
        rows.state,
        rows.x,
        rows.y,
        rows.z,
        rows.heading,
        rows.pitch,
    )
    x, y, z, heading, pitch, state = robots.x, robots.y, robots.z, robots.heading, robots.pitch, robots.state
    occupancy, frontier, blocks, shape, nbrs, radius, size, solid = (
        grid.occupancy,
        grid.frontier,
        grid.blocks,
        grid.shape,
        grid.nbrs,
        grid.radius,
        grid.size,
        grid.solid,
    )
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
            vacate(
                cell_index(x[i], y[i], z[i] if solid else 0.0, solid, radius, size),
                occupancy,
                frontier,
                blocks,
                shape,
                nbrs,
                size,
            )
        x[i] = new_x[k]
        y[i] = new_y[k]
        heading[i] = new_heading[k]
        zi = 0.0
        if solid:
            zi = new_z[k]
            z[i] = zi
            pitch[i] = new_pitch[k]
        state[i] = st
        if (st == _SEED or st == _LOCALIZED) and was != _SEED and was != _LOCALIZED:
            p = cell_index(x[i], y[i], zi, solid, radius, size)
            if not shape[p] or occupancy[p] >= 0:
                return k + 1
            occupy(p, i, occupancy, frontier, blocks, shape, nbrs, size)
        elif st != _SEED and st != _LOCALIZED and st != _SEPARATED and st != _REMOVED:
            column = int(math.floor(x[i] + 0.5)) + radius
            if column < first or column > last:
                state[i] = UNKNOWN  # moved out of the area this view follows
    return 0


class SwarmView:
    """The swarm's state as seen through the world's per-tick rows.

    Attributes:
        state: the rebuilt :class:`SwarmState`; ``state.tick`` is -1 until tick 0 arrives.
        area: (first, last) column this view follows moving robots in (regional), or None: every robot.
    """

    def __init__(self, shape: Shape, robots: int, area: tuple[int, int] | None = None) -> None:
        world = shape.world
        self.shape = shape
        self.area = area
        self._first, self._last = area if area is not None else (0, world.size - 1)
        self._radius, self._size = world.radius, world.size
        self._shape = shape.mask.ravel().copy()
        self._nbrs = world.neighbour_offsets()
        self._wall = world.wall_mask().ravel()
        self._solid = world.dims == 3
        self._none = np.empty(0)  # z and pitch in a 2D world
        self.state = self._empty(robots)

    def _empty(self, robots: int) -> SwarmState:
        world = self.shape.world
        frontier = np.zeros(world.patch_count, dtype=bool)
        solid = {"z": np.zeros(robots), "pitch": np.zeros(robots)} if self._solid else {}
        return SwarmState(
            x=np.zeros(robots),
            y=np.zeros(robots),
            heading=np.zeros(robots),
            state=np.full(robots, UNKNOWN, dtype=np.int8),
            occupancy=np.full(world.patch_count, NO_ROBOT, dtype=np.int32),
            frontier=frontier,
            frontier_blocks=frontier_blocks_of(frontier, world.size, world.dims),
            tick=-1,
            **solid,
        )

    def load(
        self,
        tick: int,
        ids: np.ndarray,
        state: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        heading: np.ndarray,
        z: np.ndarray | None = None,
        pitch: np.ndarray | None = None,
    ) -> None:
        """Start again from a snapshot: every robot's row at ``tick`` (how a restarted robot batch catches up);
        for a regional view, the rows of the stationary robots and of the moving ones in its area.

        The occupancy and frontier are rebuilt from the rows, so the view equals one
        that applied every tick's rows from tick 0 to ``tick``.

        Raises:
            ContractError: as :meth:`update` for tick 0; the view is then unusable.
        """
        if tick < 0:
            raise ContractError(f"a snapshot of tick {tick}")
        self.state = self._empty(self.state.robots)
        self.state.tick = -1
        self._apply(0, ids, state, x, y, heading, z, pitch)  # the checks of a tick-0 message: every robot once
        self.state.tick = tick

    @property
    def tick(self) -> int:
        return self.state.tick

    def update(
        self,
        tick: int,
        ids: np.ndarray,
        state: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        heading: np.ndarray,
        z: np.ndarray | None = None,
        pitch: np.ndarray | None = None,
    ) -> None:
        """Apply the rows of ``tick``, which must be the tick after the last one applied.

        Raises:
            ContractError: a tick was skipped or repeated, tick 0 does not cover every robot,
                an id is out of range, a state code is unknown, or a robot localizes on a
                patch that is not an empty shape patch. The view is then unusable.
        """
        if tick != self.state.tick + 1:
            raise ContractError(f"rows for tick {tick} arrived after tick {self.state.tick}")
        self._apply(tick, ids, state, x, y, heading, z, pitch)

    def _apply(
        self,
        tick: int,
        ids: np.ndarray,
        state: np.ndarray,
        x: np.ndarray,
        y: np.ndarray,
        heading: np.ndarray,
        z: np.ndarray | None,
        pitch: np.ndarray | None,
    ) -> None:
        s = self.state
        if self._solid != (z is not None and pitch is not None):
            raise ContractError("rows of a 3D world need z and pitch; rows of a 2D world have none")
        ids = np.asarray(ids, dtype=np.int64)
        state = np.asarray(state, dtype=np.int8)
        if (
            tick == 0
            and self.area is None
            and (ids.size != s.robots or not np.array_equal(np.sort(ids), np.arange(s.robots)))
        ):
            raise ContractError(f"tick 0 must hold every robot once ({s.robots}), got {ids.size} rows")
        if state.size and (state.min() < 0 or state.max() > max(RobotState)):
            raise ContractError(f"unknown robot state code in the rows of tick {tick}")
        f64 = np.float64
        new_z, new_pitch = (np.asarray(z, f64), np.asarray(pitch, f64)) if self._solid else (self._none, self._none)
        rows = Robots(
            np.asarray(x, dtype=f64), np.asarray(y, dtype=f64), new_z, np.asarray(heading, dtype=f64), new_pitch, state
        )
        grid = grid_of(self.shape, s, self._shape, self._wall, self._nbrs)
        bad = _apply_rows(ids, rows, robots_of(s), grid, self._first, self._last)
        if bad:
            raise ContractError(
                f"tick {tick}: row {bad - 1} (robot {ids[bad - 1]}) is out of range, "
                f"localizes on a patch that is not an empty shape patch, or returns after removal"
            )
        s.tick = tick

    def moving_ids(self) -> np.ndarray:
        """Ids of the moving robots (a regional view: those in its area), ascending."""
        state = self.state.state
        return np.flatnonzero(IS_MOVING[state] & (state != UNKNOWN))
