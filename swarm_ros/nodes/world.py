"""The world node: owns the shape and the patch occupancy, settles claims, drives the lockstep ticks.

A tick: the world has published the rows of tick t on /swarm/robots; every robot batch
decides for its moving robots and publishes on its own /swarm/decisions/<batch>; once the
decisions of every moving robot are in, the world applies them with the in-process
engine's own code (:meth:`swarm_ros.core.engine.Simulation.apply`), checks for the end,
and publishes what it applied on /swarm/decisions, the rows of tick t + 1, the occupancy
if a robot joined, and the clock.

Every message is taken only once a voucher under the run's key lists it
(:mod:`swarm_ros.ros.auth`; the world vouches for each tick's messages with one voucher),
and checked before use (:mod:`swarm_ros.protocol.checks`): a decision counts
only from the batch hosting its robot, for a moving robot, once per robot and tick, for
the tick being decided, and within the rule set's bounds (:mod:`swarm_ros.core.legality`).
A message that fails is dropped whole and counted (``rejected_messages`` on /swarm/status).

It starts when the robot batches' announcements on /swarm/batches cover every robot, sends each batch
a snapshot of every robot to start from, and never runs more than ``monitor_window``
ticks ahead of the monitor's /swarm/metrics.

A robot batch whose process is lost (liveliness lapses, or its robots stop deciding)
is waited for under ``on_batch_loss: restart`` (the default): the launcher restarts
the process, which announces the same robots again; the world sends it a snapshot of
the current tick and the lockstep goes on, with nothing lost, since a decision is a
pure function of the state, the seed, the robot and the tick. After ``max_restarts``
restarts, or ``restart_timeout`` seconds without one, or always under ``remove``, the
lost batch's robots are removed at the end of the next tick.

/swarm/status (and /swarm/occupancy) are published at least once a second of wall
time, and at once on every change of the run's state.

    ros2 run swarm_ros world --ros-args --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

import os
import time
from collections import deque

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import PointCloud2
from rclpy.duration import Duration
from rclpy.event_handler import QoSLivelinessChangedInfo, SubscriptionEventCallbacks
from std_msgs.msg import Empty, Int64MultiArray

from swarm_ros.core.engine import Simulation
from swarm_ros.core.legality import illegal
from swarm_ros.core.metrics import METRIC_COLUMNS, Outcome
from swarm_ros.core.rules import Decisions
from swarm_ros.core.state import MOVING_STATES, RobotState
from swarm_ros.core.warmup import warm_up
from swarm_ros.core.signals import PARENT_ENV, process_age
from swarm_ros.protocol.rows import DECISION_ROW, decision_rows, decisions_of, robot_rows
from swarm_ros.protocol import checks as guard
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.auth import auth_topic, open_auth
from swarm_ros.protocol.checks import Rejected, Rejections
from swarm_ros.ros.node_params import make_node, read_parameters
from swarm_ros.ros.runtime import RunFailed, run_node

_MONITOR = "monitor"  # the monitor's node name (the launcher's)
_STALL_S = 5.0  # seconds without progress after which a silent batch or monitor counts as lost
_FIRST_STALL_S = 30.0  # the same before its first decisions or report (discovery may be slow)
_LINGER = 1.0  # at most this many seconds for the last messages to reach their readers before exiting
_NO_WAIT = Duration(seconds=0)
_FINAL_WAIT = 30.0  # seconds to wait, after the end, for the monitor to catch up
STATUS_PERIOD = 1.0  # seconds of wall time between /swarm/status (and /swarm/occupancy) messages


class WorldNode:
    def __init__(self) -> None:
        self.node = node = make_node("world")
        run, own = read_parameters(node, "world")
        self.shape, self.params = run.resolve()
        self.window = self.monitor_window = int(own["monitor_window"])
        self.start_timeout = float(own["start_timeout"])
        self.on_loss = str(own["on_batch_loss"])
        self.max_restarts = int(own["max_restarts"])
        self.restart_timeout = float(own["restart_timeout"])
        self.finished = False
        self.rejections = Rejections(node.get_logger())
        self.signer, self.gate = open_auth(node, "world", self.rejections)

        signed = self.signer.publisher
        self.pub_robots = signed(PointCloud2, msgs.ROBOTS, msgs.ROBOTS_QOS)
        self.pub_shape = signed(msgs.OccupancyGrid, msgs.SHAPE, msgs.LATCHED_QOS)
        self.pub_occupancy = signed(msgs.OccupancyGrid, msgs.OCCUPANCY, msgs.LATCHED_QOS)
        self.pub_status = signed(DiagnosticArray, msgs.STATUS, msgs.LATCHED_QOS)
        self.pub_clock = signed(msgs.Clock, msgs.CLOCK, msgs.CLOCK_QOS)
        self.pub_decisions = signed(PointCloud2, msgs.DECISIONS, msgs.DECISIONS_QOS)  # applied
        self.gate.subscribe(Int64MultiArray, msgs.BATCHES, self._on_batch, msgs.BATCHES_QOS)
        self.gate.subscribe(Int64MultiArray, msgs.METRICS, self._on_metrics, msgs.METRICS_QOS)
        self._watch(msgs.alive_topic(_MONITOR), self._on_monitor_liveliness)

        n = self.params.robots
        self.host = np.full(n, -1, dtype=np.int64)  # batch number hosting each robot
        self.batch_names: list[str] = []
        self.started = False
        self.created = time.monotonic()
        self.parts: list[np.ndarray] = []
        self.received = 0
        self.monitor_tick = -1
        self.queued: deque = deque()  # (tick, rows, joined, decisions applied) held while the monitor is behind
        self.ended_at: float | None = None
        self.lost: list[str] = []  # batches (and the monitor) whose liveliness lapsed
        self.progress_at = time.monotonic()  # the last tick published or metrics received
        self.pending = np.empty(0, dtype=np.int64)  # robots of lost batches, removed at the end of the next tick
        self.decided = np.zeros(n, dtype=bool)  # robots whose decision for the coming tick is in
        self.snapshot_pubs: list = []  # per batch: /swarm/snapshot/<batch>
        self.restart_counts: list[int] = []  # per batch
        self.incarnations: list[int] = []  # per batch: the newest process's incarnation heard of
        self.down_since: dict[int, float] = {}  # batches lost and waited for: when
        self.removed_batches: set[int] = set()
        self.respawned: dict[int, np.ndarray] = {}  # batch -> robots: re-announced with no higher incarnation
        self.lapsed: set[int] = set()  # batches whose liveliness lapsed since their last accepted announcement
        self.restarts: list[tuple[int, str]] = []  # (tick, batch) of every restart
        self.status_at = -1.0  # when /swarm/status was last published
        self.published_tick = -1
        self.monitor_alive = False
        self.start_time: float | None = None  # time.monotonic() of tick 0
        self.startup_seconds = float("nan")

    def load(self) -> None:
        """The heavy part, once the endpoints exist: discovery of the peers goes on meanwhile."""
        node, n = self.node, self.params.robots
        self.sim = Simulation(self.shape, self.params)
        warm_up(self.shape, self.params)
        self.shape_cells = msgs.shape_cells(self.shape)
        self.pub_shape.publish(msgs.grid_message(self.shape, self.shape_cells, 0))
        self._publish_occupancy()
        self._publish_status()
        node.get_logger().info(f"world: {self.shape.name} ({self.shape.patches} patches), {n} robots, "
                               f"waiting for robot batches")

    # -- start --------------------------------------------------------------------
    def _on_batch(self, msg: Int64MultiArray) -> None:
        try:
            name, incarnation, ids = guard.announcement(msg, self.params.robots)
            if name not in self.batch_names and not self.started:
                taken = ids[self.host[ids] >= 0]
                if taken.size:
                    raise Rejected("robots of another batch", f"'{name}' names robot {taken[0]}, hosted by "
                                                              f"{self.batch_names[self.host[taken[0]]]}")
        except Rejected as fault:
            self.rejections.drop(msgs.BATCHES, fault)
            return
        n = self.params.robots
        log = self.node.get_logger()
        if name in self.batch_names:
            self._on_reannounce(self.batch_names.index(name), ids, incarnation)
            return
        if self.started:
            self.rejections.drop(msgs.BATCHES, Rejected("new batch after tick 0", f"'{name}'"))
            return
        k = len(self.batch_names)
        self.host[ids] = k
        self.batch_names.append(name)
        self.restart_counts.append(0)
        self.incarnations.append(0)
        self.snapshot_pubs.append(self.signer.publisher(PointCloud2, msgs.snapshot_topic(name), msgs.LATCHED_QOS))
        topic = msgs.decisions_topic(name)
        self.gate.subscribe(PointCloud2, topic, lambda m, k=k, t=topic: self._on_decisions(k, t, m),
                            msgs.DECISIONS_QOS)
        self._watch(msgs.alive_topic(name), lambda info, k=k: self._on_batch_liveliness(k, info))
        covered = int((self.host[4:] >= 0).sum())
        log.info(f"{name} hosts {ids.size} robots; {covered}/{n - 4} covered")
        if incarnation:  # restarted before the world heard from the processes before it
            self._on_reannounce(k, ids, incarnation)
        if covered == n - 4:
            self._maybe_start()

    def _on_reannounce(self, k: int, ids: np.ndarray, incarnation: int, respawn: bool = False) -> None:
        """A batch announced again: its process was restarted. Send it the current tick to start from."""
        name = self.batch_names[k]
        log = self.node.get_logger()
        if incarnation <= self.incarnations[k]:
            # The same process again, an older one's announcement, or a new process that a launcher
            # without restart counting (ros2 launch's respawn) started: that one is taken once the
            # batch is known to be lost, now or when its liveliness lapses.
            if respawn or (self.started and (k in self.down_since or k in self.lapsed)):
                incarnation = self.incarnations[k] + 1
            else:
                self.respawned[k] = ids
                return
        if not np.array_equal(ids, np.flatnonzero(self.host == k)):
            self.rejections.drop(msgs.BATCHES, Rejected("robots of another batch",
                                                        f"'{name}' announced other robots than before"))
            return
        if k in self.removed_batches or self.sim.done:
            log.warn(f"ignored a new announcement of {name}: its robots are removed or the run is over")
            return
        tick = self.sim.tick if self.started else 0
        self.respawned.pop(k, None)
        self.lapsed.discard(k)
        self.restart_counts[k] += incarnation - self.incarnations[k]
        self.restarts += [(tick, name)] * (incarnation - self.incarnations[k])
        self.incarnations[k] = incarnation
        self.down_since.pop(k, None)
        log.warn(f"{name} is back (restart {self.restart_counts[k]}) at tick {tick}"
                 + ("; sending it a snapshot" if self.started else ""))
        if self.started:
            self._send_snapshot(k)
        self._publish_status()

    def _send_snapshot(self, k: int) -> None:
        s = self.sim.state
        rows = robot_rows(np.arange(s.robots), s.state, s.x, s.y, s.heading)
        self.snapshot_pubs[k].publish(msgs.make_cloud(rows, self.sim.tick))

    def _maybe_start(self) -> None:
        """Tick 0 once batches host every robot and the monitor is there (so the run never stalls for it).

        Without a monitor to wait for (``monitor_window: 0``), or one that did not appear
        within ``_FIRST_STALL_S``, the swarm starts without it.
        """
        if self.started or int((self.host[4:] >= 0).sum()) < self.params.robots - 4:
            return
        if self.window and not (self.monitor_alive and self._monitor_reads_all()) and _MONITOR not in self.lost:
            if time.monotonic() - self.created < _FIRST_STALL_S:
                return
            self._lose_monitor(f"not seen within {_FIRST_STALL_S:g} s")
        self._start()

    def _monitor_reads_all(self) -> bool:
        """Whether this node has discovered the monitor's reader of every topic the run's bag records.

        Discovery of a reader is when this node's writers match it; the batches, on the same
        discovery traffic, match its reader of decisions at about the same time (and their
        history, TRANSIENT_LOCAL, covers a late match). Waiting for these, not only for the
        monitor's liveliness, keeps the bag whole from tick 0: a reader that matched after a
        topic's first messages would miss them (``/clock``, volatile) or keep only the last
        (``/swarm/occupancy``).
        """
        return all(any(info.node_name == _MONITOR for info in self.node.get_subscriptions_info_by_topic(topic))
                   for topic in (*msgs.MONITOR_READS, auth_topic("world")))

    def _start(self) -> None:
        self.started = True
        self.start_time = time.monotonic()
        self.startup_seconds = _startup_seconds()
        waited = " and the monitor" if self.window else ""
        self.node.get_logger().info(f"all robots hosted by {len(self.batch_names)} batches{waited}: tick 0")
        for k in range(len(self.batch_names)):
            self._send_snapshot(k)
        s = self.sim.state
        self._emit(0, msgs.make_cloud(robot_rows(np.arange(s.robots), s.state, s.x, s.y, s.heading), 0))

    # -- ticks --------------------------------------------------------------------
    def _on_decisions(self, k: int, topic: str, msg: PointCloud2) -> None:
        """Batch ``k``'s decisions (on ``topic``, its own): used whole once checked, or dropped and counted."""
        if self.started and self.sim.done:
            return  # answers to the tick after the last: the run is over
        try:
            rows = self._checked_decisions(k, msg)
        except Rejected as fault:
            self.rejections.drop(topic, fault)
            return
        if self.pending.size:  # a lost batch's last words (or a stalled one's, resumed) do not count
            rows = rows[~np.isin(rows["id"], self.pending)]
            if not rows.size:
                return
        tick = self.sim.tick + 1
        self.decided[rows["id"]] = True
        if self.down_since:  # a batch deciding is not lost
            for k in np.unique(self.host[rows["id"]]).tolist():
                self.down_since.pop(k, None)
        self.parts.append(rows)
        self.received += rows.size
        self._maybe_advance(tick)

    def _checked_decisions(self, k: int, msg: PointCloud2) -> np.ndarray:
        """The rows of a decisions message from batch ``k``, if the rules allow every one of them.

        Raises:
            Rejected: before tick 0, a tick other than the one being decided, a malformed
                cloud, a robot out of range, repeated, not hosted by batch ``k``, not moving
                or decided already this tick, or a decision out of the rules' bounds.
        """
        if not self.started:
            raise Rejected("before tick 0")
        tick, now = guard.tick_stamp(msg.header), self.sim.tick
        if tick <= now:
            raise Rejected("stale tick", f"tick {tick}; the world is deciding tick {now + 1}")
        if tick > now + 1:
            raise Rejected("future tick", f"tick {tick}; the world is deciding tick {now + 1}")
        rows = guard.cloud(msg, DECISION_ROW, self.params.robots)
        ids = rows["id"].astype(np.int64)
        guard.ids_in_range(ids, 0, self.params.robots)
        if (self.host[ids] != k).any():
            i = int(ids[self.host[ids] != k][0])
            raise Rejected("not the batch's robot", f"robot {i} is not hosted by {self.batch_names[k]}")
        s = self.sim.state
        if not np.isin(s.state[ids], MOVING_STATES).all():
            raise Rejected("robot not moving", f"robot {int(ids[~np.isin(s.state[ids], MOVING_STATES)][0])}")
        if self.decided[ids].any():
            raise Rejected("decided already", f"robot {int(ids[self.decided[ids]][0])} at tick {tick}")
        bad = illegal(self.params, self.shape.world.radius, s.frontier, s.x[ids], s.y[ids],
                      rows["claim"].astype(np.int64), rows["x"], rows["y"], rows["heading"])
        if bad.any():
            row = rows[int(np.flatnonzero(bad)[0])]
            raise Rejected("illegal decision", f"robot {int(row['id'])}: claim {int(row['claim'])}, pose "
                                               f"({row['x']!r}, {row['y']!r}, {row['heading']!r})")
        return rows

    def _maybe_advance(self, tick: int) -> None:
        """Apply the tick once every moving robot that is not being removed has decided."""
        expected = self.sim.metrics.moving - len(self._standing())
        if self.received > expected:
            raise RunFailed(f"tick {tick}: {self.received} decisions for {expected} moving robots")
        if self.received == expected:
            self._advance(tick)

    def _standing(self) -> np.ndarray:
        """Moving robots of lost batches: they stand still in their last tick, then are removed."""
        return self.pending[np.isin(self.sim.state.state[self.pending], MOVING_STATES)]

    def _advance(self, tick: int) -> None:
        parts = [decisions_of(tick, r) for r in self.parts]
        standing = self._standing()
        if standing.size:
            s = self.sim.state
            parts.append(Decisions(tick=tick, ids=standing, claim=np.full(standing.size, -1, dtype=np.int64),
                                   x=s.x[standing].copy(), y=s.y[standing].copy(),
                                   heading=s.heading[standing].copy()))
        decisions = Decisions.concatenate(parts)
        applied = msgs.make_cloud(decision_rows(decisions), tick)
        self.parts, self.received = [], 0
        self.decided[:] = False
        localized_before = self.sim.metrics.localized
        try:
            self.sim.apply(decisions)
        except ValueError as exc:
            raise RunFailed(f"tick {tick}: {exc}") from None
        if self.pending.size:
            removed = self.sim.remove(self.pending)
            self.node.get_logger().warn(f"tick {tick}: removed the {removed} robots of lost batches")
            self.pending = np.empty(0, dtype=np.int64)
        s = self.sim.state
        ids = np.union1d(self.sim.last_joins()[0], self.sim.last_removed)  # deciders and failed robots changed
        self._emit(tick, msgs.make_cloud(robot_rows(ids, s.state, s.x, s.y, s.heading), tick),
                   joined=self.sim.metrics.localized != localized_before or self.sim.last_removed.size > 0,
                   decisions=applied)

    def _emit(self, tick: int, robots_msg: PointCloud2, joined: bool = False,
              decisions: PointCloud2 | None = None) -> None:
        """Publish a tick (with the decisions applied in it) now, or queue it while the monitor is more than
        ``monitor_window`` ticks behind."""
        self.queued.append((tick, robots_msg, joined, decisions))
        self._flush()

    def _flush(self) -> None:
        while self.queued and (self.window == 0 or self.queued[0][0] - self.monitor_tick <= self.window):
            tick, robots_msg, joined, decisions = self.queued.popleft()
            with self.signer.batch():  # one voucher for the tick's messages
                if decisions is not None:
                    self.pub_decisions.publish(decisions)
                self.pub_robots.publish(robots_msg)
                self.progress_at = time.monotonic()
                if joined:
                    self._publish_occupancy()
                self.pub_clock.publish(msgs.clock_message(tick))
                self.published_tick = tick
                if tick == self.sim.tick and self.sim.done:
                    self._announce_end()
                elif tick == 0:
                    self._publish_status()

    def _publish_occupancy(self) -> None:
        """The occupancy now, stamped with the world's tick (it may be ahead of the last published rows)."""
        cells = self.shape_cells.copy()
        cells[self.sim.state.occupancy >= 0] = msgs.CELL_FULL
        self.pub_occupancy.publish(msgs.grid_message(self.shape, cells, self.sim.tick))

    def _announce_end(self) -> None:
        m, outcome = self.sim.metrics, self.sim.outcome
        self.ended_at = time.monotonic()
        self.gate.settle()  # the last status has the run's counts
        self._publish_status()
        self.node.get_logger().info(f"run ended: {outcome.value} at tick {m.tick}, {m.localized} localized")

    def _publish_status(self, note: str = "") -> None:
        """The run's state on /swarm/status (latched): outcome, the last published tick and its counts, the rule
        set, restarts and lost processes; also /swarm/occupancy, for readers that joined late."""
        self.status_at = time.monotonic()
        tick = max(self.published_tick, 0)
        level = DiagnosticStatus.OK
        if not self.started:
            outcome, message = "starting", "waiting for robot batches"
        elif self.ended_at is not None:
            outcome = self.sim.outcome.value
            message = f"{outcome} at tick {tick}"
            if self.sim.outcome not in (Outcome.COMPLETE, Outcome.COMPLETE_WITH_EXTRAS):
                level = DiagnosticStatus.WARN
        else:
            outcome, message = "running", note or "running"
        if note or self.lost or self.down_since:
            level = DiagnosticStatus.WARN
        m = self.sim.history[min(tick, self.sim.tick)] if self.started else None
        s = self.sim.state
        values = {"rules": self.params.ruleset.label, "robots": self.params.robots}
        if m is not None:
            values.update({key: int(m[METRIC_COLUMNS.index(key)]) for key in ("localized", "moving", "walking")})
        if self.started:
            values["startup_seconds"] = f"{self.startup_seconds:.3f}"
        if self.ended_at is not None:
            values["separated"] = int((s.state == RobotState.SEPARATED).sum())
            values["wall_seconds"] = f"{self.ended_at - self.start_time:.3f}"
        values["restarts"] = msgs.restarts_text(self.restarts)
        values["rejected_messages"] = self.rejections.total
        values["rejected"] = self.rejections.text()
        values["lost"] = ",".join(self.lost)
        values["waiting_for"] = ",".join(self.batch_names[k] for k in sorted(self.down_since))
        with self.signer.batch():
            self.pub_status.publish(msgs.status_message(tick, outcome, message, level, values))
            if self.started:
                self._publish_occupancy()

    def _on_metrics(self, msg: Int64MultiArray) -> None:
        try:
            tick = guard.metrics_tick(msg, METRIC_COLUMNS, self.published_tick)
        except Rejected as fault:
            self.rejections.drop(msgs.METRICS, fault)
            return
        if tick > self.monitor_tick:
            self.monitor_tick = tick
            self.progress_at = time.monotonic()
            self._flush()

    # -- lost processes (liveliness) ------------------------------------------------
    def _watch(self, topic: str, on_change) -> None:
        self.node.create_subscription(Empty, topic, lambda msg: None, msgs.ALIVE_QOS,
                                      event_callbacks=SubscriptionEventCallbacks(liveliness=on_change))

    def _on_batch_liveliness(self, k: int, info: QoSLivelinessChangedInfo) -> None:
        if info.alive_count == 0 and info.not_alive_count > 0:
            self.lapsed.add(k)
            self._lose_batch(k, "liveliness lapsed")
        elif info.alive_count > 0 and k in self.respawned and self.started:  # a respawned process is up
            self._on_reannounce(k, self.respawned[k], self.incarnations[k], respawn=True)
        elif info.alive_count > 0 and k in self.down_since:  # a process of this batch is alive (again)
            self.down_since.pop(k)

    def _lose_batch(self, k: int, why: str) -> None:
        """Batch ``k``'s process is gone (or stalled). Wait for it to come back, or remove its robots."""
        name = self.batch_names[k]
        if k in self.removed_batches or k in self.down_since or self.sim.done:
            return
        log = self.node.get_logger()
        tick = self.sim.tick
        if not self.started or (self.on_loss == "restart" and self.restart_counts[k] < self.max_restarts):
            # Before tick 0 a lost batch is always waited for (the launcher restarts it in both
            # policies): none of its robots has moved yet, so nothing is lost by waiting.
            self.down_since[k] = time.monotonic()
            log.warn(f"{name} lost ({why}) at tick {tick}: waiting up to {self.restart_timeout:g} s for it to "
                     f"restart (restarts so far: {self.restart_counts[k]} of {self.max_restarts})")
            self._publish_status(f"waiting for {name}")
            if k in self.respawned and self.started:  # its new process announced itself already
                self._on_reannounce(k, self.respawned[k], self.incarnations[k], respawn=True)
            return
        self._remove_batch(k, why)

    def _remove_batch(self, k: int, why: str) -> None:
        """Remove batch ``k``'s robots at the end of the next tick (robots lost for good)."""
        name = self.batch_names[k]
        self.down_since.pop(k, None)
        self.removed_batches.add(k)
        ids = np.flatnonzero(self.host == k)
        ids = ids[self.sim.state.state[ids] != RobotState.REMOVED]
        self.lost.append(name)
        self.pending = np.union1d(self.pending, ids)
        # decisions it sent for this tick before it was lost no longer count either
        self.parts = [r[~np.isin(r["id"], self.pending)] for r in self.parts]
        self.received = sum(r.size for r in self.parts)
        tick = self.sim.tick
        self.node.get_logger().warn(f"{name} lost ({why}) at tick {tick}: its {ids.size} robots "
                                    f"are removed at the end of tick {tick + 1}")
        self._publish_status(f"lost {name}")
        self._maybe_advance(tick + 1)  # the lost robots' decisions are no longer awaited

    def _on_monitor_liveliness(self, info: QoSLivelinessChangedInfo) -> None:
        self.monitor_alive = info.alive_count > 0
        if self.monitor_alive:
            self._maybe_start()
        if info.alive_count == 0 and info.not_alive_count > 0:
            self._lose_monitor("liveliness lapsed")
        elif info.alive_count > 0 and _MONITOR in self.lost:  # it was only starved of CPU for a moment
            self.lost.remove(_MONITOR)
            self.window = self.monitor_window
            self.node.get_logger().warn(f"the monitor is back at tick {self.sim.tick}")
            self._publish_status()

    def _lose_monitor(self, why: str) -> None:
        if _MONITOR in self.lost:
            return
        self.lost.append(_MONITOR)
        self.window = 0  # nobody to wait for: run on
        self.node.get_logger().warn(f"the monitor was lost ({why}) at tick {self.sim.tick}; "
                                    f"the swarm goes on without it")
        self._publish_status("lost the monitor")
        self._flush()

    # -- housekeeping --------------------------------------------------------------
    def close(self, code: int) -> None:
        """Nothing to release."""

    def _check_stalls(self, now: float) -> None:
        """The fallback to liveliness (a process lost before DDS matched its liveliness topic): a batch
        whose robots have not decided, or a monitor that has not reported, for ``_STALL_S`` is lost.
        Before the first decisions or report, while discovery may still be going on, the limit is
        ``_FIRST_STALL_S``."""
        if not self.started or self.sim.done:
            return
        if self.queued:
            limit = _STALL_S if self.monitor_tick >= 0 else _FIRST_STALL_S
            if self.window and now - self.progress_at >= limit:
                self._lose_monitor(f"no metrics for {limit:g} s")
            return
        limit = _STALL_S if self.sim.tick > 0 else _FIRST_STALL_S
        if now - self.progress_at < limit:
            return
        moving = self.sim.moving_ids()
        missing = np.setdiff1d(moving[~self.decided[moving]], self.pending)
        for k in np.unique(self.host[missing]).tolist():
            self._lose_batch(k, f"no decisions for {limit:g} s")
        self.progress_at = now

    def poll(self) -> None:
        now = time.monotonic()
        self.gate.expire(now)
        self._check_stalls(now)
        for k, since in list(self.down_since.items()):
            if now - since > self.restart_timeout:
                if not self.started:
                    raise RunFailed(f"{self.batch_names[k]} was lost before the run started and did not come back "
                                    f"within {self.restart_timeout:g} s (restart_timeout)")
                self._remove_batch(k, f"not back within {self.restart_timeout:g} s")
        if not self.sim.done and now - self.status_at >= STATUS_PERIOD:
            self._publish_status()
        if not self.started and now - self.created > self.start_timeout:
            covered = int((self.host[4:] >= 0).sum())
            dropped = f"; dropped: {self.rejections.text()}" if self.rejections.total else ""
            raise RunFailed(f"robot batches cover {covered} of {self.params.robots - 4} robots after "
                            f"{self.start_timeout:g} s (start_timeout){dropped}")
        if not self.started:
            self._maybe_start()
        if self.ended_at is not None:
            caught_up = self.window == 0 or self.monitor_tick >= self.sim.tick
            # the end is out once every reader acknowledged the last status and rows; a reader that died
            # never does, so wait at most _LINGER for that
            delivered = all(p.wait_for_all_acked(_NO_WAIT) for p in (self.pub_status, self.pub_robots))
            if (caught_up and (delivered or now - self.ended_at > _LINGER)) or now - self.ended_at > _FINAL_WAIT:
                self.finished = True


def _startup_seconds() -> float:
    """Seconds from the start of ``swarm-ros run`` (its process, if it is this process's parent),
    else from the start of this process, to now."""
    parent = os.environ.get(PARENT_ENV, "")
    if parent.isdigit() and int(parent) == os.getppid():
        age = process_age(int(parent))
        if age == age:  # not NaN
            return age
    return process_age()


def main(argv: list[str] | None = None) -> int:
    return run_node("world", WorldNode, argv)


if __name__ == "__main__":
    raise SystemExit(main())
