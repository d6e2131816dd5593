"""Shapes: loading from text grids and PNG images, placing them in the world, validation.

File formats
------------
*Text grid* (any extension but ``.png``): one line per row of patches, top row first;
``#`` is a shape patch, ``.`` is not. Lines starting with ``;`` are comments. All rows
have the same length. *PNG image*: one pixel per patch, top row first; a pixel is a
shape patch when it is dark (luminance < 128) and not transparent (alpha >= 128).

Centring
--------
The centre of the file's grid (not of the shape's bounding box) lands on the world's
origin, so padding a file with ``.`` moves the shape. Column ``c`` of a ``w``-wide grid
goes to ``x = c - (w - 1) // 2``; row ``r`` of an ``h``-high grid goes to
``y = (h - 1 - r) - (h - 1) // 2``. An even-sized grid has its extra column on the right
and its extra row at the top.

Validity
--------
A shape must be non-empty, lie inside the world with at least one free patch between
it and the wall ring (so robots can go round it), be one 8-connected component (growth
spreads to the 8 neighbours of localized robots, so a second component could never be
reached), and hold a 2 x 2 block for the four seed robots.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cc3d
import numpy as np

from swarm_ros.core.errors import ShapeError
from swarm_ros.core.grid import World
from swarm_ros.core.resources import data_dir


def regions(mask: np.ndarray, connectivity: int) -> tuple[np.ndarray, int]:
    """The connected regions of a 2-D bool grid: labels (0 where unset, 1..n) and n.

    ``connectivity`` is 4 (edge neighbours) or 8 (and corners). Computed by ``cc3d``, which
    imports in milliseconds where ``scipy.ndimage`` costs every node process 0.3 s of CPU.
    """
    # a uint8 copy: cc3d refuses read-only buffers, and 4.1.1 mislabels bool grids with connectivity 8
    writable = np.array(mask, dtype=np.uint8, order="C")
    labels, count = cc3d.connected_components(writable, connectivity=connectivity, return_N=True)
    return labels, int(count)


SHAPE_CHAR = "#"
EMPTY_CHAR = "."
COMMENT_CHAR = ";"


def builtin_shapes() -> dict[str, Path]:
    """Built-in shape names mapped to their text files, sorted by name."""
    return {p.stem: p for p in sorted(data_dir("shapes").glob("*.txt"))}


def read_text_grid(path: Path) -> np.ndarray:
    """Read a text grid into a boolean ``(rows, cols)`` array, top row first.

    Raises:
        ShapeError: unreadable file, stray characters, ragged or missing rows.
    """
    try:
        text = path.read_bytes().decode("utf-8-sig")  # a byte-order mark (as some Windows editors write) is fine
    except OSError as exc:
        raise ShapeError(f"{path}: cannot read shape file ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise ShapeError(f"{path}: not a text shape grid (not UTF-8 text)") from None
    rows: list[tuple[int, str]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.rstrip()
        if line.startswith(COMMENT_CHAR):
            continue
        rows.append((number, line))
    while rows and not rows[0][1]:
        rows.pop(0)
    while rows and not rows[-1][1]:
        rows.pop()
    if not rows:
        raise ShapeError(f"{path}: empty shape file (no grid rows)")
    width = len(rows[0][1])
    for number, line in rows:
        if not line:
            raise ShapeError(f"{path}:{number}: blank line inside the grid")
        bad = next((c for c in line if c not in (SHAPE_CHAR, EMPTY_CHAR)), None)
        if bad is not None:
            col = line.index(bad) + 1
            raise ShapeError(
                f"{path}:{number}:{col}: unexpected character {bad!r} "
                f"(use '{SHAPE_CHAR}' for shape, '{EMPTY_CHAR}' for free, '{COMMENT_CHAR}' for comments)"
            )
        if len(line) != width:
            raise ShapeError(f"{path}:{number}: row has {len(line)} columns, the first row has {width}")
    return np.array([[c == SHAPE_CHAR for c in line] for _, line in rows], dtype=bool)


def read_png_grid(path: Path) -> np.ndarray:
    """Read a PNG image into a boolean ``(rows, cols)`` array: dark, opaque pixels are shape.

    Raises:
        ShapeError: the file is missing or not a readable image.
    """
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            image.load()
            la = np.asarray(image.convert("LA"))
    except OSError as exc:
        reason = "not a readable image" if isinstance(exc, UnidentifiedImageError) else (exc.strerror or str(exc))
        raise ShapeError(f"{path}: cannot read shape image ({reason})") from None
    return (la[..., 0] < 128) & (la[..., 1] >= 128)


def write_text_grid(grid: np.ndarray, path: Path, comments: list[str] | tuple[str, ...] = ()) -> None:
    """Write a boolean ``(rows, cols)`` grid (top row first) as a text shape file."""
    lines = [f"{COMMENT_CHAR} {c}" for c in comments]
    lines += ["".join(SHAPE_CHAR if v else EMPTY_CHAR for v in row) for row in grid]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def read_grid(path: Path) -> np.ndarray:
    """Read a shape file by its extension: ``.png`` as an image, anything else as a text grid."""
    if path.is_dir():
        raise ShapeError(f"{path}: is a directory, not a shape file (a .txt grid or a .png image)")
    if not path.is_file():
        raise ShapeError(f"{path}: no such shape file")
    if path.suffix.lower() == ".png":
        return read_png_grid(path)
    return read_text_grid(path)


@dataclass(frozen=True, eq=False)
class Shape:
    """A validated shape placed in a world.

    Attributes:
        name: short name (built-in name or the file's stem).
        mask: boolean ``(W, W)`` world grid, ``mask[iy, ix]``; True on shape patches.
        world: the world the shape is placed in.
        source: where it came from (a file path, or a description).
    """

    name: str
    mask: np.ndarray
    world: World
    source: str
    seed_patches: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        mask = np.asarray(self.mask, dtype=bool)
        size = self.world.size
        if mask.shape != (size, size):
            raise ShapeError(f"{self.source}: mask is {mask.shape}, the world needs {(size, size)}")
        mask = mask.copy()
        mask.setflags(write=False)
        object.__setattr__(self, "mask", mask)
        self._validate()
        object.__setattr__(self, "seed_patches", self._find_seed_block())

    # -- construction -----------------------------------------------------------
    @classmethod
    def from_grid(cls, grid: np.ndarray, world: World, name: str, source: str) -> Shape:
        """Place a file grid (top row first) in ``world`` by the centring rule and validate it."""
        grid = np.asarray(grid, dtype=bool)
        if grid.ndim != 2 or grid.size == 0 or not grid.any():
            raise ShapeError(f"{source}: empty shape (no shape patches)")
        h, w = grid.shape
        rows, cols = np.nonzero(grid)
        xs = cols - (w - 1) // 2
        ys = (h - 1 - rows) - (h - 1) // 2
        r = world.radius
        beyond = (np.abs(xs) > r) | (np.abs(ys) > r)
        if beyond.any():
            k = int(np.argmax(beyond))
            raise ShapeError(
                f"{source}: shape reaches beyond the walls of the {world.size} x {world.size} world "
                f"at patch ({xs[k]}, {ys[k]}); the grid is {w} x {h}"
            )
        mask = np.zeros((world.size, world.size), dtype=bool)
        mask[ys + r, xs + r] = True
        return cls(name=name, mask=mask, world=world, source=source)

    @classmethod
    def load(cls, name_or_path: str | Path, world: World | None = None) -> Shape:
        """Load a built-in shape by name, or a shape file (text grid or PNG) by path.

        Raises:
            ShapeError: unknown name, unreadable file or invalid shape; the message names the file.
        """
        world = world or World()
        text = str(name_or_path)
        builtins = builtin_shapes()
        if not text.strip():
            raise ShapeError(f"the shape name is empty (built-in: {', '.join(builtins)}; or a .txt / .png file)")
        if text in builtins:
            path = builtins[text]
            name = text
        else:
            path = Path(text)
            name = path.stem
            if not path.exists():
                raise ShapeError(
                    f"{text}: no such shape file or built-in shape (built-in: {', '.join(builtins)})"
                )
        return cls.from_grid(read_grid(path), world, name=name, source=str(path))

    # -- properties -------------------------------------------------------------
    @property
    def patches(self) -> int:
        """Number of shape patches."""
        return int(np.count_nonzero(self.mask))

    @property
    def bbox(self) -> tuple[int, int, int, int]:
        """Bounding box ``(xmin, ymin, xmax, ymax)`` in patch coordinates."""
        iy, ix = np.nonzero(self.mask)
        r = self.world.radius
        return int(ix.min() - r), int(iy.min() - r), int(ix.max() - r), int(iy.max() - r)

    @property
    def holes(self) -> int:
        """Number of holes: 4-connected regions of non-shape patches enclosed by the shape."""
        labels, count = regions(~self.mask, connectivity=4)
        border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
        return int(count - np.count_nonzero(border))

    @property
    def free_patches(self) -> int:
        """Patches a robot may stand on at the start: every non-wall patch."""
        return (self.world.size - 2) ** 2

    # -- validation -------------------------------------------------------------
    def _validate(self) -> None:
        src, mask, world = self.source, self.mask, self.world
        if not mask.any():
            raise ShapeError(f"{src}: empty shape (no shape patches)")
        inner = np.zeros_like(mask)
        inner[2:-2, 2:-2] = True
        touching = mask & ~inner
        if touching.any():
            iy, ix = np.argwhere(touching)[0]
            r = world.radius
            raise ShapeError(
                f"{src}: shape touches the wall of the {world.size} x {world.size} world at patch "
                f"({ix - r}, {iy - r}); keep shape patches within |x|, |y| <= {r - 2}"
            )
        count = regions(mask, connectivity=8)[1]
        if count > 1:
            raise ShapeError(
                f"{src}: shape has {count} separate parts (8-connected); growth from the seeds "
                "can only fill one connected part"
            )

    def _find_seed_block(self) -> np.ndarray:
        m = self.mask
        block = m[:-1, :-1] & m[:-1, 1:] & m[1:, :-1] & m[1:, 1:]
        iy, ix = np.nonzero(block)
        if iy.size == 0:
            raise ShapeError(f"{self.source}: shape has no 2 x 2 block of patches for the four seed robots")
        r = self.world.radius
        px, py = ix - r, iy - r
        # Block centre is (px + 0.5, py + 0.5); nearest to the origin, ties to lower y then lower x.
        d2 = (2 * px + 1) ** 2 + (2 * py + 1) ** 2
        k = np.lexsort((px, py, d2))[0]
        x0, y0 = int(px[k]), int(py[k])
        return np.array([[x0, y0], [x0 + 1, y0], [x0, y0 + 1], [x0 + 1, y0 + 1]], dtype=np.int64)
