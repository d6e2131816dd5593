"""Message authentication: a node takes a message only if a holder of the run's key vouched for it.

The run's processes share a secret key, handed to them in the environment
(``SWARM_ROS_RUN_KEY``; ``swarm-ros run`` and the launch file make a new one per run),
never over the network. Messages keep their standard types: what proves a message is a
separate *voucher* on ``/swarm/auth/<role>`` (a ``diagnostic_msgs/DiagnosticStatus``),
published just before the messages it covers. It lists, for each message, its topic and
a digest of its serialized bytes (SHA-256 over topic and bytes, first 16 bytes), and is
signed as a whole with HMAC-SHA256 under the key, with a per-process nonce and a sequence
number that only grows:

    name: world                 (the sender's node name)
    hardware_id: 3f9c...        (a random nonce per process)
    values: seq=41, /swarm/decisions=<hex>, /swarm/robots=<hex>, /clock=<hex>, mac=<hex>

A receiver (:class:`Gate`) reads its topics serialized, digests what arrives, and hands a
message to its handler only once a voucher with a valid MAC has listed that digest; each
listing admits one message. A message that no voucher lists within ``HOLD_SECONDS`` is
dropped and counted as ``unauthenticated``; a voucher with a wrong MAC, or a sequence number
its sender's process used already (a replay), is dropped and counted too. Vouchers are
checked when they arrive, so only genuine digests are ever stored.

Roles: the world vouches on ``/swarm/auth/world`` (rows, snapshots, status, occupancy,
shape, clock, applied decisions), the robot batches on ``/swarm/auth/batches``
(announcements and decisions), the monitor on ``/swarm/auth/monitor`` (metrics).
docs/security.md says what this keeps out and what it does not.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2

from swarm_ros.protocol.cdr import decode_cloud
from swarm_ros.protocol.checks import Rejected, Rejections
from swarm_ros.protocol.runkey import KEY_ENV, run_key
from swarm_ros.ros import graph as msgs

AUTH = "/swarm/auth"
#: The vouchers a late reader needs: the world's rows keep ROBOTS_DEPTH ticks of history, one voucher a tick.
AUTH_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2 * msgs.ROBOTS_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
DIGEST_BYTES = 16
#: A message no voucher listed within this long is dropped as unauthenticated. Vouchers go out before
#: the messages they list, so a genuine message waits for its voucher only while the voucher is in
#: flight; long enough for a lost voucher to be sent again (DDS repairs a loss at its writer's next
#: heartbeat: every 50 ms under config/fastdds.xml, every 3 s by default).
HOLD_SECONDS = 5.0
#: At the end of a run, what has waited this long is judged at once (:meth:`Gate.settle`).
SETTLE_SECONDS = 0.2
HOLD_MESSAGES = 1024  # at most this many messages held per topic (the oldest is dropped)
HOLD_BYTES = 64 << 20  # at most this many bytes held in all (a flood of big messages cannot exhaust memory)
KEPT_DIGESTS = 16384  # digests vouched for but not yet matched, at most (the oldest is forgotten)


def role_of(topic: str) -> str:
    """Who vouches for a topic's messages: ``world``, ``batches`` or ``monitor``."""
    if topic == msgs.BATCHES or topic.startswith(msgs.BATCH_DECISIONS + "/"):
        return "batches"
    if topic == msgs.METRICS:
        return "monitor"
    return "world"


def auth_topic(role: str) -> str:
    return f"{AUTH}/{role}"


def aligned(data: bytes) -> bytes:
    """``data`` with zero bytes up to a multiple of 4, as DDS delivers serialized messages.

    A serialized message that does not end on a 4-byte boundary reaches a reader of
    another process padded with zeros (measured here: 321 bytes sent, 324 received);
    readers ignore the padding. Senders pad first, so what is digested is what arrives.
    """
    return data + bytes(-len(data) % 4)


def digest(topic: str, data: bytes) -> bytes:
    """The digest of a serialized message of ``topic``, as a voucher lists it (over the aligned bytes)."""
    return hashlib.sha256(topic.encode() + b"\0" + aligned(data)).digest()[:DIGEST_BYTES]


def _mac(key: bytes, name: str, nonce: str, values: list[tuple[str, str]]) -> str:
    text = "\n".join([name, nonce, *(f"{k}={v}" for k, v in values)])
    return hmac.new(key, text.encode(), hashlib.sha256).hexdigest()


def voucher(key: bytes, name: str, nonce: str, seq: int, entries: list[tuple[str, bytes]]) -> DiagnosticStatus:
    """The voucher for ``entries`` (topic, digest), signed with ``key``."""
    values = [("seq", str(seq)), *((topic, d.hex()) for topic, d in entries)]
    values.append(("mac", _mac(key, name, nonce, values)))
    return DiagnosticStatus(level=DiagnosticStatus.OK, name=name, hardware_id=nonce, message="",
                            values=[KeyValue(key=k, value=v) for k, v in values])


def vouched(key: bytes, msg: DiagnosticStatus) -> tuple[str, int, list[tuple[str, bytes]]]:
    """(nonce, seq, [(topic, digest)]) of a voucher whose MAC is right.

    Raises:
        Rejected: a malformed voucher, or a wrong MAC.
    """
    values = [(kv.key, kv.value) for kv in msg.values]
    if len(values) < 2 or values[0][0] != "seq" or values[-1][0] != "mac" or not values[0][1].isdigit():
        raise Rejected("malformed voucher")
    if not hmac.compare_digest(values[-1][1], _mac(key, msg.name, msg.hardware_id, values[:-1])):
        raise Rejected("voucher with a wrong MAC")
    try:
        entries = [(topic, bytes.fromhex(text)) for topic, text in values[1:-1]]
    except ValueError:
        raise Rejected("malformed voucher") from None
    return msg.hardware_id, int(values[0][1]), entries


class Signer:
    """The sending side: publishers whose messages go out with a voucher on ``/swarm/auth/<role>``."""

    def __init__(self, node, key: bytes, role: str) -> None:
        self.node, self.key = node, key
        self.name = node.get_name()
        self.nonce = secrets.token_hex(8)
        self.seq = 0
        self.pub = node.create_publisher(DiagnosticStatus, auth_topic(role), AUTH_QOS)
        self._batch: list[tuple[object, str, bytes]] | None = None  # (publisher, topic, data) while batching

    def publisher(self, msg_type, topic: str, qos) -> SignedPublisher:
        return SignedPublisher(self, self.node.create_publisher(msg_type, topic, qos), topic)

    @contextmanager
    def batch(self) -> Iterator[None]:
        """Messages published inside go out after one voucher for all of them, at the end."""
        if self._batch is not None:
            yield
            return
        self._batch = []
        try:
            yield
        finally:
            batch, self._batch = self._batch, None
            self._send(batch)

    def _publish(self, pub, topic: str, data: bytes) -> None:
        if self._batch is not None:
            self._batch.append((pub, topic, data))
        else:
            self._send([(pub, topic, data)])

    def _send(self, batch: list[tuple[object, str, bytes]]) -> None:
        if not batch:
            return
        self.seq += 1
        self.pub.publish(voucher(self.key, self.name, self.nonce, self.seq,
                                 [(topic, digest(topic, data)) for _, topic, data in batch]))
        for pub, _, data in batch:
            pub.publish(data)


class SignedPublisher:
    """A publisher whose messages are vouched for by its :class:`Signer`."""

    def __init__(self, signer: Signer, pub, topic: str) -> None:
        self.signer, self.pub, self.topic = signer, pub, topic

    def publish(self, msg) -> bytes:
        """Publish ``msg``, a message or its serialized bytes (vouched for); returns the serialized bytes."""
        data = aligned(msg if isinstance(msg, bytes) else serialize_message(msg))
        self.signer._publish(self.pub, self.topic, data)
        return data

    def wait_for_all_acked(self, timeout: Duration) -> bool:
        """Whether every reader has acknowledged the messages and their vouchers."""
        return self.pub.wait_for_all_acked(timeout) and self.signer.pub.wait_for_all_acked(timeout)


class Gate:
    """The receiving side: serialized subscriptions whose messages reach their handler once vouched for.

    Handlers get messages of one topic in the order they arrived: a vouched message waits
    for nothing but its own voucher, and a sender's vouchers come in order.
    """

    def __init__(self, node, key: bytes, rejections: Rejections) -> None:
        self.node, self.key, self.rejections = node, key, rejections
        self.handlers: dict[str, tuple[type, Callable[[object], None], Callable[[bytes], None] | None]] = {}
        self.held: dict[str, deque[tuple[float, bytes, bytes]]] = {}  # topic -> (arrived, digest, data)
        self.held_bytes = 0
        #: (topic, digest) -> listings not yet matched by a message, oldest first (the oldest are forgotten)
        self.digests: OrderedDict[tuple[str, bytes], int] = OrderedDict()
        self.last_seq: dict[str, int] = {}  # sender process nonce -> the highest sequence number taken
        self.auth_readers: dict[str, object] = {}
        self.received = 0  # callbacks so far (messages and vouchers)

    def subscribe(self, msg_type, topic: str, handler: Callable[[object], None] | None, qos,
                  raw_handler: Callable[[bytes], None] | None = None):
        """A serialized subscription to ``topic``: vouched messages go to ``raw_handler(data)`` (if given),
        then ``handler(message)``. A PointCloud2 reaches ``handler`` read in place
        (:func:`swarm_ros.protocol.cdr.decode_cloud`), not as a message object. Returns the subscription."""
        role = role_of(topic)
        if role not in self.auth_readers:
            topic_ = auth_topic(role)
            self.auth_readers[role] = self.node.create_subscription(
                DiagnosticStatus, topic_, lambda msg, t=topic_: self._on_voucher(t, msg), AUTH_QOS)
        self.handlers[topic] = (msg_type, handler, raw_handler)
        self.held[topic] = deque()
        return self.node.create_subscription(msg_type, topic, lambda data, t=topic: self._on_message(t, data), qos,
                                             raw=True)

    def _on_message(self, topic: str, data: bytes) -> None:
        self.received += 1
        d = digest(topic, data)
        if (topic, d) not in self.digests:
            self._drain_vouchers(role_of(topic))
        if (topic, d) in self.digests:
            self._take(topic, d)
            self._deliver(topic, data)
        else:
            held = self.held[topic]
            held.append((time.monotonic(), d, data))
            self.held_bytes += len(data)
            while held and (len(held) > HOLD_MESSAGES or self.held_bytes > HOLD_BYTES):
                self.held_bytes -= len(held.popleft()[2])
                self.rejections.drop(topic, Rejected("unauthenticated", "no voucher (held messages overflowed)"))
        self.expire()

    def _on_voucher(self, auth: str, msg: DiagnosticStatus) -> None:
        self.received += 1
        try:
            nonce, seq, entries = vouched(self.key, msg)
            if seq <= self.last_seq.get(nonce, 0):
                raise Rejected("replayed voucher", f"sequence number {seq} of {msg.name} again")
        except Rejected as fault:
            self.rejections.drop(auth, fault)
            return
        self.last_seq[nonce] = seq
        for topic, d in entries:
            if topic not in self.handlers or auth_topic(role_of(topic)) != auth:
                continue  # not read here, or not this role's topic (a batch cannot vouch for the world's)
            held = self.held[topic]
            match = next((i for i, (_, hd, _) in enumerate(held) if hd == d), None)
            if match is None:
                self.digests[(topic, d)] = self.digests.get((topic, d), 0) + 1
                self.digests.move_to_end((topic, d))
                if len(self.digests) > KEPT_DIGESTS:
                    self.digests.popitem(last=False)
                continue
            data = held[match][2]
            del held[match]
            self.held_bytes -= len(data)
            self._deliver(topic, data)
        self.expire()

    def _drain_vouchers(self, role: str) -> None:
        """Take the vouchers waiting in ``role``'s reader now: the voucher of a message that just arrived
        was sent before it, and is usually there, but the executor may not have handed it over yet (it
        hands over events in its own order, and sometimes loses one: runner.handle_missed)."""
        reader = self.auth_readers[role]
        while True:
            with reader.handle:
                taken = reader.handle.take_message(reader.msg_type, reader.raw)
            if taken is None:
                return
            reader.callback(taken[0])

    def _take(self, topic: str, d: bytes) -> None:
        key = (topic, d)
        self.digests[key] -= 1
        if self.digests[key] == 0:
            del self.digests[key]

    def _deliver(self, topic: str, data: bytes) -> None:
        msg_type, handler, raw_handler = self.handlers[topic]
        if raw_handler is not None:
            raw_handler(data)
        if handler is None:
            return
        if msg_type is PointCloud2:
            try:
                msg = decode_cloud(data)
            except Rejected as fault:
                self.rejections.drop(topic, fault)
                return
        else:
            msg = deserialize_message(data, msg_type)
        handler(msg)

    def expire(self, now: float | None = None, hold: float = HOLD_SECONDS) -> None:
        """Drop (and count) what has waited for a voucher longer than ``hold`` seconds."""
        now = time.monotonic() if now is None else now
        for topic, held in self.held.items():
            while held and now - held[0][0] > hold:
                self.held_bytes -= len(held.popleft()[2])
                self.rejections.drop(topic, Rejected("unauthenticated", f"no voucher within {hold:g} s"))

    def settle(self) -> None:
        """At the end of the run: drop (and count) what has waited ``SETTLE_SECONDS`` already, so the
        counts the node reports include the messages an outsider sent in the run's last seconds."""
        self.expire(hold=SETTLE_SECONDS)

    def readers_matched(self) -> bool:
        """Whether every voucher reader has matched a writer."""
        return all(r.get_publisher_count() > 0 for r in self.auth_readers.values())


def open_auth(node, role: str, rejections: Rejections) -> tuple[Signer, Gate]:
    """A node's :class:`Signer` (vouching as ``role``) and :class:`Gate`, under the run's key.

    Raises:
        ConfigError: SWARM_ROS_RUN_KEY is set but too short.
    """
    key, secret = run_key()
    if not secret:
        node.get_logger().warn(f"{KEY_ENV} is not set: this node vouches with a public key, so any participant "
                               f"on the ROS domain can impersonate the run's nodes (docs/security.md)")
    return Signer(node, key, role), Gate(node, key, rejections)
