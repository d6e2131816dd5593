"""The launcher's view of a run: a progress bar fed by /swarm/metrics."""

from __future__ import annotations

import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Int64MultiArray

from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.status import STARTING, has_ended, has_started
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import Gate
from swarm_ros.ros.dds import apply_dds_defaults

_MAX_BATCH = 10_000  # messages handled per spin() at most


class Progress:
    """Follows /swarm/metrics on ``domain_id`` and shows localized robots against the shape's patches."""

    def __init__(self, domain_id: int, patches: int, key: bytes, quiet: bool = False,
                 enclaves: str | None = None) -> None:
        from tqdm import tqdm

        apply_dds_defaults()  # as the nodes have them (launcher.node_env)
        self.context = Context()
        # Ctrl-C stays a KeyboardInterrupt for the launcher, which then stops its children.
        args = ["--ros-args", "--enclave", f"{enclaves}/swarm_ros_launcher"] if enclaves else []
        rclpy.init(args=args, context=self.context, domain_id=domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node("swarm_ros_launcher", context=self.context, start_parameter_services=False)
        # only what the run's nodes tagged (auth.Gate): a stranger's status cannot end the run here
        self.gate = Gate(self.node, key, Rejections(self.node.get_logger()))
        self.gate.subscribe(Int64MultiArray, msgs.METRICS, self._on_metrics, msgs.METRICS_QOS)
        self.gate.subscribe(DiagnosticArray, msgs.STATUS, self._on_status, msgs.LATCHED_QOS)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.bar = tqdm(total=patches, unit="patch", desc="localized", disable=True if quiet else None,
                        file=sys.stderr, dynamic_ncols=True)
        self.bar.set_postfix(tick=STARTING, refresh=False)
        self.tick = -1  #: the last tick the monitor reported; -1 before tick 0
        self.started = False  #: the world has sent tick 0 (its status says 'running', or a tick was counted)
        self.ended_at: float | None = None  #: time.monotonic() when the world's outcome arrived

    def _on_status(self, msg: DiagnosticArray) -> None:
        outcome = msgs.status_values(msg).get("outcome")
        if has_started(outcome):
            self.started = True
        if self.ended_at is None and has_ended(outcome):
            self.ended_at = time.monotonic()

    def _on_metrics(self, msg: Int64MultiArray) -> None:
        m = msgs.metrics_of(msg)
        if self.tick < 0 <= m.get("tick", -1):  # rate and time left count from tick 0, not from start-up
            self.bar.reset(total=self.bar.total)
        self.tick = max(self.tick, m.get("tick", -1))
        self.started = self.started or self.tick >= 0
        self.bar.update(m.get("localized", 0) - self.bar.n)
        self.bar.set_postfix(tick=str(m.get("tick")), moving=str(m.get("moving")), refresh=False)

    def spin(self, timeout: float) -> None:
        """Handle what arrived, waiting up to ``timeout`` for the first message.

        A spin of the executor handles one message; the monitor sends one a tick, so
        everything queued is handled here, or the launcher would fall behind the run.
        """
        self.executor.spin_once(timeout_sec=timeout)
        for _ in range(_MAX_BATCH):
            handled = self.gate.received
            self.executor.spin_once(timeout_sec=0)
            if self.gate.received == handled:
                break

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
