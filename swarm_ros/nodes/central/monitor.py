"""The monitor node of a central world's run (:mod:`swarm_ros.nodes.central.world`): records the run to Rerun as it
goes and writes the run directory at the end.

A thin shell around :class:`swarm_ros.protocol.central_monitor.CentralMonitor`, which holds the run: it reads what
the world publishes, every robot's row every ``record_every``-th tick and at the end (/swarm/<algorithm>/robots), the
metrics rows of every tick (/swarm/<algorithm>/metrics) and the outcome (/swarm/status), checks each message (and
drops and counts what fails), streams the run to ``<out_dir>.partial.rrd`` (the algorithm's ``recording``), and once
the outcome, the last robots and the metrics up to the last tick are in, writes the run directory as ``swarm-ros
simulate`` does (the algorithm's ``summary`` and ``write_run``), whole or not at all, with the run's bag (``bag/``:
every message it took, as it came).

Each time the core holds a further record (the robots and the metrics up to their tick), and once it holds the
outcome, the node makes its bag durable and reports so on /swarm/held (``[tick, ended]``, latched); the world
runs at most a window past it. A restarted process (``incarnation`` > 0) reads back the bag its process before
left, through the same handlers (:mod:`swarm_ros.ros.bag_resume`), and takes the rest from the topics' histories:
the run directory is the one an unbroken run writes.

    ros2 run swarm_ros monitor --ros-args --params-file config/swarm_ros.yaml -p algorithm:=rubenstein \\
        -p out_dir:=runs/rubenstein
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Empty, Int64MultiArray

from swarm_ros.artifacts import run_dir
from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.errors import Rejected
from swarm_ros.core.metrics import Outcome
from swarm_ros.core.params import Settings, auto_every
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.central_monitor import CentralMonitor
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.plan import HELD, MONITOR, STATUS, WORLD, CentralTopics
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import open_auth
from swarm_ros.ros.bag_resume import resume
from swarm_ros.ros.bag_writer import BagRecorder, central_topics
from swarm_ros.ros.runtime import EXIT_INTERRUPTED, handle_missed


class CentralMonitorNode:
    """The endpoints, the bag and the run directory around a :class:`CentralMonitor`."""

    def __init__(self, node: Node, run: Settings, own: dict[str, Any]) -> None:
        self.node = node
        self.shape, self.params = run.resolve()
        self.algorithm = algorithm_of(self.params.algorithm)
        wire, self.topics = self.algorithm.hook("wire")(self.shape.world.dims), CentralTopics.of(self.algorithm.name)
        self.incarnation = int(own["incarnation"])
        p = self.params
        self.out = Path(own["out_dir"]) if own["out_dir"] else run_dir.default_run_dir(self.shape.label, p)
        self.overwrite = bool(own["overwrite"])
        run_dir.check_out_dir(self.out, self.overwrite)  # fail before the run, not after it
        copy = self.algorithm.hook("engine")(self.shape, self.params)  # the run as the world reports it
        self.reported = (-1, False)  # the last [tick, ended] reported held
        self.rrd = run_dir.partial_recording(self.out) if own["record"] else None
        if self.rrd is not None and self.incarnation:
            self.rrd.unlink(missing_ok=True)  # its process before's: rebuilt from its bag (_resume, below)
        self.every = int(own["record_every"]) or auto_every(self.params)
        options = RecordingOptions(self.rrd is not None, self.every, connect=str(own["viewer_url"]) or None)
        self.recorder = self.algorithm.hook("recording")(self.rrd, copy, options) if options.active else None
        self.core = CentralMonitor(copy, wire, int(own["world_shards"]), self.recorder)
        self.finished = False
        recorded = central_topics(self.algorithm.name, self.shape.world.dims)
        self.bag = BagRecorder(self.out, recorded=recorded) if own["bag"] else None
        self.raw: bytes | None = b""  # the message being handled, as it came (into the bag once its handler took it)
        self.rejections = Rejections(node.get_logger())
        self.signer, self.gate = open_auth(node, self.rejections)
        self.pub_held = self.signer.publisher(Int64MultiArray, HELD, msgs.LATCHED_QOS)
        self.alive = node.create_publisher(Empty, msgs.alive_topic(MONITOR), msgs.ALIVE_QOS)  # liveliness only
        self.handlers = {
            self.topics.robots: self._on_robots,
            self.topics.metrics: self._on_metrics,
            STATUS: self._on_status,
        }
        cells = copy.cell_map()
        self.maps = msgs.WorldMaps(cells)  # the shape and the occupancy as the copy holds them, at each record
        self.filled = cells.filled.copy()  # the occupancy last published
        self.pub_shape = node.create_publisher(self.maps.kind, msgs.SHAPE, msgs.LATCHED_QOS)
        self.pub_occupancy = node.create_publisher(self.maps.kind, msgs.OCCUPANCY, msgs.LATCHED_QOS)
        self.pub_shape.publish(self.maps.shape_message(0))
        self.occupancy: tuple[float, bytes] | None = None  # (monotonic time, message) of the last occupancy published
        if self.incarnation:
            self._resume()
        for topic, handler in self.handlers.items():
            kind, qos = recorded[topic]
            self.gate.subscribe(kind, topic, handler, qos, raw_handler=self._keep_raw)

    def _resume(self) -> None:
        """Go on from the bag the process before this one wrote: its messages through the handlers, then the same
        messages again from the topics' histories are known (:mod:`swarm_ros.ros.bag_resume`)."""

        def take(topic: str, data: bytes) -> None:
            self.raw = None  # in the bag already
            if topic in self.handlers:  # (not the maps and the clock: this node's own, from these)
                self.handlers[topic](self.gate.open(DiagnosticArray if topic == STATUS else PointCloud2, topic, data))

        replayed = resume(self.bag, self.out, take, marker=None)
        self.raw = b""
        self.filled = self.core.copy.cell_map().filled.copy()
        self._publish_occupancy(self.maps.occupancy_message(self.filled, self.core.robots_tick))
        self.gate.verifier.taken_before()
        for _ in range(self.incarnation - sum(n == MONITOR for _, n in self.core.restarts)):  # (killed as it began too)
            self.core.restarted(max(self.core.last_tick, 0), MONITOR)
        self.node.get_logger().warn(
            f"monitor restarted (incarnation {self.incarnation}): went on from tick {self.core.last_tick} of the bag "
            f"its process before wrote ({replayed} messages)"
        )
        self._report()

    def _keep_raw(self, data: bytes) -> None:
        self.raw = data

    def _into_bag(self, topic: str) -> None:
        if self.bag is not None and self.raw is not None:
            self.bag.write(topic, self.raw)

    def _report(self) -> None:
        """Report what the core holds (:meth:`CentralMonitor.held`) once the bag holds it durably."""
        held = self.core.held()
        if held != self.reported and self.raw is not None:  # not while replaying: once, after
            if self.bag is not None:
                self.bag.durable()
            self.pub_held.publish_ints(msgs.held_values(*held), msgs.HELD_LABEL)
            self.reported = held

    def load(self) -> None:
        """Nothing heavy."""

    def _on_metrics(self, msg: Cloud) -> None:
        before = self.core.last_tick
        try:
            self.core.metrics(msg)
        except Rejected as fault:
            self.rejections.drop(self.topics.metrics, fault)
            return
        self._into_bag(self.topics.metrics)
        if self.bag is not None and self.raw is not None:
            for tick in range(before + 1, self.core.last_tick + 1):  # the world's clock, a tick a message
                self.bag.write(msgs.CLOCK, msgs.clock_message(tick))
        self._report()

    def _on_robots(self, msg: Cloud) -> None:
        before = self.core.robots_tick
        try:
            taken = self.core.robots_record(msg)
        except Rejected as fault:
            self.rejections.drop(self.topics.robots, fault)
            return
        if taken:
            self._into_bag(self.topics.robots)
            if self.core.robots_tick != before and self.raw is not None:
                self._maps()
            self._report()

    def _maps(self) -> None:
        """A new whole record: the shape into the bag with the first, and the occupancy, published and into the
        bag, if the record changed it (and with the first)."""
        tick, filled = self.core.robots_tick, self.core.copy.cell_map().filled
        first = tick == 0
        if not first and np.array_equal(filled, self.filled):
            return
        self.filled = filled.copy()
        data = self.maps.occupancy_message(filled, tick)
        self._publish_occupancy(data)
        if self.bag is not None:
            if first:
                self.bag.write(msgs.SHAPE, self.maps.shape_message(tick))
            self.bag.write(msgs.OCCUPANCY, data)

    def _on_status(self, msg: DiagnosticArray) -> None:
        self._into_bag(STATUS)
        tag = self.gate.last_tag  # the tag of this message, which the gate proved: the world or a world shard
        self.core.status(msgs.status_values(msg), msgs.tick_of(msg.header), tag.sender if tag is not None else WORLD)
        self._report()

    def _publish_occupancy(self, data: bytes) -> None:
        self.occupancy = (time.monotonic(), data)
        self.pub_occupancy.publish(data)

    def poll(self) -> None:
        if not self.finished and self.core.world_end_failure() is not None:
            handle_missed(self.node)  # (what came meanwhile, taken first)
            failure = self.core.world_end_failure()
            if failure is not None:
                raise failure
        if not self.finished and self.core.due():
            self._write(Outcome(self.core.outcome))
        if self.occupancy is not None and time.monotonic() - self.occupancy[0] >= 1.0:
            self._publish_occupancy(self.occupancy[1])  # once a second at least, for a viewer that reads it volatile

    def _write(self, outcome: Outcome) -> None:
        copy = self.core.copy
        # (the benches count a monitor's CPU per tick up to this line: the run directory's pictures are not a tick's)
        log = self.node.get_logger()
        log.info(f"last tick, {copy.tick}: {outcome.value} ({time.process_time():.2f} s of CPU)")
        wall = self.core.finish(outcome)
        summary = self.algorithm.hook("summary")(copy, wall)
        summary.update(engine="ros2", processes=None, shutdown_seconds=None)  # the launcher's to fill
        summary.update(self.core.graph_fields(self.rejections.total))
        if self.recorder is not None:
            self.recorder.finish(copy, summary["outcome"])
        summary["recording_robots_every"] = self.every if self.rrd is not None else None
        if self.bag is not None:
            summary["bag_robots_every"] = self.every
        bag = self.bag.close() if self.bag is not None else None
        write = self.algorithm.hook("write_run")
        write(self.out, copy, summary, overwrite=self.overwrite, recording=self.rrd, every=self.every, bag=bag)
        if self.bag is not None:
            self.bag.discard_holder()
        log.info(f"run written to {self.out}: {summary['outcome']} at tick {copy.tick}")
        self.finished = True

    def wake_in(self) -> float | None:
        return None

    def close(self, code: int) -> None:
        """On the way out of a run stopped before its end. Interrupted (Ctrl-C, or the launcher stopping the run) once
        the robots of a record are in: the run up to that record becomes the run directory, outcome ``interrupted``,
        as ``simulate`` writes one (metrics.csv, final_state.csv and summary.json agree on its tick). Otherwise the
        recording so far is kept as ``<out_dir>.partial.rrd`` and the bag, closed, as ``<out_dir>.partial-bag``; a
        first process interrupted before any tick came keeps neither."""
        if self.finished:
            return
        core = self.core
        if code == EXIT_INTERRUPTED and core.outcome is None:
            handle_missed(self.node)  # what the world sent before it stopped is the run so far
            if core.cut_at_record():
                try:
                    self._write(Outcome.INTERRUPTED)
                except (OSError, run_dir.OutputError, run_dir.RecordingError):  # a full disk: the bag goes beside it
                    if self.bag is not None and self.bag.holder.exists():
                        self.bag.move_to(run_dir.partial_bag(self.out))
                    raise
                return
        taken = core.last_tick >= 0
        unstarted = code == EXIT_INTERRUPTED and not taken and not self.incarnation
        if self.bag is not None:  # first: a recording that cannot be ended (a full disk) fails the close below
            self.bag.move_to(run_dir.partial_bag(self.out)) if taken else self.bag.discard()
        if self.recorder is not None:
            self.recorder.finish(core.copy, "interrupted")
        if unstarted and self.rrd is not None:
            self.rrd.unlink(missing_ok=True)  # its own, of no tick
