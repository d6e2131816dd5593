"""Topics, QoS and message builders of the swarm's ROS 2 graph (docs/protocol.md documents them).

Standard message types only. The per-tick robot rows ride in ``sensor_msgs/PointCloud2``
(see :mod:`swarm_ros.protocol.rows`): one numpy record per robot, written and read as CDR
bytes (:mod:`swarm_ros.protocol.cdr`), which keeps a tick's messages at microseconds where a
``PoseArray`` of message objects would cost milliseconds.
"""

from __future__ import annotations

import array
from collections.abc import Callable, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import OccupancyGrid
from rclpy.duration import Duration
from rclpy.event_handler import QoSLivelinessChangedInfo, SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Empty, Header, Int64MultiArray, MultiArrayDimension

from swarm_ros.core.grid import CellMap
from swarm_ros.protocol.cdr import encode_clock, encode_cloud, encode_grid
from swarm_ros.protocol.plan import (  # noqa: F401 - the graph's topics, for the nodes that use this module
    ALIVE,
    BATCHES,
    CENTRAL_KEPT,
    CLOCK,
    HELD,
    MONITOR,
    OCCUPANCY,
    SHAPE,
    STATUS,
    alive_topic,
)
from swarm_ros.protocol.rows import FRAME_ID, TICK_SECONDS

_NO_WAIT = Duration(seconds=0)

# -- topics: swarm_ros.protocol.plan names them (a contract between processes) -------------------
# -- QoS ----------------------------------------------------------------------------
#: The bare lockstep's rows (scripts/bench_bare.py), as the study's earlier graph sent its robots: reliable, and a
#: reader that matches late still gets the ticks it missed, up to the depth.
ROBOTS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=512,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
#: A KEEP_LAST reader keeps ``depth`` samples over all the writers of a topic (the batches on
#: /swarm/batches), so the depth must exceed the batches that can announce at once.
DECISIONS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=256,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
BATCHES_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=256,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
#: State that a late joiner needs once: the latest message is kept for it ("latched").
LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
#: The run's state, ten a second and on every event; the last 256 (25 s) are kept for a late reader: a
#: restarted monitor records in the bag those sent while it was down.
STATUS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=256,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
#: A central world's robots and metrics, world -> monitor: the last ``CENTRAL_KEPT`` messages are kept for a
#: restarted monitor, and the world never runs so far past the monitor's last held record that one it has not taken
#: would be pushed out (swarm_ros.protocol.central_world.monitor_reach).
CENTRAL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=CENTRAL_KEPT,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def central_shards_qos(kept: int) -> QoSProfile:
    """Between a central world's shards: each tick's messages, the last ``kept`` ticks' kept for a peer's restarted
    process, which goes on from a save at most that many ticks back
    (:func:`swarm_ros.protocol.central_checkpoint.shard_kept`)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=kept,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )


CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
#: Liveliness only: nothing is published. DDS asserts an AUTOMATIC writer alive while its process
#: runs; a killed or stopped (SIGSTOP) process misses the lease and its readers are told within it.
LIVELINESS_LEASE_S = 1.0
ALIVE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
    liveliness=LivelinessPolicy.AUTOMATIC,
    liveliness_lease_duration=Duration(seconds=LIVELINESS_LEASE_S),
)


def reader_qos(offered: QoSProfile) -> QoSProfile:
    """How the run's nodes read a topic whose writers offer ``offered``: the same reliability, durability and
    liveliness (so the two match), and a KEEP_ALL history. A reader's history is shared by every writer of
    the topic: kept to the last N, a stranger's flood could push a genuine message out before the node
    takes it. Kept whole, a full reader refuses new samples, and a reliable writer sends them again."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL,
        reliability=offered.reliability,
        durability=offered.durability,
        liveliness=offered.liveliness,
        liveliness_lease_duration=offered.liveliness_lease_duration,
    )


# OccupancyGrid cell values
CELL_OFF_SHAPE = -1  # wall or floor outside the shape ("unknown" to map tools)
CELL_EMPTY = 0  # shape patch without a localized robot
CELL_FULL = 100  # shape patch with a localized or seed robot


def stamp(tick: int) -> Time:
    return Time(sec=int(tick) * TICK_SECONDS, nanosec=0)


def tick_of(header: Header) -> int:
    return int(header.stamp.sec) // TICK_SECONDS


def ids_message(ids: np.ndarray, label: str = "robot_id") -> Int64MultiArray:
    msg = Int64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=label, size=int(ids.size), stride=int(ids.size))]
    data = array.array("q")
    data.frombytes(np.ascontiguousarray(ids, dtype="<i8").tobytes())
    msg.data = data
    return msg


#: The labels of the Int64MultiArray messages the graph sends each tick: one layout dimension, so labelled, holds
#: the values. Nodes send them as bytes (SignedPublisher.publish_ints); the message objects below are for tools.
HELD_LABEL = "held"  #: /swarm/held: the tick, and 1 if the outcome is held too


def held_values(tick: int, ended: bool) -> np.ndarray:
    """The monitor's report on /swarm/held: the last tick whose record its bag holds, and whether the outcome too."""
    return np.array([tick, int(ended)], dtype=np.int64)


def map_type(dims: int) -> type:
    """The message type of /swarm/shape and /swarm/occupancy in a world of ``dims`` dimensions."""
    return OccupancyGrid if dims == 2 else PointCloud2


class WorldMaps:
    """A run's /swarm/shape and /swarm/occupancy messages, serialized as published, from the engine's
    :class:`~swarm_ros.core.grid.CellMap` (its mask, its cells' side and corner: they stay for the run).

    2D: ``nav_msgs/OccupancyGrid`` over the cells (shape cells 0, filled ones 100, the rest -1). 3D:
    ``sensor_msgs/PointCloud2`` of voxel centres (:data:`~swarm_ros.protocol.rows.VOXEL_ROW`): every shape voxel on
    /swarm/shape, the filled ones on /swarm/occupancy; RViz shows either as boxes, one voxel wide (PointCloud2, style
    Boxes, size 1).
    """

    def __init__(self, cells: CellMap) -> None:
        self.mask, self.side, self.corner = cells.mask, cells.side, cells.corner
        self.solid = cells.mask.ndim == 3
        self.kind = map_type(cells.mask.ndim)
        self.cells = None if self.solid else np.where(cells.mask, CELL_EMPTY, CELL_OFF_SHAPE).astype(np.int8)

    def _voxels(self, flags: np.ndarray, tick: int) -> bytes:
        from swarm_ros.protocol.rows import VOXEL_ROW

        index = np.unravel_index(np.flatnonzero(flags), flags.shape)  # (iz, iy, ix)
        rows = np.zeros(index[0].size, dtype=VOXEL_ROW)
        for name, i, corner in zip("xyz", reversed(index), self.corner):
            rows[name] = corner + (i + 0.5) * self.side
        return encode_cloud(rows, tick)

    def _grid(self, cells: np.ndarray, tick: int) -> bytes:
        return encode_grid(cells, self.side, (self.corner[0], self.corner[1]), tick)

    def shape_message(self, tick: int) -> bytes:
        if self.solid:
            return self._voxels(self.mask, tick)
        assert self.cells is not None  # a 2D world's
        return self._grid(self.cells, tick)

    def occupancy_message(self, filled: np.ndarray, tick: int) -> bytes:
        """The cells ``filled`` (bool, as the mask) at ``tick``."""
        if self.solid:
            return self._voxels(filled, tick)
        assert self.cells is not None  # a 2D world's
        cells = self.cells.copy()
        cells[filled] = CELL_FULL
        return self._grid(cells, tick)


def status_message(
    tick: int, outcome: str, message: str, level: bytes = DiagnosticStatus.OK, extra: dict[str, object] | None = None
) -> DiagnosticArray:
    """The world's status: ``outcome`` is 'starting', 'running' or the run's outcome."""
    values = {"tick": tick, "outcome": outcome, **(extra or {})}
    status = DiagnosticStatus(
        level=level,
        name="swarm_ros/world",
        message=message,
        hardware_id="swarm_ros",
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
    )
    return DiagnosticArray(header=Header(stamp=stamp(tick), frame_id=FRAME_ID), status=[status])


def status_values(msg: DiagnosticArray) -> dict[str, str]:
    return {kv.key: kv.value for s in msg.status for kv in s.values}


def clock_message(tick: int) -> bytes:
    """The /clock message of ``tick``, serialized, as it is published."""
    return encode_clock(tick)


def message_class(type_name: str) -> type | None:
    """The rclpy message class of a type name like ``sensor_msgs/msg/PointCloud2`` (also ``sensor_msgs/PointCloud2``),
    or None if that type is not installed here."""
    import importlib

    package, _, name = type_name.replace("/msg/", "/").partition("/")
    try:
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except (ImportError, AttributeError, ValueError):
        return None


def watch_liveliness(node, peer: str, on_change: Callable[[int, int], None]) -> None:
    """Follow the liveliness of node ``peer``'s silent writer (``/swarm/alive/<peer>``): DDS tells when its process
    dies or stalls, and ``on_change(alive, not_alive)`` hears the writers alive and lapsed."""

    def changed(info: QoSLivelinessChangedInfo) -> None:
        on_change(info.alive_count, info.not_alive_count)

    callbacks = SubscriptionEventCallbacks(liveliness=changed)
    node.create_subscription(Empty, alive_topic(peer), lambda _: None, ALIVE_QOS, event_callbacks=callbacks)


#: The node name the ROS graph gives an endpoint whose participant has not yet said which node owns it
#: (rmw_dds_common's graph cache, until the participant's ``ros_discovery_info`` message comes)
UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"


def monitor_reads(node, topics: Sequence[str]) -> bool:
    """Whether ``node`` has discovered the monitor's reader of each of ``topics``: its writers match it then, and
    a reader that matched after a topic's first messages would keep only the last of a latched one.

    A reader the graph knows but not yet its node counts too: a full run of the suite saw a world wait 120 s on a
    monitor whose liveliness writer it matched, its readers never named. Should that reader be another's (a
    ``ros2 topic echo``), the monitor still finds tick 0 in the topics' histories: the world runs no further past the
    monitor's last report than those keep (:func:`swarm_ros.protocol.central_world.monitor_reach`)."""
    readers = (MONITOR, UNKNOWN_NODE)
    return all(any(i.node_name in readers for i in node.get_subscriptions_info_by_topic(t)) for t in topics)


def readers_seen(node, topics: Sequence[str]) -> str:
    """The nodes of each of ``topics``' readers as ``node``'s ROS graph lists them, for an error that says why a
    world still waits for its monitor: ``<topic>: <node>, ...`` (``none``), one topic after another."""
    return "; ".join(
        f"{t}: {', '.join(sorted(i.node_name for i in node.get_subscriptions_info_by_topic(t))) or 'none'}"
        for t in topics
    )


def acknowledged(publishers) -> bool:
    """Whether every reader of each of ``publishers`` has acknowledged what it sent so far."""
    return all(p.wait_for_all_acked(_NO_WAIT) for p in publishers)
