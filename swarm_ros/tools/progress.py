"""The launcher's view of a run: a progress bar fed by the world's /swarm/status (ten a second).

It does not read the run's robots or metrics: every robot's row in each record, taken by one
more Python process on the cores the run needs, for a display a person reads a few times a
second.
"""

from __future__ import annotations

import sys
import time
from contextlib import ExitStack

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.experimental import EventsExecutor

from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.status import STARTING, has_ended, has_started
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import Gate
from swarm_ros.ros.dds import apply_dds_defaults
from swarm_ros.ros.runtime import tool_node

_MAX_BATCH = 10_000  # messages handled per spin() at most


_COUNTS = ("tick", "progress", "progress_total")  #: the status values the bar counts with


class Progress:
    """Follows /swarm/status on ``domain_id`` and shows the run's progress as ``simulate``'s bar does: the cells of
    the shape done (the world's ``progress`` of ``progress_total``), named as the algorithm names them (``unit``,
    ``what``: the registry's ``progress_unit`` and ``progress_what``), with the tick and the world's words."""

    def __init__(
        self,
        domain_id: int,
        cells: int,
        key: bytes,
        quiet: bool = False,
        enclaves: str | None = None,
        unit: str = "patch",
        what: str = "localized",
    ) -> None:
        from tqdm import tqdm

        apply_dds_defaults()  # as the nodes have them (launcher.node_env)
        # Ctrl-C stays the launcher's, which then stops its children.
        enclave = ("--enclave", f"{enclaves}/swarm_ros_launcher") if enclaves else ()
        self.participant = ExitStack()  # closed by __exit__
        self.node = self.participant.enter_context(tool_node("swarm_ros_launcher", domain_id, enclave))
        try:
            # only what the run's nodes tagged (auth.Gate): a stranger's status cannot end the run here
            self.gate = Gate(self.node, key, Rejections(self.node.get_logger()))
            self.gate.subscribe(DiagnosticArray, msgs.STATUS, self._on_status, msgs.STATUS_QOS)
            self.executor = EventsExecutor(context=self.node.context)
            self.executor.add_node(self.node)
        except BaseException:
            self.participant.close()
            raise
        self.participant.callback(self.executor.shutdown)
        self.bar = tqdm(
            total=cells,
            unit=unit,
            desc=what,
            disable=True if quiet else None,
            file=sys.stderr,
            dynamic_ncols=True,
        )
        self.bar.set_postfix(tick=STARTING, refresh=False)
        self.tick = -1  #: the last tick the world's status reported; -1 before tick 0
        self.started = False  #: the world has sent tick 0 (its status says 'running', or a tick was counted)
        self.ended_at: float | None = None  #: time.monotonic() when the world's outcome arrived

    def _on_status(self, msg: DiagnosticArray) -> None:
        values = msgs.status_values(msg)
        outcome = values.get("outcome")
        if has_started(outcome):
            if not self.started:  # rate and time left count from tick 0, not from start-up
                self.bar.reset(total=self.bar.total)
            self.started = True
            counts = {k: int(v) for k, v in values.items() if k in _COUNTS and v.isdigit()}
            if counts.get("tick", -1) >= self.tick:  # not an older status that came late
                self.tick = counts.get("tick", self.tick)
                if counts.get("progress_total", 0) > 0:
                    self.bar.total = counts["progress_total"]
                self.bar.update(counts.get("progress", self.bar.n) - self.bar.n)
                words = [w for w in values.get("progress_words", "").split(",") if w in values]
                self.bar.set_postfix(tick=str(self.tick), **{w: values[w] for w in words}, refresh=False)
        if self.ended_at is None and has_ended(outcome):
            self.ended_at = time.monotonic()

    def spin(self, timeout: float) -> None:
        """Handle what arrived, waiting up to ``timeout`` for the first message (a spin of the executor
        handles one message: everything queued is handled here)."""
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
        self.participant.close()
