"""The world's lockstep driven with a fake port and clock, no ROS."""

from __future__ import annotations

import numpy as np

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.core.regions import batch_strip, columns
from swarm_ros.core.rules import Decider
from swarm_ros.core.shards import ShardPlan, WorldShard
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.lockstep import Lockstep
from swarm_ros.protocol.plan import batch_name
from swarm_ros.protocol.rows import decision_rows
from swarm_ros.protocol.world_port import Policy

ROBOTS, MAX_TICKS = 60, 400


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, text: str) -> None:
        self.lines.append(text)

    warn = warning = info


class LockstepPort:
    """Records what the lockstep publishes."""

    def __init__(self) -> None:
        self.watched: list[str] = []
        self.snapshots: list[tuple[int, int]] = []  # (batch, tick)
        self.ticks: list[int] = []
        self.statuses: list = []
        self.monitor_ready = True
        self.saver = None  # a ShardSaver, to restart from (test_world_restart.py)
        self.books: list[dict] = []
        #: (tick, batch, rows, snapshot): snapshots and region rows, as sent
        self.regions: list[tuple[int, int, np.ndarray, bool]] = []

    def watch_batch(self, k, name):
        self.watched.append(name)

    def send_snapshot(self, k, tick, rows):
        self.snapshots.append((k, tick))
        self.regions.append((tick, k, rows, True))

    def publish_tick(self, tick, rows, joined, applied, regional, tally):
        assert (applied is None) == (tick == 0) and tally is None and rows is not None  # record_every 1
        self.ticks.append(tick)
        self.regions += [(tick, k, part, False) for k, part in enumerate(regional or ())]

    def publish_status(self, status):
        self.statuses.append(status)

    def save_tick(self, tick, rows, published, applied, metrics, sent, tally):
        if self.saver is not None:
            self.saver.write_tick(tick, rows, published, applied, metrics, sent, tally)

    def send_claims(self, peer, tick, claims):
        raise AssertionError("the world alone has no peers")

    send_part = send_claims

    def ask_again(self, peer):
        raise AssertionError("the world alone has no peers")

    def save_book(self, book):
        self.books.append(book)
        if self.saver is not None:
            self.saver.save_book(book)

    def monitor_reads_all(self):
        return self.monitor_ready

    def delivered(self):
        return True

    def decisions_delivered(self):
        return True

    def startup_seconds(self):
        return 0.5


class LockstepRun:
    """A lockstep, its port and clock, and batches that decide as robot-batch processes do."""

    def __init__(self, batches: int = 2, cuts: list[int] | None = None, shape: str = "star", **policy) -> None:
        self.shape = Shape.load(shape)
        self.params = RunParams(robots=ROBOTS, seed=7, max_ticks=MAX_TICKS)
        self.cuts = text = ",".join(map(str, cuts or []))
        self.strips = [batch_strip(self.shape, self.params, k, batches, text) for k in range(batches)]
        self.clock, self.port, self.log = Clock(), LockstepPort(), Log()
        self.rejections = Rejections(self.log)
        self.ls = self.make(Policy(**{"monitor_window": 0, **policy}))
        self.batches = batches
        self.decider = Decider(self.shape, self.params)

    def make(self, policy: Policy) -> Lockstep:
        """A world process's lockstep: the world alone, a shard with no peers."""
        plan = ShardPlan(self.shape.world.radius, self.params.vision_radius, np.empty(0, dtype=np.int64))
        shard = WorldShard(self.shape, self.params, plan, 0)
        return Lockstep(shard, "world", policy, self.port, self.log, self.rejections, clock=self.clock)

    def announce(self, k: int, incarnation: int = 0) -> None:
        self.ls.announce(batch_name(k), incarnation, self.strips[k])

    def start(self) -> None:
        """Every batch announces itself (tick 0 follows, unless the monitor is awaited)."""
        for k in range(self.batches):
            self.announce(k)
        assert self.ls.started or self.ls.window

    def decide(self, k: int) -> np.ndarray:
        """Batch ``k``'s decision rows for the coming tick (its strip's moving robots not decided yet)."""
        s = self.ls.sim.state
        own = self.own(k)
        own = own[~self.ls.decided[own]]
        return decision_rows(self.decider.decide(s, own, self.ls.sim.tick + 1))

    def own(self, k: int) -> np.ndarray:
        """The moving robots in batch ``k``'s strip now."""
        s = self.ls.sim.state
        moving = s.moving_ids()
        cols = columns(s.x[moving], self.shape.world.radius)
        return moving[(cols >= self.strips[k][0]) & (cols <= self.strips[k][1])]

    def tick(self, silent: tuple[int, ...] = ()) -> None:
        """One tick: every batch but ``silent`` (and those removed for good) sends its decisions."""
        for k in range(self.batches):
            if k in self.ls.removed_batches:
                continue
            rows = self.decide(k)
            if k not in silent and rows.size:
                self.ls.decisions(k, self.ls.sim.tick + 1, rows)

    def run(self, ticks: int | None = None) -> None:
        """Up to ``ticks`` ticks (None: to the end), while the world goes on (it holds a tick back while the
        monitor is too far behind: then this returns)."""
        end = MAX_TICKS if ticks is None else self.ls.sim.tick + ticks
        while not self.ls.sim.done and self.ls.sim.tick < end:
            before = self.ls.sim.tick
            self.tick()
            if self.ls.sim.tick == before and not self._round_moved():
                return

    def _round_moved(self) -> bool:
        """Whether another round of decisions could move the world on: a batch has robots not decided yet."""
        return any(
            (own := self.own(k)).size and not self.ls.decided[own].all()
            for k in range(self.batches)
            if k not in self.ls.removed_batches
        )

    def engine(self) -> Simulation:
        sim = Simulation(self.shape, self.params)
        sim.run()
        return sim
