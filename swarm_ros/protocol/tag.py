"""Authentication inside each message: a tag, under the run's key, carried in a typed field of the message.

A node that holds the run's key (:mod:`swarm_ros.protocol.runkey`) seals each message it
sends with a *tag*, a text field of the message itself (where it lives in each type:
:mod:`swarm_ros.ros.auth`, docs/security.md)::

    swarm_ros.tag:<sender>:<nonce>:<seq>:<mac>

``sender`` is the node's name, ``nonce`` 16 hex digits drawn once per process, ``seq`` a
counter of the process's messages that only grows, and ``mac`` the first 16 bytes (32 hex
digits) of HMAC-SHA256 under the key over the topic's name, a zero byte and the message's
serialized bytes with the 32 digits of ``mac`` written as zeros. The serialized bytes hold
everything the message says, its stamp (the tick) and the tag's other parts, so the MAC
covers content, topic, tick and sender. A receiver verifies a message alone, on arrival:
the MAC, that the sender may publish on that topic, and that the sequence number is higher
than any it took from that process on that topic (a replay is refused). Nothing is held.

No rclpy here: the tag is computed over bytes, so unit tests and the benches use it without ROS.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import secrets
from collections.abc import Sequence
from dataclasses import dataclass

from swarm_ros.core.errors import ContractError, Rejected
from swarm_ros.protocol.plan import (
    BATCHES,
    HELD,
    MONITOR,
    central_sender,
    is_world,
    shard_name,
    shard_of_topic,
)
from swarm_ros.protocol.rows import TAG_PREFIX

MAC_CHARS = 32  #: hex digits of the MAC (128 bits)
BLANK = "0" * MAC_CHARS
#: sender (a node name), nonce, sequence number (from 1), MAC
_TAG = re.compile(
    re.escape(TAG_PREFIX) + r":([A-Za-z_][A-Za-z0-9_]{0,63}):([0-9a-f]{16}):([1-9][0-9]{0,18}):"
    r"([0-9a-f]{32})"
)
_TAG_BYTES = re.compile(_TAG.pattern.encode())


@dataclass(frozen=True)
class Tag:
    sender: str
    nonce: str
    seq: int
    mac: str

    @property
    def text(self) -> str:
        return f"{TAG_PREFIX}:{self.sender}:{self.nonce}:{self.seq}:{self.mac}"


def parse_tag(text: str) -> Tag:
    """The tag written as ``text``.

    Raises:
        Rejected: ("unauthenticated") not a tag.
    """
    m = _TAG.fullmatch(text)
    if m is None:
        raise Rejected("unauthenticated", "no tag" if not text else f"malformed tag {text[:40]!r}")
    return Tag(m[1], m[2], int(m[3]), m[4])


def find_tag(data: bytes) -> tuple[str, int]:
    """(text, offset) of the first tag in a serialized message, found without parsing the message: an
    untagged one is refused before any parser reads it. Where a tag belongs in each type is checked once
    the tag proved the bytes (:mod:`swarm_ros.ros.auth`).

    Raises:
        Rejected: ("unauthenticated") no tag in the bytes.
    """
    m = _TAG_BYTES.search(data)
    if m is None:
        raise Rejected("unauthenticated", "no tag")
    return m.group().decode(), m.start()


def aligned(data: bytes) -> bytes:
    """``data`` with zero bytes up to a multiple of 4, as DDS delivers serialized messages.

    A serialized message that does not end on a 4-byte boundary reaches a reader of
    another process padded with zeros (measured here: 321 bytes sent, 324 received);
    readers ignore the padding. Senders pad first, so what is sealed is what arrives.
    """
    return data + padding(len(data))


def padding(size: int) -> bytes:
    """The zero bytes :func:`aligned` appends to a message of ``size`` bytes."""
    return bytes(-size % 4)


def mac_of(key: bytes, topic: str, data: bytes | memoryview, at: int) -> str:
    """The MAC of ``data`` on ``topic``, the 32 bytes at ``at`` (the MAC's own digits) read as zeros."""
    view = memoryview(data)
    return _mac(key, topic, (view[:at], BLANK.encode(), view[at + MAC_CHARS :]))


def _mac(key: bytes, topic: str, parts) -> str:
    """The MAC of the bytes ``parts`` make, joined, on ``topic``."""
    h = hmac.new(key, topic.encode() + b"\0", hashlib.sha256)
    for part in parts:
        h.update(part)
    return h.hexdigest()[:MAC_CHARS]


def may_send(sender: str, topic: str) -> bool:
    """Whether a node named ``sender`` publishes on ``topic`` in the graph: the world (or a world shard) its
    topics, the monitor what it holds, a batch its announcement and its own decisions topic, world shard i the
    topics under /swarm/shards/<i>."""
    if topic == HELD:
        return sender == MONITOR
    if topic == BATCHES:
        return not is_world(sender) and sender != MONITOR
    central = central_sender(topic)  # a batch's decisions
    if central is not None:
        return sender == central
    shard = shard_of_topic(topic)
    if shard is not None:
        return sender == shard_name(shard)
    return is_world(sender)


class Sealer:
    """The sending side of one process: blank tags to put in messages, and their MACs once serialized."""

    def __init__(self, key: bytes, sender: str) -> None:
        self.key, self.sender = key, sender
        self.nonce = secrets.token_hex(8)
        self.seq = 0

    def blank(self) -> str:
        """The next message's tag, its MAC still zeros: put it in the message, serialize, then :meth:`seal`."""
        self.seq += 1
        return Tag(self.sender, self.nonce, self.seq, BLANK).text

    def seal(self, topic: str, data: bytes | Sequence[bytes | memoryview], blank: str) -> bytes:
        """``data`` (a message serialized with the tag ``blank`` in it), aligned, with its MAC written in.

        ``data`` may come in parts (a cloud's head, its rows as a buffer, its tail:
        :func:`swarm_ros.protocol.cdr.cloud_parts`), the blank in a ``bytes`` part: the MAC is taken over the parts
        and they are joined once, so the rows are copied once, not three times (a tick's 2 MB of rows cost the
        world 4.6 ms in copies before).
        """
        parts = [data] if isinstance(data, bytes | bytearray) else list(data)
        size = sum(memoryview(part).nbytes for part in parts)
        parts.append(padding(size))  # aligned, as DDS delivers it
        mark = blank.encode()
        found = [
            (k, at)
            for k, part in enumerate(parts)
            if isinstance(part, bytes | bytearray) and (at := part.find(mark)) >= 0
        ]
        if not found:
            raise ContractError("the message does not hold its blank tag")
        k, at = found[0]
        mac = _mac(self.key, topic, parts)  # the MAC's digits are zeros (BLANK) meanwhile, as mac_of reads them
        at += len(mark) - MAC_CHARS
        part = parts[k]
        parts[k] = part[:at] + mac.encode() + part[at + MAC_CHARS :]
        return b"".join(parts)


class Known(Rejected):
    """A message this node's process before this one took already (:meth:`Verifier.taken_before`): not an
    attack."""


class Verifier:
    """The receiving side of one process: checks each message's tag, remembering each sender's last number."""

    def __init__(self, key: bytes) -> None:
        self.key = key
        self.last: dict[tuple[str, str], int] = {}  # (topic, nonce) -> highest seq taken; genuine senders only
        self.taken: dict[tuple[str, str], int] = {}  # the same, taken by a process before this one

    def taken_before(self) -> None:
        """Count every message taken so far as taken by this node's process before this one: the same
        message again is refused as :class:`Known`, not as a replay. A restarted monitor reads back what it
        had recorded (through :meth:`verify`), then the writers' histories hand it the same messages again."""
        self.taken = dict(self.last)

    def verify(self, topic: str, data: bytes) -> Tag:
        """The tag in ``data`` (a serialized message as received, :func:`find_tag`), if it proves the message.

        Raises:
            Rejected: no or a malformed tag, a wrong MAC, a sender that does not publish on
                ``topic`` ("unauthenticated"); a sequence number taken already ("replayed").
        """
        text, at = find_tag(data)
        tag = parse_tag(text)
        if not hmac.compare_digest(mac_of(self.key, topic, data, at + len(text) - MAC_CHARS), tag.mac):
            raise Rejected("unauthenticated", f"a tag with a wrong MAC (sender {tag.sender!r})")
        if not may_send(tag.sender, topic):
            raise Rejected("unauthenticated", f"{tag.sender!r} does not publish on {topic}")
        key = (topic, tag.nonce)
        if tag.seq <= self.taken.get(key, 0):
            raise Known("recorded already", f"{tag.sender}'s message {tag.seq}")
        if tag.seq <= self.last.get(key, 0):
            raise Rejected("replayed", f"{tag.sender}'s message {tag.seq} again (after {self.last[key]})")
        self.last[key] = tag.seq
        return tag
