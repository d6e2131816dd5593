"""A central world cut into S world shards (:mod:`swarm_ros.core.strips`): each shard holds the robots of a run of
consecutive batches' strips (its own columns) and of the grid's ``reach`` (or ``rivals``, if more) columns either side
(its halo), and those every batch sees, never the whole swarm's, and the run is the one world's, exactly.

A shard's engine (the algorithm's, a :class:`ShardedRun`) holds every robot's arrays, of which
only the robots it holds (``present``) are read. A tick, for shard s:

1. its batches decide from the robots of their areas, which lie in its own columns and its halo;
2. every shard sends each other the decisions of its own deciding robots that lie in the other's halo (*border*):
   a grant reads the decisions of the robots within reach, and a claim's lottery those of the robots that can claim
   the same cell (within the grid's ``rivals``);
3. it settles and applies its own robots' moves (the engine's ``settle_shard``), and names those whose rows change
   what every shard shares (the rubenstein algorithm's: the robots that joined, which cover pixels and enter the
   running counts);
4. every shard sends every other those rows and its counts; each closes the tick alike (``close_shard``: the shared
   state, the tick's metrics and the end, the same on every shard);
5. every shard sends each other the rows of its robots now in the other's own columns or halo, or that were at the
   tick's start: robots that crossed into the other's columns are handed over, the other's halo is what its
   neighbours' robots are now, and a robot that left it comes with the row that puts it outside (for the batches'
   changes: :class:`~swarm_ros.core.strips.AreaFeed`).

A robot moves less than its reach a tick, a decision or a grant reads the robots within reach, and every robot
that every batch sees (:meth:`~swarm_ros.core.strips.CentralRun.seen_by_all`) is among those every shard shares,
so each shard decides, settles and closes as the one world does. :class:`CentralExchange` is a shard's side of those
messages, whatever order they come in; :func:`run_sharded` runs S shards end to end in one process over it, delivering
the messages in a shuffled order, for tests.

A restarted shard goes on from its last save (its engine's :meth:`~swarm_ros.core.strips.CentralRun.saved` and the
robots it held, :attr:`CentralShard.present`), at most ``ahead - 1`` ticks behind its peers, which wait for it:
every message its peers sent it since is given to it again (the graph keeps them in its topics' histories), and it
keeps those ``ahead`` ticks ahead of its own until they are due. What it sends again, its peers have: repeats.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from .errors import ContractError, Rejected
from .strips import CentralRun, Strips, merged, shard_batches


class ShardedRun(CentralRun, Protocol):
    """What an engine gives beside :class:`~swarm_ros.core.strips.CentralRun` to run in world shards."""

    def deciding(self, among: np.ndarray | None = None) -> np.ndarray: ...  # of robots ``among`` (all), ascending

    def counts(self, ids: np.ndarray) -> np.ndarray: ...  # robots ``ids``' share of the tick's counts (summed)

    def settle_shard(self, own: np.ndarray, decided: Any, halo: np.ndarray, halo_decided: Any, present: np.ndarray):
        """Settle and apply its ``own`` deciding robots' moves against every robot ``present`` (its halo's decided
        too); the ids of its robots whose rows change what every shard shares."""
        ...

    def close_shard(self, shared: np.ndarray, rows: Any, counts: np.ndarray) -> Any:
        """Close the tick alike on every shard: the ``shared`` robots' ``rows`` in, the summed ``counts``; the
        outcome."""
        ...

    def leave(self, tick: int, ids: np.ndarray) -> None:
        """Robots ``ids`` leave at the end of ``tick``, as :meth:`CentralRun.remove` would then (before the owner's
        counts, and every shard's close); only an algorithm whose robots can be removed has it."""
        ...


def take(robots: Any, ids: np.ndarray | slice) -> Any:
    """The rows of robots ``ids`` of every robot's arrays ``robots`` (a NamedTuple of arrays)."""
    return type(robots)(*(a[ids] for a in robots))


def concat(parts: list[tuple[np.ndarray, Any]]) -> tuple[np.ndarray, Any]:
    """(ids, rows) of several, in ascending id order."""
    ids = np.concatenate([p[0] for p in parts]).astype(np.int64)
    order = np.argsort(ids, kind="stable")
    rows = type(parts[0][1])(*(np.concatenate(f)[order] for f in zip(*(p[1] for p in parts))))
    return ids[order], rows


def ranges(strips: Strips, shards: int) -> list[tuple[int, int]]:
    """Each shard's own columns (first, last): the strips of its batches
    (:func:`~swarm_ros.core.strips.shard_batches`)."""
    spans = [shard_batches(s, shards, strips.batches) for s in range(shards)]
    return [(int(strips.cuts[b[0]]), int(strips.cuts[b[-1] + 1]) - 1) for b in spans]


class CentralShard:
    """World shard ``shard`` of ``shards``: the strips of its batches and one column either side. ``run``: its
    engine, at tick 0 (every robot's rows then true)."""

    def __init__(self, run: ShardedRun, strips: Strips, shard: int, shards: int) -> None:
        self.run, self.strips, self.index = run, strips, shard
        self.batches = shard_batches(shard, shards, strips.batches)
        self.ranges = ranges(strips, shards)
        self.first, self.last = self.ranges[shard]
        #: its halo's columns either side: the batches' (the grid's reach), or those of the rivals of its robots'
        #: claims (the grid's ``rivals``) if more
        self.halo = max(strips.reach, run.grid.rivals)
        self.present = self._held(np.arange(run.params.robots))

    def _within(self, ids: np.ndarray, first: int, last: int) -> np.ndarray:
        columns = self.run.grid.columns(self.run.robots.x[ids])
        return ids[(columns >= first) & (columns <= last)]

    def _held(self, ids: np.ndarray) -> np.ndarray:
        """Of robots ``ids`` (ascending), those it holds as they stand: within its own columns or halo, or seen by
        every batch."""
        robots = self.run.robots
        columns = self.run.grid.columns(robots.x[ids])
        near = (columns >= self.first - self.halo) & (columns <= self.last + self.halo)
        return ids[near | self.run.seen_by_all(robots.state[ids])]

    @property
    def own(self) -> np.ndarray:
        """Its robots: those present in its own columns, ascending."""
        return self._within(self.present, self.first, self.last)

    def neighbours(self) -> list[int]:
        """The shards whose own columns or halo touch its own or its halo: those it sends border decisions and rows
        to (a robot of its own moves less than the reach a tick, so it may enter the halo of a shard past a narrow
        one)."""
        h = self.halo
        return [
            o
            for o, (a, b) in enumerate(self.ranges)
            if o != self.index and a - h <= self.last + h and b + h >= self.first - h
        ]

    def border(self, peer: int, ids: np.ndarray) -> np.ndarray:
        """Which of robots ``ids`` (its own) lie in shard ``peer``'s halo."""
        first, last = self.ranges[peer]
        columns = self.run.grid.columns(self.run.robots.x[ids])
        return ((columns >= first - self.halo) & (columns < first)) | ((columns > last) & (columns <= last + self.halo))

    def reach(self, peer: int, ids: np.ndarray, columns: np.ndarray | None = None) -> np.ndarray:
        """Which of robots ``ids`` (its own) lie in shard ``peer``'s own columns or halo (``columns``: theirs, if not
        where they stand now)."""
        first, last = self.ranges[peer]
        if columns is None:
            columns = self.run.grid.columns(self.run.robots.x[ids])
        return (columns >= first - self.halo) & (columns <= last + self.halo)

    def restore(self, present: np.ndarray) -> None:
        """Go on holding robots ``present`` (a save's, its engine restored to the same tick).

        Raises:
            ContractError: ids that are not robots of the run, or not ascending.
        """
        ids = np.asarray(present, dtype=np.int64)
        if (
            ids.ndim != 1
            or (ids.size and (ids[0] < 0 or ids[-1] >= self.run.params.robots))
            or np.any(np.diff(ids) <= 0)
        ):
            raise ContractError("a world shard's robots that are not ascending ids of the run")
        self.present = ids

    def receive(self, rows: list[tuple[np.ndarray, Any]], shared: np.ndarray) -> None:
        """After a tick (the ``shared`` robots' rows in): the peers' robots ``rows`` (ids, every array's rows) they
        sent it (:meth:`reach`) in, it holds those of them, of the ``shared`` and of those it held that are within
        reach or seen by every batch (:meth:`_held`). The rows of robots that left its reach come too (they were
        within it before the tick), so what it sends its batches shows them gone."""
        if rows:
            ids, got = concat(rows)
            for a, b in zip(self.run.robots, got):
                a[ids] = b
            shared = np.concatenate([shared, ids])
        self.present = self._held(merged(self.present, shared))

    def holding(self) -> np.ndarray:
        """Which robots it holds (a mask over the run's)."""
        mask = np.zeros(self.run.params.robots, dtype=bool)
        mask[self.present] = True
        return mask


class ShardPort(Protocol):
    """What a :class:`CentralExchange` sends, and to whom (peers by shard index)."""

    def send_border(self, peer: int, tick: int, ids: np.ndarray, decided: Any) -> None: ...

    def send_shared(
        self, tick: int, ids: np.ndarray, rows: Any, counts: np.ndarray, leaving: np.ndarray
    ) -> None: ...  # to every peer: its robots whose rows every shard shares, its counts, and its robots that leave

    def send_rows(self, peer: int, tick: int, ids: np.ndarray, rows: Any) -> None: ...

    def closed(self, tick: int) -> None: ...  # the tick is closed on this shard: its next areas may go out


DECIDING, BORDER, SHARED, ROWS = range(4)  #: what a shard waits for in a tick: its batches, then its peers'


class CentralExchange:
    """A world shard's side of each tick's exchanges (the module's steps 2 to 5), messages in any order: what comes
    for the tick being settled or the ``ahead - 1`` after it is kept until it is due, a repeat of a closed tick is
    ignored, anything else is refused (:class:`~swarm_ros.core.errors.Rejected`, by kind). It answers through a
    :class:`ShardPort`."""

    def __init__(self, shard: CentralShard, port: ShardPort, ahead: int = 2) -> None:
        self.shard, self.port, self.ahead = shard, port, ahead
        self.neighbours = shard.neighbours()
        self.peers = [o for o in range(len(shard.ranges)) if o != shard.index]
        self.inbox: dict[tuple[str, int], dict[int, tuple]] = {}
        self.restart()

    def restart(self) -> None:
        """Go on from the shard's tick (its engine restored from a save): what is kept of later ticks stays."""
        self.tick, self.phase = self.shard.run.tick + 1, DECIDING  # the tick being settled, and what it waits for
        self.inbox = {key: got for key, got in self.inbox.items() if key[1] >= self.tick}
        self.mine = self.own = self.decided_ = self.everyones = None  # type: Any
        self.leaving = np.empty(0, dtype=np.int64)  # its robots that leave at the end of the tick being settled

    def leave(self, ids: np.ndarray) -> None:
        """Its robots ``ids`` (ascending) leave at the end of the tick being settled, every shard told with its shared
        rows (:meth:`ShardedRun.leave`); ContractError once those went out (the caller waits for the tick's close)."""
        if self.phase not in (DECIDING, BORDER):
            raise ContractError(f"robots that leave at the end of tick {self.tick}, whose shared rows went out")
        self.leaving = np.union1d(self.leaving, ids)

    def decided(self, tick: int, ids: np.ndarray, decided: Any) -> None:
        """Its batches' decisions for ``tick`` (every deciding robot of its own, ascending): on to its peers."""
        if tick != self.tick or self.phase != DECIDING:
            raise Rejected("stale tick", f"decisions for tick {tick}; the shard is at tick {self.tick}")
        self.mine, self.own, self.decided_ = self.shard.own, ids, decided
        self.before = self.shard.run.grid.columns(self.shard.run.robots.x[self.mine])  # where its robots were
        for peer in self.neighbours:
            keep = self.shard.border(peer, ids)
            self.port.send_border(peer, tick, ids[keep], take(decided, keep))
        self.phase = BORDER
        self._advance()

    def border(self, peer: int, tick: int, ids: np.ndarray, decided: Any) -> None:
        self._keep("border", peer, tick, (ids, decided), self.neighbours)

    def shared(self, peer: int, tick: int, ids: np.ndarray, rows: Any, counts: np.ndarray, leaving: np.ndarray) -> None:
        self._keep("shared", peer, tick, (ids, rows, counts, leaving), self.peers)

    def rows(self, peer: int, tick: int, ids: np.ndarray, rows: Any) -> None:
        self._keep("rows", peer, tick, (ids, rows), self.neighbours)

    def _keep(self, kind: str, peer: int, tick: int, message: tuple, senders: list[int]) -> None:
        if peer not in senders:
            raise Rejected("not its peer", f"{kind} from shard {peer}, which sends this shard none")
        if tick < self.tick:
            return  # a repeat of a closed tick
        if tick >= self.tick + self.ahead:
            raise Rejected("stale tick", f"{kind} of tick {tick}; the shard is at tick {self.tick}")
        self.inbox.setdefault((kind, tick), {}).setdefault(peer, message)
        self._advance()

    def awaited(self) -> list[int]:
        """The peers whose messages of the tick being settled it waits for (none while its batches decide)."""
        waits = {BORDER: ("border", self.neighbours), SHARED: ("shared", self.peers), ROWS: ("rows", self.neighbours)}
        if self.phase not in waits:
            return []
        kind, senders = waits[self.phase]
        got = self.inbox.get((kind, self.tick), {})
        return [p for p in senders if p not in got]

    def _all(self, kind: str, senders: list[int]) -> dict[int, tuple] | None:
        got = self.inbox.get((kind, self.tick), {})
        return got if all(p in got for p in senders) else None

    def _advance(self) -> None:
        shard, run = self.shard, self.shard.run
        if self.phase == BORDER and (borders := self._all("border", self.neighbours)) is not None:
            empty = (self.own[:0], take(self.decided_, slice(0, 0)))
            halo, halo_decided = concat([empty, *borders.values()])
            if self.leaving.size:  # (before it settles and counts: its rows are shared, its counts say they fail)
                run.leave(self.tick, self.leaving)
            ids = run.settle_shard(self.own, self.decided_, halo, halo_decided, shard.present)
            rows, counts = take(run.robots, ids), run.counts(self.mine)
            self.inbox.setdefault(("shared", self.tick), {})[shard.index] = (ids, rows, counts, self.leaving)
            self.port.send_shared(self.tick, ids, rows, counts, self.leaving)
            self.phase = SHARED
        if self.phase == SHARED and (shared := self._all("shared", [*self.peers, shard.index])) is not None:
            ids, rows = concat([(i, r) for i, r, _, _ in shared.values()])
            leaving = np.concatenate([gone for *_, gone in shared.values()])
            if leaving.size:
                run.leave(self.tick, np.unique(leaving))
            run.close_shard(ids, rows, np.sum([c for _, _, c, _ in shared.values()], axis=0))
            self.everyones = ids  # the rows every shard now shares
            for peer in self.neighbours:  # its robots within the peer's reach, or that were at the tick's start
                keep = shard.reach(peer, self.mine) | shard.reach(peer, self.mine, self.before)
                self.port.send_rows(peer, self.tick, self.mine[keep], take(run.robots, self.mine[keep]))
            self.phase = ROWS
        if self.phase == ROWS and (rows_in := self._all("rows", self.neighbours)) is not None:
            shard.receive(list(rows_in.values()), self.everyones)
            for kind in ("border", "shared", "rows"):
                self.inbox.pop((kind, self.tick), None)
            self.tick, self.phase, self.leaving = self.tick + 1, DECIDING, self.leaving[:0]
            self.port.closed(self.tick - 1)


def _owned(world: list[CentralShard]) -> Any:
    """Every robot's arrays as its owner holds them (the shards at one tick)."""
    truth = type(world[0].run.robots)(*(np.zeros_like(a) for a in world[0].run.robots))
    for w in world:
        for a, b in zip(truth, w.run.robots):
            a[w.own] = b[w.own]
    return truth


def _check_view(store: Any, truth: Any) -> None:
    """That a batch sees what it would in one world, as it stands (:class:`~swarm_ros.core.strips.AreaStore`).

    Raises:
        ContractError: it does not (a robot that left its view still in it, or a row not the robot's).
    """
    from .strips import view_of

    view = np.flatnonzero(view_of(store.start, store.strips, store.k, truth))
    if not np.array_equal(store.seen, view) or any(
        not np.array_equal(a[view], b[view]) for a, b in zip(store.robots, truth)
    ):
        raise ContractError(f"batch {store.k} does not see what it would in one world at tick {store.tick}")


class _Mail:
    """An in-process transport: every message into one bag, delivered in a shuffled order; every message to a shard
    kept, as the graph's topics keep their histories, to give a restarted shard again."""

    def __init__(self, seed: int) -> None:
        self.bag: list[Callable[[], None]] = []
        self.rng = random.Random(seed)
        self.exchanges: list[CentralExchange] = []
        self.sent: list[list[tuple[int, Callable[[], None]]]] = []  # by receiver: (tick, delivery)

    def port(self, s: int) -> ShardPort:
        mail = self

        def post(peer: int, tick: int, deliver: Callable[[CentralExchange], None]) -> None:
            def thunk() -> None:
                deliver(mail.exchanges[peer])  # to the peer's process at delivery

            mail.bag.append(thunk)
            mail.sent[peer].append((tick, thunk))

        class Port:
            def send_border(self, peer, tick, ids, decided):
                post(peer, tick, lambda ex: ex.border(s, tick, ids, decided))

            def send_shared(self, tick, ids, rows, counts, leaving):
                for o in range(len(mail.exchanges)):
                    if o != s:
                        post(o, tick, lambda ex: ex.shared(s, tick, ids, rows, counts, leaving))

            def send_rows(self, peer, tick, ids, rows):
                post(peer, tick, lambda ex: ex.rows(s, tick, ids, rows))

            def closed(self, tick):
                pass

        return Port()

    def deliver(self) -> None:
        while self.bag:
            self.bag.pop(self.rng.randrange(len(self.bag)))()

    def again(self, s: int, after: int) -> None:
        """Give shard ``s`` again every message sent to it for the ticks after ``after``."""
        self.bag += [thunk for tick, thunk in self.sent[s] if tick > after]


def run_sharded(
    make_run: Callable[[], ShardedRun],
    batch: Callable[[ShardedRun, Strips, int], Any],
    shards: int,
    batches: int,
    max_ticks: int | None = None,
    region_cuts: str = "",
    seed: int = 0,
    restarts: dict[int, int] | None = None,
    save_every: int = 10,
    removals: dict[int, int] | None = None,
) -> list[CentralShard]:
    """Run a central world as ``shards`` world shards of ``batches`` batches (``batch(run, strips, k)`` gives batch
    k, as the algorithm's wire does), from ``make_run()`` (a fresh engine, one per shard), to its end or
    ``max_ticks`` ticks: each shard a :class:`CentralExchange`, their messages delivered in an order shuffled by
    ``seed``. Each shard saves every ``save_every`` ticks; ``restarts`` (tick -> shard) restarts a shard as it is
    about to decide that tick: a fresh engine from its last save, given again what its peers sent it since;
    ``removals`` (tick t -> batch k) removes batch k as tick t + 1 is decided: the robots deciding in its strip leave
    at that tick's end (the world goes on deciding its strip, here with the same batch). Returns
    the shards: each one's engine has the run's metrics and outcome, and the rows of its own robots.

    Raises:
        ContractError: the shards did not end at the same tick, or a restart never came.
    """
    from .strips import AreaFeed, AreaStore, strips_for

    runs = [make_run() for _ in range(shards)]
    strips = strips_for(runs[0], batches, region_cuts)
    world = [CentralShard(runs[s], strips, s, shards) for s in range(shards)]
    hosts = {k: batch(w.run, strips, k) for w in world for k in w.batches}
    feeds = [AreaFeed(w.run, strips) for w in world]  # what each shard sends its batches: whole views, then changes
    stores = {k: AreaStore(w.run, strips, k) for w in world for k in w.batches}
    mail = _Mail(seed)
    mail.sent = [[] for _ in range(shards)]
    ahead = save_every + 2  # the ticks a restarted shard may be behind its peers, and the one they are at
    mail.exchanges = [CentralExchange(w, mail.port(s), ahead) for s, w in enumerate(world)]
    end = None if max_ticks is None else runs[0].tick + max_ticks
    saves: dict[int, tuple[int, dict[str, np.ndarray], np.ndarray]] = {}
    pending = dict(restarts or {})
    while True:
        due = [
            s
            for s, (w, ex) in enumerate(zip(world, mail.exchanges))
            if ex.phase == DECIDING and w.run.outcome is None and (end is None or ex.tick <= end)
        ]
        if not due and not mail.bag:
            break
        ticks = {w.run.tick for w in world}
        truth = _owned(world) if len(ticks) == 1 else None  # every robot as its owner has it, at that tick
        for s in due:
            w = world[s]
            if pending.get(w.run.tick + 1) == s:  # (killed before it saved the tick it closed: the most behind)
                del pending[w.run.tick + 1]
                fresh = make_run()
                w = world[s] = CentralShard(fresh, strips, s, shards)
                tick = 0  # killed before its first save: from the start
                if s in saves:
                    tick, arrays, present = saves[s]
                    fresh.restore(tick, arrays)
                    w.restore(present)
                hosts.update({k: batch(fresh, strips, k) for k in w.batches})
                feeds[s] = AreaFeed(fresh, strips)  # (its batches are sent their whole views again)
                mail.exchanges[s] = CentralExchange(w, mail.port(s), ahead)
                mail.again(s, tick)
            if w.run.tick % save_every == 0:  # as the graph saves: before the tick's areas go out
                saves[s] = (w.run.tick, {k: np.copy(v) for k, v in w.run.saved().items()}, w.present.copy())
            parts = []
            for k, (ids, whole) in feeds[s].send(list(w.batches), among=w.holding()).items():
                changed = stores[k].take(w.run.tick, ids, take(w.run.robots, ids), whole)
                if truth is not None and ticks == {w.run.tick}:  # (not a shard just restarted from its save)
                    _check_view(stores[k], truth)
                parts.append(hosts[k].decide(w.run.tick + 1, stores[k].seen, changed, stores[k].robots))
            if (k := (removals or {}).get(w.run.tick, -1)) in w.batches:  # its robots deciding in k's strip leave
                mine = w.run.deciding(w.present)
                mail.exchanges[s].leave(mine[strips.in_strip(w.run.grid.columns(w.run.robots.x[mine]), k)])
            mail.exchanges[s].decided(w.run.tick + 1, *concat(parts))
        mail.deliver()
    if len({(w.run.tick, w.run.outcome) for w in world}) != 1:
        raise ContractError(f"the shards ended at ticks {[w.run.tick for w in world]}")
    if pending:
        raise ContractError(f"the run ended before the restarts at ticks {sorted(pending)}")
    return world
