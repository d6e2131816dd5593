"""The world node of a rubenstein run (``--algorithm rubenstein``): holds every robot, sends each robot batch its
area, settles the batches' decisions, and publishes the run for the monitor.

A thin shell around :class:`swarm_ros.protocol.rubenstein.lockstep.RubensteinLockstep`: each batch announces its
strip of cell columns on /swarm/batches (``[first, last]``); once the strips tile the grid, and the monitor reads
the run's topics, tick 0 goes out: each batch's area rows on /swarm/rubenstein/area/<batch>, every robot's row on
/swarm/rubenstein/robots, the metrics on /swarm/rubenstein/metrics and ``running`` on /swarm/status. Each tick, once
every batch's decisions are in (checked, or dropped and counted), it settles them and sends the next areas; every
``record_every``-th tick and at the end it sends the robots and the metrics rows since the last. It runs at most
``monitor_window`` ticks past the last record the monitor reports held on /swarm/rubenstein/held
(:func:`~swarm_ros.protocol.rubenstein.lockstep.monitor_reach`), so a restarted monitor finds in the topics'
histories every record its bag lacks. At the end it publishes the outcome and exits once the monitor holds it (or,
with no window, once its readers have everything or after a grace period). It saves a checkpoint at tick 0 and every
1,000 ticks or so, before the tick goes out; a restarted process goes on from the last one
(:mod:`swarm_ros.protocol.rubenstein.checkpoint`).

    ros2 run swarm_ros world --ros-args --params-file config/swarm_ros.yaml -p algorithm:=rubenstein
"""

from __future__ import annotations

import functools
import time
from pathlib import Path
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.duration import Duration
from rclpy.event_handler import QoSLivelinessChangedInfo, SubscriptionEventCallbacks
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Empty, Int64MultiArray

from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.params import Settings, auto_every
from swarm_ros.core.rubenstein.run import RubensteinRun
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import Rejections, parse_batch_label
from swarm_ros.protocol.plan import (
    BATCHES,
    MONITOR,
    RUBENSTEIN_HELD,
    RUBENSTEIN_METRICS,
    RUBENSTEIN_ROBOTS,
    STATUS,
    rubenstein_area_topic,
    rubenstein_decisions_topic,
)
from swarm_ros.protocol.rubenstein import checkpoint
from swarm_ros.protocol.rubenstein.checkpoint import save_every
from swarm_ros.protocol.rubenstein.lockstep import RubensteinLockstep, RubensteinWatch, check_held, monitor_reach
from swarm_ros.protocol.rubenstein.rows import RUBENSTEIN_DECISION_ROW, metrics_rows, rubenstein_rows
from swarm_ros.protocol.status import RUNNING, STARTING
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import SignedPublisher, open_auth

_LINGER = 5.0  #: seconds, at most, for the last messages to be acknowledged before exiting
_NO_WAIT = Duration(seconds=0)


class RubensteinWorldNode:
    def __init__(self, node: Node, run: Settings, own: dict[str, Any]) -> None:
        self.node = node
        self.shape, self.params = run.resolve()
        self.every = int(own["record_every"]) or auto_every(self.params)
        self.save_every = save_every(self.every)
        self.reach = monitor_reach(int(own["monitor_window"]), self.every)
        self.held, self.held_end = -1, False  # the monitor's last held record, and whether it holds the outcome
        self.pending = False  # a settled tick waits for the monitor to catch up before it goes out
        self.checkpoint = Path(str(own["checkpoint"])) if own["checkpoint"] else None
        self.start_timeout = float(own["start_timeout"])
        self.created = time.monotonic()
        self.ls = RubensteinLockstep(RubensteinRun(self.shape, self.params))
        self.sent_metrics = -1  # the last tick whose metrics row went out
        self.first = True  # the first tick this process publishes is still to go out
        if int(own["incarnation"]):  # a restarted process: on from the last checkpoint
            self._resume()
        self.ended_at: float | None = None
        self.finished = False
        self.rejections = Rejections(node.get_logger())
        self.signer, self.gate = open_auth(node, self.rejections)
        self.pub_status = self.signer.publisher(DiagnosticArray, STATUS, msgs.STATUS_QOS)
        self.pub_robots = self.signer.publisher(PointCloud2, RUBENSTEIN_ROBOTS, msgs.RUBENSTEIN_QOS)
        self.pub_metrics = self.signer.publisher(PointCloud2, RUBENSTEIN_METRICS, msgs.RUBENSTEIN_QOS)
        self.areas: dict[str, SignedPublisher] = {}  # batch node name -> its area's publisher
        self.gate.subscribe(Int64MultiArray, BATCHES, self._on_batch, msgs.BATCHES_QOS)
        self.gate.subscribe(Int64MultiArray, RUBENSTEIN_HELD, self._on_held, msgs.LATCHED_QOS)
        self.watch = RubensteinWatch(self.created)
        self._watch_alive(MONITOR)
        self.waiting: list[int] = []  # batches announced before the monitor read the run's topics
        self._status(STARTING, "waiting for robot batches and the monitor")

    def _resume(self) -> None:
        """Go on from the checkpoint the process before saved: the run at its tick, the batches it served (their
        announcements, latched, come again and are sent their areas of that tick), and the metrics rows from the
        last record before it sent again (the monitor drops what it holds)."""
        if self.checkpoint is None:
            raise RunFailed("a restarted world has no checkpoint to go on from (the checkpoint parameter is empty)")
        if not self.checkpoint.exists():  # tick 0 is saved before anything of it goes out: nothing did
            self.node.get_logger().info("restarted before tick 0 went out: the run starts from tick 0")
            return
        saved = checkpoint.load(self.checkpoint, self.ls.run)
        self.ls.run.resume(saved.tick, saved.robots, saved.covered, saved.tally, saved.history)
        self.ls.resume(saved.hosts, saved.cuts)
        self.sent_metrics = saved.tick - self.every if saved.tick else -1
        self.node.get_logger().info(f"restarted: on from the checkpoint of tick {saved.tick}")

    def load(self) -> None:
        """Nothing heavy: the kernels compile (or load from numba's cache) on the first tick."""

    # -- inbound ---------------------------------------------------------------------------
    def _on_batch(self, msg: Int64MultiArray) -> None:
        try:
            name, _ = parse_batch_label(msg.layout.dim[0].label if msg.layout.dim else "")
            if len(msg.data) != 2:
                raise Rejected("strip", f"{len(msg.data)} values, expected its first and last cell column")
            strip = int(msg.data[0]), int(msg.data[1])
            first = name not in self.areas
            send = self.ls.announce(name, strip)
        except Rejected as fault:
            self.rejections.drop(BATCHES, fault)
            return
        if first:
            self.areas[name] = self.signer.publisher(PointCloud2, rubenstein_area_topic(name), msgs.LATCHED_QOS)
            topic = rubenstein_decisions_topic(name)
            self.gate.subscribe(
                PointCloud2, topic, functools.partial(self._on_decisions, name, topic), msgs.DECISIONS_QOS
            )
            self._watch_alive(name)
        self.waiting += send
        self.node.get_logger().info(f"{name}: cell columns {strip[0]}..{strip[1]}")

    def _on_decisions(self, name: str, topic: str, msg: Cloud) -> None:
        k = self.ls.number(name)
        if self.ls.run.outcome is not None or self.first or k is None:  # before its first tick: the process before's
            return
        try:
            tick = checks.tick_stamp(msg.header)
            rows = checks.cloud(msg, RUBENSTEIN_DECISION_ROW, self.params.robots, min_rows=0)
            settled = self.ls.decisions(k, tick, rows)
        except Rejected as fault:
            self.rejections.drop(topic, fault)
            return
        if settled:
            self.pending = True
            self._go_on()

    def _on_held(self, msg: Int64MultiArray) -> None:
        try:
            tick, ended = check_held(np.asarray(msg.data, dtype=np.int64), self.ls.run)
        except Rejected as fault:
            self.rejections.drop(RUBENSTEIN_HELD, fault)
            return
        if tick > self.held or ended > self.held_end:
            self.watch.moved(time.monotonic())
        self.held, self.held_end = max(self.held, tick), self.held_end or ended
        self._go_on()

    def _watch_alive(self, name: str) -> None:
        """Follow the liveliness of peer ``name``'s silent writer (DDS tells when its process dies or stalls)."""
        on_change = functools.partial(self._on_liveliness, name)
        callbacks = SubscriptionEventCallbacks(liveliness=on_change)
        self.node.create_subscription(
            Empty, msgs.alive_topic(name), lambda _: None, msgs.ALIVE_QOS, event_callbacks=callbacks
        )

    def _on_liveliness(self, name: str, info: QoSLivelinessChangedInfo) -> None:
        said = self.watch.liveliness(name, info.alive_count, info.not_alive_count)
        if said is not None:
            if name in self.watch.lapsed:  # (a logger method picked by a conditional expression and called in this
                self.node.get_logger().warning(said)  # event callback crashed the process inside rclpy, 3 runs of 3)
            else:
                self.node.get_logger().info(said)
            if self.ended_at is None:
                self._status(RUNNING if self.ls.started and not self.first else STARTING, said)

    def _go_on(self) -> None:
        """Send the settled tick, unless it is past the monitor's reach (then once the monitor reports more held)."""
        if self.pending and (self.reach is None or self.ls.run.tick <= self.held + self.reach):
            self.pending = False
            self._publish_tick()

    # -- outbound --------------------------------------------------------------------------
    def _monitor_reads(self) -> bool:
        return all(
            any(info.node_name == MONITOR for info in self.node.get_subscriptions_info_by_topic(topic))
            for topic in (RUBENSTEIN_ROBOTS, RUBENSTEIN_METRICS, STATUS)
        )

    def _send_areas(self, batches: list[int]) -> None:
        for k in batches:
            self.areas[self.ls.hosts[k]].publish_rows(self.ls.area(k), self.ls.run.tick)

    def _publish_tick(self) -> None:
        run = self.ls.run
        tick, ended = run.tick, run.outcome is not None
        self.watch.moved(time.monotonic())
        if self.checkpoint is not None and not ended and tick % self.save_every == 0:  # before the tick goes out
            checkpoint.save(self.checkpoint, run, self.ls.hosts, self.ls.cuts)
        if ended or tick % self.every == 0:
            self.pub_metrics.publish_rows(metrics_rows(run.history[self.sent_metrics + 1 :]), tick)
            self.sent_metrics = tick
            everyone = np.arange(self.params.robots)
            self.pub_robots.publish_rows(rubenstein_rows(everyone, run.robots), tick)
        if ended:
            self.ended_at = time.monotonic()
            self._status(str(run.outcome), f"the run ended at tick {tick}: {run.outcome}")
        else:
            self._send_areas(list(range(self.ls.batches)))

    def _status(self, outcome: str, message: str) -> None:
        waiting: dict[str, object] = {"waiting_for": ",".join(sorted(self.watch.lapsed))}  # lost peers, awaited
        self.pub_status.publish(msgs.status_message(self.ls.run.tick, outcome, message, extra=waiting))

    # -- the node runtime's hooks ----------------------------------------------------------
    def poll(self) -> None:
        heard = self.ls.started and all(name in self.areas for name in self.ls.hosts.values())  # resumed: every batch
        if self.waiting and heard and (not self.first or self._monitor_reads()):
            batches, self.waiting = sorted(set(self.waiting)), []
            if self.first:  # tick 0, or the checkpoint's: the robots, the metrics and the areas
                self.first = False
                self._status(RUNNING, f"{self.ls.batches} robot batches in: tick {self.ls.run.tick}")
                self.pending = True
                self._go_on()
            elif not self.pending:  # a batch process that came back: its area at the current tick (if it went out:
                self._send_areas(batches)  # a tick waiting for the monitor goes to every batch when it does)
        if not self.ls.started and time.monotonic() - self.created > self.start_timeout:
            raise RunFailed(f"robot batches did not all announce themselves within {self.start_timeout:g} s")
        if self.ls.started and self.ended_at is None and self.watch.still(time.monotonic()):  # for STILL_S
            unheard = [name for name in self.ls.hosts.values() if name not in self.areas]  # a resumed world's
            awaited = (unheard or [MONITOR]) if self.first or self.pending else self.ls.awaited()
            raise self.watch.failure(self.ls.run.tick, awaited, self.rejections.text())
        if self.ended_at is not None and self.reach is not None:  # the monitor holds the end: nothing more to keep
            self.finished = self.held_end
        elif self.ended_at is not None:
            acked = all(p.wait_for_all_acked(_NO_WAIT) for p in (self.pub_status, self.pub_robots, self.pub_metrics))
            self.finished = acked or time.monotonic() - self.ended_at > _LINGER

    def wake_in(self) -> float | None:
        return None

    def close(self, code: int) -> None:
        self.node.get_logger().info(f"the world ended at tick {self.ls.run.tick}")
