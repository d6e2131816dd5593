"""Three-dimensional shape files: layered text grids and triangle meshes, and a voxel shape's topology.

*Layered text grid* (``.txt``): the 2D text grid (:mod:`swarm_ros.core.shapes`), one grid per
z layer, the layers separated by a line of dashes (``---``), the top layer (highest z)
first, as rows go top row first. Every layer has the same rows and columns.

*Triangle mesh* (``.stl``, ``.obj``, ``.ply``): read and voxelized by ``trimesh``. The mesh
must be closed (watertight); it is scaled by ``mesh_scale`` voxels per mesh unit (1: one
mesh unit is one voxel), its surface is voxelized at one voxel (every voxel a point of the
subdivided surface falls in) and the inside filled. The voxel grid then goes to the world
by the same centring rule as a text grid.

Grids here are ``(layers, rows, cols)`` arrays, top layer and top row first.
"""

from __future__ import annotations

import io
import itertools
from pathlib import Path

import numpy as np

from swarm_ros.core.errors import ShapeError
from swarm_ros.core.inputs import MESH_LIMIT, read_bounded

LAYER_SEPARATOR = "-"  #: a line of these (at least three) ends one z layer of a layered text grid
MESH_SUFFIXES = (".stl", ".obj", ".ply")
#: A mesh whose box at its scale is wider than this many voxels is refused before it is voxelized
#: (the largest world that fits this machine's memory is far smaller).
MAX_MESH_VOXELS = 4096


def is_separator(line: str) -> bool:
    return len(line) >= 3 and set(line) == {LAYER_SEPARATOR}


def split_layers(rows: list[tuple[int, str]]) -> list[list[tuple[int, str]]]:
    """Numbered grid lines split at separator lines (one list per layer, separators dropped)."""
    layers: list[list[tuple[int, str]]] = [[]]
    for number, line in rows:
        if is_separator(line):
            layers.append([])
        else:
            layers[-1].append((number, line))
    return layers


def stack_layers(path: Path, layers: list[np.ndarray]) -> np.ndarray:
    """Layer grids (top first) as one ``(layers, rows, cols)`` grid.

    Raises:
        ShapeError: a layer's size differs from the first's.
    """
    first = layers[0].shape
    for k, layer in enumerate(layers[1:], start=2):
        if layer.shape != first:
            raise ShapeError(
                f"{path}: layer {k} is {layer.shape[1]} x {layer.shape[0]}, the first layer is "
                f"{first[1]} x {first[0]} (columns x rows)"
            )
    return np.stack(layers)


def read_mesh(path: Path, scale: float) -> np.ndarray:
    """Voxelize a closed triangle mesh at ``scale`` voxels per mesh unit into a filled ``(layers, rows, cols)`` grid.

    Raises:
        ShapeError: an unreadable mesh, an open one, or one far too large at this scale.
    """
    import trimesh  # only a mesh needs it

    data = read_bounded(path, MESH_LIMIT, "mesh", ShapeError)
    try:
        mesh = trimesh.load(io.BytesIO(data), file_type=path.suffix.lower().lstrip("."), force="mesh", process=True)
    except Exception as exc:  # trimesh raises many kinds on a corrupt file
        raise ShapeError(f"{path}: cannot read the mesh ({type(exc).__name__}: {exc})".splitlines()[0]) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ShapeError(f"{path}: the mesh has no triangles")
    if not mesh.is_watertight:
        open_edges = len(trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1))
        raise ShapeError(
            f"{path}: the mesh does not close ({open_edges} edges belong to one triangle only); "
            "a shape needs a closed surface to have an inside"
        )
    extent = mesh.extents * scale
    if not np.all(np.isfinite(extent)) or extent.max() > MAX_MESH_VOXELS:
        raise ShapeError(
            f"{path}: at mesh_scale {scale:g} the mesh is {extent.max():.0f} voxels wide; "
            f"lower mesh_scale so that it fits the world"
        )
    mesh.apply_scale(scale)
    voxels = mesh.voxelized(pitch=1.0).fill()
    matrix = np.asarray(voxels.matrix, dtype=bool)  # [ix, iy, iz], low corner first
    if not matrix.any():
        raise ShapeError(f"{path}: at mesh_scale {scale:g} the mesh fills no voxel; raise mesh_scale")
    return np.ascontiguousarray(matrix.transpose(2, 1, 0)[::-1, ::-1, :])


def euler_characteristic(mask: np.ndarray) -> int:
    """Euler characteristic of the union of a grid's set cells, each a closed unit square (cube).

    Counts the union's vertices, edges, faces and cubes: a cell of the complex is present when
    any set cell touches it. Closed cells make cells that share only a corner connected, which
    is the 8- (26-) connectivity growth uses.
    """
    padded = np.pad(np.asarray(mask, dtype=bool), 1)
    chi = 0
    for spans in itertools.product((False, True), repeat=padded.ndim):
        cells = padded
        for axis, span in enumerate(spans):
            if not span:  # a lattice point between two cells along this axis: either cell touches it
                lo = [slice(None)] * padded.ndim
                hi = [slice(None)] * padded.ndim
                lo[axis], hi[axis] = slice(0, -1), slice(1, None)
                cells = cells[tuple(lo)] | cells[tuple(hi)]
        chi += (-1) ** sum(spans) * int(np.count_nonzero(cells))
    return chi
