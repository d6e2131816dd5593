"""Robot states and the swarm's state arrays (struct of arrays, indexed by robot id)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, fields
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from swarm_ros.core.errors import ParameterError
from swarm_ros.core.rng import (
    STREAM_PLACE_HEADING,
    STREAM_PLACE_PITCH,
    STREAM_PLACE_X,
    STREAM_PLACE_Y,
    STREAM_PLACE_Z,
    uniform_array,
)
from swarm_ros.core.shapes import Shape

NO_ROBOT = -1  #: occupancy value of a patch without a localized robot
FRONTIER_BLOCK = 8  #: side, in patches, of the blocks whose frontier patches are counted (nearest-frontier search)
FRONTIER_SUPER = 8  #: side, in blocks, of the super-blocks counted too: the search's coarse level (64 patches)


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
            patches (blocks row by row from the world's bottom-left corner), then per super-block of
            ``FRONTIER_SUPER`` x ``FRONTIER_SUPER`` blocks, then the total (int32, (B*B + S*S + 1,));
            kept in step with ``frontier`` (:func:`frontier_blocks_of`).
        z, pitch: (3D worlds only; None in 2D) the z position in patches, and the heading's
            elevation in radians, in [-pi/2, pi/2]: a robot faces
            ``(cos pitch cos heading, cos pitch sin heading, sin pitch)``.
        tick: the tick this state is the end of (0 = initial placement).
    """

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    state: np.ndarray
    occupancy: np.ndarray
    frontier: np.ndarray
    frontier_blocks: np.ndarray
    z: np.ndarray | None = None
    pitch: np.ndarray | None = None
    tick: int = 0

    @property
    def robots(self) -> int:
        return int(self.x.size)

    def copy(self) -> SwarmState:
        return SwarmState(
            **{
                f.name: (
                    getattr(self, f.name).copy()
                    if isinstance(getattr(self, f.name), np.ndarray)
                    else getattr(self, f.name)
                )
                for f in fields(self)
            }
        )

    def counts(self) -> np.ndarray:
        """Robots per :class:`RobotState` code (int64, (STATE_COUNT,))."""
        return np.bincount(self.state, minlength=STATE_COUNT)

    def moving_ids(self) -> np.ndarray:
        """Ids of moving robots, ascending (int64)."""
        return np.flatnonzero(IS_MOVING[self.state])


class Poses(NamedTuple):
    """A 2D swarm's robots as a central world's graph carries them (:mod:`swarm_ros.core.strips`): arrays indexed by
    robot id, in patches and radians."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    state: np.ndarray


class Poses3D(NamedTuple):
    """A 3D swarm's robots, as :class:`Poses`, with z and the heading's elevation."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    heading: np.ndarray
    pitch: np.ndarray
    state: np.ndarray


def poses_of(s: SwarmState) -> Poses | Poses3D:
    """The robots of ``s`` (its own arrays, not copies)."""
    if s.z is not None and s.pitch is not None:
        return Poses3D(s.x, s.y, s.z, s.heading, s.pitch, s.state)
    return Poses(s.x, s.y, s.heading, s.state)


def frontier_of(shape: Shape, occupancy: np.ndarray) -> np.ndarray:
    """Recompute the frontier grid (flat bool) from scratch: empty shape patches next to a localized robot."""
    occupied = (occupancy >= 0).reshape(shape.mask.shape)
    return (shape.mask & ~occupied & near_any(occupied)).ravel()


def near_any(grid: np.ndarray) -> np.ndarray:
    """Cells of a 2-D (3-D) bool grid that are set or have a set 8-neighbour (26-neighbour): a
    3 x 3 (x 3) binary dilation.

    Nine (27) slices of the zero-padded grid, ORed: the same as ``scipy.ndimage.binary_dilation``
    with a full 3 x 3 structure (a test checks it), without the 0.3 s of CPU it takes every node
    process to import ``scipy.ndimage``.
    """
    padded = np.pad(grid, 1)
    near = np.zeros_like(grid)
    for shift in itertools.product(range(3), repeat=grid.ndim):
        near |= padded[tuple(slice(d, d + n) for d, n in zip(shift, grid.shape))]
    return near


def frontier_blocks_of(frontier: np.ndarray, size: int, dims: int = 2) -> np.ndarray:
    """Frontier patches per ``FRONTIER_BLOCK``-sided block (cube in 3D) of a flat grid ``size`` patches
    a side, blocks in flat order from the world's low corner; then per ``FRONTIER_SUPER``-sided super-block
    of blocks, in the same order; then the total."""
    blocks = _block_sums(frontier.reshape((size,) * dims), FRONTIER_BLOCK)
    supers = _block_sums(blocks, FRONTIER_SUPER)
    return np.concatenate([blocks.ravel(), supers.ravel(), [blocks.sum()]]).astype(np.int32)


def _block_sums(grid: np.ndarray, b: int) -> np.ndarray:
    """The sums of ``grid`` over blocks of side ``b`` (the last ones cut short at the grid's far edges)."""
    nb = -(-grid.shape[0] // b)
    padded = np.zeros((nb * b,) * grid.ndim, dtype=np.int32)
    padded[tuple(slice(0, n) for n in grid.shape)] = grid
    return padded.reshape((nb, b) * grid.ndim).sum(axis=tuple(range(1, 2 * grid.ndim, 2)))


def initial_state(shape: Shape, robots: int, seed: int) -> SwarmState:
    """Tick 0: seeds on their 2 x 2 block (3D: their corner of four voxels; ids 0-3), everyone else on
    distinct random free patches.

    Robots 4..N-1 each get a different non-wall, non-seed patch drawn without
    replacement from the run seed, a uniform offset within that patch and a uniform
    heading (3D: a direction uniform on the sphere), both from the robot's own stream at tick 0.

    Raises:
        ParameterError: fewer than 4 robots, or more robots than free patches.
    """
    world = shape.world
    if robots < 4:
        raise ParameterError(f"robots must be at least 4 (the seed robots), got {robots}")
    try:
        shape.check_room(robots)
    except ParameterError as exc:
        raise ParameterError(f"{shape.source}: {exc}") from None
    seeds = shape.seed_patches
    seed_flat = world.flat_of(*seeds.T)
    free = ~world.wall_mask().ravel()
    free[seed_flat] = False
    candidates = np.flatnonzero(free)
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, 0x5EED])))
    chosen = rng.choice(candidates, size=robots - 4, replace=False)
    coords = world.patch_coords(chosen)

    ids = np.arange(4, robots, dtype=np.int64)
    position = []
    for axis, stream in enumerate((STREAM_PLACE_X, STREAM_PLACE_Y, STREAM_PLACE_Z)[: world.dims]):
        c = np.empty(robots)
        c[:4] = seeds[:, axis]
        c[4:] = coords[axis] + (uniform_array(seed, ids, 0, stream) - 0.5)
        position.append(c)
    heading = np.empty(robots)
    heading[:4] = 0.0
    heading[4:] = 2.0 * math.pi * uniform_array(seed, ids, 0, STREAM_PLACE_HEADING)
    extra = {}
    if world.dims == 3:  # a direction uniform on the sphere: sin(pitch) uniform in [-1, 1)
        pitch = np.zeros(robots)
        # math.asin (the C library's) element by element, not np.arcsin: numpy computes it with other code on a
        # CPU with AVX-512 (its SIMD dispatch), whose last bits differ, and the same seed gave another 3D run there
        sines = 2.0 * uniform_array(seed, ids, 0, STREAM_PLACE_PITCH) - 1.0
        pitch[4:] = np.fromiter(map(math.asin, sines.tolist()), dtype=np.float64, count=sines.size)
        extra = {"z": position[2], "pitch": pitch}

    state = np.empty(robots, dtype=np.int8)
    state[:4] = RobotState.SEED
    on_shape = shape.mask.ravel()[chosen]
    state[4:] = np.where(on_shape, RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE)

    occupancy = np.full(world.patch_count, -1, dtype=np.int32)
    occupancy[seed_flat] = np.arange(4, dtype=np.int32)
    frontier = frontier_of(shape, occupancy)
    return SwarmState(
        x=position[0],
        y=position[1],
        heading=heading,
        state=state,
        occupancy=occupancy,
        frontier=frontier,
        frontier_blocks=frontier_blocks_of(frontier, world.size, world.dims),
        tick=0,
        **extra,
    )
