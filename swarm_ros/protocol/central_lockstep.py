"""The batches' side of a central world's run in the ROS 2 graph, as plain code (no rclpy): which batches are in,
what each is sent, and when a tick is settled (the world's other side: :mod:`swarm_ros.protocol.central_world`). A
central world is one process holding every robot (:mod:`swarm_ros.core.strips`): the rubenstein algorithm's, and a
plug-in's.

A robot batch announces the strip of columns it decides for (``[first, last]``: the study's model's batches
announce theirs in patch columns); once the batches' strips tile the grid, batch k being the k-th from the west,
the world sends each batch the rows of tick 0 of every robot it sees (its *whole view*: its area's, and those every
batch sees) on /swarm/<algorithm>/area/<batch>. A batch answers with its strip's decisions for the next tick; when
every batch has answered, the world settles the tick (the engine's :meth:`~swarm_ros.core.strips.CentralRun.settle`)
and sends each batch the rows that changed in it, of the robots it saw or sees now, on
/swarm/<algorithm>/changes/<batch> (:class:`~swarm_ros.core.strips.AreaFeed`): a batch keeps what it was sent. A
batch process that announces itself again (restarted) is sent its whole view of the current tick, and so is every
batch by a world that went on from its checkpoint; a batch keeps nothing else between ticks, so it decides as the one
it replaces would have.

A batch lost for good (``on_batch_loss: remove``, for an algorithm whose robots can be removed) is *removed*
(:meth:`CentralLockstep.remove_batch`): the robots that decide in its strip as it is lost leave the world at the end
of the next tick, and from then on the world decides for the robots in its strip itself, with the algorithm's batch
fed what the batch would have been sent, so the run is the in-process run with those robots removed then.

What is the algorithm's own here is its :class:`~swarm_ros.protocol.central_rows.Wire` (the registry's ``wire``
hook): its rows and their checks.
Decisions are checked before they are used: the tick, then the wire's ``check_decisions`` (the rows' own bounds,
that they are exactly the batch's robots, and that each follows the rule's bounds).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from swarm_ros.core.errors import ContractError, Rejected
from swarm_ros.core.strips import AreaFeed, AreaStore, CentralRun, Strips

from .central_rows import Wire


class CentralLockstep:
    """The world's half of a central world's run: ``run`` is the whole swarm, as in one process; ``wire`` the
    algorithm's rows."""

    def __init__(self, run: CentralRun, wire: Wire) -> None:
        self.run, self.wire = run, wire
        self.strips: Strips | None = None  #: set once the announced strips tile the grid
        self.hosts: dict[int, str] = {}  #: batch number -> its node name
        self.announced: dict[str, tuple[int, int]] = {}  #: before the start: node name -> its strip
        self.decided: dict[int, tuple[np.ndarray, Any]] = {}  #: the decisions in for the next tick, by batch
        self.started = False
        #: after a resume from a checkpoint: the last tick the process before may have had decisions of (the tick of
        #: its next save); the batches' topics' histories hand them to this process too
        self.before = -1
        self._columns_at: tuple[int, np.ndarray] = (-1, np.empty(0, dtype=np.int64))
        self.on_settled: Callable[[], None] = lambda: None  #: told when a tick settles later than its decisions
        self.shard_index: int | None = None  #: a world shard's index (``central_shards``), None for the world
        self.feed: AreaFeed | None = None  #: what each batch is sent, made once the strips are known
        #: batch -> the ticks of the whole views sent it: a process that comes back answers the last its topic kept,
        #: maybe after the world sent it the next as it announced itself
        self.wholes: dict[int, set[int]] = {}
        #: the batches removed (lost for good): the world's own batch for each strip, and what it was sent
        self.removed: dict[int, tuple[Any, AreaStore]] = {}
        self.removing: list[tuple[int, np.ndarray]] = []  #: (tick, robots removed at its end), ticks ascending

    @property
    def batches(self) -> int:
        return 0 if self.strips is None else self.strips.batches

    @property
    def mine(self) -> list[int]:
        """The batches it serves: every one."""
        return list(range(self.batches))

    def recorded(self) -> np.ndarray:
        """The robots whose rows its records hold: every robot."""
        return np.arange(self.run.params.robots)

    def announce(self, name: str, strip: tuple[int, int]) -> list[int]:
        """Node ``name`` is up and decides for the cell columns ``strip`` (first, last): the batches to send their
        area now (all of them once the strips tile the grid; a batch that announces itself again, its own).

        Raises:
            Rejected: a strip outside the grid, one that overlaps another batch's, another strip than the node's
                before, or, once the run has started, a strip or a name that is not one of its batches'.
        """
        first, last = strip
        columns = self.run.grid.nx
        if not 0 <= first <= last < columns:
            raise Rejected("strip", f"cell columns {first}..{last}; the grid has {columns}")
        if self.strips is not None:  # started: a batch's process again
            k = next((k for k in range(self.strips.batches) if self.strips.strip(k) == (first, last)), None)
            if k is None or self.hosts[k] != name:
                raise Rejected("strip", f"{name}'s cell columns {first}..{last} are no batch's strip of the run")
            return [k]
        if self.announced.get(name, strip) != strip:
            raise Rejected("strip", f"{name} announced cell columns {self.announced[name]} before, now {strip}")
        if any(other != name and not (b < first or a > last) for other, (a, b) in self.announced.items()):
            raise Rejected("strip", f"{name}'s cell columns {first}..{last} overlap another batch's")
        self.announced[name] = (first, last)
        strips = Strips.tiling(list(self.announced.values()), columns, self.run.grid.reach)
        if strips is None:
            return []
        by_strip = {where: who for who, where in self.announced.items()}
        self.hosts = {k: by_strip[strips.strip(k)] for k in range(strips.batches)}
        self.strips, self.started = strips, True
        return list(range(strips.batches))

    @property
    def cuts(self) -> np.ndarray:
        """The batches' strips, once the run has started (:attr:`Strips.cuts`)."""
        assert self.strips is not None
        return self.strips.cuts

    def number(self, name: str) -> int | None:
        """The batch number of node ``name``, once the run has started; None for a node that is no batch of it."""
        return next((k for k, who in self.hosts.items() if who == name), None)

    def kept(self) -> dict[str, np.ndarray]:
        """What it saves beside the run in a checkpoint: the batches removed and the robots still to remove, at
        which tick's end (a world shard's: its robots too)."""
        if not self.removed:
            return {}
        removing = [[tick, ids.size, *ids.tolist()] for tick, ids in self.removing]
        return {"removed": np.array(sorted(self.removed)), "removing": np.array(sum(removing, []), dtype=np.int64)}

    def resume(self, hosts: dict[int, str], cuts: np.ndarray, kept: dict[str, np.ndarray], before: int = -1) -> None:
        """Serve again, from a checkpoint, the batches named ``hosts`` (batch number -> node name) of the strips cut
        at ``cuts`` (:attr:`Strips.cuts`): their announcements are taken as a restarted batch's, each sent its area
        of the run's tick. ``kept``: what :meth:`kept` gave (the batches removed, and the robots to remove). Decisions
        of other ticks than the one being decided, up to ``before``, are the process before's: ignored, not faults.

        Raises:
            ContractError: ``kept`` that is not what :meth:`kept` gives for these batches.
        """
        self.strips = Strips(np.asarray(cuts, dtype=np.int64), self.run.grid.reach)
        self.hosts = dict(hosts)
        self.started, self.before = True, before
        removed, flat = kept.get("removed", np.empty(0, dtype=np.int64)), kept.get("removing", np.empty(0)).tolist()
        if not set(removed.tolist()) <= set(hosts):
            raise ContractError(f"removed batches {removed.tolist()} of a checkpoint that has batches {sorted(hosts)}")
        for k in removed.tolist():
            self._host_locally(int(k))
        while flat:
            tick, n = int(flat[0]), int(flat[1])
            self.removing.append((tick, np.array(flat[2 : 2 + n], dtype=np.int64)))
            flat = flat[2 + n :]

    # -- batches removed (lost for good) --------------------------------------------------------------------
    def can_remove(self) -> bool:
        """Whether a batch can be removed now (a world's: always)."""
        return True

    def remove_batch(self, k: int) -> np.ndarray:
        """Batch k is lost for good: the robots deciding in its strip now leave the world at the end of the next
        tick, and from then on the world decides for its strip itself (its decisions for the next tick, if in
        already, stand). Returns those robots (none if it was removed already)."""
        if k in self.removed or self.strips is None:
            return np.empty(0, dtype=np.int64)
        ids = self.own(k)
        self.removing.append((self.run.tick + 1, ids))
        self._host_locally(k)
        if k not in self.decided:
            self._decide_locally(k, whole=True)
        return ids

    def _host_locally(self, k: int) -> None:
        assert self.strips is not None
        self.removed[k] = (self.wire.batch(self.run, self.strips, k), AreaStore(self.run, self.strips, k))

    def _decide_locally(self, k: int, whole: bool) -> None:
        """Removed batch k's decisions for the next tick, made here from what it would be sent."""
        host, store = self.removed[k]
        assert self.feed is not None and self.strips is not None
        (ids, entire), robots = (
            self.feed.send([k], {k} if whole else set(), self._columns(), self.holding())[k],
            self.run.robots,
        )
        changed = store.take(self.run.tick, ids, type(robots)(*(a[ids] for a in robots)), entire)
        self.decided[k] = host.decide(self.run.tick + 1, store.seen, changed, store.robots)

    def ready(self) -> bool:
        """Whether every batch's decisions for the next tick are in (the removed ones' are the world's own)."""
        return self.started and len(self.decided) == len(self.mine)

    def _columns(self) -> np.ndarray:
        """Every robot's cell column at the current tick (found once a tick)."""
        if self._columns_at[0] != self.run.tick:
            self._columns_at = (self.run.tick, self.run.grid.columns(self.run.robots.x))
        return self._columns_at[1]

    def area(self, k: int) -> np.ndarray:
        """The rows of the robots batch k sees at the current tick, all of them (its whole view)."""
        return self.areas([k], {k})[k][0]

    def areas(self, batches: list[int], whole: set[int]) -> dict[int, tuple[np.ndarray, bool]]:
        """What to send each of ``batches`` at the current tick: (rows, whether they are its whole view); the whole
        view to the batches ``whole`` and to every one the first time (:class:`~swarm_ros.core.strips.AreaFeed`)."""
        assert self.strips is not None
        if self.feed is None:
            self.feed = AreaFeed(self.run, self.strips)
        for k in [k for k in batches if k in self.removed]:
            self._decide_locally(k, k in whole)
        out = {}
        remote = [k for k in batches if k not in self.removed]
        for k, (ids, entire) in self.feed.send(remote, whole, self._columns(), self.holding()).items():
            out[k] = (self.wire.rows(ids, self.run.robots), entire)
            if entire:
                self.wholes.setdefault(k, set()).add(self.run.tick)
        return out

    def holding(self) -> np.ndarray | None:
        """The robots it holds, a mask; None: every one."""
        return None

    def awaited(self) -> list[str]:
        """The batches whose decisions for the next tick are not in yet, by node name."""
        return [name for k, name in sorted(self.hosts.items()) if k not in self.decided and k not in self.removed]

    def own(self, k: int) -> np.ndarray:
        """The robots batch k decides for at the next tick: its strip's deciding robots, ascending."""
        assert self.strips is not None
        deciding = self.run.deciding()
        return deciding[self.strips.in_strip(self._columns()[deciding], k)]

    def decisions(self, k: int, tick: int, rows: np.ndarray) -> bool:
        """Batch k's decisions for ``tick``: checked, kept, and once every batch's are in, the tick settled.
        Returns whether it was.

        Raises:
            Rejected: decisions that cannot be batch k's for the tick being decided (nothing is kept).
        """
        if not self.started:
            raise Rejected("stale tick", "no tick has gone out yet")
        if tick != self.run.tick + 1 and tick <= self.before:
            return False  # sent to the process before this one (settled in its checkpoint, or past it): no fault
        if tick == self.run.tick and self.run.tick > 0:
            # a restarted batch's second answer to the tick just settled: it answered the area its topic kept, which
            # settled the tick, and then the same area, which the world sent it again as it announced itself
            return False
        if tick - 1 in self.wholes.get(k, ()) and tick <= self.run.tick:
            return False  # a restarted batch's answer to a whole view its topic kept, older than the one it asked for
        if tick != self.run.tick + 1:
            raise Rejected("stale tick", f"tick {tick}; the world is deciding tick {self.run.tick + 1}")
        if k in self.removed:
            raise Rejected("removed batch", f"{self.hosts[k]}'s robots were removed; the world decides its strip")
        if k in self.decided:
            return False  # a restarted batch's second answer: the same, by the rule
        ids, decided = self.wire.check_decisions(self.run, rows, tick, self.own(k))
        self.decided[k] = (ids, decided)
        if not self.ready():
            return False
        return self.settle()

    def settle(self) -> bool:
        """Every batch's decisions are in: settle the tick (here, at once: True), then remove the robots due to
        leave at its end."""
        self.run.settle([self.decided[b] for b in range(self.batches)])
        self.decided.clear()
        while self.removing and self.removing[0][0] <= self.run.tick:
            _, ids = self.removing.pop(0)
            if self.run.outcome is None:
                self.run.remove(ids)
        return True
