"""The rubenstein algorithm's robot batch: decides, each tick, for the robots of its strip of the cell grid.

Batch k of K announces its strip, ``[first, last]`` cell column (the strips cut at ``region_cuts``, x positions in
d, or balanced over the robots at tick 0: :func:`~swarm_ros.core.rubenstein.strips.strips_for`). The world sends
it, after each tick, the rows of its area (its strip and one cell column of halo, the communication range wide) on
/swarm/rubenstein/area/<batch>: what the robots there broadcast. The batch checks them, decides the next tick for
its strip's robots not joined (:class:`swarm_ros.core.rubenstein.strips.RubensteinBatch`) and answers on
/swarm/rubenstein/decisions/<batch>. It keeps nothing between ticks, so a restarted batch decides as the one it
replaces would have.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from swarm_ros.core.errors import Rejected
from swarm_ros.core.params import RunParams
from swarm_ros.core.rubenstein.run import RubensteinRun
from swarm_ros.core.rubenstein.strips import RubensteinBatch, strips_for
from swarm_ros.core.shapes import Shape
from swarm_ros.protocol import checks
from swarm_ros.protocol.batch_host import Inbox, Reply
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.plan import rubenstein_area_topic, rubenstein_decisions_topic
from swarm_ros.protocol.rubenstein.rows import RUBENSTEIN_ROW, check_rubenstein_rows, robots_of_rows, rubenstein_rows


class RubensteinBatchHost:
    def __init__(
        self, shape: Shape, params: RunParams, own: dict[str, Any], drop: Callable[[str, Rejected], None]
    ) -> None:
        self.robots = params.robots
        frame = RubensteinRun(shape, params)  # the grid, the rule and the shape; its robots are not used
        strips = strips_for(frame, int(own["batches"]), str(own["region_cuts"]))
        self.host = RubensteinBatch(frame, strips, int(own["batch"]))
        self.strip = strips.strip(int(own["batch"]))
        self.tick = -1  # the last tick whose area came in
        name = str(own["name"])
        self.decisions = rubenstein_decisions_topic(name)
        self.inboxes = (Inbox(rubenstein_area_topic(name), True, self._on_area),)

    def describe(self) -> str:
        return f"cell columns {self.strip[0]}..{self.strip[1]}"

    def load(self) -> None:
        """Nothing heavy: the kernels load on the first area."""

    def summary(self) -> str:
        return f"decided up to tick {self.tick + 1}"

    def _on_area(self, msg: Cloud) -> Reply:
        tick = checks.tick_stamp(msg.header)
        rows = checks.cloud(msg, RUBENSTEIN_ROW, self.robots, min_rows=0)
        check_rubenstein_rows(rows, self.robots, tick)
        self.tick = max(self.tick, tick)  # an older tick's area is a restarted world's, from its checkpoint: decided
        own, decided = self.host.decide(tick + 1, *robots_of_rows(rows))
        return rubenstein_rows(own, decided), tick + 1
