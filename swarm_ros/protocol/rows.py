"""What every algorithm's rows on the wire share (no ROS here; :mod:`swarm_ros.ros.graph` wraps them): units, the
frame, PointField codes, a row type's fields, the tag field, a batch's label, and the 3D maps' voxel rows. Each
algorithm's own row types are its protocol package's (:mod:`swarm_ros.protocol.darr_niazi.rows`,
:mod:`swarm_ros.protocol.rubenstein.rows`).

Rows travel as the ``data`` of ``sensor_msgs/PointCloud2`` messages: one point per robot, little-endian, with the
fields their record type names, so stock tools (``ros2 topic echo``, RViz) can read them, while a node turns a whole
message into a numpy array without a Python loop.

Units: one patch is one metre (:data:`PATCH_METRES`), and one tick is one second of
simulation time (:data:`TICK_SECONDS`), so a message of tick t is stamped t s, 0 ns.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from swarm_ros.core.errors import ContractError

PATCH_METRES = 1.0
TICK_SECONDS = 1
FRAME_ID = "world"

# sensor_msgs/PointField datatype codes
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)
_CODE_OF = {"i1": INT8, "u1": UINT8, "i2": INT16, "u2": UINT16, "i4": INT32, "u4": UINT32, "f4": FLOAT32, "f8": FLOAT64}
_DTYPE_OF = {code: np.dtype("<" + kind) for kind, code in _CODE_OF.items()}

#: World -> viewers, in a 3D world: a voxel's centre, metres (/swarm/shape: every shape voxel; /swarm/occupancy:
#: the filled ones). A 2D world sends nav_msgs/OccupancyGrid on those topics instead.
VOXEL_ROW = np.dtype({"names": ["x", "y", "z"], "formats": ["<f4", "<f4", "<f4"], "offsets": [0, 4, 8], "itemsize": 12})


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


def batch_label(node_name: str, incarnation: int) -> str:
    """The label of a batch's announcement on /swarm/batches: ``<node>/<incarnation>`` (0 = its first process)."""
    return f"{node_name}/{incarnation}"


def parse_batch_label(label: str) -> tuple[str, int]:
    """(node name, incarnation) of an announcement's label; a label without ``/<n>`` is incarnation 0."""
    name, sep, number = label.rpartition("/")
    if sep and number.isdigit():
        return name, int(number)
    return label, 0
