"""The patch world, square (2D) or cubic (3D): coordinates, walls and patch indexing.

Patches have integer coordinates ``(px, py)`` with ``-R <= px, py <= R``; the world
is ``W = 2R + 1`` patches wide. Grids over the world are numpy arrays indexed
``grid[iy, ix]`` with ``ix = px + R`` and ``iy = py + R``, so row 0 is the bottom
(``py = -R``); flat patch indices are ``iy * W + ix``. A continuous position
``(x, y)`` (in patches) is on the patch whose centre is nearest:
``px = floor(x + 0.5)``.

A 3D world (``dims = 3``) is a cube of voxels, ``-R <= px, py, pz <= R``; grids are indexed
``grid[iz, iy, ix]`` and flat indices are ``(iz * W + iy) * W + ix``, so a 2D world's flat
indices are those of the 3D world's bottom layer. "Patch" means a voxel there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from swarm_ros.core.errors import ParameterError


class CellMap(NamedTuple):
    """A run's shape as cells, for viewers (the graph's /swarm/shape and /swarm/occupancy): ``mask`` (bool, ``[y,
    x]`` or ``[z, y, x]``, index 0 at the low corner) the shape's cells, ``filled`` (bool, as ``mask``) those done
    so far, ``side`` a cell's side and ``corner`` the low corner of cell 0 (x, y[, z]), in the unit of the robots'
    positions on the wire."""

    mask: np.ndarray
    filled: np.ndarray
    side: float
    corner: tuple[float, ...]


DEFAULT_RADIUS = 32
MIN_RADIUS = 3  # a wall ring, the seeds' 2 x 2 block and room to move
DIMS = (2, 3)


@dataclass(frozen=True)
class World:
    """A ``(2R+1) x (2R+1)`` patch grid whose border ring is a wall, or (``dims = 3``) a
    ``(2R+1)^3`` voxel cube whose outer shell is a wall.

    Attributes:
        radius: R, in patches; patch coordinates run from -R to R.
        dims: 2 (the study's plane) or 3.
    """

    radius: int = DEFAULT_RADIUS
    dims: int = 2

    def __post_init__(self) -> None:
        if not isinstance(self.radius, (int, np.integer)) or self.radius < MIN_RADIUS:
            raise ParameterError(f"world_radius must be an integer >= {MIN_RADIUS}, got {self.radius!r}")
        if self.dims not in DIMS:
            raise ParameterError(f"a world has 2 or 3 dimensions, got {self.dims!r}")

    @property
    def size(self) -> int:
        """W, the number of patches along one side."""
        return 2 * self.radius + 1

    @property
    def patch_count(self) -> int:
        return self.size**self.dims

    @property
    def grid_shape(self) -> tuple[int, ...]:
        """``(W, W)``, or ``(W, W, W)`` in 3D (z first)."""
        return (self.size,) * self.dims

    def describe(self) -> str:
        """``65 x 65`` or ``33 x 33 x 33``: the world's size in words."""
        return " x ".join([str(self.size)] * self.dims)

    def wall_mask(self) -> np.ndarray:
        """Boolean grid, True on the border ring (patches with < 8 neighbours) or, in 3D, the outer shell."""
        wall = np.ones(self.grid_shape, dtype=bool)
        wall[(slice(1, -1),) * self.dims] = False
        return wall

    def neighbour_offsets(self) -> np.ndarray:
        """Flat-index offsets of a patch's 8 neighbours (26 in 3D), ascending (int64)."""
        steps = np.array([-1, 0, 1])
        grids = np.meshgrid(*([steps] * self.dims), indexing="ij")  # z (or y) first
        weights = self.size ** np.arange(self.dims - 1, -1, -1)
        offsets = sum(g.ravel() * w for g, w in zip(grids, weights))
        return np.sort(offsets[offsets != 0]).astype(np.int64)

    def cell_map(self, mask: np.ndarray, filled: np.ndarray) -> CellMap:
        """A shape ``mask`` over this world's patches (``grid_shape``) and the ``filled`` ones, as cells one patch
        wide, cell 0's centre at patch (-R, -R[, -R])."""
        return CellMap(mask, filled, 1.0, (-(self.radius + 0.5),) * self.dims)

    def patch_coords(self, flat: np.ndarray | int) -> tuple[np.ndarray, ...]:
        """Patch coordinates ``(px, py)`` or ``(px, py, pz)`` of flat indices."""
        index = np.unravel_index(flat, self.grid_shape)  # (iy, ix) or (iz, iy, ix)
        return tuple(i - self.radius for i in reversed(index))

    def flat_of(self, *coords: np.ndarray | int) -> np.ndarray | int:
        """Flat index of patch coordinates ``px, py[, pz]`` (no bounds check)."""
        flat: np.ndarray | int = 0
        for c in reversed(coords):
            flat = flat * self.size + (c + self.radius)
        return flat

    def flat_index(self, px: np.ndarray | int, py: np.ndarray | int) -> np.ndarray | int:
        """Flat patch index of 2D patch coordinates (no bounds check): :meth:`flat_of` with two axes."""
        return self.flat_of(px, py)

    def patch_xy(self, flat: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """Patch coordinates ``(px, py)`` of a 2D world's flat patch indices: :meth:`patch_coords`."""
        px, py = self.patch_coords(flat)
        return px, py

    def patch_of(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Patch coordinates of continuous positions (nearest patch centre)."""
        return np.floor(x + 0.5).astype(np.int64), np.floor(y + 0.5).astype(np.int64)
