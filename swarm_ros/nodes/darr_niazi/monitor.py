"""The monitor node: per-tick metrics from what the world publishes, and the run's output directory.

It rebuilds the swarm's state from /swarm/robots (:class:`swarm_ros.core.swarm_view.SwarmView`), counts it
with the in-process engine's own functions (:func:`swarm_ros.core.metrics.tick_metrics`, :func:`~.outcome_of`),
publishes each tick's metrics on /swarm/metrics and, its bag durable, the tick as held on /swarm/held (the world
runs at most ``monitor_window`` ticks past it), records the run with the in-process
engine's own :class:`~swarm_ros.artifacts.rerun_recording.Recorder` (streamed to ``<out_dir>.partial.rrd``
while the run goes on), and when the run ends writes the run directory exactly as
``swarm-ros simulate`` does, with ``engine: ros2``. It checks its outcome against the world's /swarm/status.
It takes and records in the bag only what a tag under the run's key proves (:mod:`swarm_ros.ros.auth`).

    ros2 run swarm_ros monitor --ros-args --params-file config/swarm_ros.yaml -p out_dir:=runs/star
"""

from __future__ import annotations

import importlib
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.publisher import Publisher
from std_msgs.msg import Empty, Int64MultiArray

from swarm_ros.artifacts import run_dir
from swarm_ros.artifacts.model_files import write_run
from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.metrics import Outcome
from swarm_ros.core.params import Settings
from swarm_ros.core.warmup import warm_up
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.monitoring import MonitorCore
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import open_auth
from swarm_ros.ros.bag_resume import resume
from swarm_ros.ros.bag_writer import TOPICS, BagRecorder
from swarm_ros.ros.runtime import EXIT_INTERRUPTED, EXIT_ORPHANED, handle_missed, take_waiting

LATE_TICK_0_S = 1.0  # seconds an interrupted monitor with no tick yet waits for a world's latched ones
_MATCH_POLL = 0.005  # seconds between looks at the readers' matches, before the liveliness writer appears


class MonitorNode:
    """The monitor's endpoints around a :class:`MonitorCore`, and its port
    (:class:`~swarm_ros.protocol.monitoring.MonitorPort`)."""

    def __init__(self, node: Node, run: Settings, own: dict[str, Any]) -> None:
        self.node = node
        self.shape, self.params = run.resolve()
        p = self.params
        self.out = Path(own["out_dir"]) if own["out_dir"] else run_dir.default_run_dir(self.shape.name, p)
        self.overwrite = bool(own["overwrite"])
        self.incarnation = int(own["incarnation"])
        self.shards = int(own["world_shards"])  # world processes whose parts make each tick's rows
        run_dir.check_out_dir(self.out, self.overwrite)  # fail before the run, not after it
        if not self.incarnation:  # a restarted process goes on from what its process before left
            run_dir.check_leftovers(self.out)
        self.world_radius = run.world_radius
        self.recording = RecordingOptions(
            enabled=bool(own["record"]), every=int(own["record_every"]), connect=str(own["viewer_url"]) or None
        ).reachable()
        self.rrd = run_dir.partial_recording(self.out)
        self.core: MonitorCore | None = None  # made in load(), before the readers can hand it anything
        self.finished = False
        self.written: Path | None = None
        self.rejections = Rejections(node.get_logger())

        self.signer, self.gate = open_auth(node, self.rejections)
        self.pub_metrics = self.signer.publisher(Int64MultiArray, msgs.METRICS, msgs.METRICS_QOS)
        self.pub_held = self.signer.publisher(Int64MultiArray, msgs.HELD, msgs.LATCHED_QOS)
        # Serialized subscriptions to the tagged topics it records (plan.MONITOR_READS): see _bagger.
        self.bag: BagRecorder | None = None  # opened below, with the heavy part
        self.handlers = {
            msgs.ROBOTS: self._on_robots,
            msgs.STATUS: self._on_status,
            msgs.DECISIONS: self._on_decisions,
            msgs.TALLY: self._on_tally,
        }
        self.raw = b""  # the message being handled, as it came (recorded once its handler takes it)
        self.readers = {topic: self._subscribe(topic) for topic in msgs.MONITOR_READS if topic != msgs.STATUS}
        # The world starts tick 0 once it sees this node's liveliness writer, which appears only when these
        # readers have matched their writers (a thread watches, while the heavy part below loads), and its
        # reader of /swarm/status, made once the heavy part is loaded: a reader that matches after a
        # topic's first messages would miss them, or keep only the last, and a monitor still loading would
        # take the CPU the first ticks need. (The liveliness writer is made early: DDS takes a few tenths
        # of a second to report a new writer alive, a new reader is discovered in milliseconds.)
        self.alive: Publisher | None = None
        self.closing = threading.Event()
        threading.Thread(target=self._announce_when_matched, name="monitor-ready", daemon=True).start()
        self.bag_on = bool(own["bag"])

    @property
    def counter(self) -> MonitorCore:
        """The monitor's core, for the callbacks: made in load(), before the readers can hand it anything."""
        assert self.core is not None
        return self.core

    def load(self) -> None:
        """The heavy part, once the first endpoints exist: discovery goes on meanwhile in the DDS threads. Once the
        core, the recording, the bag and the kernels are loaded, its last reader goes up and the world starts; the
        pictures' library (matplotlib) loads after that, while the world's first ticks wait in the readers (the
        README's command: 2.05x simulate's time against 2.25x with it loaded first, medians of three A/B rounds)."""
        node, p = self.node, self.params
        if self.incarnation:
            self.rrd.unlink(missing_ok=True)  # its process before's: rebuilt from its bag (_resume, below)
        recorder = self.recording.open(self.rrd, self.shape, p)
        every, log = self.recording.every_for(p), node.get_logger()
        self.core = MonitorCore(
            self.shape, p, self.world_radius, self, recorder, log, self.incarnation, self.shards, every
        )
        self.bag = BagRecorder(self.out, self.shape.dims) if self.bag_on else None
        warm_up(self.shape, p)
        if self.incarnation:
            self._resume()
        self.readers[msgs.STATUS] = self._subscribe(msgs.STATUS)  # loaded: the world may start (latched)
        importlib.import_module("swarm_ros.artifacts.plots")  # matplotlib: while the world's first ticks go out
        every = recorder.every if recorder is not None else 1
        node.get_logger().info(f"monitor: writing to {self.out}" + f" (robots every {every} ticks)" * (every > 1))

    def _resume(self) -> None:
        """Go on from the bag the process before this one wrote: its messages through the handlers, inside the
        core's replay (:mod:`swarm_ros.ros.bag_resume`)."""
        metrics: list[tuple[int, ...]] = []

        def take(topic: str, data: bytes) -> None:  # the world's maps and /clock: in the bag only, untagged
            if topic == msgs.METRICS:
                metrics.append(tuple(self.gate.open(TOPICS[topic][0], topic, data).data))
            elif topic in self.handlers:
                self.handlers[topic](self.gate.open(TOPICS[topic][0], topic, data))

        with self.counter.replay():
            replayed = resume(self.bag, self.out, take)
        if replayed:
            self.gate.verifier.taken_before()  # the same messages again from the topics' histories: known
        self.counter.replayed(metrics)
        if replayed:
            self.node.get_logger().warn(
                f"monitor restarted (incarnation {self.incarnation}): went on from tick "
                f"{self.counter.resumed_at} of the bag its process before wrote"
            )

    def _subscribe(self, topic: str):
        """A reader of ``topic``: each message its tag proves goes into the bag as it came, then to its handler."""
        return self.gate.subscribe(
            TOPICS[topic][0], topic, self.handlers.get(topic), TOPICS[topic][1], raw_handler=self._bagger(topic)
        )

    def _readers_matched(self) -> bool:
        """Every reader has matched a writer; the decisions reader, every batch's the graph shows."""
        for topic, reader in list(self.readers.items()):  # load() adds one meanwhile
            matched = reader.get_publisher_count()
            if matched < 1 or (topic == msgs.DECISIONS and matched < self.node.count_publishers(topic)):
                return False
        return True

    def _announce_when_matched(self) -> None:
        while not self.closing.wait(_MATCH_POLL):
            if self._readers_matched():
                self.alive = self.node.create_publisher(Empty, msgs.alive_topic(self.node.get_name()), msgs.ALIVE_QOS)
                return

    def _bagger(self, topic: str):
        """What writes a proven message of ``topic``, as it came, into the bag (if there is one). Rows and
        decisions wait for their handler: only a tick not recorded yet goes in (a restarted world sends the
        last ticks again)."""

        def write(data: bytes) -> None:
            if topic in (msgs.ROBOTS, msgs.DECISIONS, msgs.TALLY):
                self.raw = data
            elif self.bag is not None:
                self.bag.write(topic, data)

        return write

    # -- inbound ----------------------------------------------------------------------
    def _sender(self) -> str:
        tag = self.gate.last_tag  # the tag of the message being handled, which the gate proved
        return tag.sender if tag is not None else ""

    def _on_robots(self, msg: Cloud) -> None:
        try:
            self.counter.robots(msg, self._sender(), self.raw)
        except Rejected as fault:
            self.rejections.drop(msgs.ROBOTS, fault)

    def _on_tally(self, msg: Int64MultiArray) -> None:
        try:
            self.counter.tally(np.asarray(msg.data, dtype=np.int64), self._sender(), self.raw)
        except Rejected as fault:
            self.rejections.drop(msgs.TALLY, fault)

    def _on_decisions(self, msg: Cloud) -> None:
        try:
            self.counter.decisions(msg, self._sender())
        except Rejected as fault:
            self.rejections.drop(msgs.DECISIONS, fault)

    def _on_status(self, msg: DiagnosticArray) -> None:
        self.counter.status(msgs.status_values(msg), msgs.tick_of(msg.header), self._sender())

    # -- the core's port ---------------------------------------------------------------
    def tick_counted(self, tick, metrics, occupancy, first, changed, messages) -> None:
        data = self.pub_metrics.seal_ints(np.asarray(metrics, dtype=np.int64), msgs.METRICS_LABEL)
        if self.bag is not None:  # the tick's messages are durable before the world hears of it
            for topic, raw in messages:
                self.bag.write(topic, raw)
            self.bag.write(msgs.METRICS, data)
            self.bag.write_world(msgs.study_cells(self.shape, occupancy), tick, first, changed)
            take_waiting(self.readers[msgs.DECISIONS])  # one the executor lost the event of: in, now
            self.bag.durable()
        self.pub_metrics.send(data)
        self.pub_held.publish_ints(msgs.held_values(tick, self.counter.outcome is not None), msgs.HELD_LABEL)

    def decisions_taken(self, tick: int) -> None:
        if self.bag is not None:
            self.bag.write(msgs.DECISIONS, self.raw)

    def take_missed(self) -> int:
        return handle_missed(self.node)  # what the executor may not have handed over (runtime.handle_missed)

    # -- the node runtime's hooks ----------------------------------------------------------
    def wake_in(self) -> float | None:
        return None  # polled when idle: nothing of its own waits for the clock

    def poll(self) -> None:
        if self.counter.due(self.bag is not None):
            self._write()
            self.finished = True

    def _write(self, outcome: Outcome | None = None) -> None:
        self.written = write_run(
            self.out,
            self.counter.record(self.rejections.total, outcome),
            overwrite=self.overwrite,
            recording=self.rrd if self.recording.enabled else None,
            bag=self.bag.close() if self.bag is not None else None,
            robots_every=self.recording.every_for(self.params),
        )
        if self.bag is not None:
            self.bag.discard_holder()
        self.node.get_logger().info(f"run written to {self.written}")

    def close(self, code: int) -> None:
        """On the way out of a run stopped before its end. Interrupted after tick 0: the run so far becomes the run
        directory (outcome ``interrupted``); before tick 0, nothing is kept. Failed, or orphaned (the launcher died):
        the recording so far is kept, closed and marked, as ``<out_dir>.partial.rrd``."""
        self.closing.set()
        core = self.core
        if self.written is not None or core is None:
            return
        if code == EXIT_INTERRUPTED and core.outcome is None:
            # stopped while loading or behind: what the world sent is the run so far (it waits in the readers). Just
            # loaded, the world's latched tick 0 may still be on its way: waited for while a world is there
            deadline = time.monotonic() + LATE_TICK_0_S
            try:
                handle_missed(self.node)
                while not core.rows and time.monotonic() < deadline and self.node.count_publishers(msgs.ROBOTS):
                    time.sleep(0.02)
                    handle_missed(self.node)
                handle_missed(self.node)  # what reached the readers as the world left
            except RunFailed as exc:
                self.node.get_logger().error(f"while taking the ticks already sent: {exc}")
        unstarted = code == EXIT_INTERRUPTED and not core.rows and not self.incarnation  # holds nothing of a run
        interrupted = code == EXIT_INTERRUPTED and bool(core.rows) and core.outcome is None
        if self.bag is not None and not interrupted:
            # closed, kept beside the run (an interrupted run takes it); before tick 0 removed, not to block the next
            self.bag.discard() if unstarted else self.bag.move_to(run_dir.partial_bag(self.out))
        lost: run_dir.RecordingError | None = None
        try:
            core.close_recording(stopped=code in (EXIT_INTERRUPTED, EXIT_ORPHANED))
        except run_dir.RecordingError as exc:  # a full disk: the recording is removed; the bag is still to go
            if not interrupted:
                raise
            lost = exc
        if unstarted:  # its own: a first process refuses to start beside an earlier run's
            self.rrd.unlink(missing_ok=True)
        if interrupted:
            try:
                if lost is not None:
                    raise lost  # no whole run without its recording
                self._write(Outcome.INTERRUPTED)
            except (OSError, run_dir.OutputError, run_dir.RecordingError):  # a full disk: the bag goes beside the run
                if self.bag is not None and self.bag.holder.exists():
                    self.bag.move_to(run_dir.partial_bag(self.out))
                raise
