"""The launcher's view of a run: a progress bar fed by /swarm/metrics."""

from __future__ import annotations

import os
import sys

import rclpy
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Int64MultiArray

from . import messages as msgs


class Progress:
    """Follows /swarm/metrics on ``domain_id`` and shows localized robots against the shape's patches."""

    def __init__(self, domain_id: int, patches: int, quiet: bool = False) -> None:
        from tqdm import tqdm

        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        self.context = Context()
        # Ctrl-C stays a KeyboardInterrupt for the launcher, which then stops its children.
        rclpy.init(args=[], context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node("swarm_ros_launcher", context=self.context, start_parameter_services=False)
        self.node.create_subscription(Int64MultiArray, msgs.METRICS, self._on_metrics, msgs.METRICS_QOS)
        self.executor = EventsExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.bar = tqdm(total=patches, unit="patch", desc="localized", disable=True if quiet else None,
                        file=sys.stderr, dynamic_ncols=True)
        self.bar.set_postfix(tick="starting", refresh=False)
        self.tick = -1  #: the last tick the monitor reported; -1 before tick 0

    def _on_metrics(self, msg: Int64MultiArray) -> None:
        m = msgs.metrics_of(msg)
        self.tick = max(self.tick, m.get("tick", -1))
        self.bar.update(m.get("localized", 0) - self.bar.n)
        self.bar.set_postfix(tick=str(m.get("tick")), moving=str(m.get("moving")), refresh=False)

    def spin(self, timeout: float) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.bar.close()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
