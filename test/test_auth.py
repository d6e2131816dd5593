"""Vouchers (swarm_ros.ros.auth) without DDS: a stub node hands the Gate's callbacks to the test."""

from __future__ import annotations

from collections import deque

import pytest

pytest.importorskip("rclpy")

from diagnostic_msgs.msg import DiagnosticArray, KeyValue  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402

from swarm_ros.core.errors import ConfigError  # noqa: E402
from swarm_ros.protocol.checks import Rejections  # noqa: E402
from swarm_ros.protocol.runkey import KEY_ENV, PUBLIC_KEY, run_key, with_run_key  # noqa: E402
from swarm_ros.ros import auth  # noqa: E402
from swarm_ros.ros import graph as msgs  # noqa: E402

pytestmark = pytest.mark.unit

KEY = b"k" * 32


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


class _Subscription:
    """What Gate takes from a reader itself (as runner.handle_missed does): messages still waiting in it."""

    def __init__(self, msg_type, callback, raw: bool, waiting: list) -> None:
        self.msg_type, self.callback, self.raw, self.waiting = msg_type, callback, raw, waiting
        self.handle = self

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass

    def take_message(self, msg_type, raw):
        return (self.waiting.pop(0), {}) if self.waiting else None


class _Node:
    """What Signer and Gate use of an rclpy node: publishers append to ``sent``, subscriptions are kept."""

    def __init__(self, name: str = "world") -> None:
        self.name, self.sent, self.callbacks = name, [], {}
        self.waiting: dict[str, list] = {}  # topic -> messages in its reader, not handed to the callback

    def get_name(self) -> str:
        return self.name

    def create_publisher(self, msg_type, topic, qos):
        return _Pub(self.sent, topic)

    def create_subscription(self, msg_type, topic, callback, qos, raw=False):
        self.callbacks[topic] = callback
        return _Subscription(msg_type, callback, raw, self.waiting.setdefault(topic, []))


class _Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch):
    clock = _Clock()
    monkeypatch.setattr(auth.time, "monotonic", clock)
    return clock


def _status(tick: int) -> DiagnosticArray:
    return msgs.status_message(tick, "running", f"tick {tick}")


def _receiver():
    node = _Node("rx")
    got: list = []
    gate = auth.Gate(node, KEY, Rejections(_Log()))
    gate.subscribe(DiagnosticArray, msgs.STATUS, lambda m: got.append(msgs.tick_of(m.header)), None)
    return node, gate, got


def _deliver(node: _Node, sent: list, order=None) -> None:
    """Hand what a Signer published to the receiver's callbacks (in ``order``: indices into ``sent``)."""
    for i in (range(len(sent)) if order is None else order):
        topic, msg = sent[i]
        node.callbacks[topic](msg)


def _world(key: bytes = KEY, name: str = "world"):
    node = _Node(name)
    signer = auth.Signer(node, key, "world")
    return node, signer, signer.publisher(DiagnosticArray, msgs.STATUS, None)


def test_a_vouched_message_is_taken_once_whichever_comes_first(clock):
    node, signer, pub = _world()
    pub.publish(_status(1))
    pub.publish(_status(2))
    assert [t for t, _ in node.sent] == [auth.auth_topic("world"), msgs.STATUS] * 2  # voucher first
    rx, gate, got = _receiver()
    _deliver(rx, node.sent, [1, 0, 2, 3])  # the message of tick 1 before its voucher
    assert got == [1, 2]
    _deliver(rx, node.sent, [3])  # the same bytes again: one listing admits one message
    clock.now += auth.HOLD_SECONDS + 0.1
    gate.expire()
    assert got == [1, 2]
    assert gate.rejections.counts == {f"{msgs.STATUS}: unauthenticated": 1}


def test_a_voucher_waiting_in_its_reader_is_taken_when_its_message_arrives(clock):
    node, signer, pub = _world()
    pub.publish(_status(1))
    rx, gate, got = _receiver()
    rx.waiting[auth.auth_topic("world")].append(node.sent[0][1])  # arrived, not handed over by the executor
    _deliver(rx, node.sent, [1])
    assert got == [1] and gate.held[msgs.STATUS] == deque() and rx.waiting[auth.auth_topic("world")] == []


def test_a_message_nobody_vouched_for_is_dropped_and_counted_after_the_hold(clock):
    rx, gate, got = _receiver()
    rx.callbacks[msgs.STATUS](auth.aligned(serialize_message(_status(5))))
    clock.now += auth.HOLD_SECONDS / 2
    gate.expire()
    assert gate.rejections.total == 0  # its voucher may still come
    clock.now += auth.HOLD_SECONDS
    gate.expire()
    assert got == [] and gate.rejections.counts == {f"{msgs.STATUS}: unauthenticated": 1}


def test_at_the_end_of_a_run_what_waited_a_moment_is_judged_at_once(clock):
    rx, gate, got = _receiver()
    rx.callbacks[msgs.STATUS](auth.aligned(serialize_message(_status(5))))
    clock.now += auth.SETTLE_SECONDS / 2
    rx.callbacks[msgs.STATUS](auth.aligned(serialize_message(_status(6))))
    clock.now += auth.SETTLE_SECONDS * 0.75
    gate.settle()
    assert gate.rejections.total == 1 and len(gate.held[msgs.STATUS]) == 1  # the second is too recent


def test_a_forgery_before_the_real_message_is_not_taken_and_does_not_block_it(clock):
    node, signer, pub = _world()
    pub.publish(_status(3))
    rx, gate, got = _receiver()
    forged = _status(3)
    forged.status[0].message = "complete at tick 3"
    rx.callbacks[msgs.STATUS](auth.aligned(serialize_message(forged)))
    _deliver(rx, node.sent)
    assert got == [3]
    clock.now += auth.HOLD_SECONDS + 0.1
    gate.expire()
    assert gate.rejections.counts == {f"{msgs.STATUS}: unauthenticated": 1}


@pytest.mark.parametrize("tamper", ["key", "digest", "seq", "name", "no mac", "bad hex"])
def test_a_voucher_that_is_not_the_keys_is_dropped(clock, tamper):
    node, signer, pub = _world(key=b"another key entirely" if tamper == "key" else KEY)
    data = pub.publish(_status(4))
    voucher = node.sent[0][1]
    if tamper == "digest":
        voucher.values[1].value = auth.digest(msgs.STATUS, data + b"x").hex()
    elif tamper == "seq":
        voucher.values[0].value = "99"
    elif tamper == "name":
        voucher.name = "monitor"
    elif tamper == "no mac":
        voucher.values = voucher.values[:-1]
    elif tamper == "bad hex":  # a well-signed voucher whose digest is not hex
        voucher.values[1].value = "zz"
        values = [(kv.key, kv.value) for kv in voucher.values[:-1]]
        voucher.values[-1] = KeyValue(key="mac", value=auth._mac(KEY, voucher.name, voucher.hardware_id, values))
    rx, gate, got = _receiver()
    _deliver(rx, node.sent)
    clock.now += auth.HOLD_SECONDS + 0.1
    gate.expire()
    assert got == []
    kind = {"key": "voucher with a wrong MAC", "no mac": "malformed voucher", "bad hex": "malformed voucher"}.get(
        tamper, "voucher with a wrong MAC")
    assert gate.rejections.counts == {f"{auth.auth_topic('world')}: {kind}": 1,
                                      f"{msgs.STATUS}: unauthenticated": 1}


def test_a_replayed_voucher_admits_nothing(clock):
    node, signer, pub = _world()
    pub.publish(_status(6))
    rx, gate, got = _receiver()
    _deliver(rx, node.sent)
    _deliver(rx, node.sent)  # voucher and message again, as a recording of them would replay them
    clock.now += auth.HOLD_SECONDS + 0.1
    gate.expire()
    assert got == [6]
    assert gate.rejections.counts == {f"{auth.auth_topic('world')}: replayed voucher": 1,
                                      f"{msgs.STATUS}: unauthenticated": 1}


def test_several_senders_on_one_topic_are_each_taken_in_any_order(clock):
    a, _, pub_a = _world(name="batch_a")
    b, _, pub_b = _world(name="batch_b")
    pub_a.publish(_status(1))
    pub_b.publish(_status(2))
    rx, gate, got = _receiver()
    # a's message, b's message, b's voucher, a's voucher: a's waits for its own voucher, not b's
    for topic, msg in (a.sent[1], b.sent[1], b.sent[0], a.sent[0]):
        rx.callbacks[topic](msg)
    assert got == [2, 1] and gate.rejections.total == 0


def test_a_batch_vouches_for_its_messages_at_once(clock):
    node, signer, pub = _world()
    other = signer.publisher(DiagnosticArray, msgs.OCCUPANCY, None)
    with signer.batch():
        pub.publish(_status(1))
        with signer.batch():  # nested: still one voucher
            other.publish(_status(2))
        assert node.sent == []  # nothing goes out before the batch ends
    assert [t for t, _ in node.sent] == [auth.auth_topic("world"), msgs.STATUS, msgs.OCCUPANCY]
    assert [kv.key for kv in node.sent[0][1].values] == ["seq", msgs.STATUS, msgs.OCCUPANCY, "mac"]


def test_vouchers_for_other_topics_are_not_kept_and_kept_digests_are_bounded(clock, monkeypatch):
    monkeypatch.setattr(auth, "KEPT_DIGESTS", 3)
    node, signer, pub = _world()
    other = signer.publisher(DiagnosticArray, msgs.OCCUPANCY, None)
    for tick in range(5):
        other.publish(_status(tick))
        pub.publish(_status(tick))
    rx, gate, got = _receiver()
    _deliver(rx, [s for s in node.sent if s[0] == auth.auth_topic("world")])  # only the vouchers
    assert len(gate.digests) == 3 and all(topic == msgs.STATUS for topic, _ in gate.digests)
    _deliver(rx, [s for s in node.sent if s[0] == msgs.STATUS])
    assert got == [2, 3, 4]  # the two oldest listings were forgotten


def test_a_voucher_counts_only_for_its_roles_topics(clock):
    from std_msgs.msg import Int64MultiArray

    node = _Node("robot_batch_0")
    signer = auth.Signer(node, KEY, "batches")  # on /swarm/auth/batches, vouching for a monitor's topic
    signer.publisher(Int64MultiArray, msgs.METRICS, None).publish(msgs.metrics_message([3] + [0] * 6))
    assert node.sent[0][0] == auth.auth_topic("batches")
    rx = _Node("world")
    gate = auth.Gate(rx, KEY, Rejections(_Log()))
    got = []
    gate.subscribe(Int64MultiArray, msgs.METRICS, got.append, None)
    gate.subscribe(Int64MultiArray, msgs.BATCHES, got.append, None)  # the world reads /swarm/auth/batches too
    _deliver(rx, node.sent)
    assert got == [] and not gate.digests


def test_what_waits_for_a_voucher_is_bounded_in_count_and_bytes(clock, monkeypatch):
    monkeypatch.setattr(auth, "HOLD_MESSAGES", 3)
    rx, gate, got = _receiver()
    for tick in range(5):
        rx.callbacks[msgs.STATUS](auth.aligned(serialize_message(_status(tick))))
    assert len(gate.held[msgs.STATUS]) == 3 and gate.rejections.total == 2
    monkeypatch.setattr(auth, "HOLD_BYTES", 1000)
    rx.callbacks[msgs.STATUS](b"x" * 2000)  # bigger than all that may wait: dropped with the rest
    assert len(gate.held[msgs.STATUS]) == 0 and gate.held_bytes == 0 and gate.rejections.total == 6


def test_messages_are_aligned_to_four_bytes_as_dds_delivers_them():
    assert auth.aligned(b"abcde") == b"abcde\0\0\0" and auth.aligned(b"abcd") == b"abcd"
    assert auth.digest("/t", b"abcde") == auth.digest("/t", b"abcde\0\0\0") != auth.digest("/u", b"abcde")


def test_the_run_key_comes_from_the_environment():
    assert run_key({}) == (PUBLIC_KEY, False)
    assert run_key({KEY_ENV: "x" * 16}) == (b"x" * 16, True)
    with pytest.raises(ConfigError, match="at least 16 characters"):
        run_key({KEY_ENV: "short"})
    made = with_run_key({})[KEY_ENV]
    assert len(made) == 64 and made != with_run_key({})[KEY_ENV]
    assert with_run_key({KEY_ENV: "y" * 20}) == {KEY_ENV: "y" * 20}


def test_roles():
    assert auth.role_of(msgs.ROBOTS) == auth.role_of(msgs.snapshot_topic("b")) == auth.role_of(msgs.DECISIONS) \
        == "world"
    assert auth.role_of(msgs.decisions_topic("b")) == auth.role_of(msgs.BATCHES) == "batches"
    assert auth.role_of(msgs.METRICS) == "monitor"
