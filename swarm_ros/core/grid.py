"""The square patch world: coordinates, walls and patch indexing.

Patches have integer coordinates ``(px, py)`` with ``-R <= px, py <= R``; the world
is ``W = 2R + 1`` patches wide. Grids over the world are numpy arrays indexed
``grid[iy, ix]`` with ``ix = px + R`` and ``iy = py + R``, so row 0 is the bottom
(``py = -R``); flat patch indices are ``iy * W + ix``. A continuous position
``(x, y)`` (in patches) is on the patch whose centre is nearest:
``px = floor(x + 0.5)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm_ros.core.errors import ParameterError

DEFAULT_RADIUS = 32
MIN_RADIUS = 3  # a wall ring, the seeds' 2 x 2 block and room to move


@dataclass(frozen=True)
class World:
    """A ``(2R+1) x (2R+1)`` patch grid whose border ring is a wall.

    Attributes:
        radius: R, in patches; patch coordinates run from -R to R.
    """

    radius: int = DEFAULT_RADIUS

    def __post_init__(self) -> None:
        if not isinstance(self.radius, (int, np.integer)) or self.radius < MIN_RADIUS:
            raise ParameterError(f"world_radius must be an integer >= {MIN_RADIUS}, got {self.radius!r}")

    @property
    def size(self) -> int:
        """W, the number of patches along one side."""
        return 2 * self.radius + 1

    @property
    def patch_count(self) -> int:
        return self.size * self.size

    def wall_mask(self) -> np.ndarray:
        """Boolean ``(W, W)`` grid, True on the border ring (patches with < 8 neighbours)."""
        wall = np.zeros((self.size, self.size), dtype=bool)
        wall[0, :] = wall[-1, :] = wall[:, 0] = wall[:, -1] = True
        return wall

    def flat_index(self, px: np.ndarray | int, py: np.ndarray | int) -> np.ndarray | int:
        """Flat patch index of patch coordinates (no bounds check)."""
        return (py + self.radius) * self.size + (px + self.radius)

    def patch_xy(self, flat: np.ndarray | int) -> tuple[np.ndarray, np.ndarray]:
        """Patch coordinates ``(px, py)`` of flat patch indices."""
        iy, ix = np.divmod(flat, self.size)
        return ix - self.radius, iy - self.radius

    def patch_of(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Patch coordinates of continuous positions (nearest patch centre)."""
        return np.floor(x + 0.5).astype(np.int64), np.floor(y + 0.5).astype(np.int64)
