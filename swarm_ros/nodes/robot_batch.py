"""The ``robot_batch`` executable and node, one for every algorithm: a batch of the run's robots, which decides for
those in its strip each tick.

The node announces its strip on /swarm/batches (``[first, last]`` column, labelled with its name and incarnation),
takes the rows the world sends it on the topics its algorithm's host reads (:mod:`swarm_ros.protocol.batch_host`),
and publishes what the host decides on its decisions topic. It takes only messages whose tag proves them the
world's (:mod:`swarm_ros.ros.auth`), and tags its own; one that fails a check is dropped, counted and logged. It
keeps a silent liveliness writer on /swarm/alive/<name>, and stops when /swarm/status reports the run's outcome,
once its last decisions are acknowledged (or after :data:`_LINGER`). Its host, every algorithm's, is
:class:`swarm_ros.protocol.central_batch.CentralBatch` over the algorithm's wire.

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

from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.errors import ParameterError, Rejected
from swarm_ros.core.params import Settings
from swarm_ros.nodes.roles import start
from swarm_ros.protocol.batch_host import BatchHost, Inbox
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.plan import ROBOT_BATCH
from swarm_ros.protocol.rows import batch_label
from swarm_ros.protocol.status import has_ended
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import open_auth

_LINGER = 2.0  # seconds, at most, for the last decisions to be acknowledged before exiting
_NO_WAIT = Duration(seconds=0)


class RobotBatchNode:
    def __init__(self, node: Node, run: Settings, own: dict[str, Any]) -> None:
        self.node = node
        name = node.get_name()
        shape, params = run.resolve()
        self.rejections = Rejections(node.get_logger())
        host = algorithm_of(run.algorithm).hook("batch_host")
        if host is None:
            raise ParameterError(f"the {run.algorithm} algorithm has no batch_host for its robot-batch node")
        self.host: BatchHost = host(shape, params, {**own, "name": name}, self.rejections.drop)
        self.finished = False
        self.ended_at: float | None = None  # time.monotonic() when the world's outcome arrived
        self.signer, self.gate = open_auth(node, self.rejections)
        self.pub_decisions = self.signer.publisher(PointCloud2, self.host.decisions, msgs.DECISIONS_QOS)
        for inbox in self.host.inboxes:
            self.gate.subscribe(PointCloud2, inbox.topic, self._taker(inbox), msgs.LATCHED_QOS)
        self.gate.subscribe(DiagnosticArray, msgs.STATUS, self._on_status, msgs.STATUS_QOS)
        self.alive = node.create_publisher(Empty, msgs.alive_topic(name), msgs.ALIVE_QOS)  # liveliness only
        announce = self.signer.publisher(Int64MultiArray, msgs.BATCHES, msgs.BATCHES_QOS)
        hello = msgs.ids_message(np.asarray(self.host.strip, dtype=np.int64))
        hello.layout.dim[0].label = batch_label(name, int(own["incarnation"]))
        announce.publish(hello)
        node.get_logger().info(f"{name}: {self.host.describe()}")

    def load(self) -> None:
        """The host's heavy part, once the endpoints exist: the world and the other batches are discovered meanwhile."""
        self.host.load()

    def _taker(self, inbox: Inbox):
        def take(msg: Cloud) -> None:
            try:
                decided = inbox.take(msg)
            except Rejected as fault:
                self.rejections.drop(inbox.topic, fault)
                return
            if decided is not None:
                self.pub_decisions.publish_rows(*decided)

        return take

    def _on_status(self, msg: DiagnosticArray) -> None:
        if self.ended_at is None and has_ended(msgs.status_values(msg).get("outcome")):
            self.ended_at = time.monotonic()

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

    def close(self, code: int) -> None:
        """Nothing to release; say what the host took and decided."""
        self.node.get_logger().info(f"{self.node.get_name()}: {self.host.summary()}")


def main(argv: list[str] | None = None) -> int:
    return start(ROBOT_BATCH, argv)


if __name__ == "__main__":
    raise SystemExit(main())
