"""A world shard node: the world's endpoints for the robot batches in its strips, and its exchanges with the
other shards (``swarm-ros run --world-shards S``).

A thin shell, as the world node is: every decision is :class:`swarm_ros.protocol.shard_lockstep.ShardLockstep`'s
(admission, ticks, the monitor window, lost batches) or its :class:`~swarm_ros.protocol.shard_exchange.ShardExchange`'s
(claims, parts, repeats, restarts). This node turns the topics under /swarm/shards into calls on them, joining a
peer's part rows and counts of one tick, and saves the shard at every close (``checkpoint``), written to a
temporary name and renamed, before anything of the next tick goes out. Every message is taken only once its tag
proves it and it passes its checks; one that fails is dropped whole and counted.

    ros2 run swarm_ros world_shard --ros-args -r __node:=world_shard_0 -p shard:=0 -p shards:=2 -p batches:=4 \\
        --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Int64MultiArray

from swarm_ros.core.errors import ConfigError, ParameterError, Rejected
from swarm_ros.core.regions import batch_cuts, shard_batches, shard_cuts
from swarm_ros.core.rules import Decisions
from swarm_ros.core.shard_parts import Part
from swarm_ros.core.shards import ShardPlan, WorldShard
from swarm_ros.core.warmup import warm_up
from swarm_ros.nodes.world import WorldNode
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.plan import WORLD_SHARD, again_topic, claims_topic, counts_topic, part_topic
from swarm_ros.protocol.rows import decision_row, decision_rows, decisions_of
from swarm_ros.protocol.shard_exchange import KEPT_TICKS
from swarm_ros.protocol.shard_lockstep import ShardLockstep
from swarm_ros.protocol.shard_rows import assemble, counts_data, counts_of, part_row, part_rows
from swarm_ros.protocol.shard_save import ShardSaver
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.runtime import EXIT_INTERRUPTED, EXIT_OK, run_node


class WorldShardNode(WorldNode):
    """World shard ``shard``'s endpoints around a :class:`ShardLockstep`; its port (``ShardNodePort``)."""

    KIND = WORLD_SHARD

    def __init__(self) -> None:
        super().__init__()
        p = self.placement
        self.index, self.shards, batches = int(p["shard"]), int(p["shards"]), int(p["batches"])
        try:
            shard_batches(self.index, self.shards, batches)  # checks S <= K and the index
            cuts = batch_cuts(self.shape, self.params, batches, str(p["region_cuts"]))
        except ParameterError as exc:
            raise ConfigError(f"node '{self.node.get_name()}': {exc}") from None
        between = shard_cuts(cuts, self.shards, batches)
        self.plan = ShardPlan(self.shape.world.radius, self.params.vision_radius, between)
        self.peers = [j for j in range(self.shards) if j != self.index]
        signed, qos = self.signer.publisher, msgs.SHARDS_QOS
        self.pub_claims = {j: signed(PointCloud2, claims_topic(self.index, j), qos) for j in self.peers}
        self.pub_parts = {j: signed(PointCloud2, part_topic(self.index, j), qos) for j in self.peers}
        self.pub_counts = signed(Int64MultiArray, counts_topic(self.index), qos)
        self.pub_again = signed(Int64MultiArray, again_topic(self.index), msgs.AGAIN_QOS)
        self.held: dict[tuple[int, int], dict[str, object]] = {}  # (peer, tick) -> its part's rows and counts
        self.shard_saver: ShardSaver | None = None  # made in load(), with a checkpoint path
        self.parts_sent: set[tuple[int, int]] = set()  # (tick, peer) of the parts sent in the kept ticks
        self.peer_rows = [0, 0]  # part rows and claims taken from the peers (scripts/bench_scale.py reports them)
        for j in self.peers:
            for topic, handler, kind, q in (
                (claims_topic(j, self.index), self._on_claims, PointCloud2, qos),
                (part_topic(j, self.index), self._on_part_rows, PointCloud2, qos),
                (counts_topic(j), self._on_counts, Int64MultiArray, qos),
                (again_topic(j), self._on_again, Int64MultiArray, msgs.AGAIN_QOS),
            ):
                self.gate.subscribe(kind, topic, functools.partial(handler, j, topic), q)

    @property
    def shard_ls(self) -> ShardLockstep:
        assert isinstance(self.lockstep, ShardLockstep)
        return self.lockstep

    def load(self) -> None:
        shard = WorldShard(self.shape, self.params, self.plan, self.index)
        warm_up(self.shape, self.params)
        if self.viewers:
            self.pub_shape.publish(self.maps.shape_message(0))
        name, log = self.node.get_name(), self.node.get_logger()
        self.lockstep = ls = ShardLockstep(shard, name, self.policy, self, log, self.rejections, created=self.created)
        saved = None
        if self.checkpoint_path:
            self.shard_saver = saver = ShardSaver(
                Path(self.checkpoint_path),
                self.params,
                self.plan,
                self.index,
                self.policy.monitor_window + 2,
                self.shape.dims,
            )
            if self.incarnation and saver.path.exists():
                saved = saver.restore()
            else:
                saver.create()
        if saved is not None:
            ls.restore(saved, self.incarnation)
        else:
            ls.restarts += [(0, name)] * self.incarnation
        self._publish_occupancy()
        ls.publish_status()
        if saved is None:
            first, last = shard.strip
            log.info(f"{name}: columns {first}..{last} of {self.shape.name}, waiting for its robot batches")

    # -- inbound from peers ------------------------------------------------------------
    def _on_claims(self, peer: int, topic: str, msg: Cloud) -> None:
        try:
            tick = checks.tick_stamp(msg.header)
            rows = checks.cloud(msg, decision_row(self.shape.dims), self.params.robots, min_rows=0)
            checks.ids_in_range(rows["id"].astype(np.int64), 0, self.params.robots)
            self.peer_rows[1] += rows.size
            self.shard_ls.exchange.peer_claims(peer, tick, decisions_of(tick, rows))
        except Rejected as fault:
            self.rejections.drop(topic, fault)

    def _on_part_rows(self, peer: int, topic: str, msg: Cloud) -> None:
        try:
            tick = checks.tick_stamp(msg.header)
            rows = checks.cloud(msg, part_row(self.shape.dims), self.params.robots, min_rows=0)
        except Rejected as fault:
            self.rejections.drop(topic, fault)
            return
        self.peer_rows[0] += rows.size
        self._hold(peer, tick, "rows", rows, topic)

    def _on_counts(self, peer: int, topic: str, msg: Int64MultiArray) -> None:
        try:
            counts = counts_of(np.asarray(msg.data, dtype=np.int64), self.params.robots, self.shards)
            if counts[1] != peer:
                raise Rejected("unknown shard", f"counts of shard {counts[1]} on {topic}")
        except Rejected as fault:
            self.rejections.drop(topic, fault)
            return
        self._hold(peer, counts[0], "counts", counts, topic)

    def _hold(self, peer: int, tick: int, what: str, value, topic: str) -> None:
        """Keep a peer's part rows or counts of ``tick`` until both are in, then hand the part over."""
        now = self.shard_ls.exchange.tick
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
                self.shard_ls.exchange.peer_part(peer, tick, part)
            except Rejected as fault:
                self.rejections.drop(topic, fault)

    def _on_again(self, peer: int, topic: str, msg: Int64MultiArray) -> None:
        if list(msg.data) == [self.index]:
            self.shard_ls.exchange.resend(peer)

    # -- the exchange's port -----------------------------------------------------------
    def send_claims(self, peer: int, tick: int, claims: Decisions) -> None:
        self.pub_claims[peer].publish_rows(decision_rows(claims), tick)

    def send_part(self, peer: int, tick: int, part: Part) -> None:
        """The part's rows to ``peer``; its counts, the same for every peer, once a tick on one topic (again with
        the rows of a part sent again: the peer may have dropped what it held)."""
        self.pub_parts[peer].publish_rows(part_rows(part, self.shape.dims), tick)
        if (tick, peer) in self.parts_sent or all(t != tick for t, _ in self.parts_sent):
            self.pub_counts.publish(msgs.ids_message(counts_data(part), "shard_counts"))
        self.parts_sent = {(t, j) for t, j in self.parts_sent if t > tick - 1 - KEPT_TICKS} | {(tick, peer)}

    def ask_again(self, peer: int) -> None:
        self.pub_again.publish(msgs.ids_message(np.array([peer], dtype=np.int64), "shard"))

    def save_tick(self, tick, rows, published, applied, metrics, sent, tally) -> None:
        if self.shard_saver is not None:
            self.shard_saver.write_tick(tick, rows, published, applied, metrics, sent, tally)

    def save_book(self, book: dict) -> None:
        if self.shard_saver is not None:
            self.shard_saver.save_book(book)

    def _monitor_reported(self, tick: int) -> None:
        if self.shard_saver is not None:
            self.shard_saver.monitor_reported(tick)

    def close(self, code: int) -> None:
        """The save is removed once the run has ended or was stopped; a failed or orphaned shard leaves it. Say
        how much this shard took from its peers."""
        self.linger(code)
        rows, claims = self.peer_rows
        if isinstance(self.lockstep, ShardLockstep):  # loaded
            tick = self.lockstep.exchange.tick
            self.node.get_logger().info(
                f"received {rows} part rows and {claims} claims from its peers up to tick {tick}"
            )
        if self.shard_saver is not None and code in (EXIT_OK, EXIT_INTERRUPTED):
            self.shard_saver.remove()


def main(argv: list[str] | None = None) -> int:
    return run_node(WORLD_SHARD, WorldShardNode, argv)


if __name__ == "__main__":
    raise SystemExit(main())
