"""The world node: owns the shape and the patch occupancy, settles claims, drives the lockstep ticks. The same node
is a world shard (``--world-shards S``, executable ``world_shard``); the world is the shard with no peers.

A thin shell: every decision (admission of batches, tick 0, applying a tick, the monitor window, lost processes)
is :class:`swarm_ros.protocol.lockstep.Lockstep`'s, every exchange with the peers its exchange's. This node turns
messages and liveliness events into calls on them (the peers' topics: :mod:`swarm_ros.ros.shard_links`), what they
decide into messages, and saves each tick (``checkpoint``) before anything of the next goes out. A message is
taken only once its tag under the run's key proves it (:mod:`swarm_ros.ros.auth`) and it passes its checks
(:mod:`swarm_ros.protocol.checks`); one that fails is dropped whole and counted (``rejected_messages``).

    ros2 run swarm_ros world --ros-args --params-file config/swarm_ros.yaml
    ros2 run swarm_ros world_shard --ros-args -r __node:=world_shard_0 -p shard:=0 -p shards:=2 -p batches:=4 \\
        --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

import functools
import time
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Int64MultiArray

from swarm_ros.core.errors import ConfigError, ParameterError, Rejected
from swarm_ros.core.params import Settings
from swarm_ros.core.shards import ShardPlan, WorldShard
from swarm_ros.core.signals import run_age
from swarm_ros.core.warmup import warm_up
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.lockstep import Lockstep
from swarm_ros.protocol.plan import MONITOR
from swarm_ros.protocol.shard_save import ShardSave, ShardSaver
from swarm_ros.protocol.status import Status
from swarm_ros.protocol.world_port import LINGER, Policy
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import open_auth
from swarm_ros.ros.runtime import EXIT_INTERRUPTED, EXIT_OK
from swarm_ros.ros.shard_links import ShardLinks


class WorldNode:
    """The world's (or world shard ``shard``'s) endpoints around a :class:`Lockstep`; its port
    (``swarm_ros.protocol.world_port.WorldPort``)."""

    def __init__(self, node: Node, run: Settings, own: dict[str, Any]) -> None:
        self.node = node
        self.created = time.monotonic()
        self.shape, self.params = run.resolve()
        self.checkpoint_path = str(own.pop("checkpoint"))
        self.incarnation = int(own.pop("incarnation"))
        placement = {name: own.pop(name) for name in ("shard", "shards", "batches", "region_cuts") if name in own}
        self.index, self.shards = int(placement.get("shard", 0)), int(placement.get("shards", 1))
        try:
            where = (int(placement.get("batches", 1)), str(placement.get("region_cuts", "")))
            self.plan = ShardPlan.placed(self.shape, self.params, self.index, self.shards, *where)
        except ParameterError as exc:
            raise ConfigError(f"node '{node.get_name()}': {exc}") from None
        self.viewers = self.index == 0  # /swarm/shape, /swarm/occupancy, /clock: one process
        self.policy = Policy(**own)
        self.rejections = Rejections(node.get_logger())
        self.signer, self.gate = open_auth(node, self.rejections)
        signed = self.signer.publisher
        self.pub_robots = signed(PointCloud2, msgs.ROBOTS, msgs.ROBOTS_QOS)
        self.pub_status = signed(DiagnosticArray, msgs.STATUS, msgs.STATUS_QOS)
        self.pub_decisions = signed(PointCloud2, msgs.DECISIONS, msgs.DECISIONS_QOS)  # applied
        self.pub_tally = signed(Int64MultiArray, msgs.TALLY, msgs.ROBOTS_QOS)  # record_every > 1
        # for viewers only: these types have no field for a tag, and no node of the run reads them (auth)
        self.maps = msgs.WorldMaps(msgs.study_cells(self.shape))  # OccupancyGrids in 2D, voxel clouds in 3D
        self.pub_shape = node.create_publisher(self.maps.kind, msgs.SHAPE, msgs.LATCHED_QOS)
        self.pub_occupancy = node.create_publisher(self.maps.kind, msgs.OCCUPANCY, msgs.LATCHED_QOS)
        self.pub_clock = node.create_publisher(Clock, msgs.CLOCK, msgs.CLOCK_QOS)
        self.snapshot_pubs: list = []  # per batch: /swarm/snapshot/<batch>
        self.region_pubs: list = []  # per batch: /swarm/region/<batch>
        self.occupancy_at = 0.0  # time.monotonic() of the last /swarm/occupancy
        self.lockstep: Lockstep | None = None  # made in load(), before the first callback can run
        self.saver: ShardSaver | None = None  # made in load(), with a checkpoint path
        self.gate.subscribe(Int64MultiArray, msgs.BATCHES, self._on_batch, msgs.BATCHES_QOS)
        self.gate.subscribe(Int64MultiArray, msgs.HELD, self._on_held, msgs.LATCHED_QOS)
        msgs.watch_liveliness(node, MONITOR, lambda alive, lapsed: self.ls.monitor_liveliness(alive, lapsed))
        # the peers' topics (none for the world alone), and the exchange's sends to them
        robots, dims = self.params.robots, self.shape.dims
        self.links = links = ShardLinks(self.signer, self.gate, self.rejections, self.index, self.shards, robots, dims)
        self.send_claims, self.send_part, self.ask_again = links.send_claims, links.send_part, links.ask_again

    @property
    def ls(self) -> Lockstep:
        """The lockstep, for the callbacks: made in load(), before the first of them can run."""
        assert self.lockstep is not None
        return self.lockstep

    @property
    def finished(self) -> bool:
        return self.lockstep is not None and self.lockstep.finished

    def load(self) -> None:
        """The heavy part, once the endpoints exist: discovery of the peers goes on meanwhile."""
        shard = WorldShard(self.shape, self.params, self.plan, self.index)
        warm_up(self.shape, self.params)
        if self.viewers:
            self.pub_shape.publish(self.maps.shape_message(0))
        name, log = self.node.get_name(), self.node.get_logger()
        self.lockstep = ls = Lockstep(shard, name, self.policy, self, log, self.rejections, created=self.created)
        self.links.exchange = ls.exchange
        saved = self._open_checkpoint()
        if saved is not None:
            ls.restore(saved, self.incarnation)
        else:  # none before this one got as far as tick 0
            ls.restarts += [(0, name)] * self.incarnation
        self._publish_occupancy()
        ls.publish_status()
        if saved is None:
            first, last = shard.strip
            part = f"columns {first}..{last} of " if self.shards > 1 else ""
            log.info(
                f"{name}: {part}{self.shape.name} ({self.shape.patches} patches), "
                f"{self.params.robots} robots, waiting for robot batches"
            )

    def _open_checkpoint(self) -> ShardSave | None:
        """The checkpoint to write (``checkpoint``); for a restarted process, what the one before saved in it."""
        if not self.checkpoint_path:
            return None
        path, slots = Path(self.checkpoint_path), self.policy.monitor_window + 2
        self.saver = saver = ShardSaver(path, self.params, self.plan, self.index, slots, self.shape.dims)
        if self.incarnation and saver.path.exists():
            return saver.restore()
        saver.create()
        return None

    # -- inbound ----------------------------------------------------------------------
    def _on_batch(self, msg: Int64MultiArray) -> None:
        try:
            name, incarnation, strip = checks.announcement(msg, self.shape.world.size)
            self.ls.announce(name, incarnation, strip)
        except Rejected as fault:
            self.rejections.drop(msgs.BATCHES, fault)

    def _on_decisions(self, k: int, topic: str, msg: Cloud) -> None:
        """Batch ``k``'s decisions (on ``topic``, its own): used whole once checked, or dropped and counted."""
        if self.ls.over:
            return
        try:
            tick, rows = checks.decision_message(msg, self.params.robots, self.shape.dims)
            self.ls.decisions(k, tick, rows)
        except Rejected as fault:
            self.rejections.drop(topic, fault)

    def _on_held(self, msg: Int64MultiArray) -> None:
        try:
            tick, _ = checks.held_report(np.asarray(msg.data, dtype=np.int64), self.ls.published_tick)
        except Rejected as fault:
            self.rejections.drop(msgs.HELD, fault)
            return
        tag = self.gate.last_tag  # the tag of this message, which the gate proved
        self.ls.held(tick, tag.nonce if tag is not None else "")
        self._monitor_reported(self.ls.monitor_tick)

    def _monitor_reported(self, tick: int) -> None:
        if self.saver is not None:
            self.saver.monitor_reported(tick)

    # -- the lockstep's port ---------------------------------------------------------------
    def watch_batch(self, k: int, name: str) -> None:
        self.snapshot_pubs.append(self.signer.publisher(PointCloud2, msgs.snapshot_topic(name), msgs.LATCHED_QOS))
        self.region_pubs.append(self.signer.publisher(PointCloud2, msgs.region_topic(name), msgs.ROBOTS_QOS))
        topic = msgs.decisions_topic(name)
        self.gate.subscribe(PointCloud2, topic, functools.partial(self._on_decisions, k, topic), msgs.DECISIONS_QOS)
        msgs.watch_liveliness(self.node, name, functools.partial(self.ls.batch_liveliness, k))

    def send_snapshot(self, k: int, tick: int, rows: np.ndarray) -> None:
        self.snapshot_pubs[k].publish_rows(rows, tick)

    def publish_tick(
        self,
        tick: int,
        rows: np.ndarray | None,
        joined: bool,
        applied: np.ndarray | None,
        regional: list[np.ndarray] | None,
        tally: np.ndarray | None,
    ) -> None:
        for pub, part in zip(self.region_pubs, regional or ()):
            pub.publish_rows(part, tick)  # first: the batches decide the next tick from these
        if applied is not None and applied.size:  # a world shard whose strips hold no moving robot: none
            self.pub_decisions.publish_rows(applied, tick)
        if tally is not None:
            self.pub_tally.publish_ints(msgs.tally_values(tick, self.ls.every, tally), msgs.tally_label())
        if rows is not None:
            self.pub_robots.publish_rows(rows, tick)
        if joined:
            self._publish_occupancy()
        if self.viewers:
            self.pub_clock.publish(msgs.clock_message(tick))

    def save_tick(self, tick, rows, published, applied, metrics, sent, tally) -> None:
        if self.saver is not None:
            self.saver.write_tick(tick, rows, published, applied, metrics, sent, tally)

    def save_book(self, book: dict) -> None:
        if self.saver is not None:
            self.saver.save_book(book)

    def publish_status(self, status: Status) -> None:
        level = DiagnosticStatus.WARN if status.warn else DiagnosticStatus.OK
        self.pub_status.publish(msgs.status_message(status.tick, status.outcome, status.message, level, status.values))
        now = time.monotonic()
        if self.lockstep is not None and self.lockstep.started and now - self.occupancy_at >= 1.0:
            self._publish_occupancy()  # once a second at least, for a viewer that reads it volatile

    def _publish_occupancy(self) -> None:
        """The occupancy now, stamped with the world's tick (it may be ahead of the last published rows)."""
        sim = self.ls.sim
        self.occupancy_at = time.monotonic()
        if self.viewers:
            filled = msgs.study_cells(self.shape, sim.state.occupancy).filled
            self.pub_occupancy.publish(self.maps.occupancy_message(filled, sim.tick))

    def monitor_reads_all(self) -> bool:
        """Whether this node has discovered the monitor's reader of every topic it takes from the network.

        Discovery of a reader is when this node's writers match it; the batches, on the same
        discovery traffic, match its reader of decisions at about the same time (and their
        history, TRANSIENT_LOCAL, covers a late match). Waiting for these, not only for the
        monitor's liveliness, keeps the bag whole from tick 0: a reader that matched after a
        topic's first messages would keep only the last of a latched one (``/swarm/status``).
        """
        return msgs.monitor_reads(self.node, msgs.MONITOR_READS)

    def delivered(self) -> bool:
        return msgs.acknowledged((self.pub_status, self.pub_robots, self.pub_tally))

    def decisions_delivered(self) -> bool:
        return msgs.acknowledged((self.pub_decisions,))

    def startup_seconds(self) -> float:
        return run_age()

    # -- the node runtime's hooks ----------------------------------------------------------
    def poll(self) -> None:
        self.ls.poll()

    def wake_in(self) -> float | None:
        return None if self.lockstep is None else self.lockstep.wake_in()

    def close(self, code: int) -> None:
        """The save is removed once the run has ended or was stopped (Ctrl-C): no process of this run will restart
        from it. A failed or orphaned world leaves it. A shard says how much it took from its peers."""
        self.linger(code)
        if said := self.links.summary():
            self.node.get_logger().info(said)
        if self.saver is not None and code in (EXIT_OK, EXIT_INTERRUPTED):
            self.saver.remove()

    def linger(self, code: int) -> None:
        """Stopped after tick 0: what it published gets up to ``LINGER`` to reach its readers, as at a run's end.
        The monitor writes the interrupted run from it (CI once stopped a world just after tick 0: it left before
        its rows reached the still-loading monitor, and the run directory was not written)."""
        if code == EXIT_INTERRUPTED and self.lockstep is not None and self.lockstep.started:
            deadline = time.monotonic() + LINGER
            while not (self.delivered() and self.decisions_delivered()) and time.monotonic() < deadline:
                time.sleep(0.01)
