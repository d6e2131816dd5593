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

Three dimensions
----------------
A layered text grid or a triangle mesh (:mod:`swarm_ros.core.voxels`) is a 3D shape: it
is placed in a cubic world of the same radius, by the same centring rule along z (layer
``l`` of ``d`` goes to ``z = (d - 1 - l) - (d - 1) // 2``), must be one 26-connected
component and hold a seed corner: a voxel and its +x, +y and +z neighbours.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cc3d
import numpy as np

from swarm_ros.core.errors import ParameterError, ShapeError
from swarm_ros.core.grid import World
from swarm_ros.core.inputs import SHAPE_LIMIT, read_bounded, shown
from swarm_ros.core.resources import check_world_memory, data_dir
from swarm_ros.core.voxels import (
    LAYER_SEPARATOR,
    MESH_SUFFIXES,
    euler_characteristic,
    is_separator,
    read_mesh,
    split_layers,
    stack_layers,
)

#: Growth's and the empty space's connectivity in a grid of each dimension: (shape, empty).
CONNECTIVITY = {2: (8, 4), 3: (26, 6)}


def regions(mask: np.ndarray, connectivity: int) -> tuple[np.ndarray, int]:
    """The connected regions of a 2-D or 3-D bool grid: labels (0 where unset, 1..n) and n.

    ``connectivity`` is 4 (edge neighbours) or 8 (and corners); in 3D 6, 18 or 26. Computed by
    ``cc3d``, which imports in milliseconds where ``scipy.ndimage`` costs every node process 0.3 s of CPU.
    """
    # a uint8 copy: cc3d refuses read-only buffers, and 4.1.1 mislabels bool grids with connectivity 8
    writable = np.array(mask, dtype=np.uint8, order="C")
    labels, count = cc3d.connected_components(
        writable,
        connectivity=connectivity,  # type: ignore[call-overload]
        return_N=True,
    )  # (cc3d's stubs know a bool grid only)
    return labels, int(count)


SHAPE_CHAR = "#"
EMPTY_CHAR = "."
COMMENT_CHAR = ";"


def builtin_shapes() -> dict[str, Path]:
    """Built-in 2D shape names mapped to their text files, sorted by name."""
    return {p.stem: p for p in sorted(data_dir("shapes").glob("*.txt"))}


def builtin_shapes_3d() -> dict[str, Path]:
    """Built-in 3D shape names mapped to their layered text files (``shapes/3d``), sorted by name."""
    return {p.stem: p for p in sorted((data_dir("shapes") / "3d").glob("*.txt"))}


def read_text_grid(path: Path) -> np.ndarray:
    """Read a text grid into a boolean ``(rows, cols)`` array, top row first; a layered text grid
    (:mod:`swarm_ros.core.voxels`) into ``(layers, rows, cols)``, top layer first.

    Raises:
        ShapeError: unreadable file, stray characters, ragged or missing rows.
    """
    data = read_bounded(path, SHAPE_LIMIT, "shape file", ShapeError)
    try:
        text = data.decode("utf-8-sig")  # a byte-order mark (as some Windows editors write) is fine
    except UnicodeDecodeError:
        raise ShapeError(f"{path}: not a text shape grid (not UTF-8 text)") from None
    rows: list[tuple[int, str]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.rstrip()
        if line.startswith(COMMENT_CHAR):
            continue
        rows.append((number, line))
    if any(is_separator(line) for _, line in rows):
        return stack_layers(path, [_grid_rows(path, layer) for layer in split_layers(rows)])
    return _grid_rows(path, rows)


def _grid_rows(path: Path, rows: list[tuple[int, str]]) -> np.ndarray:
    """One grid from its numbered lines (comments removed): ``(rows, cols)``, top row first."""
    rows = list(rows)
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
    import io
    import warnings

    from PIL import Image, UnidentifiedImageError

    data = read_bounded(path, SHAPE_LIMIT, "shape file", ShapeError)
    # Pillow's own bound against decompression bombs (it warns above it, refuses twice it): refused here in our
    # words, before Pillow says anything
    most = Image.MAX_IMAGE_PIXELS or 0
    too_large = (
        f"{path}: the image has more than {most:,} pixels{{}}, the most a shape image may "
        f"have (Pillow's bound against decompression bombs)"
    )
    try:
        with warnings.catch_warnings():  # Pillow warns of a large image in its own words; it is refused below
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            image = Image.open(io.BytesIO(data))  # reads the header only
        with image:
            width, height = image.size
            if width * height > most:
                raise ShapeError(too_large.format(f" ({width} x {height})"))
            image.load()
            la = np.asarray(image.convert("LA"))
    except Image.DecompressionBombError:  # Pillow refuses twice its bound at open
        raise ShapeError(too_large.format("")) from None
    except OSError as exc:
        reason = "not a readable image" if isinstance(exc, UnidentifiedImageError) else (exc.strerror or str(exc))
        raise ShapeError(f"{path}: cannot read shape image ({reason})") from None
    return (la[..., 0] < 128) & (la[..., 1] >= 128)


def write_text_grid(grid: np.ndarray, path: Path, comments: list[str] | tuple[str, ...] = ()) -> None:
    """Write a boolean ``(rows, cols)`` grid (top row first) as a text shape file, or a
    ``(layers, rows, cols)`` one (top layer first) as a layered text grid."""
    lines = [f"{COMMENT_CHAR} {c}" for c in comments]
    layers = grid if grid.ndim == 3 else [grid]
    for k, layer in enumerate(layers):
        if k:
            lines.append(LAYER_SEPARATOR * 3)
        lines += ["".join(SHAPE_CHAR if v else EMPTY_CHAR for v in row) for row in layer]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def read_grid(path: Path, mesh_scale: float = 1.0) -> np.ndarray:
    """Read a shape file by its extension: ``.png`` as an image, ``.stl``, ``.obj`` and ``.ply`` as
    a mesh voxelized at ``mesh_scale`` voxels per mesh unit, anything else as a text grid."""
    if path.is_dir():
        raise ShapeError(
            f"{path}: is a directory, not a shape file (a .txt grid or a .png image) nor a mesh (.stl, .obj, .ply)"
        )
    suffix = path.suffix.lower()
    if suffix == ".png":
        return read_png_grid(path)
    if suffix in MESH_SUFFIXES:
        return read_mesh(path, mesh_scale)
    return read_text_grid(path)


def upscaled(grid: np.ndarray, scale: int, source: str) -> np.ndarray:
    """A 2D shape grid ``scale`` times larger each way, every pixel a ``scale`` x ``scale`` block (ShapeError: 3D)."""
    if grid.ndim != 2:
        raise ShapeError(f"{source}: shape_scale applies to 2D shapes only, got {scale} for a 3D grid")
    return np.repeat(np.repeat(grid, scale, axis=0), scale, axis=1)


@dataclass(frozen=True, eq=False)
class Shape:
    """A validated shape placed in a world.

    Attributes:
        name: short name (built-in name or the file's stem).
        mask: boolean ``(W, W)`` world grid, ``mask[iy, ix]`` (3D: ``(W, W, W)``, ``mask[iz, iy, ix]``);
            True on shape patches.
        world: the world the shape is placed in.
        source: where it came from (a file path, or a description).
        mesh_scale: voxels per mesh unit it was voxelized at (1 for every shape not read from a mesh).
        scale: the integer upscale of a 2D shape's grid it was read at (``shape_scale``: each pixel a
            ``scale`` x ``scale`` block), 1 for none.
    """

    name: str
    mask: np.ndarray
    world: World
    source: str
    mesh_scale: float = 1.0
    scale: int = 1
    seed_patches: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        mask = np.asarray(self.mask, dtype=bool)
        if mask.shape != self.world.grid_shape:
            raise ShapeError(f"{self.source}: mask is {mask.shape}, the world needs {self.world.grid_shape}")
        mask = mask.copy()
        mask.setflags(write=False)
        object.__setattr__(self, "mask", mask)
        self._validate()
        object.__setattr__(self, "seed_patches", self._find_seed_block())

    # -- construction -----------------------------------------------------------
    @classmethod
    def from_grid(
        cls, grid: np.ndarray, world: World, name: str, source: str, mesh_scale: float = 1.0, scale: int = 1
    ) -> Shape:
        """Place a file grid (top row first; a 3D grid top layer first) in a world of ``world``'s radius
        and the grid's dimensions, by the centring rule, and validate it (``scale``: the upscale it was read at)."""
        grid = np.asarray(grid, dtype=bool)
        if grid.ndim not in (2, 3) or grid.size == 0 or not grid.any():
            raise ShapeError(f"{source}: empty shape (no shape patches)")
        world = World(world.radius, grid.ndim)
        if world.dims == 3:  # the cube may not fit in memory where the square did (checked before this)
            check_world_memory(world.radius, dims=3)
        r = world.radius
        index = np.nonzero(grid)  # (rows, cols) or (layers, rows, cols)
        coords = [index[-1] - (grid.shape[-1] - 1) // 2]  # x from the column
        for axis in range(grid.ndim - 2, -1, -1):  # y from the row, z from the layer: the first one is the top
            n = grid.shape[axis]
            coords.append((n - 1 - index[axis]) - (n - 1) // 2)
        beyond = np.zeros(coords[0].size, dtype=bool)
        for c in coords:
            beyond |= np.abs(c) > r
        if beyond.any():
            k = int(np.argmax(beyond))
            at = ", ".join(str(c[k]) for c in coords)
            size = " x ".join(str(n) for n in reversed(grid.shape))
            holds = max(int(np.abs(c).max()) for c in coords) + 2  # off the two outer layers (_validate)
            scaled = f" at shape_scale {scale} (--world-radius {holds} or more holds it)" if scale > 1 else ""
            raise ShapeError(
                f"{source}: shape reaches beyond the walls of the {world.describe()} world "
                f"at patch ({at}); the grid is {size}{scaled}"
            )
        mask = np.zeros(world.grid_shape, dtype=bool)
        mask[tuple(c + r for c in reversed(coords))] = True
        return cls(name=name, mask=mask, world=world, source=source, mesh_scale=mesh_scale, scale=scale)

    @classmethod
    def load(
        cls, name_or_path: str | Path, world: World | None = None, mesh_scale: float = 1.0, scale: int = 1
    ) -> Shape:
        """Load a built-in shape by name, or a shape file (text grid, PNG, layered text grid or mesh) by path.

        ``world`` gives the radius; a 3D shape goes into a cubic world of that radius.
        ``mesh_scale`` (voxels per mesh unit) applies to meshes only; ``scale`` (``shape_scale``: an integer
        upscale, each pixel a ``scale`` x ``scale`` block) to 2D shapes only.

        Raises:
            ShapeError: unknown name, unreadable file or invalid shape; the message names the file.
        """
        world = world or World()
        text = str(name_or_path)
        flat, solid = builtin_shapes(), builtin_shapes_3d()
        known = f"built-in: {', '.join(flat)}) or built-in 3D shape ({', '.join(solid)}"
        if not text.strip():
            raise ShapeError(f"the shape name is empty ({known}; or a .txt / .png file or a mesh)")
        if mesh_scale != 1.0 and Path(text).suffix.lower() not in MESH_SUFFIXES:
            raise ShapeError(f"{text}: mesh_scale applies to mesh shapes (.stl, .obj, .ply) only, got {mesh_scale:g}")
        if scale != 1 and Path(text).suffix.lower() in MESH_SUFFIXES:
            raise ShapeError(
                f"{text}: shape_scale applies to 2D shapes only, got {scale}; a mesh scales with --mesh-scale"
            )
        builtins = {**flat, **solid}
        if text in builtins:
            path = builtins[text]
            name = text
        else:
            path = Path(text)
            name = path.stem
            try:
                path.stat()
            except FileNotFoundError:
                raise ShapeError(f"{text}: no such shape file or built-in shape ({known})") from None
            except OSError as exc:  # a name too long, a folder on the way not readable, ...
                raise ShapeError(f"{shown(text)}: cannot read shape file ({exc.strerror or exc})") from None
        grid = read_grid(path, mesh_scale)
        if scale != 1:
            grid = upscaled(grid, scale, text)
        try:
            return cls.from_grid(grid, world, name=name, source=str(path), mesh_scale=mesh_scale, scale=scale)
        except ShapeError as exc:
            if path.suffix.lower() not in MESH_SUFFIXES:
                raise
            # a mesh's voxels depend on its scale: say which one, since another may fix it
            raise ShapeError(f"{exc} (at mesh_scale {mesh_scale:g}; --mesh-scale sets another)") from None

    # -- properties -------------------------------------------------------------
    @property
    def label(self) -> str:
        """Its name, with the upscale it was read at if any (``star-x3``): what a default run directory is named by."""
        return self.name if self.scale == 1 else f"{self.name}-x{self.scale}"

    @property
    def patches(self) -> int:
        """Number of shape patches."""
        return int(np.count_nonzero(self.mask))

    @property
    def dims(self) -> int:
        return self.world.dims

    @property
    def bbox(self) -> tuple[int, ...]:
        """Bounding box ``(xmin, ymin, xmax, ymax)`` in patch coordinates
        (3D: ``(xmin, ymin, zmin, xmax, ymax, zmax)``)."""
        coords = self.world.patch_coords(np.flatnonzero(self.mask))
        return (*(int(c.min()) for c in coords), *(int(c.max()) for c in coords))

    @property
    def cavities(self) -> int:
        """Regions of non-shape patches enclosed by the shape (4-connected; 3D: 6-connected): a 2D
        shape's holes, a 3D shape's closed cavities."""
        labels, count = regions(~self.mask, connectivity=CONNECTIVITY[self.dims][1])
        border = np.unique(
            np.concatenate(
                [np.moveaxis(labels, axis, 0)[end].ravel() for axis in range(labels.ndim) for end in (0, -1)]
            )
        )
        return int(count - np.count_nonzero(border))

    @property
    def tunnels(self) -> int:
        """Tunnels through a 3D shape (a torus has 1): the shape's first Betti number, from its Euler
        characteristic, ``1 + cavities - chi`` (one component). A 2D shape's holes are its cavities: 0."""
        if self.dims == 2:
            return 0
        return 1 + self.cavities - euler_characteristic(self.mask)

    @property
    def holes(self) -> int:
        """Number of holes: 4-connected regions of non-shape patches enclosed by the shape; in 3D,
        tunnels plus cavities."""
        return self.cavities + self.tunnels

    @property
    def free_patches(self) -> int:
        """Patches a robot may stand on at the start: every non-wall patch."""
        return (self.world.size - 2) ** self.dims

    def check_room(self, robots: int) -> None:
        """Refuse more robots than this shape's world holds: one a free patch, under every algorithm (the bound of
        a run's group size, here only; docs/model.md, "Group sizes").

        Raises:
            ParameterError: ``robots`` > :attr:`free_patches`, in one line without the shape's name (the caller
            says where the count came from).
        """
        if robots > self.free_patches:
            raise ParameterError(
                f"{robots} robots do not fit on the {self.free_patches} free patches of the {self.world.describe()} "
                "world"
            )

    # -- validation -------------------------------------------------------------
    def _validate(self) -> None:
        src, mask, world = self.source, self.mask, self.world
        if not mask.any():
            raise ShapeError(f"{src}: empty shape (no shape patches)")
        inner = np.zeros_like(mask)
        inner[(slice(2, -2),) * world.dims] = True
        touching = mask & ~inner
        if touching.any():
            at = world.patch_coords(int(np.flatnonzero(touching)[0]))
            axes = ", ".join(f"|{a}|" for a in "xyz"[: world.dims])
            raise ShapeError(
                f"{src}: shape touches the wall of the {world.describe()} world at patch "
                f"({', '.join(str(int(c)) for c in at)}); keep shape patches within {axes} <= {world.radius - 2}"
            )
        connectivity = CONNECTIVITY[world.dims][0]
        count = regions(mask, connectivity=connectivity)[1]
        if count > 1:
            raise ShapeError(
                f"{src}: shape has {count} separate parts ({connectivity}-connected); growth from the seeds "
                "can only fill one connected part"
            )

    def _find_seed_block(self) -> np.ndarray:
        if self.dims == 3:
            return self._find_seed_corner()
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

    def _find_seed_corner(self) -> np.ndarray:
        """3D seeds: a voxel and its +x, +y and +z neighbours, the four points that fix a 3D frame (an origin
        and three axes; a flat 2 x 2 block would not), with the corner's centroid nearest the origin,
        ties to lower z, then y, then x."""
        m = self.mask
        corner = m[:-1, :-1, :-1] & m[:-1, :-1, 1:] & m[:-1, 1:, :-1] & m[1:, :-1, :-1]
        iz, iy, ix = np.nonzero(corner)
        if iz.size == 0:
            raise ShapeError(
                f"{self.source}: shape has no corner of four voxels (a voxel and its +x, +y and +z "
                "neighbours) for the four seed robots"
            )
        r = self.world.radius
        px, py, pz = ix - r, iy - r, iz - r
        d2 = (4 * px + 1) ** 2 + (4 * py + 1) ** 2 + (4 * pz + 1) ** 2  # centroid (p + 1/4) in quarters
        k = np.lexsort((px, py, pz, d2))[0]
        x0, y0, z0 = int(px[k]), int(py[k]), int(pz[k])
        return np.array([[x0, y0, z0], [x0 + 1, y0, z0], [x0, y0 + 1, z0], [x0, y0, z0 + 1]], dtype=np.int64)
