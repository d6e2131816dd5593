"""Message authentication on the graph: every message carries its own tag, checked on arrival.

The run's processes share a secret key, handed to them in the environment
(``SWARM_ROS_RUN_KEY``; ``swarm-ros run`` and the launch file make a new one per run),
never over the network. Each message is sealed with a tag under that key
(:mod:`swarm_ros.protocol.tag`: sender, process nonce, sequence number, MAC over the
topic and the serialized message) in a typed field of the message itself, so the
topics keep their standard types and a receiver verifies each message alone:

- ``sensor_msgs/PointCloud2``: one more ``PointField`` after the rows' fields, whose
  ``name`` is the tag (offset 0, UINT8, ``count`` 0: it holds no bytes of any point);
- ``diagnostic_msgs/DiagnosticArray``: a last ``KeyValue`` of the last status,
  key ``swarm_ros.tag``, value the tag;
- ``std_msgs/Int64MultiArray``: a last ``MultiArrayDimension`` of size 1, stride 1, whose
  ``label`` is the tag (the array's element count is unchanged).

``nav_msgs/OccupancyGrid`` and ``rosgraph_msgs/Clock`` have no field that could hold a tag
without breaking their readers (RViz places a map by its ``frame_id``), so the world
publishes ``/swarm/shape``, ``/swarm/occupancy`` and ``/clock`` untagged, for viewers, and no
node of the run takes them from the network (the monitor writes them into the bag from its
own verified state). docs/security.md says what this keeps out and what it does not.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, KeyValue
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Int64MultiArray, MultiArrayDimension

from swarm_ros.core.errors import ContractError, Rejected
from swarm_ros.protocol.cdr import TAG_DATATYPE, cloud_parts, decode_cloud, encode_ints
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.plan import BATCHES
from swarm_ros.protocol.rows import TAG_PREFIX, is_tag, parse_batch_label
from swarm_ros.protocol.runkey import KEY_ENV, run_key
from swarm_ros.protocol.tag import Known, Sealer, Tag, Verifier
from swarm_ros.ros.graph import reader_qos

TAGGED_TYPES = (PointCloud2, DiagnosticArray, Int64MultiArray)  #: the types that carry a tag


def put_tag(msg, tag: str) -> None:
    """Put ``tag`` in ``msg`` (of a :data:`TAGGED_TYPES` type; a DiagnosticArray with a status), where readers look."""
    if isinstance(msg, PointCloud2):
        msg.fields.append(PointField(name=tag, offset=0, datatype=TAG_DATATYPE, count=0))
    elif isinstance(msg, DiagnosticArray):
        msg.status[-1].values.append(KeyValue(key=TAG_PREFIX, value=tag))
    elif isinstance(msg, Int64MultiArray):
        msg.layout.dim.append(MultiArrayDimension(label=tag, size=1, stride=1))
    else:
        raise ContractError(f"a {type(msg).__name__} carries no tag")


def take_tag(msg) -> str:
    """The tag in ``msg`` (a received message), taken out of it; "" if it has none."""
    if isinstance(msg, DiagnosticArray):
        values = msg.status[-1].values if msg.status else []
        if values and values[-1].key == TAG_PREFIX:
            return values.pop().value
    elif isinstance(msg, Int64MultiArray):
        dims = msg.layout.dim
        if dims and is_tag(dims[-1].label) and dims[-1].size == 1:
            return dims.pop().label
    return ""


class Signer:
    """The sending side of a node: publishers whose messages go out sealed with a tag."""

    def __init__(self, node, key: bytes, sender: str | None = None) -> None:
        """Tags name ``sender`` (by default the node's name: the name the graph's plan gives each node)."""
        self.node = node
        self.sealer = Sealer(key, sender or node.get_name())

    def publisher(self, msg_type, topic: str, qos) -> SignedPublisher:
        if msg_type not in TAGGED_TYPES:
            raise ContractError(f"a {msg_type.__name__} carries no tag: publish {topic} with a plain publisher")
        return SignedPublisher(self.sealer, self.node.create_publisher(msg_type, topic, qos), topic)


class SignedPublisher:
    """A publisher that seals each message it sends (:class:`swarm_ros.protocol.tag.Sealer`)."""

    def __init__(self, sealer: Sealer, pub, topic: str) -> None:
        self.sealer, self.pub, self.topic = sealer, pub, topic

    def publish(self, msg) -> bytes:
        """Publish ``msg`` (it gets the tag: :func:`put_tag`) sealed; returns its bytes. Clouds of rows go
        faster through :meth:`publish_rows`."""
        data = self.seal(msg)
        self.pub.publish(data)
        return data

    def seal(self, msg) -> bytes:
        """``msg`` tagged and sealed, not sent (yet: :meth:`send`)."""
        blank = self.sealer.blank()
        put_tag(msg, blank)
        return self.sealer.seal(self.topic, serialize_message(msg), blank)

    def seal_ints(self, values: np.ndarray, label: str) -> bytes:
        """An Int64MultiArray of ``values`` labelled ``label`` (:func:`encode_ints`), tagged and sealed, not sent:
        the bytes :meth:`seal` makes of the same message, without building it."""
        blank = self.sealer.blank()
        return self.sealer.seal(self.topic, encode_ints(values, label, tag=blank), blank)

    def publish_ints(self, values: np.ndarray, label: str) -> bytes:
        """Publish :meth:`seal_ints`'s bytes; returns them."""
        data = self.seal_ints(values, label)
        self.pub.publish(data)
        return data

    def send(self, data: bytes) -> None:
        """Publish bytes :meth:`seal` made."""
        self.pub.publish(data)

    def publish_rows(self, rows: np.ndarray, tick: int) -> bytes:
        """Publish ``rows`` as a PointCloud2 stamped with ``tick`` (:func:`encode_cloud`), sealed; returns its bytes."""
        blank = self.sealer.blank()
        return self._send(cloud_parts(rows, tick, tag=blank), blank)

    def _send(self, parts: tuple, blank: str) -> bytes:
        data = self.sealer.seal(self.topic, parts, blank)
        self.pub.publish(data)
        return data

    def wait_for_all_acked(self, timeout) -> bool:
        """Whether every reader has acknowledged the messages sent so far."""
        return self.pub.wait_for_all_acked(timeout)


class Gate:
    """The receiving side of a node: serialized subscriptions whose messages reach their handler once their
    tag proves them (:class:`swarm_ros.protocol.tag.Verifier`). What fails is dropped and counted at once."""

    def __init__(self, node, key: bytes, rejections: Rejections) -> None:
        self.node, self.verifier, self.rejections = node, Verifier(key), rejections
        self.received = 0  # messages arrived so far, taken or not
        self.last_tag: Tag | None = None  # the tag of the message being handled (sender, nonce, seq)
        self.known = 0  # messages dropped as taken already by a process before this one (Verifier.known)

    def subscribe(
        self,
        msg_type,
        topic: str,
        handler: Callable[[Any], None] | None,
        qos,
        raw_handler: Callable[[bytes], None] | None = None,
    ):
        """A serialized subscription to ``topic``, whose writers offer ``qos`` (read with
        :func:`swarm_ros.ros.graph.reader_qos`: a stranger's flood cannot push a genuine message out).
        Proven messages go to ``raw_handler(data)`` (if given), then ``handler(message)``, without their tag.
        A PointCloud2 reaches ``handler`` read in place (:func:`swarm_ros.protocol.cdr.decode_cloud`), not as
        a message object. Returns the subscription."""
        if msg_type not in TAGGED_TYPES:
            raise ContractError(f"a {msg_type.__name__} carries no tag: nothing on {topic} can be proven")

        def on_message(data: bytes) -> None:
            self.received += 1
            try:
                msg = self.open(msg_type, topic, data)
            except Known:
                self.known += 1  # recorded already by this node's process before (a restarted monitor's bag)
                return
            except Rejected as fault:
                self.rejections.drop(topic, fault)
                return
            if raw_handler is not None:
                raw_handler(data)
            if handler is not None:
                handler(msg)

        return self.node.create_subscription(msg_type, topic, on_message, qos and reader_qos(qos), raw=True)

    def open(self, msg_type, topic: str, data: bytes):
        """The message serialized in ``data``, once its tag proves it (tag taken out). The tag is found and
        checked on the bytes first: what no key holder sealed never reaches a parser.

        Raises:
            Rejected: its tag does not prove it, it does not parse, or its tag is not where it belongs.
        """
        tag = self.verifier.verify(topic, data)  # before any parser reads the bytes: only a key holder's are read
        self.last_tag = tag
        msg: Any
        if msg_type is PointCloud2:
            msg = decode_cloud(data)
            text = msg.tag
        else:
            try:
                msg = deserialize_message(data, msg_type)
            except Exception:  # rclpy raises a bare RuntimeError on bytes that are not the type
                raise Rejected("malformed CDR", f"not a {msg_type.__name__}") from None
            text = take_tag(msg)
        if text != tag.text:
            raise Rejected("unauthenticated", "a tag out of its place in the message")
        sender = tag.sender
        if topic == BATCHES:
            label = msg.layout.dim[0].label if msg.layout.dim else ""
            if parse_batch_label(label)[0] != sender:
                raise Rejected("unauthenticated", f"{sender!r} announced {label[:40]!r}")
        return msg


def open_auth(node, rejections: Rejections) -> tuple[Signer, Gate]:
    """A node's :class:`Signer` and :class:`Gate`, under the run's key.

    Raises:
        ConfigError: SWARM_ROS_RUN_KEY is set but too short.
    """
    key, secret = run_key()
    if not secret:
        node.get_logger().warn(
            f"{KEY_ENV} is not set: this node seals with a public key, so any participant "
            f"on the ROS domain can impersonate the run's nodes (docs/security.md)"
        )
    return Signer(node, key), Gate(node, key, rejections)
