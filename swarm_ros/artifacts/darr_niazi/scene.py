"""What a run's Rerun recording shows: its entities, the classes' names and colours, the viewer's layout.

What is logged, on one timeline ``tick`` (sequence):

``world`` (static)            y-up transform, so the 2D view shows +y upwards
``world/map`` (static)        :class:`rerun.SegmentationImage`: free, wall and shape patches
``world/occupancy``           SegmentationImage of the filled shape patches, logged when it changed
``world/robots``              :class:`rerun.Points2D` of every robot in id order (instance i is
                              robot i), positions in patches, ``class_ids`` = the robot's
                              :class:`~swarm_ros.core.darr_niazi.state.RobotState` code (0-6)
``metrics/<column>``          :class:`rerun.Scalars`, one series per ``metrics.csv`` column, every tick
``events``                    :class:`rerun.TextLog`: the outcome, at the final tick; restarts
``run`` (static)              :class:`rerun.TextDocument`: the run's parameters, rule set included

A 3D run logs the same entities in 3D, shown in a 3D view: ``world/map`` is a static
:class:`rerun.Boxes3D` of the shape's voxels (and one box for the walls' inside), ``world/occupancy``
Boxes3D of the filled voxels, ``world/robots`` :class:`rerun.Points3D`.

One :class:`rerun.AnnotationContext` on ``world`` names and colours the robot states
and the patch classes. Robots (and occupancy) can be logged every k-th tick only
(``every``) for very large runs; the final tick and the metrics are always logged.
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from swarm_ros.core.darr_niazi.metrics import METRIC_COLUMNS
from swarm_ros.core.darr_niazi.state import RobotState
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape

WORLD, MAP, OCCUPANCY, ROBOTS, EVENTS, RUN_INFO = (
    "world",
    "world/map",
    "world/occupancy",
    "world/robots",
    "events",
    "run",
)
METRICS = "metrics"
SERIES: tuple[str, ...] = METRIC_COLUMNS[1:]  #: the logged series (every metrics.csv column but tick)

# Patch classes of the map and occupancy images (robot classes are the RobotState codes 0-6).
FREE, WALL, SHAPE_PATCH, FILLED = 10, 11, 12, 13

# Colour-blind-safe colours (Okabe-Ito), as in final.png.
_ROBOT_CLASSES = {
    RobotState.SEED: ("seed", (213, 94, 0)),
    RobotState.MOVING_OUTSIDE: ("moving outside", (0, 158, 115)),
    RobotState.MOVING_INSIDE: ("moving inside", (240, 228, 66)),
    RobotState.LOCALIZED: ("localized", (0, 114, 178)),
    RobotState.SEPARATED: ("separated", (204, 121, 167)),
    RobotState.REMOVED: ("removed (failed)", (0, 0, 0, 0)),
    RobotState.WALKING: ("walking to the frontier", (230, 159, 0)),
}
_PATCH_CLASSES = {
    FREE: ("free patch", (0, 0, 0, 0)),
    WALL: ("wall", (110, 110, 110, 255)),
    SHAPE_PATCH: ("shape patch", (243, 217, 164, 255)),
    FILLED: ("filled shape patch", (86, 180, 233, 160)),
}
_SERIES_COLOURS = {
    "stationary": (230, 159, 0),
    "localized": (0, 114, 178),
    "inside": (240, 228, 66),
    "moving": (0, 158, 115),
    "empty_patches": (204, 121, 167),
    "walking": (86, 180, 233),
}
_ROBOT_RADIUS = 0.35  # patches


def blueprint(dims: int = 2) -> rrb.Blueprint:
    """The default layout: the world (a 2D or 3D view) beside the convergence plot, the outcome below it."""
    view = rrb.Spatial2DView if dims == 2 else rrb.Spatial3DView
    return rrb.Blueprint(
        rrb.Horizontal(
            view(name="world", origin="/", contents=[f"{WORLD}/**"]),
            rrb.Vertical(
                rrb.TimeSeriesView(name="convergence", origin=METRICS),
                rrb.TextLogView(name="events", origin=EVENTS),
                row_shares=[4, 1],
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def log_scene(rec: rr.RecordingStream, shape: Shape, params: RunParams, every: int) -> None:
    """The recording's static entities: the classes' names and colours, the world's map, the series' styles,
    the run's parameters (``every``: robots are logged every k-th tick)."""
    world = shape.world
    classes = [
        rr.AnnotationInfo(id=int(k), label=label, color=colour)
        for k, (label, colour) in [*_ROBOT_CLASSES.items(), *_PATCH_CLASSES.items()]
    ]
    rec.log(WORLD, rr.AnnotationContext(classes), static=True)
    if world.dims == 3:
        _log_world_3d(rec, shape)
    else:
        _log_world_2d(rec, shape)
    for name in SERIES:
        rec.log(f"{METRICS}/{name}", rr.SeriesLines(names=name, colors=_SERIES_COLOURS[name], widths=1.5), static=True)
    lines = [
        f"# {shape.name}",
        "",
        "| parameter | value |",
        "|---|---|",
        f"| shape patches | {shape.patches} |",
        f"| world | {world.describe()} patches |",
    ]
    lines += [f"| {key} | {value} |" for key, value in params.as_dict().items()]
    lines += [f"| rule set in force | {params.ruleset.label} |"]
    lines += [f"| robots logged | every {every} tick(s) |"]
    rec.log(RUN_INFO, rr.TextDocument("\n".join(lines) + "\n", media_type=rr.MediaType.MARKDOWN), static=True)


def _log_world_3d(rec: rr.RecordingStream, shape: Shape) -> None:
    """The shape's voxels as wire boxes, the walls' inside as one box; filled voxels and robots on top."""
    world = shape.world
    centres = np.stack(world.patch_coords(np.flatnonzero(shape.mask)), axis=1).astype(np.float32)
    rec.log(
        MAP,
        rr.Boxes3D(
            centers=centres,
            half_sizes=[0.5, 0.5, 0.5],
            class_ids=SHAPE_PATCH,
            fill_mode="majorwireframe",
            show_labels=False,
        ),
        static=True,
    )
    rec.log(
        f"{MAP}/walls",
        rr.Boxes3D(centers=[0, 0, 0], half_sizes=[world.radius - 0.5] * 3, class_ids=WALL, show_labels=False),
        static=True,
    )
    rec.log(
        OCCUPANCY,
        rr.Boxes3D.from_fields(half_sizes=[0.45, 0.45, 0.45], class_ids=FILLED, fill_mode="solid", show_labels=False),
        static=True,
    )
    rec.log(ROBOTS, rr.Points3D.from_fields(radii=_ROBOT_RADIUS), static=True)


def _log_world_2d(rec: rr.RecordingStream, shape: Shape) -> None:
    world = shape.world
    # Shown with +y up: the 2D view's y axis points down.
    rec.log(WORLD, rr.Transform3D(mat3x3=[[1, 0, 0], [0, -1, 0], [0, 0, 1]]), static=True)
    # Pixel (ix, iy) of a grid[iy, ix] image covers [ix, ix+1] x [iy, iy+1]; move its centre onto patch (px, py).
    corner = [-world.radius - 0.5, -world.radius - 0.5, 0.0]
    grid = np.full((world.size, world.size), FREE, dtype=np.uint8)
    grid[world.wall_mask()] = WALL
    grid[shape.mask] = SHAPE_PATCH
    for entity in (MAP, OCCUPANCY):
        rec.log(entity, rr.Transform3D(translation=corner), static=True)
    rec.log(MAP, rr.SegmentationImage(grid, draw_order=0.0), static=True)
    rec.log(
        OCCUPANCY,
        rr.SegmentationImage.from_fields(
            format=rr.components.ImageFormat(width=world.size, height=world.size, channel_datatype="U8"), draw_order=1.0
        ),
        static=True,
    )
    rec.log(ROBOTS, rr.Points2D.from_fields(radii=_ROBOT_RADIUS, draw_order=2.0), static=True)
