"""A world shard's endpoints to its peers (``--world-shards S``): the topics under /swarm/shards, turned into
calls on its :class:`~swarm_ros.protocol.shard_exchange.ShardExchange`, and the exchange's sends turned into
messages. A world alone (S = 1) has no peers, and so no endpoints here.

Every message is taken only once its tag proves it (the node's gate) and it passes its checks; one that fails is
dropped whole and counted. A peer's part comes as two messages of a tick, its rows and its counts: they are held
until both are in, then handed over as one part.
"""

from __future__ import annotations

import functools

import numpy as np
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Int64MultiArray

from swarm_ros.core.errors import Rejected
from swarm_ros.core.rules import Decisions
from swarm_ros.core.shard_parts import Part
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.plan import again_topic, claims_topic, counts_topic, part_topic
from swarm_ros.protocol.rows import decision_row, decision_rows, decisions_of
from swarm_ros.protocol.shard_exchange import KEPT_TICKS, ShardExchange
from swarm_ros.protocol.shard_rows import assemble, counts_data, counts_of, part_row, part_rows
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import Gate, Signer


class ShardLinks:
    """Shard ``index`` of ``shards``' publishers to and subscriptions from each peer; :attr:`exchange`: its exchange
    (set once the node has loaded, before a callback can run)."""

    def __init__(
        self,
        signer: Signer,
        gate: Gate,
        rejections: Rejections,
        index: int,
        shards: int,
        robots: int,
        dims: int,
    ) -> None:
        self.index, self.shards, self.robots, self.dims = index, shards, robots, dims
        self.rejections = rejections
        self.exchange: ShardExchange | None = None
        self.peers = [j for j in range(shards) if j != index]
        signed, qos = signer.publisher, msgs.SHARDS_QOS
        self.pub_claims = {j: signed(PointCloud2, claims_topic(index, j), qos) for j in self.peers}
        self.pub_parts = {j: signed(PointCloud2, part_topic(index, j), qos) for j in self.peers}
        self.pub_counts = signed(Int64MultiArray, counts_topic(index), qos) if self.peers else None
        self.pub_again = signed(Int64MultiArray, again_topic(index), msgs.AGAIN_QOS) if self.peers else None
        self.held: dict[tuple[int, int], dict[str, object]] = {}  # (peer, tick) -> its part's rows and counts
        self.parts_sent: set[tuple[int, int]] = set()  # (tick, peer) of the parts sent in the kept ticks
        self.peer_rows = [0, 0]  # part rows and claims taken from the peers (scripts/bench_scale.py reports them)
        for j in self.peers:
            for topic, handler, kind, q in (
                (claims_topic(j, index), self._on_claims, PointCloud2, qos),
                (part_topic(j, index), self._on_part_rows, PointCloud2, qos),
                (counts_topic(j), self._on_counts, Int64MultiArray, qos),
                (again_topic(j), self._on_again, Int64MultiArray, msgs.AGAIN_QOS),
            ):
                gate.subscribe(kind, topic, functools.partial(handler, j, topic), q)

    def _exchange(self) -> ShardExchange:
        assert self.exchange is not None  # set in the node's load(), before the first callback
        return self.exchange

    def summary(self) -> str:
        """How much it took from its peers (scripts/bench_scale.py reads it); "" without peers or an exchange."""
        if not self.peers or self.exchange is None:
            return ""
        rows, claims = self.peer_rows
        return f"received {rows} part rows and {claims} claims from its peers up to tick {self.exchange.tick}"

    # -- inbound ---------------------------------------------------------------------
    def _on_claims(self, peer: int, topic: str, msg: Cloud) -> None:
        try:
            tick = checks.tick_stamp(msg.header)
            rows = checks.cloud(msg, decision_row(self.dims), self.robots, min_rows=0)
            checks.ids_in_range(rows["id"].astype(np.int64), 0, self.robots)
            self.peer_rows[1] += rows.size
            self._exchange().peer_claims(peer, tick, decisions_of(tick, rows))
        except Rejected as fault:
            self.rejections.drop(topic, fault)

    def _on_part_rows(self, peer: int, topic: str, msg: Cloud) -> None:
        try:
            tick = checks.tick_stamp(msg.header)
            rows = checks.cloud(msg, part_row(self.dims), self.robots, min_rows=0)
        except Rejected as fault:
            self.rejections.drop(topic, fault)
            return
        self.peer_rows[0] += rows.size
        self._hold(peer, tick, "rows", rows, topic)

    def _on_counts(self, peer: int, topic: str, msg: Int64MultiArray) -> None:
        try:
            counts = counts_of(np.asarray(msg.data, dtype=np.int64), self.robots, self.shards)
            if counts[1] != peer:
                raise Rejected("unknown shard", f"counts of shard {counts[1]} on {topic}")
        except Rejected as fault:
            self.rejections.drop(topic, fault)
            return
        self._hold(peer, counts[0], "counts", counts, topic)

    def _hold(self, peer: int, tick: int, what: str, value, topic: str) -> None:
        """Keep a peer's part rows or counts of ``tick`` until both are in, then hand the part over."""
        now = self._exchange().tick
        if tick <= now:
            return  # a repeat (history, or sent again)
        if tick > now + 1 + KEPT_TICKS:
            self.rejections.drop(topic, Rejected("future tick", f"tick {tick}; shard at {now}"))
            return
        for key in [key for key in self.held if key[1] <= now]:
            del self.held[key]
        held = self.held.setdefault((peer, tick), {})
        held[what] = value
        if "rows" in held and "counts" in held:
            del self.held[(peer, tick)]
            try:
                part = assemble(tick, peer, held["rows"], held["counts"])  # type: ignore[arg-type]
                self._exchange().peer_part(peer, tick, part)
            except Rejected as fault:
                self.rejections.drop(topic, fault)

    def _on_again(self, peer: int, topic: str, msg: Int64MultiArray) -> None:
        if list(msg.data) == [self.index]:
            self._exchange().resend(peer)

    # -- the exchange's sends -----------------------------------------------------------
    def send_claims(self, peer: int, tick: int, claims: Decisions) -> None:
        self.pub_claims[peer].publish_rows(decision_rows(claims), tick)

    def send_part(self, peer: int, tick: int, part: Part) -> None:
        """The part's rows to ``peer``; its counts, the same for every peer, once a tick on one topic (again with
        the rows of a part sent again: the peer may have dropped what it held)."""
        assert self.pub_counts is not None  # a shard with peers
        self.pub_parts[peer].publish_rows(part_rows(part, self.dims), tick)
        if (tick, peer) in self.parts_sent or all(t != tick for t, _ in self.parts_sent):
            self.pub_counts.publish_ints(counts_data(part), "shard_counts")
        self.parts_sent = {(t, j) for t, j in self.parts_sent if t > tick - 1 - KEPT_TICKS} | {(tick, peer)}

    def ask_again(self, peer: int) -> None:
        assert self.pub_again is not None  # a shard with peers
        self.pub_again.publish(msgs.ids_message(np.array([peer], dtype=np.int64), "shard"))
