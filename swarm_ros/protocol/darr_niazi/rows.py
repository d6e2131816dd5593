"""The study's model's rows on the wire (a :class:`~swarm_ros.protocol.darr_niazi.wire.StudyWire`'s), as numpy
record types: a robot's pose and state (world -> batches and monitor), and a decision's claim and pose (batch ->
world), each in a 2D and a 3D layout. Positions are float64 so the graph carries the exact state.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from swarm_ros.core.errors import Rejected

from ..cdr import register_row_types
from ..rows import PATCH_METRES

if TYPE_CHECKING:  # the rules load numba: a reader of rows alone does without it
    from swarm_ros.core.darr_niazi.rules import Decisions

#: World -> everyone, after each tick: the robots whose row changed (all robots at tick 0).
ROBOT_ROW = np.dtype(
    {
        "names": ["x", "y", "z", "heading", "id", "state"],
        "formats": ["<f8", "<f8", "<f8", "<f8", "<u4", "<u1"],
        "offsets": [0, 8, 16, 24, 32, 36],
        "itemsize": 40,
    }
)

#: Robot batch -> world, each tick: what each of its moving robots decided.
#: ``claim`` is the flat index (py + R) * W + (px + R) of the patch claimed, or -1;
#: x, y, heading are the pose the robot takes if it does not join.
DECISION_ROW = np.dtype(
    {
        "names": ["x", "y", "z", "heading", "id", "claim"],
        "formats": ["<f8", "<f8", "<f8", "<f8", "<u4", "<i4"],
        "offsets": [0, 8, 16, 24, 32, 36],
        "itemsize": 40,
    }
)


#: The rows of a 3D world: the same fields and ``pitch``, the heading's elevation (radians, [-pi/2, pi/2]),
#: after ``heading`` (2D rows keep their layout: their z is 0).
ROBOT_ROW_3D = np.dtype(
    {
        "names": ["x", "y", "z", "heading", "pitch", "id", "state"],
        "formats": ["<f8", "<f8", "<f8", "<f8", "<f8", "<u4", "<u1"],
        "offsets": [0, 8, 16, 24, 32, 40, 44],
        "itemsize": 48,
    }
)
#: ``claim`` is the flat index ((pz + R) * W + py + R) * W + px + R of the voxel claimed, or -1.
DECISION_ROW_3D = np.dtype(
    {
        "names": ["x", "y", "z", "heading", "pitch", "id", "claim"],
        "formats": ["<f8", "<f8", "<f8", "<f8", "<f8", "<u4", "<i4"],
        "offsets": [0, 8, 16, 24, 32, 40, 44],
        "itemsize": 48,
    }
)
STUDY_ROW_TYPES = (ROBOT_ROW, DECISION_ROW, ROBOT_ROW_3D, DECISION_ROW_3D)  #: the study's model's row layouts
register_row_types(*STUDY_ROW_TYPES)  # decoded at the speed of every known layout (cdr)


def robot_row(dims: int) -> np.dtype:
    """The robot row layout of a world of ``dims`` dimensions."""
    return ROBOT_ROW if dims == 2 else ROBOT_ROW_3D


def decision_row(dims: int) -> np.dtype:
    """The decision row layout of a world of ``dims`` dimensions."""
    return DECISION_ROW if dims == 2 else DECISION_ROW_3D


def robot_rows(
    ids: np.ndarray,
    state: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    z: np.ndarray | None = None,
    pitch: np.ndarray | None = None,
) -> np.ndarray:
    """Rows of the robots ``ids`` from whole-swarm state arrays (3D rows when ``z`` and ``pitch`` are given)."""
    rows = np.zeros(ids.size, dtype=ROBOT_ROW if z is None else ROBOT_ROW_3D)
    rows["id"] = ids
    rows["state"] = state[ids]
    rows["x"] = x[ids] * PATCH_METRES
    rows["y"] = y[ids] * PATCH_METRES
    rows["heading"] = heading[ids]
    if z is not None and pitch is not None:
        rows["z"] = z[ids] * PATCH_METRES
        rows["pitch"] = pitch[ids]
    return rows


def state_rows(ids: np.ndarray, s) -> np.ndarray:
    """Rows of the robots ``ids`` of a :class:`~swarm_ros.core.darr_niazi.state.SwarmState` (2D or 3D)."""
    return robot_rows(ids, s.state, s.x, s.y, s.heading, s.z, s.pitch)


def pose_of(rows: np.ndarray) -> dict[str, np.ndarray]:
    """The pose a message's robot rows carry, in patches: x, y, heading and (3D rows) z, pitch, as keyword
    arguments of :meth:`~swarm_ros.core.darr_niazi.swarm_view.SwarmView.update`."""
    pose = {"x": rows["x"] / PATCH_METRES, "y": rows["y"] / PATCH_METRES, "heading": rows["heading"].astype(np.float64)}
    if "pitch" in (rows.dtype.names or ()):
        pose["z"] = rows["z"] / PATCH_METRES
        pose["pitch"] = rows["pitch"].astype(np.float64)
    return pose


def decision_rows(decisions: Decisions) -> np.ndarray:
    rows = np.zeros(decisions.ids.size, dtype=DECISION_ROW if decisions.z is None else DECISION_ROW_3D)
    rows["id"] = decisions.ids
    rows["claim"] = decisions.claim
    rows["x"] = decisions.x * PATCH_METRES
    rows["y"] = decisions.y * PATCH_METRES
    rows["heading"] = decisions.heading
    if decisions.z is not None:
        rows["z"] = decisions.z * PATCH_METRES
        rows["pitch"] = decisions.pitch
    return rows


def decisions_of(tick: int, rows: np.ndarray) -> Decisions:
    """The :class:`Decisions` a message of DECISION_ROW (or DECISION_ROW_3D) rows carries."""
    from swarm_ros.core.darr_niazi.rules import Decisions

    return Decisions(tick=tick, ids=rows["id"].astype(np.int64), claim=rows["claim"].astype(np.int64), **pose_of(rows))


def inside_world(rows: np.ndarray, radius: int) -> None:
    """Raises Rejected unless every row's pose is finite, inside the world and headed in [0, 2 pi]
    (3D rows: with z inside the world too and an elevation in [-pi/2, pi/2])."""
    limit = (radius + 0.5) * PATCH_METRES
    x, y, heading = rows["x"], rows["y"], rows["heading"]
    solid = "pitch" in (rows.dtype.names or ())
    with np.errstate(invalid="ignore"):
        ok = (np.abs(x) <= limit) & (np.abs(y) <= limit) & (heading >= 0) & (heading <= 2 * math.pi)
        if solid:
            ok &= (np.abs(rows["z"]) <= limit) & (np.abs(rows["pitch"]) <= math.pi / 2)
    if not ok.all():
        i = int(np.flatnonzero(~ok)[0])
        z = f", z {rows['z'][i]!r}, pitch {rows['pitch'][i]!r}" if solid else ""
        raise Rejected("pose outside the world", f"({x[i]!r}, {y[i]!r}, heading {heading[i]!r}{z})")
