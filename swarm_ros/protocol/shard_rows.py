"""The messages world shards send each other, as standard message payloads (numpy here; no ROS).

A world shard's node (:mod:`swarm_ros.nodes.world_shard`) sends, each tick:

* its robots' claims on a peer's window: ``sensor_msgs/PointCloud2`` of decision rows
  (:data:`~swarm_ros.protocol.rows.DECISION_ROW`), the layout a batch's decisions take;
* the rows of its part routed to a peer: ``PointCloud2`` of :data:`PART_ROW` (a compact robot row and the
  robot's column before the tick);
* its part's counts and the robots it removes at the tick's end, the same for every peer, once:
  ``std_msgs/Int64MultiArray`` of :func:`counts_data` (tick, sender, the counts of
  :data:`~swarm_ros.core.shard_parts.COUNTS`, then the ids removed).

A receiver joins a peer's rows and counts of one tick into a :class:`~swarm_ros.core.shard_parts.Part`
(:func:`assemble`) and hands it to its :class:`~swarm_ros.protocol.shard_exchange.ShardExchange`, whose shard
checks its content. What is checked here is the form: lengths, ranges, and that rows and counts agree on
tick and sender.
"""

from __future__ import annotations

import numpy as np

from swarm_ros.core.errors import Rejected
from swarm_ros.core.shard_parts import COUNTS, Part
from swarm_ros.protocol.rows import PATCH_METRES

#: World shard -> world shard: a robot's row in a part (compact, as a region row) and its column before the tick.
PART_ROW = np.dtype(
    {
        "names": ["x", "y", "heading", "before", "id", "state"],
        "formats": ["<f8", "<f8", "<f8", "<i4", "<u4", "<u1"],
        "offsets": [0, 8, 16, 24, 28, 32],
        "itemsize": 33,
    }
)
PART_ROW_3D = np.dtype(
    {
        "names": ["x", "y", "z", "heading", "pitch", "before", "id", "state"],
        "formats": ["<f8", "<f8", "<f8", "<f8", "<f8", "<i4", "<u4", "<u1"],
        "offsets": [0, 8, 16, 24, 32, 40, 44, 48],
        "itemsize": 49,
    }
)
_HEAD = 2  #: an Int64MultiArray of counts starts with the tick and the sender


def part_row(dims: int) -> np.dtype:
    """The part row layout of a world of ``dims`` dimensions."""
    return PART_ROW if dims == 2 else PART_ROW_3D


def part_rows(part: Part, dims: int) -> np.ndarray:
    """The rows of ``part`` (as routed to one peer) in the part layout of a ``dims``-dimensional world; positions
    in metres."""
    solid = dims == 3
    rows = np.zeros(part.ids.size, dtype=part_row(dims))
    rows["id"], rows["state"], rows["before"] = part.ids, part.state, part.before
    rows["x"], rows["y"], rows["heading"] = part.x * PATCH_METRES, part.y * PATCH_METRES, part.heading
    if solid:
        rows["z"], rows["pitch"] = part.z * PATCH_METRES, part.pitch
    return rows


def counts_data(part: Part) -> np.ndarray:
    """The counts message's data of ``part``: tick, sender, its counts, the ids it removes."""
    head = np.array([part.tick, part.source], dtype=np.int64)
    return np.concatenate([head, part.counts.astype(np.int64), part.removing.astype(np.int64)])


def counts_of(data: np.ndarray, robots: int, shards: int) -> tuple[int, int, np.ndarray, np.ndarray]:
    """(tick, sender, counts, ids removed) of a counts message's data, checked in form.

    Raises:
        Rejected: too short, a negative tick or count, a sender that is no shard, or removed ids out of range
            or repeated.
    """
    data = np.asarray(data, dtype=np.int64)
    if data.ndim != 1 or data.size < _HEAD + len(COUNTS) or data.size > _HEAD + len(COUNTS) + robots:
        raise Rejected("malformed counts", f"{data.size} numbers")
    tick, source = int(data[0]), int(data[1])
    counts, removing = data[_HEAD : _HEAD + len(COUNTS)].copy(), data[_HEAD + len(COUNTS) :].copy()
    if tick < 1 or not 0 <= source < shards or (counts < 0).any():
        raise Rejected("malformed counts", f"tick {tick}, shard {source}, counts {counts.tolist()}")
    if removing.size and (removing.min() < 0 or removing.max() >= robots or np.unique(removing).size < removing.size):
        raise Rejected("malformed counts", "robots removed out of range, or twice")
    return tick, source, counts, removing


def assemble(tick: int, source: int, rows: np.ndarray, counts: tuple[int, int, np.ndarray, np.ndarray]) -> Part:
    """Shard ``source``'s part of ``tick``: its ``rows`` (a part row cloud's) and its ``counts``
    (:func:`counts_of`).

    Raises:
        Rejected: the rows and the counts are of other ticks or senders.
    """
    if counts[:2] != (tick, source):
        raise Rejected("mismatched part", f"rows of shard {source} at tick {tick}, counts of {counts[:2]}")
    solid = "pitch" in (rows.dtype.names or ())
    empty = np.empty(0)
    return Part(
        tick=tick,
        source=source,
        ids=rows["id"].astype(np.int64),
        state=rows["state"].astype(np.int8),
        x=rows["x"] / PATCH_METRES,
        y=rows["y"] / PATCH_METRES,
        heading=rows["heading"].astype(np.float64),
        z=rows["z"] / PATCH_METRES if solid else empty,
        pitch=rows["pitch"].astype(np.float64) if solid else empty,
        before=rows["before"].astype(np.int64),
        counts=counts[2],
        removing=counts[3],
    )
