"""What the compiled kernels take, by name: the robots, the grid, the rule set, the moves decided.

The kernels of :mod:`~swarm_ros.core.darr_niazi.rules`, :mod:`~swarm_ros.core.darr_niazi.rules3d`,
:mod:`~swarm_ros.core.darr_niazi.arbitration` and :mod:`~swarm_ros.core.darr_niazi.engine` read and write numpy arrays.
They take them grouped in these named tuples, which numba passes as records: a kernel reads
``robots.x`` or ``grid.radius``, so two arrays of one type cannot be swapped by position, and a
caller builds each group in one place (:func:`robots_of`, :func:`grid_of`, :func:`rules_of`).
Building a tuple copies nothing: its fields are the arrays themselves, and what a kernel writes
into them lands in the :class:`~swarm_ros.core.darr_niazi.state.SwarmState` they belong to.

The world's dimension is data, ``grid.solid``. In a 2D world ``robots.z``, ``robots.pitch``,
``moves.z`` and ``moves.pitch`` are empty arrays that no kernel reads.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from swarm_ros.core.darr_niazi.state import SwarmState
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape

_EMPTY = np.empty(0)


class Robots(NamedTuple):
    """Every robot's pose and state (float64 poses in patches and radians, int8 :class:`RobotState` codes)."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray  #: empty in 2D
    heading: np.ndarray
    pitch: np.ndarray  #: empty in 2D
    state: np.ndarray


class Grid(NamedTuple):
    """The world's flat per-patch arrays (voxels in 3D) and its geometry."""

    shape: np.ndarray  #: bool: a shape patch
    wall: np.ndarray  #: bool: a wall patch
    frontier: np.ndarray  #: bool: an empty shape patch next to a filled one
    blocks: np.ndarray  #: frontier patches per block of FRONTIER_BLOCK patches, and their total last
    occupancy: np.ndarray  #: int64: the robot localized on each patch, or -1
    nbrs: np.ndarray  #: flat offsets of a patch's neighbours (8 in 2D, 26 in 3D)
    radius: int  #: the world spans [-radius, radius] on each axis
    size: int  #: 2 * radius + 1
    solid: bool  #: a 3D world


class Rules(NamedTuple):
    """The run's parameters the kernels use, and its rule set's codes (:mod:`swarm_ros.core.darr_niazi.rulesets`)."""

    vision: float
    wiggle: float  #: radians
    seed: int
    join: int
    crowd: int
    steps: int


class Moves(NamedTuple):
    """What robots decided, per position k of the ids decided: the patch claimed (flat index, or -1) and the pose
    taken if the robot does not win it."""

    claim: np.ndarray  #: int64
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray  #: empty in 2D
    heading: np.ndarray
    pitch: np.ndarray  #: empty in 2D


def robots_of(state: SwarmState) -> Robots:
    """The robots' arrays of ``state`` (the same arrays, not copies)."""
    z = state.z if state.z is not None else _EMPTY
    pitch = state.pitch if state.pitch is not None else _EMPTY
    return Robots(state.x, state.y, z, state.heading, pitch, state.state)


def grid_of(shape: Shape, state: SwarmState, shape_mask: np.ndarray, wall: np.ndarray, nbrs: np.ndarray) -> Grid:
    """The grid of ``state``'s frontier and occupancy (the same arrays), with the world's flat ``shape_mask``,
    ``wall`` and neighbour offsets ``nbrs``."""
    world = shape.world
    return Grid(
        shape_mask,
        wall,
        state.frontier,
        state.frontier_blocks,
        state.occupancy,
        nbrs,
        int(world.radius),
        int(world.size),
        world.dims == 3,
    )


def rules_of(params: RunParams) -> Rules:
    join, crowd, steps = params.ruleset.codes()
    return Rules(
        float(params.vision_radius), float(params.wiggle_rad), int(params.seed), int(join), int(crowd), int(steps)
    )


def moves_for(robots: int, solid: bool) -> Moves:
    """Empty arrays for the moves of up to ``robots`` robots."""
    extra = robots if solid else 0
    return Moves(
        np.empty(robots, dtype=np.int64),
        np.empty(robots),
        np.empty(robots),
        np.empty(extra),
        np.empty(robots),
        np.empty(extra),
    )
