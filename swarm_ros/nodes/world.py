"""The world node: owns the shape and the patch occupancy, settles claims, drives the lockstep ticks.

A thin shell: every decision about the run (admission of batches, tick 0, applying a tick,
the monitor window, lost processes) is :class:`swarm_ros.protocol.lockstep.Lockstep`'s.
This node turns its messages and liveliness events into calls on it, and what it decides
into messages. Every message is taken only once its tag under the run's key proves it
(:mod:`swarm_ros.ros.auth`) and it passes its checks (:mod:`swarm_ros.protocol.checks`);
one that fails is dropped whole and counted (``rejected_messages`` on /swarm/status).

    ros2 run swarm_ros world --ros-args --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

import functools
import os
import time
from pathlib import Path

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.duration import Duration
from rclpy.event_handler import QoSLivelinessChangedInfo, SubscriptionEventCallbacks
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Empty, Int64MultiArray

from swarm_ros.core.engine import Simulation
from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.metrics import METRIC_COLUMNS
from swarm_ros.core.signals import PARENT_ENV, process_age
from swarm_ros.core.warmup import warm_up
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checkpoint import Checkpoint, Saved
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.lockstep import Lockstep
from swarm_ros.protocol.plan import MONITOR, WORLD
from swarm_ros.protocol.status import Status
from swarm_ros.protocol.world_port import LINGER, Policy
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import open_auth
from swarm_ros.ros.node_params import make_node, read_parameters
from swarm_ros.ros.runtime import EXIT_INTERRUPTED, EXIT_OK, run_node

_NO_WAIT = Duration(seconds=0)


class WorldNode:
    """The world's endpoints around a :class:`Lockstep`; its port (``swarm_ros.protocol.lockstep.WorldPort``)."""

    KIND = WORLD  #: its parameters' kind (a world shard's node has more: swarm_ros.nodes.world_shard)

    def __init__(self) -> None:
        self.node = node = make_node(self.KIND)
        run, own = read_parameters(node, self.KIND)
        self.created = time.monotonic()
        self.shape, self.params = run.resolve()
        self.checkpoint_path = str(own.pop("checkpoint"))
        self.incarnation = int(own.pop("incarnation"))
        self.saver: Checkpoint | None = None
        self.placement = {name: own.pop(name) for name in ("shard", "shards", "batches", "region_cuts") if name in own}
        self.viewers = self.placement.get("shard", 0) == 0  # /swarm/shape, /swarm/occupancy, /clock: one process
        self.policy = Policy(**own)
        self.rejections = Rejections(node.get_logger())
        self.signer, self.gate = open_auth(node, self.rejections)
        signed = self.signer.publisher
        self.pub_robots = signed(PointCloud2, msgs.ROBOTS, msgs.ROBOTS_QOS)
        self.pub_status = signed(DiagnosticArray, msgs.STATUS, msgs.STATUS_QOS)
        self.pub_decisions = signed(PointCloud2, msgs.DECISIONS, msgs.DECISIONS_QOS)  # applied
        self.pub_tally = signed(Int64MultiArray, msgs.TALLY, msgs.ROBOTS_QOS)  # record_every > 1
        # for viewers only: these types have no field for a tag, and no node of the run reads them (auth)
        self.maps = msgs.WorldMaps(self.shape)  # OccupancyGrids in 2D, voxel clouds in 3D
        self.pub_shape = node.create_publisher(self.maps.kind, msgs.SHAPE, msgs.LATCHED_QOS)
        self.pub_occupancy = node.create_publisher(self.maps.kind, msgs.OCCUPANCY, msgs.LATCHED_QOS)
        self.pub_clock = node.create_publisher(Clock, msgs.CLOCK, msgs.CLOCK_QOS)
        self.snapshot_pubs: list = []  # per batch: /swarm/snapshot/<batch>
        self.region_pubs: list = []  # per batch: /swarm/region/<batch>
        self.occupancy_at = 0.0  # time.monotonic() of the last /swarm/occupancy
        self.lockstep: Lockstep | None = None  # made in load(), before the first callback can run
        self.gate.subscribe(Int64MultiArray, msgs.BATCHES, self._on_batch, msgs.BATCHES_QOS)
        self.gate.subscribe(Int64MultiArray, msgs.METRICS, self._on_metrics, msgs.METRICS_QOS)
        self._watch(msgs.alive_topic(MONITOR), self._on_monitor_liveliness)

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
        sim = Simulation(self.shape, self.params)
        warm_up(self.shape, self.params)
        self.pub_shape.publish(self.maps.shape_message(0))
        self.lockstep = Lockstep(sim, self.policy, self, self.node.get_logger(), self.rejections, created=self.created)
        saved = self._open_checkpoint()
        if saved is not None:
            self.lockstep.restore(saved, self.incarnation)
        else:  # none before this one got as far as tick 0
            self.lockstep.restarts += [(0, WORLD)] * self.incarnation
        self._publish_occupancy()
        self.lockstep.publish_status()
        if saved is None:
            self.node.get_logger().info(
                f"world: {self.shape.name} ({self.shape.patches} patches), "
                f"{self.params.robots} robots, waiting for robot batches"
            )

    def _open_checkpoint(self) -> Saved | None:
        """The checkpoint to write (``checkpoint``); for a restarted world, what the one before saved in it."""
        if not self.checkpoint_path:
            return None
        path, n, cols = Path(self.checkpoint_path), self.params.robots, len(METRIC_COLUMNS)
        try:
            if self.incarnation and path.exists():
                self.saver = Checkpoint.open(path, n, self.params.max_ticks, cols, self.shape.dims)
                return self.saver.saved()
            self.saver = Checkpoint(
                path, n, self.params.max_ticks, cols, self.policy.monitor_window + 2, self.shape.dims
            )
            self.saver.create()
        except OSError as exc:
            raise RunFailed(f"checkpoint {path}: {getattr(exc, 'strerror', None) or exc}") from None
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

    def _on_metrics(self, msg: Int64MultiArray) -> None:
        try:
            tick = checks.metrics_tick(msg, METRIC_COLUMNS, self.ls.published_tick)
        except Rejected as fault:
            self.rejections.drop(msgs.METRICS, fault)
            return
        tag = self.gate.last_tag  # the tag of this message, which the gate proved
        self.ls.metrics(tick, tag.nonce if tag is not None else "")
        self._monitor_reported(self.ls.monitor_tick)

    def _monitor_reported(self, tick: int) -> None:
        if self.saver is not None:
            self.saver.monitor_reported(tick)

    def _watch(self, topic: str, on_change) -> None:
        self.node.create_subscription(
            Empty,
            topic,
            lambda msg: None,
            msgs.ALIVE_QOS,
            event_callbacks=SubscriptionEventCallbacks(liveliness=on_change),
        )

    def _on_batch_liveliness(self, k: int, info: QoSLivelinessChangedInfo) -> None:
        self.ls.batch_liveliness(k, info.alive_count, info.not_alive_count)

    def _on_monitor_liveliness(self, info: QoSLivelinessChangedInfo) -> None:
        self.ls.monitor_liveliness(info.alive_count, info.not_alive_count)

    # -- the lockstep's port ---------------------------------------------------------------
    def watch_batch(self, k: int, name: str) -> None:
        self.snapshot_pubs.append(self.signer.publisher(PointCloud2, msgs.snapshot_topic(name), msgs.LATCHED_QOS))
        self.region_pubs.append(self.signer.publisher(PointCloud2, msgs.region_topic(name), msgs.ROBOTS_QOS))
        topic = msgs.decisions_topic(name)
        self.gate.subscribe(PointCloud2, topic, functools.partial(self._on_decisions, k, topic), msgs.DECISIONS_QOS)
        self._watch(msgs.alive_topic(name), functools.partial(self._on_batch_liveliness, k))

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
            self.pub_tally.publish(msgs.tally_message(tick, self.ls.every, tally))
        if rows is not None:
            self.pub_robots.publish_rows(rows, tick)
        if joined:
            self._publish_occupancy()
        if self.viewers:
            self.pub_clock.publish(msgs.clock_message(tick))

    def checkpoint(
        self,
        tick: int,
        rows: np.ndarray,
        applied: np.ndarray | None,
        metrics: np.ndarray,
        published: int,
        tally: np.ndarray | None,
    ) -> None:
        if self.saver is not None:
            self.saver.write(tick, rows, applied, metrics, published, tally)

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
            self.pub_occupancy.publish(self.maps.occupancy_message(sim.state.occupancy, sim.tick))

    def monitor_reads_all(self) -> bool:
        """Whether this node has discovered the monitor's reader of every topic it takes from the network.

        Discovery of a reader is when this node's writers match it; the batches, on the same
        discovery traffic, match its reader of decisions at about the same time (and their
        history, TRANSIENT_LOCAL, covers a late match). Waiting for these, not only for the
        monitor's liveliness, keeps the bag whole from tick 0: a reader that matched after a
        topic's first messages would keep only the last of a latched one (``/swarm/status``).
        """
        return all(
            any(info.node_name == MONITOR for info in self.node.get_subscriptions_info_by_topic(topic))
            for topic in msgs.MONITOR_READS
        )

    def delivered(self) -> bool:
        return all(p.wait_for_all_acked(_NO_WAIT) for p in (self.pub_status, self.pub_robots, self.pub_tally))

    def decisions_delivered(self) -> bool:
        return self.pub_decisions.wait_for_all_acked(_NO_WAIT)

    def startup_seconds(self) -> float:
        """Seconds from the start of ``swarm-ros run`` (its process, if it is this process's parent),
        else from the start of this process, to now."""
        parent = os.environ.get(PARENT_ENV, "")
        if parent.isdigit() and int(parent) == os.getppid():
            age = process_age(int(parent))
            if age == age:  # not NaN
                return age
        return process_age()

    # -- the node runtime's hooks ----------------------------------------------------------
    def poll(self) -> None:
        self.ls.poll()

    def wake_in(self) -> float | None:
        return None if self.lockstep is None else self.lockstep.wake_in()

    def close(self, code: int) -> None:
        """The checkpoint is removed once the run has ended or was stopped (Ctrl-C): no process of this run
        will restart from it. A failed or orphaned world leaves it."""
        self.linger(code)
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


def main(argv: list[str] | None = None) -> int:
    return run_node("world", WorldNode, argv)


if __name__ == "__main__":
    raise SystemExit(main())
