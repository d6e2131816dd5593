"""A robot-batch node of a rubenstein run: decides, each tick, for the robots of its strip of the cell grid.

Batch k of K announces its strip, ``[first, last]`` cell column, on /swarm/batches (the strips cut at
``region_cuts``, x positions in d, or balanced over the robots at tick 0:
:func:`~swarm_ros.core.rubenstein.strips.strips_for`). The world sends it, after each tick, the rows of its area
(its strip and one cell column of halo, the communication range wide) on /swarm/rubenstein/area/<batch>: what the
robots there broadcast. The batch checks them (dropped and counted if they fail), decides the next tick for its
strip's robots not joined (:class:`swarm_ros.core.rubenstein.strips.RubensteinBatch`) and answers on
/swarm/rubenstein/decisions/<batch>. It keeps nothing between ticks, so a restarted batch decides as the one it
replaces would have. It stops when /swarm/status reports the run's outcome.

    ros2 run swarm_ros robot_batch --ros-args --params-file config/swarm_ros.yaml -p algorithm:=rubenstein \\
        -r __node:=robot_batch_0 -p batch:=0 -p batches:=2
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

from swarm_ros.core.errors import Rejected
from swarm_ros.core.params import Settings
from swarm_ros.core.rubenstein.run import RubensteinRun
from swarm_ros.core.rubenstein.strips import RubensteinBatch, strips_for
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.plan import BATCHES, STATUS, rubenstein_area_topic, rubenstein_decisions_topic
from swarm_ros.protocol.rows import batch_label
from swarm_ros.protocol.rubenstein.rows import RUBENSTEIN_ROW, check_rubenstein_rows, robots_of_rows, rubenstein_rows
from swarm_ros.protocol.status import has_ended
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import open_auth

_LINGER = 2.0  # seconds, at most, for the last decisions to be acknowledged before exiting
_NO_WAIT = Duration(seconds=0)


class RubensteinBatchNode:
    def __init__(self, node: Node, run: Settings, own: dict[str, Any]) -> None:
        self.node = node
        self.shape, self.params = run.resolve()
        self.k, batches = int(own["batch"]), int(own["batches"])
        frame = RubensteinRun(self.shape, self.params)  # the grid, the rule and the shape; its robots are not used
        strips = strips_for(frame, batches, str(own["region_cuts"]))
        self.host = RubensteinBatch(frame, strips, self.k)
        first, last = strips.strip(self.k)
        self.tick = -1  # the last tick whose area came in
        self.ended_at: float | None = None
        self.finished = False
        self.rejections = Rejections(node.get_logger())
        self.signer, self.gate = open_auth(node, self.rejections)
        name = node.get_name()
        self.area = rubenstein_area_topic(name)
        self.pub_decisions = self.signer.publisher(PointCloud2, rubenstein_decisions_topic(name), msgs.DECISIONS_QOS)
        self.gate.subscribe(PointCloud2, self.area, self._on_area, msgs.LATCHED_QOS)
        self.gate.subscribe(DiagnosticArray, STATUS, self._on_status, msgs.STATUS_QOS)
        self.alive = node.create_publisher(Empty, msgs.alive_topic(name), msgs.ALIVE_QOS)  # liveliness only
        announce = self.signer.publisher(Int64MultiArray, BATCHES, msgs.BATCHES_QOS)
        hello = msgs.ids_message(np.array([first, last], dtype=np.int64))  # the cell columns it decides for
        hello.layout.dim[0].label = batch_label(name, int(own["incarnation"]))
        announce.publish(hello)
        node.get_logger().info(f"{name}: batch {self.k} of {batches}, cell columns {first}..{last}")

    def load(self) -> None:
        """Nothing heavy: the kernels load on the first area."""

    def _on_area(self, msg: Cloud) -> None:
        try:
            tick = checks.tick_stamp(msg.header)
            rows = checks.cloud(msg, RUBENSTEIN_ROW, self.params.robots, min_rows=0)
            check_rubenstein_rows(rows, self.params.robots, tick)
        except Rejected as fault:
            self.rejections.drop(self.area, fault)
            return
        self.tick = max(self.tick, tick)  # an older tick's area is a restarted world's, from its checkpoint: decided
        own, decided = self.host.decide(tick + 1, *robots_of_rows(rows))
        self.pub_decisions.publish_rows(rubenstein_rows(own, decided), tick + 1)

    def _on_status(self, msg: DiagnosticArray) -> None:
        if self.ended_at is None and has_ended(msgs.status_values(msg).get("outcome")):
            self.ended_at = time.monotonic()

    def poll(self) -> None:
        if self.ended_at is not None:
            acked = self.pub_decisions.wait_for_all_acked(_NO_WAIT)
            self.finished = acked or time.monotonic() - self.ended_at > _LINGER

    def wake_in(self) -> float | None:
        return None

    def close(self, code: int) -> None:
        self.node.get_logger().info(f"{self.node.get_name()}: decided up to tick {self.tick + 1}")
