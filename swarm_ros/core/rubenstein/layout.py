"""Where a Kilobot run starts: the shape in the seeds' frame, the four seeds, and the packed start.

Lengths are in robot diameters d (a robot is a disc of diameter 1). The frame is the seeds': the
origin is the centre of the rhombus of the four touching seeds, the root seed at (-1/2, 0), the
others at (1/2, 0) and (0, +-sqrt(3)/2).

* **The shape** is the shape's bitmap (any of the package's 2D shapes, a user's grid or PNG) with a
  pixel of side ``pixel_size``. It is placed with its lowest pixel row resting on the x axis (its
  bottom edge at y = 0) and the left edge of that row's leftmost set pixel at x = -1, so the seeds
  stand at the shape's lower-left corner: the upper seed inside it, the root and its partner on its
  lower edge. A point is inside the shape when the pixel it falls in is set.
* **The start** is a touching hexagonal pack (spacing 1) below and left of the seeds, on the seeds'
  own lattice: the lattice points at y <= -sqrt(3) (the rows below the lowest seed) and x <= 0,
  nearest the lowest seed first (ties: higher rows, then larger x), as many as there are robots
  besides the seeds. The pack is connected to the seeds, every robot in it is at least sqrt(3) > 1.5
  from any point of the shape (which lies at y >= 0), and no part of the shape's lowest row hangs over
  it: robots that join along that row's lower edge would otherwise wall in the lane the
  edge-followers take along the pack's top (docs/model.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from swarm_ros.core.errors import ParameterError
from swarm_ros.core.shapes import Shape, regions

if TYPE_CHECKING:
    from swarm_ros.core.params import RunParams

H = math.sqrt(3.0) / 2.0  #: the height of a row of the touching hexagonal lattice
#: the seeds, root first
SEEDS = np.array([[-0.5, 0.0], [0.5, 0.0], [0.0, H], [0.0, -H]])
LEFT = -1.0  #: the x of the left edge of the shape's lowest row
SEED_G = np.array([0, 1, 1, 1], dtype=np.int64)  #: the root's gradient is 0, the others' 1


@dataclass(frozen=True)
class ShapeFrame:
    """A shape's bitmap in the seeds' frame.

    Attributes:
        mask: ``mask[row, col]``, row 0 at the bottom; True where the pixel is set.
        pixel: the pixel's side, in d.
        x0, y0: the frame position of the bitmap's lower-left corner.
    """

    mask: np.ndarray
    pixel: float
    x0: float
    y0: float

    @staticmethod
    def of(shape: Shape, pixel: float) -> ShapeFrame:
        """The 2D ``shape``'s bitmap, trimmed to its set pixels, placed as the module says."""
        check_shape(shape)
        rows = np.flatnonzero(shape.mask.any(axis=1))
        cols = np.flatnonzero(shape.mask.any(axis=0))
        mask = shape.mask[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1].copy()  # row 0 the bottom
        mask.setflags(write=False)
        left = int(np.flatnonzero(mask[0])[0])  # the lowest row's leftmost set pixel
        return ShapeFrame(mask=mask, pixel=float(pixel), x0=LEFT - left * pixel, y0=0.0)

    @property
    def pixels(self) -> int:
        return int(np.count_nonzero(self.mask))

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the bitmap in the frame."""
        rows, cols = self.mask.shape
        return self.x0, self.y0, self.x0 + cols * self.pixel, self.y0 + rows * self.pixel

    @property
    def holes(self) -> np.ndarray:
        """``holes[row, col]``: True where the pixel lies in one of the shape's holes, a 4-connected region of
        unset pixels that does not reach the trimmed bitmap's border (as the shape's own count of holes)."""
        labels, _ = regions(~self.mask, connectivity=4)
        outer = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
        return (labels > 0) & ~np.isin(labels, outer)

    def inside(self, x: np.ndarray, y: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
        """Whether each point falls in a set pixel of ``where`` (a mask of the bitmap's size; by default the
        shape's own)."""
        where = self.mask if where is None else where
        col = np.floor((np.asarray(x) - self.x0) / self.pixel).astype(np.int64)
        row = np.floor((np.asarray(y) - self.y0) / self.pixel).astype(np.int64)
        rows, cols = self.mask.shape
        ok = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
        out = np.zeros(np.shape(x), dtype=bool)
        out[ok] = where[row[ok], col[ok]]
        return out


def start_positions(robots: int) -> np.ndarray:
    """The start positions of ``robots`` robots, seeds first (``SEEDS``), then the pack, as the module says:
    a ``(robots, 2)`` array."""
    others = robots - len(SEEDS)
    if others < 0:
        raise ParameterError(f"robots must be at least {len(SEEDS)} (the seeds), got {robots}")
    # lattice points (-1/2 + a + b/2, b H) with rows b <= -2; enough rows and columns for a quarter disc
    reach = int(math.ceil(math.sqrt(4.0 * others / math.pi / H))) + 3
    b = np.arange(-2, -2 - reach, -1)
    a = np.arange(-2 * reach, 2 * reach + 1)
    bb, aa = np.meshgrid(b, a, indexing="ij")
    x = (-0.5 + aa + bb / 2.0).ravel()
    y = (bb * H).ravel()
    west = x <= 0.0
    x, y = x[west], y[west]
    d2 = x * x + (y + H) ** 2  # from the lowest seed
    order = np.lexsort((-x, -y, np.round(d2, 9)))[:others]
    return np.concatenate([SEEDS, np.stack([x[order], y[order]], axis=1)])


def check_params(p: RunParams) -> None:
    """The rubenstein algorithm's lengths: d < DESIRED < G < sqrt(3) d, so that the gradient counts the rings of
    a touching hexagonal pack; G and YIELD within the communication range.

    Raises:
        ParameterError: in one line.
    """
    if not p.desired_distance < p.gradient_range < math.sqrt(3.0):
        raise ParameterError(
            "the rubenstein algorithm needs 1 < desired_distance < gradient_range < sqrt(3) (robot diameters), "
            f"got desired_distance {p.desired_distance:g} and gradient_range {p.gradient_range:g}"
        )
    if p.comm_range < 1.0 + p.step_length:  # the world checks a step against the robots within C
        raise ParameterError(
            f"comm_range must be at least 1 + step_length ({1.0 + p.step_length:g}), got {p.comm_range:g}"
        )
    for name in ("gradient_range", "yield_distance"):
        if getattr(p, name) >= p.comm_range:
            raise ParameterError(f"{name} must be below comm_range ({p.comm_range:g}), got {getattr(p, name):g}")


def check_shape_of(_params: RunParams, shape: Shape) -> None:
    """:func:`check_shape`, as core.algorithm's part ``check_shape`` (whatever the parameters)."""
    check_shape(shape)


def check_shape(shape: Shape) -> None:
    """Refuse a shape the algorithm cannot take (a 3D one), in one line.

    Raises:
        ParameterError: the shape is not 2D.
    """
    if shape.dims != 2:
        raise ParameterError(f"{shape.source}: the rubenstein algorithm forms 2D shapes only")
