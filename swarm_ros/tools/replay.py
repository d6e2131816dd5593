"""``swarm-ros replay BAG``: publish a recorded run's topics again, with their types and QoS.

Every message of the bag is published as it was recorded (the CDR bytes, unchanged) on
its topic, with the message type and the QoS its publisher offered (from metadata.yaml),
paced by the recorded receive times divided by ``rate``. RViz, Foxglove, ``ros2 topic``
or ``swarm-ros topics`` on the same ROS domain then see the past run as if it were live.
Like ``ros2 bag play``, it waits ``delay`` seconds after creating the publishers, so that
subscribers started beforehand are matched before the first message (and first, until its publishers
have ``subscribers`` matched subscriptions between them: a condition, where a delay is a guess), starts ``start_offset``
seconds into the bag, and with ``loop`` plays it again and again until Ctrl-C. From an offset,
the last message before it of each latched topic (transient local, depth 1: the shape and the
occupancy) is published first, as a reader that joined a live run then would have it.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from swarm_ros.core.errors import InputError
from swarm_ros.ros.graph import message_class
from swarm_ros.ros.runtime import tool_node

_ACK_WAIT_S = 2.0  # seconds to let readers acknowledge the last messages before exiting
_MATCH_POLL_S = 0.02  # how often it looks for the subscriptions it waits for


class ReplayError(InputError):
    """The bag cannot be replayed (not a bag, unreadable, or a message type that is not installed)."""


def _message_class(msgtype: str) -> type:
    found = message_class(msgtype)
    if found is None:
        raise ReplayError(f"message type {msgtype} is not installed here, so its topic cannot be published")
    return found


def open_bag(bag: Path):
    """A rosbags Reader, opened; ReplayError in one line if ``bag`` is not a readable rosbag2."""
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError

    if not bag.exists():
        raise ReplayError(f"{bag}: no such file or directory")
    if not bag.is_dir() or not (bag / "metadata.yaml").is_file():
        raise ReplayError(f"{bag}: not a rosbag2 directory (it has no metadata.yaml); a run's bag is <run>/bag")
    try:
        reader = Reader(bag)
        reader.open()
    except (ReaderError, OSError, ValueError, KeyError) as exc:
        detail = str(exc.args[0] if exc.args else exc).strip().splitlines() or [type(exc).__name__]
        raise ReplayError(f"{bag}: cannot read this bag ({detail[0]})") from None
    return reader


def replay(
    bag: Path,
    domain_id: int,
    rate: float = 1.0,
    delay: float = 1.0,
    quiet: bool = False,
    start_offset: float = 0.0,
    loop: bool = False,
    subscribers: int = 0,
) -> int:
    """Publish the bag's messages on ``domain_id``; return an exit code (0, or 130 if interrupted).

    Raises:
        ReplayError: not a bag, unreadable, empty, a type that is not installed, or an offset past its end.
    """
    reader = open_bag(bag)
    try:
        classes = {c.id: _message_class(c.msgtype) for c in reader.connections}
        if reader.message_count == 0:
            raise ReplayError(f"{bag}: the bag holds no messages")
        length = (reader.end_time - reader.start_time) / 1e9
        if start_offset > length:
            raise ReplayError(f"--start-offset {start_offset:g} is past the bag's end (it lasts {length:.3f} s)")
        return _publish(reader, classes, domain_id, rate, (subscribers, delay), quiet, int(start_offset * 1e9), loop)
    finally:
        reader.close()


def _publish(
    reader, classes: dict, domain_id: int, rate: float, wait: tuple[int, float], quiet: bool, offset: int, loop: bool
) -> int:
    """Publish the bag (``wait``: the subscriptions its publishers must have matched between them, then the seconds
    of delay)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from tqdm import tqdm

    from swarm_ros.ros.bag_writer import ros_qos
    from swarm_ros.ros.dds import apply_dds_defaults

    apply_dds_defaults()  # on this host, as a run's nodes (set ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET to share it)
    with tool_node("swarm_ros_replay", domain_id) as node:
        pubs, latched = {}, set()
        for c in reader.connections:
            offered = c.ext.offered_qos_profiles
            qos = ros_qos(offered[0]) if offered else QoSProfile(depth=10)
            pubs[c.id] = node.create_publisher(classes[c.id], c.topic, qos)
            if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL and qos.depth == 1:
                latched.add(c.id)  # ROS's "latched": a late reader gets the last message
        if not quiet:
            print(
                f"swarm-ros: replaying {reader.message_count} messages on {len(pubs)} topics, ROS domain "
                f"{domain_id}, at {rate:g}x",
                file=sys.stderr,
                flush=True,
            )
        subscribers, delay = wait
        try:
            while sum(pub.get_subscription_count() for pub in pubs.values()) < subscribers:
                time.sleep(_MATCH_POLL_S)
            time.sleep(delay)
        except KeyboardInterrupt:
            return 130
        first = reader.start_time + offset
        with tqdm(
            total=None if loop else reader.message_count,
            unit="msg",
            desc="replayed",
            file=sys.stderr,
            disable=True if quiet else None,
            dynamic_ncols=True,
        ) as bar:
            try:
                while True:
                    _play(reader, pubs, first, rate, latched, bar)
                    if not loop:
                        break
            except KeyboardInterrupt:
                return 130
        from rclpy.duration import Duration

        deadline = time.monotonic() + _ACK_WAIT_S
        for pub in pubs.values():
            pub.wait_for_all_acked(Duration(seconds=max(deadline - time.monotonic(), 0.0)))
        return 0


def _play(reader, pubs: dict, first: int, rate: float, latched: set, bar) -> None:
    """One pass over the bag from the time ``first`` (ns): before it, only the newest message of each latched
    connection, published when the pass starts."""
    held: dict[int, bytes] = {}
    start = None
    for connection, stamp, data in reader.messages():
        if stamp < first:
            if connection.id in latched:
                held[connection.id] = bytes(data)
            bar.update()
            continue
        if start is None:
            start = time.monotonic()
            for cid, message in held.items():
                pubs[cid].publish(message)
        wait = start + (stamp - first) / 1e9 / rate - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        pubs[connection.id].publish(bytes(data))
        bar.update()
