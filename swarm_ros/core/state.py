"""Robot states and the swarm's state arrays (struct of arrays, indexed by robot id)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from enum import IntEnum

import numpy as np

from swarm_ros.core.errors import ParameterError
from swarm_ros.core.rng import STREAM_PLACE_HEADING, STREAM_PLACE_X, STREAM_PLACE_Y, uniform_array
from swarm_ros.core.shapes import Shape

NO_ROBOT = -1  #: occupancy value of a patch without a localized robot
FRONTIER_BLOCK = 8  #: side, in patches, of the blocks whose frontier patches are counted (nearest-frontier search)


class RobotState(IntEnum):
    """What a robot is doing. Codes are stable: they appear in files and messages."""

    SEED = 0  #: one of the four robots the shape grows from; stationary, localized
    MOVING_OUTSIDE = 1  #: wandering on a non-shape patch
    MOVING_INSIDE = 2  #: wandering on a shape patch, looking for a place to join
    LOCALIZED = 3  #: joined the shape: stationary on a shape patch
    SEPARATED = 4  #: left over after the shape completed: stationary, unlocalized
    REMOVED = 5  #: failed and taken out of the world (``--fail-robots``, a lost process): holds no patch
    WALKING = 6  #: (join ``walk``) heading straight for the nearest frontier patch, one patch a tick

    @property
    def label(self) -> str:
        return self.name.lower()


STATE_COUNT = len(RobotState)
#: The states of robots that decide each tick.
MOVING_STATES = (RobotState.MOVING_OUTSIDE, RobotState.MOVING_INSIDE, RobotState.WALKING)
#: Indexed by a state code: whether robots in it move (``IS_MOVING[states]``, a lookup where ``np.isin`` costs
#: ~20 us a call on the graph's per-message path).
IS_MOVING = np.isin(np.arange(STATE_COUNT), MOVING_STATES)


def has_repeats(values: np.ndarray) -> bool:
    """Whether a value occurs twice in ``values`` (a sort: ``np.unique`` costs several times more)."""
    ordered = np.sort(values)
    return bool((ordered[1:] == ordered[:-1]).any())


@dataclass
class SwarmState:
    """The whole swarm at the end of one tick.

    Attributes:
        x, y: positions in patches (float64, shape (N,)); the robot is on patch
            ``(floor(x + 0.5), floor(y + 0.5))``.
        heading: radians, counter-clockwise from +x, in [0, 2 pi) (float64, (N,)).
        state: :class:`RobotState` codes (int8, (N,)).
        occupancy: flat world grid (int32, (W*W,)): id of the localized robot (or seed)
            on each patch, or ``NO_ROBOT``.
        frontier: flat world grid (bool, (W*W,)): empty shape patches with at least
            one localized 8-neighbour, i.e. the patches robots may join.
        frontier_blocks: frontier patches per block of ``FRONTIER_BLOCK`` x ``FRONTIER_BLOCK``
            patches (int32, (B*B + 1,), blocks row by row from the world's bottom-left corner),
            the last entry the total; kept in step with ``frontier`` (:func:`frontier_blocks_of`).
        tick: the tick this state is the end of (0 = initial placement).
    """

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    state: np.ndarray
    occupancy: np.ndarray
    frontier: np.ndarray
    frontier_blocks: np.ndarray
    tick: int = 0

    @property
    def robots(self) -> int:
        return int(self.x.size)

    def copy(self) -> SwarmState:
        return SwarmState(**{f.name: (getattr(self, f.name).copy() if f.name != "tick" else self.tick)
                             for f in fields(self)})

    def counts(self) -> np.ndarray:
        """Robots per :class:`RobotState` code (int64, (STATE_COUNT,))."""
        return np.bincount(self.state, minlength=STATE_COUNT)

    def moving_ids(self) -> np.ndarray:
        """Ids of moving robots, ascending (int64)."""
        return np.flatnonzero(IS_MOVING[self.state])


def frontier_of(shape: Shape, occupancy: np.ndarray) -> np.ndarray:
    """Recompute the frontier grid (flat bool) from scratch: empty shape patches next to a localized robot."""
    w = shape.world.size
    occupied = (occupancy >= 0).reshape(w, w)
    return (shape.mask & ~occupied & near_any(occupied)).ravel()


def near_any(grid: np.ndarray) -> np.ndarray:
    """Cells of a 2-D bool grid that are set or have a set 8-neighbour (a 3 x 3 binary dilation).

    Nine slices of the zero-padded grid, ORed: the same as ``scipy.ndimage.binary_dilation``
    with a 3 x 3 structure (a test checks it), without the 0.3 s of CPU it takes every node
    process to import ``scipy.ndimage``.
    """
    h, w = grid.shape
    padded = np.pad(grid, 1)
    near = np.zeros_like(grid)
    for dy in range(3):
        for dx in range(3):
            near |= padded[dy:dy + h, dx:dx + w]
    return near


def frontier_blocks_of(frontier: np.ndarray, size: int) -> np.ndarray:
    """Frontier patches per ``FRONTIER_BLOCK``-sided block of a ``size`` x ``size`` flat grid, then the total."""
    b = FRONTIER_BLOCK
    nb = -(-size // b)
    grid = np.zeros((nb * b, nb * b), dtype=np.int32)
    grid[:size, :size] = frontier.reshape(size, size)
    counts = grid.reshape(nb, b, nb, b).sum(axis=(1, 3)).ravel()
    return np.append(counts, counts.sum()).astype(np.int32)


def initial_state(shape: Shape, robots: int, seed: int) -> SwarmState:
    """Tick 0: seeds on their 2 x 2 block (ids 0-3), everyone else on distinct random free patches.

    Robots 4..N-1 each get a different non-wall, non-seed patch drawn without
    replacement from the run seed, a uniform offset within that patch and a uniform
    heading, both from the robot's own stream at tick 0.

    Raises:
        ParameterError: fewer than 4 robots, or more robots than free patches.
    """
    world = shape.world
    if robots < 4:
        raise ParameterError(f"robots must be at least 4 (the seed robots), got {robots}")
    if robots > shape.free_patches:
        raise ParameterError(
            f"{shape.source}: {robots} robots do not fit on the {shape.free_patches} free patches "
            f"of the {world.size} x {world.size} world"
        )
    w = world.size
    seeds = shape.seed_patches
    seed_flat = world.flat_index(seeds[:, 0], seeds[:, 1])
    free = ~world.wall_mask().ravel()
    free[seed_flat] = False
    candidates = np.flatnonzero(free)
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, 0x5EED])))
    chosen = rng.choice(candidates, size=robots - 4, replace=False)
    px, py = world.patch_xy(chosen)

    ids = np.arange(4, robots, dtype=np.int64)
    x = np.empty(robots)
    y = np.empty(robots)
    heading = np.empty(robots)
    x[:4], y[:4], heading[:4] = seeds[:, 0], seeds[:, 1], 0.0
    x[4:] = px + (uniform_array(seed, ids, 0, STREAM_PLACE_X) - 0.5)
    y[4:] = py + (uniform_array(seed, ids, 0, STREAM_PLACE_Y) - 0.5)
    heading[4:] = 2.0 * math.pi * uniform_array(seed, ids, 0, STREAM_PLACE_HEADING)

    state = np.empty(robots, dtype=np.int8)
    state[:4] = RobotState.SEED
    on_shape = shape.mask.ravel()[chosen]
    state[4:] = np.where(on_shape, RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE)

    occupancy = np.full(w * w, -1, dtype=np.int32)
    occupancy[seed_flat] = np.arange(4, dtype=np.int32)
    frontier = frontier_of(shape, occupancy)
    return SwarmState(x=x, y=y, heading=heading, state=state, occupancy=occupancy, frontier=frontier,
                      frontier_blocks=frontier_blocks_of(frontier, w), tick=0)
