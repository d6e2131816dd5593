"""The hot-path message layouts, as numpy record types (no ROS here; :mod:`swarm_ros.ros.graph` wraps them).

Robot rows travel as the ``data`` of ``sensor_msgs/PointCloud2`` messages: one point per
robot, little-endian, with the fields named below, so stock tools (``ros2 topic echo``,
RViz) can read them, while a node turns a whole message into a numpy array without a
Python loop. Positions are float64 so the distributed engine carries the exact state.

Units: one patch is one metre (:data:`PATCH_METRES`), and one tick is one second of
simulation time (:data:`TICK_SECONDS`), so a message of tick t is stamped t s, 0 ns.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from swarm_ros.core.errors import ContractError

if TYPE_CHECKING:  # the rules load numba: readers of rows (the launcher's progress) do without it
    from swarm_ros.core.darr_niazi.rules import Decisions

PATCH_METRES = 1.0
TICK_SECONDS = 1
FRAME_ID = "world"

# sensor_msgs/PointField datatype codes
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)
_CODE_OF = {"i1": INT8, "u1": UINT8, "i2": INT16, "u2": UINT16, "i4": INT32, "u4": UINT32, "f4": FLOAT32, "f8": FLOAT64}
_DTYPE_OF = {code: np.dtype("<" + kind) for kind, code in _CODE_OF.items()}

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
ROW_TYPES = (
    ROBOT_ROW,
    DECISION_ROW,
    ROBOT_ROW_3D,
    DECISION_ROW_3D,
)  #: every row layout, for readers of any
#: World -> viewers, in a 3D world: a voxel's centre, metres (/swarm/shape: every shape voxel; /swarm/occupancy:
#: the filled ones). A 2D world sends nav_msgs/OccupancyGrid on those topics instead.
VOXEL_ROW = np.dtype({"names": ["x", "y", "z"], "formats": ["<f4", "<f4", "<f4"], "offsets": [0, 4, 8], "itemsize": 12})


def robot_row(dims: int) -> np.dtype:
    """The robot row layout of a world of ``dims`` dimensions."""
    return ROBOT_ROW if dims == 2 else ROBOT_ROW_3D


def decision_row(dims: int) -> np.dtype:
    """The decision row layout of a world of ``dims`` dimensions."""
    return DECISION_ROW if dims == 2 else DECISION_ROW_3D


@functools.lru_cache(maxsize=64)
def point_fields(dtype: np.dtype) -> tuple[tuple[str, int, int, int], ...]:
    """(name, offset, PointField datatype, count) of each field of a row type (found once a type: every message a
    node checks compares its fields with them)."""
    fields = dtype.fields
    assert fields is not None and dtype.names is not None  # a row type is a structured dtype
    return tuple((name, fields[name][1], _CODE_OF[fields[name][0].str[1:]], 1) for name in dtype.names)


TAG_PREFIX = "swarm_ros.tag"  #: a message's tag starts so (swarm_ros.protocol.tag); in a cloud, a last field's name


def is_tag(text: str) -> bool:
    """Whether ``text`` claims to be a tag (it may still be malformed): a reader of rows skips such a field."""
    return text.startswith(TAG_PREFIX + ":")


def check_fields(fields: Sequence[tuple[str, int, int, int]], point_step: int, dtype: np.dtype) -> None:
    """Raise ContractError unless a message's fields and point step are exactly those of ``dtype``, and a
    last field that holds nothing (count 0) and is named by a tag, which is skipped."""
    got = tuple(fields)
    if got and got[-1][3] == 0 and is_tag(got[-1][0]):
        got = got[:-1]
    if point_step != dtype.itemsize or got != point_fields(dtype):
        raise ContractError(
            f"unexpected point layout {list(got)} (step {point_step}); "
            f"expected {list(point_fields(dtype))} (step {dtype.itemsize})"
        )


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


def batch_label(node_name: str, incarnation: int) -> str:
    """The label of a batch's announcement on /swarm/batches: ``<node>/<incarnation>`` (0 = its first process)."""
    return f"{node_name}/{incarnation}"


def parse_batch_label(label: str) -> tuple[str, int]:
    """(node name, incarnation) of an announcement's label; a label without ``/<n>`` is incarnation 0."""
    name, sep, number = label.rpartition("/")
    if sep and number.isdigit():
        return name, int(number)
    return label, 0
