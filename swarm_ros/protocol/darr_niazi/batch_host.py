"""The study's model's robot batch: hosts a strip of the world and runs the core's robot rule for the robots in it.

The batch announces its strip of columns (:mod:`swarm_ros.core.regions`). The world answers with a snapshot of
its region (the strip and a halo: the robots its robots can sense, and every stationary robot) on
/swarm/snapshot/<batch> (at tick 0, or at the current tick for a batch process that was restarted in the middle of
a run); the batch builds its regional copy of the swarm's state from it (:class:`~swarm_ros.core.swarm_view
.SwarmView`), follows the world's rows for its region on /swarm/region/<batch> from there
(:mod:`swarm_ros.protocol.hosting`), and after each tick sends, on /swarm/decisions/<batch>, what each moving
robot in its strip decided for the next one. A robot that crosses into another strip is that batch's from the next
tick on: the world's row of it is the handover. Rows are checked first (:mod:`swarm_ros.protocol.checks`, and
:meth:`SwarmView.inconsistent`). A decision is a pure function of the state, the seed, the robot and the tick, so a
restarted batch decides exactly as the one it replaces would have. A robot senses only what arrived on the topics,
and the rule reads only the robots within its vision radius of the point ahead.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from swarm_ros.core import regions
from swarm_ros.core.errors import ContractError, Rejected, RunFailed
from swarm_ros.core.params import RunParams
from swarm_ros.core.rules import Decider
from swarm_ros.core.shapes import Shape
from swarm_ros.core.swarm_view import SwarmView
from swarm_ros.core.warmup import warm_up
from swarm_ros.protocol import checks
from swarm_ros.protocol.batch_host import Inbox, Reply
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import apply_robots, checked_robots
from swarm_ros.protocol.plan import ROBOTS_DEPTH, decisions_topic, region_topic, snapshot_topic
from swarm_ros.protocol.rows import decision_rows, pose_of


class StudyBatch:
    def __init__(
        self, shape: Shape, params: RunParams, own: dict[str, Any], drop: Callable[[str, Rejected], None]
    ) -> None:
        self.shape, self.params, self.drop = shape, params, drop
        self.strip = regions.batch_strip(shape, params, own["batch"], own["batches"], own["region_cuts"])
        world = shape.world
        self.view = SwarmView(
            shape, params.robots, regions.area(self.strip, regions.halo(params.vision_radius), world.size)
        )
        self.decider = Decider(shape, params)
        self.radius = world.radius
        self.early: dict[int, np.ndarray] = {}  # checked rows that arrived before the snapshot, by tick
        self.received = 0  # bytes of rows taken from the region topic (scripts/bench_scale.py reports them)
        name = str(own["name"])
        self.decisions = decisions_topic(name)
        self.region = region_topic(name)
        self.inboxes = (
            Inbox(snapshot_topic(name), True, self._on_snapshot),
            Inbox(self.region, False, self._on_robots),
        )

    def describe(self) -> str:
        return f"strip {regions.format_strip(*self.strip, self.radius)}"

    def load(self) -> None:
        warm_up(self.shape, self.params)

    def summary(self) -> str:
        return f"received {self.received} bytes of rows on {self.region} up to tick {self.view.tick}"

    def _on_snapshot(self, msg: Cloud) -> Reply:
        """This batch's region at some tick (its area's moving robots, every stationary one): start (again) from
        it if it is newer than what the view holds."""
        tick, rows = checks.snapshot(msg, self.params.robots, self.radius, self.shape.dims)
        if tick <= self.view.tick:
            return None  # an older snapshot (latched from an earlier restart of this batch)
        try:
            self.view.load(tick, rows["id"], rows["state"], **pose_of(rows))
        except ContractError as exc:
            raise RunFailed(f"snapshot of tick {tick}: {exc}") from None
        while self.view.tick + 1 in self.early:  # rows published after the snapshot was taken
            self._apply(self.view.tick + 1, self.early.pop(self.view.tick + 1))
        self.early.clear()
        return self._decide()

    def _on_robots(self, msg: Cloud) -> Reply:
        self.received += len(msg.data)
        tick, rows = checked_robots(self.view, msg, self.radius)
        if tick <= self.view.tick:
            return None  # history from before the snapshot
        if tick > self.view.tick + 1:
            # No snapshot yet, or an old one (latched from before a restart): keep the newest rows
            # until the world's answer to our announcement, a snapshot of the current tick, comes.
            self.early[tick] = rows
            if len(self.early) > ROBOTS_DEPTH:
                del self.early[min(self.early)]
            return None
        return self._decide() if self._apply(tick, rows) else None

    def _apply(self, tick: int, rows: np.ndarray) -> bool:
        """Apply checked rows to the view; False (dropped and counted) if they cannot be the world's."""
        try:
            apply_robots(self.view, tick, rows)
        except Rejected as fault:
            self.drop(self.region, fault)
            return False
        return True

    def _decide(self) -> Reply:
        """The decisions of the moving robots in this batch's strip for the tick after the view's."""
        moving = self.view.moving_ids()
        cols = regions.columns(self.view.state.x[moving], self.radius)
        own = moving[(cols >= self.strip[0]) & (cols <= self.strip[1])]
        if not own.size:
            return None
        tick = self.view.tick + 1
        return decision_rows(self.decider.decide(self.view.state, own, tick, moving)), tick
