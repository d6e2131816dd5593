"""The run's rosbag2: every message of the swarm's topics, in MCAP storage.

The monitor subscribes to the tagged topics in serialized form (CDR bytes, as they travel)
and hands each message its tag proved to :class:`BagRecorder`, which stores it unchanged with the
``rosbags`` library: ``bag/metadata.yaml`` and ``bag/bag_0.mcap``, the layout of
``ros2 bag record -s mcap``, with each topic's type, QoS and full message definition,
so Foxglove, PlotJuggler, ``ros2 bag play`` or any MCAP reader open it with no ROS
install. Timestamps are the monitor's receive times (wall clock, ns), as rosbag2's. The
untagged topics (shape, occupancy, clock) are the monitor's own, encoded from the verified rows
(:mod:`swarm_ros.nodes.central.monitor`).

While the run goes on the bag is written beside the run directory (a hidden
``.<run>.bag-XXXX/bag``); the run directory gets it as ``bag/`` when it is written. A
failed run leaves it, closed and readable, as ``<run>.partial-bag`` (:func:`swarm_ros.artifacts.run_dir.partial_bag`).
"""

from __future__ import annotations

import re
import shutil
import struct
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2

from swarm_ros.artifacts.run_dir import BAG_DIR
from swarm_ros.protocol.plan import CentralTopics
from swarm_ros.ros import graph as msgs


def central_topics(algorithm: str, dims: int = 2) -> dict[str, tuple[type, QoSProfile]]:
    """The recorded topics of a central world's run of ``algorithm`` in a world of ``dims`` dimensions (its monitor
    reads no decisions): every robot's row every record_every-th tick, the metrics of every tick, the status; and,
    as the monitor encodes them from those, the shape, the occupancy at each record that changed it and the clock
    of every tick (:mod:`swarm_ros.nodes.central.monitor`)."""
    topics, kind = CentralTopics.of(algorithm), msgs.map_type(dims)
    return {
        topics.robots: (PointCloud2, msgs.CENTRAL_QOS),
        topics.metrics: (PointCloud2, msgs.CENTRAL_QOS),
        msgs.STATUS: (DiagnosticArray, msgs.STATUS_QOS),
        msgs.SHAPE: (kind, msgs.LATCHED_QOS),
        msgs.OCCUPANCY: (kind, msgs.LATCHED_QOS),
        msgs.CLOCK: (Clock, msgs.CLOCK_QOS),
    }


STORE = "ros2_jazzy"  #: the rosbags type store of the message definitions (rosbags.typesys.Stores)

if TYPE_CHECKING:  # rosbags loads when a bag is opened: off the start of the nodes
    from rosbags.interfaces import Qos, QosTime


def type_name(kind: type) -> str:
    """A message class's ROS type name, e.g. ``sensor_msgs/msg/PointCloud2``."""
    return f"{kind.__module__.split('.')[0]}/msg/{kind.__name__}"


def _duration(d) -> QosTime:  # rclpy Duration -> rosbags time; "infinite" is rclpy's 0
    from rosbags.interfaces import QosTime

    sec, nsec = divmod(d.nanoseconds, 1_000_000_000)
    return QosTime(sec=sec, nsec=nsec)


def bag_qos(qos: QoSProfile) -> Qos:
    """A QoS profile as rosbag2 stores it (``offered_qos_profiles``)."""
    from rosbags.interfaces import Qos
    from rosbags.interfaces import QosDurability as Durability
    from rosbags.interfaces import QosHistory as History
    from rosbags.interfaces import QosLiveliness as Liveliness
    from rosbags.interfaces import QosReliability as Reliability

    return Qos(
        history=History(int(qos.history)),
        depth=qos.depth,
        reliability=Reliability(int(qos.reliability)),
        durability=Durability(int(qos.durability)),
        deadline=_duration(qos.deadline),
        lifespan=_duration(qos.lifespan),
        liveliness=Liveliness(int(qos.liveliness)),
        liveliness_lease_duration=_duration(qos.liveliness_lease_duration),
        avoid_ros_namespace_conventions=qos.avoid_ros_namespace_conventions,
    )


def ros_qos(qos: Qos) -> QoSProfile:
    """The inverse of :func:`bag_qos` (for replay); unknown policies fall back to the system default."""
    from rclpy.duration import Duration

    def policy(kind, value):
        try:
            return kind(int(getattr(value, "value", value)))
        except (TypeError, ValueError):
            return kind.SYSTEM_DEFAULT

    def duration(t: QosTime) -> Duration:
        return Duration(seconds=t.sec, nanoseconds=t.nsec)

    return QoSProfile(
        history=policy(HistoryPolicy, qos.history),
        depth=max(int(qos.depth), 1),
        reliability=policy(ReliabilityPolicy, qos.reliability),
        durability=policy(DurabilityPolicy, qos.durability),
        deadline=duration(qos.deadline),
        lifespan=duration(qos.lifespan),
        liveliness=policy(LivelinessPolicy, qos.liveliness),
        liveliness_lease_duration=duration(qos.liveliness_lease_duration),
    )


def held_tick(holders: Iterable[Path]) -> int:
    """The last tick a run's monitor holds durably in the bags in ``holders`` (a restarted monitor's is a new one):
    the last second of its /clock messages, one written as it takes each tick's metrics; -1 before tick 0. For
    watching a run from outside (tests, benchmarks)."""
    seconds = [
        struct.unpack_from("<i", data, 4)[0]  # (the CDR header, then the clock's sec)
        for holder in holders
        for topic, _, data in unfinished_messages(holder)
        if topic == msgs.CLOCK and len(data) >= 8
    ]
    return max(seconds, default=-1)


def unfinished_messages(holder: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time in ns, CDR bytes) of every message a monitor killed while writing its bag in
    ``holder`` had made durable (:meth:`BagRecorder.durable`), in the order written. The file has no
    summary (the writer never closed it); its records are read in order until the first that is cut off."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    out: list[tuple[str, int, bytes]] = []
    for path in sorted((holder / BAG_DIR).glob("*.mcap")):
        topics: dict[int, str] = {}
        with open(path, "rb") as f:
            try:
                for record in StreamReader(f, skip_magic=False).records:
                    if isinstance(record, Channel):
                        topics[record.id] = record.topic
                    elif isinstance(record, Message) and record.channel_id in topics:
                        out.append((topics[record.channel_id], record.log_time, bytes(record.data)))
            except (McapError, ValueError, EOFError, struct.error):
                pass  # cut off here: the rest was never made durable
    return out


def _name_first_file(bag: Path) -> None:
    """Rename the storage file ``bag.mcap`` to ``bag_0.mcap``, as rosbag2 names a bag's first file
    (rosbags names it after the directory alone), and say so in metadata.yaml: its two lines naming the file
    (``relative_file_paths`` and ``files``) are rewritten in place, the rest stays as rosbags wrote it (a
    YAML round trip cost 0.15 s of CPU per run). Should the pinned rosbags ever lay them out otherwise, the
    bag keeps the name rosbags gave it, which its metadata.yaml then still names."""
    old = f"{bag.name}.mcap"
    new = f"{bag.name}_0.mcap"
    meta = bag / "metadata.yaml"
    text = meta.read_text(encoding="utf-8")
    renamed, lines = re.subn(rf"^(\s*(?:- |path: )){re.escape(old)}$", rf"\g<1>{new}", text, flags=re.M)
    if lines != 2:
        return
    (bag / old).rename(bag / new)
    tmp = meta.with_name(f".{meta.name}.tmp")
    tmp.write_text(renamed, encoding="utf-8")
    tmp.replace(meta)


class BagRecorder:
    """Writes the recorded topics' serialized messages into a new rosbag2 (MCAP storage)."""

    def __init__(self, out: Path, recorded: dict[str, tuple[type, QoSProfile]]) -> None:
        """Open a bag for the run directory ``out`` (in a fresh hidden place beside it) of the topics ``recorded``
        (:func:`central_topics`)."""
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        out.parent.mkdir(parents=True, exist_ok=True)
        self.holder = Path(tempfile.mkdtemp(prefix=f".{out.name}.bag-", dir=out.parent))
        self.path = self.holder / BAG_DIR
        self.writer = Writer(self.path, version=Writer.VERSION_LATEST, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        store = get_typestore(Stores(STORE))
        self.connections = {
            topic: self.writer.add_connection(
                topic, type_name(kind), typestore=store, offered_qos_profiles=[bag_qos(qos)]
            )
            for topic, (kind, qos) in recorded.items()
        }
        self.closed = False

    def write(self, topic: str, data: bytes, at: int | None = None) -> None:
        """Store one message of ``topic`` (CDR bytes), stamped ``at`` (ns), or now."""
        if not self.closed:
            self.writer.write(self.connections[topic], time.time_ns() if at is None else at, data)

    def durable(self) -> None:
        """Hand everything written so far to the operating system: a SIGKILL of this process from now on loses
        none of it (a restarted monitor reads it back, :func:`unfinished_messages`). The MCAP writer keeps its
        current chunk in memory until it is closed; here it is closed (one chunk per tick)."""
        storage = self.writer.storage  # rosbags' MCAP storage: pinned (requirements.txt); no public flush
        # its MCAP writer's own fields, not in rosbags' typed interface
        if not self.closed and storage is not None and storage.chunk.bio.tell():  # type: ignore[attr-defined]
            storage.close_chunk()  # type: ignore[attr-defined]
            storage.bio.flush()  # type: ignore[attr-defined]

    def close(self) -> Path:
        """Finish the bag (the MCAP summary and metadata.yaml); return its directory. Safe to call again."""
        if not self.closed:
            self.closed = True
            self.writer.close()
            _name_first_file(self.path)
        return self.path

    def discard_holder(self) -> None:
        """Remove the hidden folder the bag was written in, once the bag was moved out of it."""
        if not self.path.exists():
            shutil.rmtree(self.holder, ignore_errors=True)

    def discard(self) -> None:
        """Remove the bag and the hidden folder it was written in (a run that never started holds nothing), whether
        or not the bag could be closed (a full disk)."""
        try:
            self.close()
        except OSError:
            pass  # it goes anyway
        shutil.rmtree(self.holder, ignore_errors=True)

    def move_to(self, target: Path) -> Path | None:
        """Close, then move the bag directory to ``target`` (which must not exist); return where it is, or None:
        ``target`` exists, or the bag could not be closed (a full disk) and is removed, since no reader could
        open it."""
        try:
            self.close()
        except OSError:
            shutil.rmtree(self.holder, ignore_errors=True)
            return None
        if target.exists():
            return None
        self.path.rename(target)
        shutil.rmtree(self.holder, ignore_errors=True)
        return target
