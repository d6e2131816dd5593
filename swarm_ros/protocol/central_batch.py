"""A central world's robot batch: decides, each tick, for the deciding robots of its strip
(:mod:`swarm_ros.core.strips`).

Batch k of K announces its strip, ``[first, last]`` column (the strips cut at ``region_cuts``, x positions, or
balanced over the robots at tick 0: :func:`~swarm_ros.core.strips.strips_for`). The world sends it the rows of every
robot it sees (its area: its strip and the grid's reach either side; and those every batch sees) at tick 0 on
/swarm/<algorithm>/area/<batch>, then after each tick the rows of those that changed on
/swarm/<algorithm>/changes/<batch>: what the robots there broadcast. The batch checks them, keeps them
(:class:`~swarm_ros.core.strips.AreaStore`), decides the next tick for its strip's deciding robots (the
algorithm's ``wire``: its rows and its batch) and answers on /swarm/<algorithm>/decisions/<batch>. A restarted batch
is sent its whole view again, so it decides as the one it replaces would have.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.errors import Rejected
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape
from swarm_ros.core.strips import AreaStore, strips_for
from swarm_ros.protocol import checks
from swarm_ros.protocol.batch_host import Inbox, Reply
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.plan import CentralTopics


class CentralBatch:
    """A :class:`~swarm_ros.protocol.batch_host.BatchHost` of a central world's run (the ``batch_host`` hook)."""

    def __init__(
        self, shape: Shape, params: RunParams, own: dict[str, Any], drop: Callable[[str, Rejected], None]
    ) -> None:
        algorithm = algorithm_of(params.algorithm)
        self.robots = params.robots
        self.wire = algorithm.hook("wire")(shape.world.dims)
        self.start = algorithm.hook("engine")(shape, params)  # the grid, the rule and the shape; robots at tick 0
        strips = strips_for(self.start, int(own["batches"]), str(own["region_cuts"]))
        self.host = self.wire.batch(self.start, strips, int(own["batch"]))
        self.strips, self.k = strips, int(own["batch"])
        self.store = AreaStore(self.start, strips, self.k)  # what it was sent, kept
        self.rewound: AreaStore | None = None  # from a whole view older than the store: see _take
        self.decided_from: AreaStore | None = None  # the store the host decided from last
        self.strip = strips.strip(int(own["batch"]))
        self.tick = -1  # the last tick it decided from
        self.received = 0  # bytes of rows taken from its area and changes topics (its log's last line says)
        name, topics = str(own["name"]), CentralTopics.of(params.algorithm)
        self.decisions = topics.decisions(name)
        self.inboxes = (
            Inbox(topics.area(name), functools.partial(self._take, True)),
            Inbox(topics.changes(name), functools.partial(self._take, False)),
        )

    def describe(self) -> str:
        return f"columns {self.strip[0]}..{self.strip[1]}"

    def load(self) -> None:
        """Nothing heavy: the kernels load on the first area."""

    def summary(self) -> str:
        return f"decided up to tick {self.tick + 1}; received {self.received} bytes of rows on its area and changes"

    def _take(self, whole: bool, msg: Cloud) -> Reply:
        """The whole view the world sent (at the start, to this process as it came back, from a world that went on
        from its checkpoint), or the changes of the tick after the one it holds (others: none it can follow, as a
        process that just came back finds the last in its topic's history).

        A whole view older than what it holds is kept beside it (``rewound``), not in its place: it is either a world's
        that went on from its checkpoint, whose next changes follow that view, or one sent as this process came back
        that reached it after changes it had followed, whose next changes follow the store. The changes that follow
        one of the two decide which it was."""
        tick = checks.tick_stamp(msg.header)
        rows = checks.cloud(msg, self.wire.row, self.robots, min_rows=0)
        if whole:
            store = self.store if tick >= self.store.tick else AreaStore(self.start, self.strips, self.k)
            self.rewound = None if store is self.store else store
        elif self.store.follows(tick):
            store, self.rewound = self.store, None
        elif self.rewound is not None and self.rewound.follows(tick):
            store = self.store = self.rewound
            self.rewound = None
        else:
            return None
        self.wire.check_rows(self.start, rows, tick)
        self.received += rows.nbytes
        ids, robots = self.wire.robots_of(rows)
        changed = store.take(tick, ids, robots, whole)
        if store is not self.decided_from:  # the host last decided from the other store: it takes this one whole
            changed, self.decided_from = None, store
        own, decided = self.host.decide(tick + 1, store.seen, changed, store.robots)
        self.tick = max(self.tick, tick)
        return self.wire.decision_rows(own, decided), tick + 1
