"""Tags inside each message (swarm_ros.protocol.tag, swarm_ros.ros.auth) without DDS: a stub node hands
what a Signer publishes to a Gate's callbacks."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import OccupancyGrid
from rclpy.serialization import deserialize_message, serialize_message
from runs import cloud_rows
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Int64MultiArray

from swarm_ros.core.errors import ConfigError, ContractError, Rejected
from swarm_ros.protocol import tag as tags
from swarm_ros.protocol.cdr import cloud_parts, encode_cloud
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.darr_niazi.rows import DECISION_ROW, ROBOT_ROW
from swarm_ros.protocol.plan import CentralTopics
from swarm_ros.protocol.rows import TAG_PREFIX, batch_label, is_tag
from swarm_ros.protocol.runkey import KEY_ENV, PUBLIC_KEY, run_key, with_run_key
from swarm_ros.ros import auth
from swarm_ros.ros import graph as msgs

pytestmark = pytest.mark.unit

KEY = b"k" * 32
TOPICS = CentralTopics.of("darr-niazi")  # a run's topics: the world's robots, a batch's decisions
ROBOTS, DECISIONS = TOPICS.robots, TOPICS.decisions("robot_batch_0")


class _Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def warn(self, text: str) -> None:
        self.lines.append(text)


class _Pub:
    def __init__(self, log: list, topic: str) -> None:
        self.log, self.topic = log, topic

    def publish(self, msg) -> None:
        self.log.append((self.topic, msg))


class _Node:
    """What Signer and Gate use of an rclpy node: publishers append to ``sent``, subscriptions are kept."""

    def __init__(self, name: str = "world") -> None:
        self.name, self.sent, self.callbacks = name, [], {}

    def get_name(self) -> str:
        return self.name

    def create_publisher(self, msg_type, topic, qos):
        return _Pub(self.sent, topic)

    def create_subscription(self, msg_type, topic, callback, qos, raw=False):
        assert raw, "a gate reads serialized messages"
        self.callbacks[topic] = callback
        return object()


def _gate(topics: dict[str, type], key: bytes = KEY):
    """A receiver of ``topics`` (name -> type): its node, gate, and what its handlers got, in order."""
    node, got = _Node("rx"), []
    gate = auth.Gate(node, key, Rejections(_Log()))
    for topic, kind in topics.items():
        gate.subscribe(kind, topic, lambda m, t=topic: got.append((t, m)), None)
    return node, gate, got


def _deliver(rx: _Node, sent: list) -> None:
    for topic, data in sent:
        rx.callbacks[topic](data)


def _rows(dtype, n: int) -> np.ndarray:
    rows = np.zeros(n, dtype=dtype)
    rows["id"] = np.arange(4, 4 + n)
    return rows


def test_every_tagged_type_reaches_its_handler_whole_and_without_its_tag():
    world, batch, monitor = _Node("world"), _Node("robot_batch_0"), _Node("monitor")
    auth.Signer(world, KEY).publisher(PointCloud2, ROBOTS, None).publish_rows(_rows(ROBOT_ROW, 3), 7)
    auth.Signer(world, KEY).publisher(DiagnosticArray, msgs.STATUS, None).publish(
        msgs.status_message(7, "running", "running", extra={"robots": 9})
    )
    auth.Signer(monitor, KEY).publisher(Int64MultiArray, msgs.HELD, None).publish_ints(
        msgs.held_values(7, False), msgs.HELD_LABEL
    )
    hello = msgs.ids_message(np.array([4, 5, 6]))
    hello.layout.dim[0].label = batch_label("robot_batch_0", 2)
    auth.Signer(batch, KEY).publisher(Int64MultiArray, msgs.BATCHES, None).publish(hello)
    rx, gate, got = _gate(
        {
            ROBOTS: PointCloud2,
            msgs.STATUS: DiagnosticArray,
            msgs.HELD: Int64MultiArray,
            msgs.BATCHES: Int64MultiArray,
        }
    )
    _deliver(rx, world.sent + monitor.sent + batch.sent)
    assert gate.rejections.total == 0 and [t for t, _ in got] == [ROBOTS, msgs.STATUS, msgs.HELD, msgs.BATCHES]
    cloud, status, held, batches = (m for _, m in got)
    assert [f.name for f in cloud.fields] == list(ROBOT_ROW.names) and cloud.tag.startswith("swarm_ros.tag:world:")
    assert np.array_equal(np.frombuffer(cloud.data, ROBOT_ROW)["id"], [4, 5, 6])
    assert msgs.status_values(status) == {"tick": "7", "outcome": "running", "robots": "9"}
    assert list(held.data) == [7, 0] and [d.label for d in held.layout.dim] == [msgs.HELD_LABEL]
    assert batches.layout.dim[0].label == "robot_batch_0/2" and list(batches.data) == [4, 5, 6]


def test_outside_readers_see_the_standard_type_with_one_more_field():
    """rclpy's own deserializer reads a tagged message; the tag is where docs/security.md says."""
    node = _Node("world")
    signer = auth.Signer(node, KEY)
    signer.publisher(PointCloud2, ROBOTS, None).publish_rows(_rows(ROBOT_ROW, 2), 3)
    signer.publisher(DiagnosticArray, msgs.STATUS, None).publish(msgs.status_message(3, "running", "x"))
    cloud = deserialize_message(node.sent[0][1], PointCloud2)
    assert cloud.width == 2 and len(cloud.data) == 2 * ROBOT_ROW.itemsize
    last = cloud.fields[-1]
    assert is_tag(last.name) and (last.offset, last.count) == (0, 0)
    assert np.array_equal(cloud_rows(cloud, ROBOT_ROW)["id"], [4, 5])  # a reader of rows skips it
    status = deserialize_message(node.sent[1][1], DiagnosticArray)
    assert status.status[0].values[-1].key == TAG_PREFIX and is_tag(status.status[0].values[-1].value)


def _one_cloud(sender: str = "world", topic: str = ROBOTS, key: bytes = KEY) -> bytes:
    node = _Node(sender)
    auth.Signer(node, key).publisher(PointCloud2, topic, None).publish_rows(_rows(DECISION_ROW, 4), 5)
    return node.sent[0][1]


def test_a_message_without_a_tag_or_with_another_keys_is_dropped_at_once():
    rx, gate, got = _gate({ROBOTS: PointCloud2})
    rx.callbacks[ROBOTS](tags.aligned(encode_cloud(_rows(DECISION_ROW, 4), 5)))  # no tag
    rx.callbacks[ROBOTS](_one_cloud(key=b"x" * 32))  # a tag under another key
    assert got == [] and gate.rejections.counts == {f"{ROBOTS}: unauthenticated": 2}


@pytest.mark.parametrize("where", ["rows", "stamp", "tag's sender", "mac"])
def test_a_changed_byte_anywhere_makes_the_tag_fail(where):
    data = bytearray(_one_cloud())
    text = data.decode("latin-1")
    at = {
        "rows": len(data) - 10,
        "stamp": 5,
        "tag's sender": text.index("swarm_ros.tag:world") + len("swarm_ros.tag:"),
        "mac": text.index("swarm_ros.tag:world") + 60,
    }[where]
    data[at] = data[at] ^ 0x01 if where != "tag's sender" else ord("o")  # 'world' -> 'oorld'
    rx, gate, got = _gate({ROBOTS: PointCloud2})
    rx.callbacks[ROBOTS](bytes(data))
    assert got == [] and sum(gate.rejections.counts.values()) == 1


def test_the_topic_is_part_of_what_the_tag_proves():
    data = _one_cloud(topic=DECISIONS)  # a batch's decisions, sent on as the world's rows
    rx, gate, got = _gate({ROBOTS: PointCloud2})
    rx.callbacks[ROBOTS](data)
    assert got == [] and gate.rejections.counts == {f"{ROBOTS}: unauthenticated": 1}


def test_a_replay_is_refused_and_a_restarted_sender_is_taken():
    rx, gate, got = _gate({ROBOTS: PointCloud2})
    node = _Node("world")
    pub = auth.Signer(node, KEY).publisher(PointCloud2, ROBOTS, None)
    for tick in (1, 2):
        pub.publish_rows(_rows(ROBOT_ROW, 1), tick)
    _deliver(rx, node.sent)
    _deliver(rx, node.sent[:1])  # tick 1's message again, later
    restarted = _Node("world")
    auth.Signer(restarted, KEY).publisher(PointCloud2, ROBOTS, None).publish_rows(_rows(ROBOT_ROW, 1), 3)
    _deliver(rx, restarted.sent)
    assert [m.header.stamp.sec for _, m in got] == [1, 2, 3]
    assert gate.rejections.counts == {f"{ROBOTS}: replayed": 1}


@pytest.mark.parametrize(
    "sender, topic",
    [
        ("robot_batch_0", ROBOTS),
        ("robot_batch_1", DECISIONS),
        ("world", msgs.HELD),
        ("robot_batch_0", msgs.HELD),
        ("monitor", msgs.BATCHES),
    ],
)
def test_a_node_of_the_run_is_taken_only_on_its_own_topics(sender, topic):
    node = _Node(sender)
    kind = Int64MultiArray if topic in (msgs.HELD, msgs.BATCHES) else PointCloud2
    pub = auth.Signer(node, KEY).publisher(kind, topic, None)
    if kind is PointCloud2:
        pub.publish_rows(_rows(DECISION_ROW, 1), 1)
    else:
        hello = msgs.ids_message(np.array([4]))
        hello.layout.dim[0].label = batch_label(sender, 0)
        pub.publish(hello)
    rx, gate, got = _gate({topic: kind})
    _deliver(rx, node.sent)
    assert got == [] and gate.rejections.counts == {f"{topic}: unauthenticated": 1}


def test_a_batch_announces_only_itself():
    node = _Node("robot_batch_1")
    hello = msgs.ids_message(np.array([4]))
    hello.layout.dim[0].label = batch_label("robot_batch_0", 0)
    auth.Signer(node, KEY).publisher(Int64MultiArray, msgs.BATCHES, None).publish(hello)
    rx, gate, got = _gate({msgs.BATCHES: Int64MultiArray})
    _deliver(rx, node.sent)
    assert got == [] and gate.rejections.counts == {f"{msgs.BATCHES}: unauthenticated": 1}


@pytest.mark.parametrize("data", [b"", b"\x00\x01\x00\x00", b"\x00\x01\x00\x00" + b"\xff" * 64, bytes(range(256))])
def test_bytes_that_are_not_the_type_are_dropped_as_malformed(data):
    rx, gate, got = _gate({msgs.STATUS: DiagnosticArray, ROBOTS: PointCloud2})
    rx.callbacks[msgs.STATUS](data)
    rx.callbacks[ROBOTS](data)
    assert got == [] and gate.rejections.total == 2 and gate.received == 2


def test_types_without_a_field_for_a_tag_are_neither_signed_nor_taken():
    node = _Node("world")
    with pytest.raises(ContractError, match="carries no tag"):
        auth.Signer(node, KEY).publisher(OccupancyGrid, msgs.OCCUPANCY, None)
    with pytest.raises(ContractError, match="carries no tag"):
        auth.Gate(node, KEY, Rejections(_Log())).subscribe(OccupancyGrid, msgs.OCCUPANCY, print, None)


def test_parse_tag_refuses_what_is_not_a_tag():
    good = tags.Tag("world", "0123456789abcdef", 12, "a" * 32)
    assert tags.parse_tag(good.text) == good
    for text in (
        "",
        good.text + "0",
        good.text.replace(":12:", ":012:"),
        good.text.replace("world", "wo rld"),
        good.text.upper(),
        "swarm_ros.tag:world:0123456789abcdef:0:" + "a" * 32,
    ):
        with pytest.raises(Rejected, match="unauthenticated"):
            tags.parse_tag(text)


def test_messages_are_aligned_to_four_bytes_as_dds_delivers_them():
    assert tags.aligned(b"abc") == b"abc\x00" and tags.aligned(b"abcd") == b"abcd"
    node = _Node("world")
    auth.Signer(node, KEY).publisher(DiagnosticArray, msgs.STATUS, None).publish(msgs.status_message(1, "r", "x"))
    assert len(node.sent[0][1]) % 4 == 0


@pytest.mark.parametrize("n", [0, 1, 3, 1000])
def test_a_cloud_sealed_in_parts_is_the_cloud_sealed_whole(n):
    """The publishers seal a cloud's parts (the rows not copied); the bytes are those of sealing it whole, and a
    verifier takes them."""
    rows = _rows(ROBOT_ROW, n)
    parts_sealer, whole_sealer = tags.Sealer(KEY, "world"), tags.Sealer(KEY, "world")
    whole_sealer.nonce = parts_sealer.nonce
    blank, same_blank = parts_sealer.blank(), whole_sealer.blank()
    sealed = parts_sealer.seal(ROBOTS, cloud_parts(rows, 7, tag=blank), blank)
    assert sealed == whole_sealer.seal(ROBOTS, encode_cloud(rows, 7, tag=same_blank), same_blank)
    assert len(sealed) % 4 == 0
    assert tags.Verifier(KEY).verify(ROBOTS, sealed).sender == "world"
    with pytest.raises(ContractError, match="blank tag"):  # a blank among the rows is not where a tag belongs
        parts_sealer.seal(ROBOTS, (b"head", memoryview(blank.encode())), blank)


def test_the_run_key_comes_from_the_environment():
    assert run_key({}) == (PUBLIC_KEY, False)
    assert run_key({KEY_ENV: "x" * 16}) == (b"x" * 16, True)
    with pytest.raises(ConfigError, match="at least 16"):
        run_key({KEY_ENV: "short"})
    env = with_run_key({})
    assert len(env[KEY_ENV]) == 64 and with_run_key(dict(env)) == env


def test_only_a_key_holders_bytes_reach_a_parser_and_they_must_parse_with_the_tag_in_its_place():
    rx, gate, got = _gate({msgs.STATUS: DiagnosticArray, ROBOTS: PointCloud2})
    sealer = tags.Sealer(KEY, "world")
    for topic in (msgs.STATUS, ROBOTS):  # sealed garbage: proven, then refused by the parser
        blank = sealer.blank()
        rx.callbacks[topic](sealer.seal(topic, b"\x00\x01\x00\x00" + blank.encode() + b"\xff" * 40, blank))
    status = msgs.status_message(1, "running", "x")
    blank = sealer.blank()
    status.status[0].message = blank  # the tag in another field than its own
    rx.callbacks[msgs.STATUS](sealer.seal(msgs.STATUS, serialize_message(status), blank))
    assert got == [] and gate.rejections.counts == {
        f"{msgs.STATUS}: malformed CDR": 1,
        f"{ROBOTS}: malformed CDR": 1,
        f"{msgs.STATUS}: unauthenticated": 1,
    }


class _RosNode(_Node):
    """The stub, with what a node class also uses: a logger, and subscriptions with event callbacks."""

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.log = _Log()

    def get_logger(self) -> _Log:
        return self.log

    def create_subscription(self, msg_type, topic, callback, qos, raw=False, event_callbacks=None):
        self.callbacks[topic] = callback
        return object()


def test_the_world_node_counts_a_key_holders_decisions_that_its_checks_refuse(monkeypatch):
    """A batch's decisions sealed under the run's key, whose rows are not decision rows: the gate proves them,
    the node's checks refuse them, and the world node counts them by topic and goes on (no tick is decided)."""
    from swarm_ros.core.params import NODE_PARAMETERS, Settings
    from swarm_ros.nodes.central.world import CentralWorldNode

    monkeypatch.setenv(KEY_ENV, KEY.decode())
    node = _RosNode("world")
    own = {p.name: p.default for p in NODE_PARAMETERS["world"]}
    world = CentralWorldNode(node, Settings(shape="star", algorithm="rubenstein", robots=150), own)
    world.watch_batch("robot_batch_0")
    topic = CentralTopics.of("rubenstein").decisions("robot_batch_0")
    assert topic in node.callbacks
    batch = _Node("robot_batch_0")
    auth.Signer(batch, KEY).publisher(PointCloud2, topic, None).publish_rows(_rows(ROBOT_ROW, 2), 1)
    node.callbacks[topic](batch.sent[0][1])
    assert world.rejections.counts == {f"{topic}: point layout": 1}, world.rejections.counts
