"""A robot-batch node: hosts a strip of the world and runs the core's robot rule for the robots in it every tick.

It announces its strip of columns (:mod:`swarm_ros.core.regions`) on /swarm/batches. The
world answers with a snapshot of its region (the strip and a halo: the robots its
robots can sense, and every stationary robot) on /swarm/snapshot/<batch> (at tick 0, or
at the current tick for a batch process that was restarted in the middle of a run); the
batch builds its regional copy of the swarm's state from it
(:class:`swarm_ros.core.swarm_view.SwarmView`), follows the world's rows for its region on
/swarm/region/<batch> from there (:mod:`swarm_ros.protocol.hosting`), and after each
tick publishes, on its own /swarm/decisions/<batch>, what each moving robot in its
strip decided for the next one. A robot that crosses into another strip is that
batch's from the next tick on: the world's row of it is the handover.
It takes only messages whose tag proves them the world's (:mod:`swarm_ros.ros.auth`), and tags its own.
Every message it takes is checked first (:mod:`swarm_ros.protocol.checks`, and
:meth:`SwarmView.inconsistent` for rows); one that fails is dropped, counted and logged. A decision is a pure function
of the state, the seed, the robot and the tick, so a restarted batch decides exactly
as the one it replaces would have. A robot senses only what arrived on the topics, and the rule reads only the
robots within its vision radius of the point ahead. It stops when /swarm/status
reports the run's outcome.

    ros2 run swarm_ros robot_batch --ros-args --params-file config/swarm_ros.yaml -p batch:=0 -p batches:=2
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Empty, Int64MultiArray

from swarm_ros.core import regions
from swarm_ros.core.errors import ContractError, Rejected, RunFailed
from swarm_ros.core.params import Settings
from swarm_ros.core.rules import Decider
from swarm_ros.core.swarm_view import SwarmView
from swarm_ros.core.warmup import warm_up
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import Rejections, apply_robots, checked_robots
from swarm_ros.protocol.rows import batch_label, decision_rows, pose_of
from swarm_ros.protocol.status import has_ended
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import open_auth

_LINGER = 2.0  # seconds, at most, for the last decisions to be acknowledged before exiting
_NO_WAIT = Duration(seconds=0)


class RobotBatchNode:
    def __init__(self, node: Node, run: Settings, own: dict[str, Any]) -> None:
        self.node = node
        self.shape, self.params = run.resolve()
        n, world = self.params.robots, self.shape.world
        self.strip = regions.batch_strip(self.shape, self.params, own["batch"], own["batches"], own["region_cuts"])
        self.view = SwarmView(
            self.shape, n, regions.area(self.strip, regions.halo(self.params.vision_radius), world.size)
        )
        self.decider = Decider(self.shape, self.params)
        self.finished = False
        self.ended_at: float | None = None  # time.monotonic() when the world's outcome arrived

        self.early: dict[int, np.ndarray] = {}  # checked rows that arrived before the snapshot, by tick
        self.received = 0  # bytes of rows taken from the region topic (scripts/bench_scale.py reports them)
        self.radius = self.shape.world.radius
        self.rejections = Rejections(node.get_logger())

        self.signer, self.gate = open_auth(node, self.rejections)
        self.pub_decisions = self.signer.publisher(
            PointCloud2, msgs.decisions_topic(node.get_name()), msgs.DECISIONS_QOS
        )
        self.gate.subscribe(PointCloud2, msgs.snapshot_topic(node.get_name()), self._on_snapshot, msgs.LATCHED_QOS)
        self.region = msgs.region_topic(node.get_name())
        self.gate.subscribe(PointCloud2, self.region, self._on_robots, msgs.ROBOTS_QOS)
        self.gate.subscribe(DiagnosticArray, msgs.STATUS, self._on_status, msgs.STATUS_QOS)
        self.alive = node.create_publisher(Empty, msgs.alive_topic(node.get_name()), msgs.ALIVE_QOS)
        announce = self.signer.publisher(Int64MultiArray, msgs.BATCHES, msgs.BATCHES_QOS)
        hello = msgs.ids_message(np.asarray(self.strip, dtype=np.int64))
        hello.layout.dim[0].label = batch_label(node.get_name(), int(own["incarnation"]))
        announce.publish(hello)
        node.get_logger().info(f"{node.get_name()}: strip {regions.format_strip(*self.strip, world.radius)}")

    def load(self) -> None:
        """The heavy part, once the endpoints exist: the world and the other batches are discovered meanwhile."""
        warm_up(self.shape, self.params)

    def _on_snapshot(self, msg: Cloud) -> None:
        """This batch's region at some tick (its area's moving robots, every stationary one): start (again) from
        it if it is newer than what we hold."""
        try:
            tick, rows = checks.snapshot(msg, self.params.robots, self.radius, self.shape.dims)
        except Rejected as fault:
            self.rejections.drop(msgs.snapshot_topic(self.node.get_name()), fault)
            return
        if tick <= self.view.tick:
            return  # an older snapshot (latched from an earlier restart of this batch)
        try:
            self.view.load(tick, rows["id"], rows["state"], **pose_of(rows))
        except ContractError as exc:
            raise RunFailed(f"snapshot of tick {tick}: {exc}") from None
        while self.view.tick + 1 in self.early:  # rows published after the snapshot was taken
            self._apply(self.view.tick + 1, self.early.pop(self.view.tick + 1))
        self.early.clear()
        self._decide()

    def _on_robots(self, msg: Cloud) -> None:
        self.received += len(msg.data)
        try:
            tick, rows = checked_robots(self.view, msg, self.radius)
        except Rejected as fault:
            self.rejections.drop(self.region, fault)
            return
        if tick <= self.view.tick:
            return  # history from before the snapshot
        if tick > self.view.tick + 1:
            # No snapshot yet, or an old one (latched from before a restart): keep the newest rows
            # until the world's answer to our announcement, a snapshot of the current tick, comes.
            self.early[tick] = rows
            if len(self.early) > msgs.ROBOTS_DEPTH:
                del self.early[min(self.early)]
            return
        if self._apply(tick, rows):
            self._decide()

    def _apply(self, tick: int, rows) -> bool:
        """Apply checked rows to the view; False (and counted) if they cannot be the world's."""
        try:
            apply_robots(self.view, tick, rows)
        except Rejected as fault:
            self.rejections.drop(self.region, fault)
            return False
        return True

    def _decide(self) -> None:
        """Publish the decisions of the moving robots in this batch's strip for the tick after the view's."""
        moving = self.view.moving_ids()
        cols = regions.columns(self.view.state.x[moving], self.radius)
        own = moving[(cols >= self.strip[0]) & (cols <= self.strip[1])]
        if own.size:
            tick = self.view.tick + 1
            decisions = self.decider.decide(self.view.state, own, tick, moving)
            self.pub_decisions.publish_rows(decision_rows(decisions), tick)

    def _on_status(self, msg: DiagnosticArray) -> None:
        if self.ended_at is None and has_ended(msgs.status_values(msg).get("outcome")):
            self.ended_at = time.monotonic()

    def close(self, code: int) -> None:
        """Nothing to release; say how much this batch received."""
        self.node.get_logger().info(
            f"received {self.received} bytes of rows on {self.region} up to tick {self.view.tick}"
        )

    def wake_in(self) -> float | None:
        return None  # polled when idle: nothing of its own waits for the clock

    def poll(self) -> None:
        # After the outcome, exit once every reader has acknowledged this batch's decisions: the world
        # has them all, but the monitor, which records them in the bag, may be far behind. A reader
        # that died never acknowledges, so wait at most _LINGER.
        if self.ended_at is not None and (
            self.pub_decisions.wait_for_all_acked(_NO_WAIT) or time.monotonic() - self.ended_at > _LINGER
        ):
            self.finished = True
