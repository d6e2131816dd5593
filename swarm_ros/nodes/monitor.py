"""The monitor node: per-tick metrics from what the world publishes, and the run's output directory.

It rebuilds the swarm's state from /swarm/robots (:class:`swarm_ros.core.replica.Replica`), counts it
with the in-process engine's own functions (:func:`swarm_ros.core.metrics.tick_metrics`, :func:`~.outcome_of`),
publishes each tick's metrics on /swarm/metrics, records the run with the in-process
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

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Empty, Int64MultiArray

from swarm_ros.artifacts import run_dir
from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.core.metrics import METRIC_COLUMNS, Outcome, TickMetrics, outcome_of, tick_metrics
from swarm_ros.core.replica import Replica
from swarm_ros.core.state import STATE_COUNT, RobotState
from swarm_ros.core.warmup import warm_up
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import Rejected, Rejections, apply_robots, checked_robots
from swarm_ros.protocol.status import RunFailed, WorldReport, restart_event
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import open_auth
from swarm_ros.ros.bag_resume import resume
from swarm_ros.ros.bag_writer import TOPICS, BagRecorder
from swarm_ros.ros.node_params import make_node, read_parameters
from swarm_ros.ros.runtime import EXIT_INTERRUPTED, EXIT_ORPHANED, handle_missed, run_node, take_waiting

_STATUS_WAIT = 5.0  # seconds to wait for the world's outcome after the monitor saw the end
_MATCH_POLL = 0.005  # seconds between looks at the readers' matches, before the liveliness writer appears
_BAG_WAIT = 1.0  # seconds to wait, after the end, for the last tick's decisions to reach the bag


class MonitorNode:
    def __init__(self) -> None:
        self.node = node = make_node("monitor")
        run, own = read_parameters(node, "monitor")
        self.shape, self.params = run.resolve()
        p = self.params
        self.out = Path(own["out_dir"]) if own["out_dir"] else \
            run_dir.default_run_dir(self.shape.name, p.robots, p.vision_radius, p.seed)
        self.overwrite = bool(own["overwrite"])
        self.incarnation = int(own["incarnation"])
        run_dir.check_out_dir(self.out, self.overwrite)  # fail before the run, not after it
        if not self.incarnation:  # a restarted process goes on from what its process before left
            run_dir.check_leftovers(self.out)
        self.world_radius = run.world_radius
        self.recording = RecordingOptions(enabled=bool(own["record"]), every=int(own["record_every"]),
                                          connect=str(own["viewer_url"]) or None).reachable()
        self.rrd = run_dir.partial_recording(self.out)
        self.losses: list[tuple[int, int]] = []  # (tick, robots removed), seen as rows turning 'removed'
        self.rows: list[tuple[int, ...]] = []
        self.outcome = None
        self.world = WorldReport()  # what the world's status said: restarts, its clock, its drops, the outcome
        self.world_end: tuple[float, int] | None = None  # (time.monotonic(), tick) when the world's outcome came
        self.ended_at: float | None = None
        self.started_at: float | None = None
        self.finished = False
        self.written: Path | None = None
        self.decided_rows: dict[int, int] = {}  # tick -> decision rows seen (with the bag on)
        self.rejections = Rejections(node.get_logger())

        self.signer, self.gate = open_auth(node, self.rejections)
        self.pub_metrics = self.signer.publisher(Int64MultiArray, msgs.METRICS, msgs.METRICS_QOS)
        # Serialized subscriptions to the tagged topics it records (plan.MONITOR_READS): see _bagger.
        self.bag: BagRecorder | None = None  # opened below, with the heavy part
        self.handlers = {msgs.ROBOTS: self._on_robots, msgs.STATUS: self._on_status,
                         msgs.DECISIONS: self._on_decisions}
        self.raw = b""  # the message being handled, as it came (recorded once its handler takes it)
        self.replaying, self.resumed_at = False, 0  # replaying its process before's bag; the tick it went on from
        self.readers = {topic: self._subscribe(topic) for topic in msgs.MONITOR_READS if topic != msgs.STATUS}
        # The world starts tick 0 once it sees this node's liveliness writer, which appears only when these
        # readers have matched their writers (a thread watches, while the heavy part below loads), and its
        # reader of /swarm/status, made once the heavy part is loaded: a reader that matches after a
        # topic's first messages would miss them, or keep only the last, and a monitor still loading would
        # take the CPU the first ticks need. (The liveliness writer is made early: DDS takes a few tenths
        # of a second to report a new writer alive, a new reader is discovered in milliseconds.)
        self.alive = None
        self.closing = threading.Event()
        threading.Thread(target=self._announce_when_matched, name="monitor-ready", daemon=True).start()
        self.bag_on = bool(own["bag"])

    def load(self) -> None:
        """The heavy part, once the first endpoints exist: discovery goes on meanwhile in the DDS threads, and
        once this is loaded the world can see this node's last reader, and it starts."""
        node, p = self.node, self.params
        if self.incarnation:
            self.rrd.unlink(missing_ok=True)  # its process before's: rebuilt from its bag (resume, below)
        self.recorder = self.recording.open(self.rrd, self.shape, p)
        self.bag = BagRecorder(self.out, self.shape.dims) if self.bag_on else None
        self.replica = Replica(self.shape, p.robots)
        warm_up(self.shape, p)
        if self.incarnation:
            resume(self)
        importlib.import_module("swarm_ros.artifacts.plots")  # matplotlib: now, not at the end, when the run is written
        self.readers[msgs.STATUS] = self._subscribe(msgs.STATUS)  # loaded: the world may start (latched)
        every = self.recorder.every if self.recorder is not None else 1
        node.get_logger().info(f"monitor: writing to {self.out}" + f" (robots every {every} ticks)" * (every > 1))

    def _subscribe(self, topic: str):
        """A reader of ``topic``: each message its tag proves goes into the bag as it came, then to its handler."""
        return self.gate.subscribe(TOPICS[topic][0], topic, self.handlers.get(topic), TOPICS[topic][1],
                                   raw_handler=self._bagger(topic))

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
                self.alive = self.node.create_publisher(Empty, msgs.alive_topic(self.node.get_name()),
                                                        msgs.ALIVE_QOS)
                return

    def _bagger(self, topic: str):
        """What writes a proven message of ``topic``, as it came, into the bag (if there is one). Rows and
        decisions wait for their handler: only a tick not recorded yet goes in (a restarted world sends the
        last ticks again)."""
        def write(data: bytes) -> None:
            if topic in (msgs.ROBOTS, msgs.DECISIONS):
                self.raw = data
            elif self.bag is not None:
                self.bag.write(topic, data)
        return write

    def _on_robots(self, msg: Cloud) -> None:
        if self.outcome is not None:
            return
        removed_before = self.removed
        try:
            tick, rows = checked_robots(self.replica, msg, self.world_radius)
            if tick <= self.replica.tick:
                return  # again (a late-matched reader's history)
            apply_robots(self.replica, tick, rows)
        except Rejected as fault:
            self.rejections.drop(msgs.ROBOTS, fault)
            return
        if self.started_at is None:
            self.started_at = time.perf_counter()
        counts = np.bincount(self.replica.state.state, minlength=STATE_COUNT)
        metrics = tick_metrics(tick, counts, self.shape.patches)
        self.rows.append(tuple(metrics))
        if not self.replaying:
            data = self.pub_metrics.seal(msgs.metrics_message(metrics))
            if self.bag is not None:  # the tick's messages are durable before the world hears of it
                self.bag.write(msgs.ROBOTS, self.raw)
                self.bag.write(msgs.METRICS, data)
                joined = len(self.rows) < 2 or self.rows[-1][METRIC_COLUMNS.index("localized")] != \
                    self.rows[-2][METRIC_COLUMNS.index("localized")]
                self.bag.write_world(self.shape, self.replica.state.occupancy, tick, len(self.rows) == 1,
                                     joined or self.removed > removed_before)
                take_waiting(self.readers[msgs.DECISIONS])  # one the executor lost the event of: in, now
                self.bag.durable()
            self.pub_metrics.send(data)
        if self.removed > removed_before:
            self.losses.append((tick, self.removed - removed_before))
        p = self.params
        self.outcome = outcome_of(metrics, self.shape.patches, p.robots - self.removed, p.max_ticks)
        if self.recorder is not None:
            self.recorder.metrics([metrics])
            self.recorder.robots(self.replica.state, force=self.outcome is not None)
        if self.outcome is not None:  # its CPU so far: per tick, without writing the run (scripts/bench_scale.py)
            self.ended_at, self.wall = time.monotonic(), time.perf_counter() - (self.started_at or time.perf_counter())
            self.node.get_logger().info(f"last tick, {tick}: {self.outcome.value} ({time.process_time():.2f} s of CPU)")

    def _on_decisions(self, msg: Cloud) -> None:
        """Count the decision rows of each tick (for the bag: see :meth:`_bag_complete`)."""
        try:
            tick, rows = checks.decision_message(msg, self.params.robots, self.shape.dims)
        except Rejected as fault:
            self.rejections.drop(msgs.DECISIONS, fault)
            return
        if tick in self.decided_rows and not self.replaying:
            return  # recorded already (a restarted world sends the last ticks again)
        self.decided_rows[tick] = self.decided_rows.get(tick, 0) + rows.size
        if self.bag is not None and not self.replaying:
            self.bag.write(msgs.DECISIONS, self.raw)

    def _bag_complete(self) -> bool:
        """Whether the last tick's decisions are in the bag: they may arrive after the world's last rows."""
        last = self.replica.tick
        if last <= 0 or len(self.rows) < last:
            return True
        return self.decided_rows.get(last, 0) >= self.rows[last - 1][METRIC_COLUMNS.index("moving")]

    @property
    def removed(self) -> int:
        return int((self.replica.state.state == RobotState.REMOVED).sum())

    def _on_status(self, msg: DiagnosticArray) -> None:
        for tick, node in self.world.update(msgs.status_values(msg)):
            self.node.get_logger().warn(f"{node} was restarted at tick {tick}")
            if self.recorder is not None and not self.recorder.closed:
                self.recorder.event(tick, restart_event(tick, node))
        if self.world.outcome is not None and self.world_end is None:
            self.world_end = (time.monotonic(), msgs.tick_of(msg.header))

    def poll(self) -> None:
        if self.outcome is None:
            self._check_world_end()
            return
        if self.world.outcome is None and time.monotonic() - self.ended_at < _STATUS_WAIT:
            return
        if self.bag is not None and not self._bag_complete() and time.monotonic() - self.ended_at < _BAG_WAIT:
            return
        missed = handle_missed(self.node)  # what the executor may not have handed over (runner.handle_missed)
        if missed:
            self.node.get_logger().warn(f"{missed} messages were still in the readers, not handed over by the "
                                        f"executor; handled before writing the run")
        if self.world.outcome is not None and self.world.outcome != self.outcome.value:
            raise RunFailed(f"the world reports '{self.world.outcome}', the monitor counted "
                            f"'{self.outcome.value}' at tick {self.replica.tick}")
        if self.recorder is not None:  # closed only now: the world's last status may add restart events
            self.recorder.outcome(self.outcome.value, TickMetrics(*self.rows[-1]))
            self.recorder.close()
        self._write()
        self.finished = True

    def _check_world_end(self) -> None:
        """Fail, rather than wait forever, when the world has ended the run but this node's count has not:
        the robots' last messages never came (a process that is not under ``swarm-ros run`` or ``ros2
        launch`` has nobody else to stop it)."""
        if self.world_end is None or time.monotonic() - self.world_end[0] < _STATUS_WAIT:
            return
        handle_missed(self.node)
        if self.outcome is None:
            raise RunFailed(f"the world ended the run ('{self.world.outcome}') at tick {self.world_end[1]}, but the "
                            f"robots' messages reached the monitor only up to tick {self.replica.tick} within "
                            f"{_STATUS_WAIT:g} s")

    def _write(self, outcome: Outcome | None = None) -> None:
        record = self.world.record(self.shape, self.params, self.replica.state, self.rows, outcome or self.outcome,
                                   self.wall, self.losses, self.rejections.total,
                                   monitor=(self.incarnation, self.resumed_at))
        self.written = run_dir.write_run(self.out, record, overwrite=self.overwrite,
                                 recording=self.rrd if self.recording.enabled else None,
                                 bag=self.bag.close() if self.bag is not None else None)
        if self.bag is not None:
            self.bag.discard_holder()
        self.node.get_logger().info(f"run written to {self.written}")

    def close(self, code: int) -> None:
        """On the way out of a run stopped before its end. Interrupted after tick 0: the run so far becomes the run
        directory (outcome ``interrupted``); before tick 0, nothing is kept. Failed, or orphaned (the launcher died):
        the recording so far is kept, closed and marked, as ``<out_dir>.partial.rrd``."""
        self.closing.set()
        if self.written is not None:
            return
        if code == EXIT_INTERRUPTED and self.outcome is None and hasattr(self, "replica"):
            # stopped while loading or behind: what the world sent is the run so far (it waits in the readers)
            try:
                handle_missed(self.node)
            except RunFailed as exc:
                self.node.get_logger().error(f"while taking the ticks already sent: {exc}")
        unstarted = code == EXIT_INTERRUPTED and not self.rows and not self.incarnation  # holds nothing of a run
        if self.bag is not None and not (code == EXIT_INTERRUPTED and self.rows and self.outcome is None):
            # closed, kept beside the run (an interrupted run takes it); before tick 0 removed, not to block the next
            self.bag.discard() if unstarted else self.bag.move_to(run_dir.partial_bag(self.out))
        if self.outcome is not None:  # ended, but stopped before the world confirmed it: keep the recording
            if self.recorder is not None:
                self.recorder.outcome("interrupted", TickMetrics(*self.rows[-1]))
                self.recorder.close()
            return
        interrupted = code == EXIT_INTERRUPTED and bool(self.rows)
        if self.recorder is not None:
            if self.rows:
                stopped = code in (EXIT_INTERRUPTED, EXIT_ORPHANED)
                self.recorder.outcome("interrupted" if stopped else "failed", TickMetrics(*self.rows[-1]))
            self.recorder.close()
        if unstarted:  # its own: a first process refuses to start beside an earlier run's
            self.rrd.unlink(missing_ok=True)
        if interrupted:
            self.wall = time.perf_counter() - (self.started_at or time.perf_counter())
            self._write(Outcome.INTERRUPTED)


def main(argv: list[str] | None = None) -> int:
    return run_node("monitor", MonitorNode, argv)


if __name__ == "__main__":
    raise SystemExit(main())
