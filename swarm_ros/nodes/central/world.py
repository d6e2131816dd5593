"""The world node of a central world's run (an algorithm whose world is one process, as the rubenstein algorithm's:
:mod:`swarm_ros.core.strips`): holds every robot, sends each robot batch its area, settles the batches' decisions,
and publishes the run for the monitor.

A thin shell around :class:`swarm_ros.protocol.central_world.CentralWorld`, its port: each batch announces its strip
of columns on /swarm/batches (``[first, last]``); once the strips tile the grid, and the monitor reads the run's
topics, tick 0 goes out: each batch's area rows on /swarm/<algorithm>/area/<batch>, every robot's row on
/swarm/<algorithm>/robots, the metrics on /swarm/<algorithm>/metrics and ``running`` on /swarm/status. Each tick,
once every batch's decisions are in (checked, or dropped and counted), it settles them and sends the next areas;
every ``record_every``-th tick and at the end it sends the robots and the metrics rows since the last. It runs at
most ``monitor_window`` ticks past the last record the monitor reports held on /swarm/held
(:func:`~swarm_ros.protocol.central_world.monitor_reach`), so a restarted monitor finds in the topics' histories
every record its bag lacks. At the end it publishes the outcome and exits once the monitor holds it and each batch
has the outcome (or, with no window, once its readers have everything), or after a grace period. It saves a
checkpoint at tick 0 and every 1,000 ticks or so (a world shard: every 100 or so), before the tick goes out; a
restarted process goes on from the last one (:mod:`swarm_ros.protocol.central_checkpoint`). The algorithm's name's
hyphens are underscores in the topics.

    ros2 run swarm_ros world --ros-args --params-file config/swarm_ros.yaml -p algorithm:=rubenstein
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Int64MultiArray

from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.central_shards import CentralShard
from swarm_ros.core.errors import Rejected
from swarm_ros.core.params import Settings, auto_every
from swarm_ros.core.signals import run_age
from swarm_ros.core.strips import strips_for
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.central_checkpoint import shard_kept
from swarm_ros.protocol.central_shard_world import ShardLockstep
from swarm_ros.protocol.central_world import CentralWorld
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.plan import BATCHES, HELD, MONITOR, STATUS, CentralTopics, counts_topic, shard_topic
from swarm_ros.protocol.status import STARTING
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import SignedPublisher, open_auth


class CentralWorldNode:
    """The endpoints of a :class:`CentralWorld`, and its port."""

    def __init__(self, node: Node, run: Settings, own: dict[str, Any]) -> None:
        self.node = node
        shape, self.params = run.resolve()
        algorithm = algorithm_of(self.params.algorithm)
        self.wire, self.topics = algorithm.hook("wire")(shape.world.dims), CentralTopics.of(algorithm.name)
        self.rejections = Rejections(node.get_logger())
        self.signer, self.gate = open_auth(node, self.rejections)
        self.pub_status = self.signer.publisher(DiagnosticArray, STATUS, msgs.STATUS_QOS)
        self.pub_robots = self.signer.publisher(PointCloud2, self.topics.robots, msgs.CENTRAL_QOS)
        self.pub_metrics = self.signer.publisher(PointCloud2, self.topics.metrics, msgs.CENTRAL_QOS)
        first = int(own.get("shard", 0)) == 0  # the world, or world shard 0: /clock (untagged, as ROS tools read it)
        self.pub_clock = node.create_publisher(Clock, msgs.CLOCK, msgs.CLOCK_QOS) if first else None
        self.areas: dict[str, SignedPublisher] = {}  # batch node name -> its whole view's publisher
        self.changes: dict[str, SignedPublisher] = {}  # batch node name -> its changes' publisher
        engine = algorithm.hook("engine")(shape, self.params)
        lockstep = self._shard(engine, own) if int(own.get("shards", 1)) > 1 else None
        self.world = CentralWorld(
            engine, self.wire, own, self, node.get_logger(), self.rejections, lockstep=lockstep,
            removes=algorithm.removes_lost_robots,
        )  # fmt: skip
        self.gate.subscribe(Int64MultiArray, BATCHES, self._on_batch, msgs.BATCHES_QOS)
        self.gate.subscribe(Int64MultiArray, HELD, self._on_held, msgs.LATCHED_QOS)
        self._watch_alive(MONITOR)
        self.world.status(STARTING, "waiting for robot batches and the monitor")

    def _shard(self, engine: Any, own: dict[str, Any]) -> ShardLockstep:
        """World shard ``shard`` of ``shards``: its lockstep, and its links to its peers (plan.shard_topic)."""
        strips = strips_for(engine, int(own["batches"]), str(own["region_cuts"]))
        kept = shard_kept(int(own["record_every"]) or auto_every(self.params))  # ticks a restarted peer may be behind
        shard = CentralShard(engine, strips, int(own["shard"]), int(own["shards"]))
        ls = ShardLockstep(shard, self.wire, self, ahead=kept)
        i, ex, qos = ls.shard.index, ls.exchange, msgs.central_shards_qos(kept)
        self.to_peer = {
            (what, j): self.signer.publisher(PointCloud2, shard_topic(i, f"{what}_to_{j}"), qos)
            for j in ex.neighbours
            for what in ("border", "rows")
        }
        self.pub_shared = self.signer.publisher(PointCloud2, shard_topic(i, "shared"), qos)
        self.pub_counts = self.signer.publisher(Int64MultiArray, counts_topic(i), qos)
        self.halves: dict[tuple[int, int], dict[str, np.ndarray]] = {}  # (peer, tick) -> its shared rows, counts
        self.shard_ls = ls
        for j in ex.neighbours:
            for what, handler in (("border", ls.border), ("rows", ls.rows)):
                topic = shard_topic(j, f"{what}_to_{i}")
                row = self.wire.decision_row if what == "border" else self.wire.row
                take = functools.partial(self._on_peer, handler, j, topic, row)
                self.gate.subscribe(PointCloud2, topic, take, qos)
        for j in ex.peers:
            topic = shard_topic(j, "shared")
            self.gate.subscribe(PointCloud2, topic, functools.partial(self._on_shared, j, topic), qos)
            self.gate.subscribe(Int64MultiArray, counts_topic(j), functools.partial(self._on_counts, j), qos)
        return ls

    def _on_peer(self, handler: Any, peer: int, topic: str, row: Any, msg: Cloud) -> None:
        try:
            handler(peer, checks.tick_stamp(msg.header), checks.cloud(msg, row, self.params.robots, min_rows=0))
        except Rejected as fault:
            self.rejections.drop(topic, fault)

    def _on_shared(self, peer: int, topic: str, msg: Cloud) -> None:
        try:
            tick, rows = checks.tick_stamp(msg.header), checks.cloud(msg, self.wire.row, self.params.robots, min_rows=0)
        except Rejected as fault:
            self.rejections.drop(topic, fault)
            return
        self._half(peer, tick, "rows", rows, topic)

    def _on_counts(self, peer: int, msg: Int64MultiArray) -> None:
        values = np.asarray(msg.data, dtype=np.int64)
        if values.size < 2:
            self.rejections.drop(counts_topic(peer), Rejected("bad number", "no tick and counts"))
            return
        self._half(peer, int(values[0]), "counts", values[1:], counts_topic(peer))

    def _half(self, peer: int, tick: int, what: str, values: np.ndarray, topic: str) -> None:
        """Half of shard ``peer``'s shared message of ``tick`` (its rows, or its counts): on once both are in."""
        got = self.halves.setdefault((peer, tick), {})
        got.setdefault(what, values)
        if len(got) == 2:
            del self.halves[(peer, tick)]
            try:
                self.shard_ls.shared(peer, tick, got["rows"], got["counts"])
            except Rejected as fault:
                self.rejections.drop(topic, fault)

    # -- a world shard's port to its peers (ShardLockstep) ------------------------------------------------------
    def send_border(self, peer: int, tick: int, rows: np.ndarray) -> None:
        self.to_peer[("border", peer)].publish_rows(rows, tick)

    def send_rows(self, peer: int, tick: int, rows: np.ndarray) -> None:
        self.to_peer[("rows", peer)].publish_rows(rows, tick)

    def send_shared(self, tick: int, rows: np.ndarray, counts: np.ndarray) -> None:
        self.pub_shared.publish_rows(rows, tick)
        self.pub_counts.publish_ints(np.concatenate([[tick], counts]).astype(np.int64), "counts")

    def load(self) -> None:
        """Nothing heavy: the kernels compile (or load from numba's cache) on the first tick."""

    @property
    def finished(self) -> bool:
        return self.world.finished

    # -- inbound ---------------------------------------------------------------------------
    def _on_batch(self, msg: Int64MultiArray) -> None:
        try:
            name, incarnation, strip = checks.announcement(msg, self.world.run.grid.nx)
            tag = self.gate.last_tag  # the tag the gate proved: its nonce tells this batch's process from another
            self.world.batch(name, strip, incarnation, tag.nonce if tag is not None else "")
        except Rejected as fault:
            self.rejections.drop(BATCHES, fault)

    def _on_decisions(self, name: str, topic: str, msg: Cloud) -> None:
        try:
            tick = checks.tick_stamp(msg.header)
            rows = checks.cloud(msg, self.wire.decision_row, self.params.robots, min_rows=0)
            self.world.decisions(name, tick, rows)
        except Rejected as fault:
            self.rejections.drop(topic, fault)

    def _on_held(self, msg: Int64MultiArray) -> None:
        try:
            self.world.held_report(np.asarray(msg.data, dtype=np.int64))
        except Rejected as fault:
            self.rejections.drop(HELD, fault)

    def _watch_alive(self, name: str) -> None:
        msgs.watch_liveliness(self.node, name, functools.partial(self.world.liveliness, name))

    # -- the world's port -------------------------------------------------------------------
    def watch_batch(self, name: str) -> None:
        self.areas[name] = self.signer.publisher(PointCloud2, self.topics.area(name), msgs.LATCHED_QOS)
        # (latched too: the changes after a whole view go out once the batch answered it, maybe before its reader of
        # them matched)
        self.changes[name] = self.signer.publisher(PointCloud2, self.topics.changes(name), msgs.LATCHED_QOS)
        topic = self.topics.decisions(name)
        self.gate.subscribe(PointCloud2, topic, functools.partial(self._on_decisions, name, topic), msgs.DECISIONS_QOS)
        self._watch_alive(name)

    def send_area(self, name: str, tick: int, rows: np.ndarray, whole: bool) -> None:
        (self.areas if whole else self.changes)[name].publish_rows(rows, tick)

    def publish_record(self, tick: int, metrics: np.ndarray | None, robots: np.ndarray) -> None:
        if metrics is not None:  # (a world shard other than shard 0 sends no metrics: shard 0's are the same)
            self.pub_metrics.publish_rows(metrics, tick)
        self.pub_robots.publish_rows(robots, tick)

    def publish_clock(self, tick: int) -> None:
        if self.pub_clock is not None:
            self.pub_clock.publish(msgs.clock_message(tick))

    def publish_status(self, tick: int, outcome: str, message: str, values: dict[str, object]) -> None:
        self.pub_status.publish(msgs.status_message(tick, outcome, message, extra=values))

    def monitor_reads(self) -> bool:
        return msgs.monitor_reads(self.node, (self.topics.robots, self.topics.metrics, STATUS))

    def monitor_seen(self) -> str:
        return msgs.readers_seen(self.node, (self.topics.robots, self.topics.metrics, STATUS))

    def delivered(self) -> bool:
        return msgs.acknowledged((self.pub_status, self.pub_robots, self.pub_metrics))

    def told(self) -> bool:
        return msgs.acknowledged((self.pub_status,))

    def startup_seconds(self) -> float:
        return run_age()

    # -- the node runtime's hooks ----------------------------------------------------------
    def poll(self) -> None:
        self.world.poll()

    def wake_in(self) -> float | None:
        return self.world.wake_in()

    def close(self, code: int) -> None:
        self.node.get_logger().info(f"the world ended at tick {self.world.run.tick}")
