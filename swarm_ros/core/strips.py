"""A run cut among K robot batches by strips of columns, for an algorithm whose world holds every robot (a *central
world*, one process or S world shards: :mod:`swarm_ros.core.central_shards`), as every algorithm's graph does.

The algorithm's engine lays a grid of columns over its world (:class:`StripGrid`: columns ``side`` wide from
``x0``), wide enough that a robot decides from the robots within one column either side of its own. The world is
cut into K strips of whole columns (:func:`strips_for`: at ``region_cuts``, or as many robots in each at the start
as whole columns allow); batch k decides for the deciding robots whose column, at the last tick, lies in its strip,
and it needs the robots of its *area*: its strip and one column either side (the halo). The world sends each batch
its area's robots as they stand after a tick, takes every batch's decisions for the next, and settles them as the
in-process engine does. A batch keeps nothing between ticks that the world does not send it again, so a restarted
batch decides as the one it replaces would have, and a batch's work a tick is its area's, never the whole swarm's.

What an engine gives for it (:class:`CentralRun`) is the graph's whole contract with the algorithm's core; the
rows on the wire are the algorithm's protocol part (:mod:`swarm_ros.protocol.central_world`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol

import numpy as np

from .errors import ParameterError
from .grid import CellMap


def parse_cuts(text: str) -> np.ndarray:
    """Cut positions from a list like ``"-20,0,20"`` (x in patches, ascending): empty for none.

    Raises:
        ParameterError: not a list of integers, or not strictly ascending.
    """
    compact = text.replace(" ", "")
    parts = compact.split(",") if compact else []
    if "" in parts:  # '-10,,10' or '10,': a position left out is a typo, not a cut fewer
        raise ParameterError(f"region_cuts must be whole x positions like '-20,0,20', got {text!r} (an empty one)")
    try:
        cuts = np.array([int(p) for p in parts], dtype=np.int64)
    except ValueError:
        raise ParameterError(f"region_cuts must be whole x positions like '-20,0,20', got {text!r}") from None
    if cuts.size > 1 and (np.diff(cuts) <= 0).any():
        raise ParameterError(f"region_cuts must be strictly ascending, got {text!r}")
    return cuts


def shard_batches(shard: int, shards: int, batches: int) -> range:
    """The batches world shard ``shard`` of ``shards`` admits: a run of consecutive strips, as many as can be.

    Raises:
        ParameterError: more shards than batches, or ``shard`` not one of them.
    """
    if not 1 <= shards <= batches:
        raise ParameterError(f"world_shards must be in [1, {batches}] (one batch at least each), got {shards}")
    if not 0 <= shard < shards:
        raise ParameterError(f"shard must be in [0, {shards}), got {shard}")
    return range(shard * batches // shards, (shard + 1) * batches // shards)


class StripGrid(NamedTuple):
    """Columns ``side`` wide from x = ``x0``, ``nx`` of them: a robot's column is where its x falls (clipped);
    ``unit``: the unit of x, as an error names it; ``reach``: the columns either side of its own whose robots a
    robot's decision reads (a batch's halo); ``rivals``: the columns either side whose robots' decisions settling a
    robot's reads (those that can claim what it claims), if more than ``reach`` (world shards send them each other).
    """

    x0: float
    side: float
    nx: int
    unit: str = ""
    reach: int = 1
    rivals: int = 0

    def columns(self, x: np.ndarray) -> np.ndarray:
        """The column of each x."""
        return np.clip(np.floor((x - self.x0) / self.side).astype(np.int64), 0, self.nx - 1)


class CentralRun(Protocol):
    """What an in-process engine gives the central world's graph (beside ``run()``, ``step()`` and the rest every
    engine has): the graph's world holds one, its monitor a copy it loads with what the world reports."""

    params: Any
    tick: int
    outcome: Any
    robots: Any  #: a NamedTuple of arrays indexed by robot id, ``x`` and ``state`` among them
    grid: StripGrid  #: the columns the batches' strips are cut in
    columns: tuple[str, ...]  #: metrics.csv's columns, the first ``tick``: a row of them a tick (``history``)

    @property
    def history(self) -> np.ndarray: ...  # every tick's metrics row (the engine's ``columns``), tick 0 first

    def deciding(self) -> np.ndarray: ...  # the robots that decide the next tick, ascending ids

    def seen_by_all(self, state: np.ndarray) -> np.ndarray:
        """Which robots, by their ``state`` (``robots.state``), every batch sees wherever they stand, beside its
        area's (the study's model's stationary robots, from which its rule finds the frontier anywhere); none for a
        rule that reads only the robots within its reach. With world shards they must be among the rows every shard
        shares."""
        ...

    def progress(self) -> tuple[int, int, dict[str, str]]: ...  # cells done, all of them, words (progress bars)

    def cell_map(self) -> CellMap: ...  # the shape's cells and the ones done now (the graph's maps)

    def settle(self, decided: list[tuple[np.ndarray, Any]]) -> Any: ...  # a tick from each batch's (ids, decisions)

    def load(self, tick: int, robots: Any, history: np.ndarray, outcome: Any = None) -> None: ...

    def saved(self) -> dict[str, np.ndarray]: ...  # all a restarted world needs to go on exactly (a checkpoint)

    def restore(self, tick: int, arrays: dict[str, np.ndarray]) -> None: ...  # from saved(); ContractError if not

    def remove(self, ids: np.ndarray) -> int:
        """Robots ``ids`` leave the world at the end of the tick (a batch lost for good): only an algorithm whose
        robots can be removed (its registry entry's ``no_removal`` empty) has it. How many left."""
        ...


@dataclass(frozen=True)
class Strips:
    """K strips of whole columns: strip k is the columns ``cuts[k]`` to ``cuts[k + 1] - 1``; a batch's area is its
    strip and ``reach`` columns either side (the grid's :attr:`StripGrid.reach`)."""

    cuts: np.ndarray  #: int64, K + 1 ascending column numbers, the first 0 and the last the grid's width
    reach: int = 1

    @staticmethod
    def balanced(start_columns: np.ndarray, columns: int, batches: int, reach: int = 1) -> Strips:
        """``batches`` strips of whole columns holding, at the start, as nearly equal numbers of robots as whole
        columns allow (``start_columns``: each robot's column at tick 0), each at least one column wide.

        Raises:
            ParameterError: more batches than columns.
        """
        if not 1 <= batches <= columns:
            raise ParameterError(f"processes must be between 1 and the {columns} cell columns, got {batches}")
        held = np.cumsum(np.bincount(start_columns, minlength=columns))
        cuts = [0]
        for k in range(1, batches):
            at = int(np.searchsorted(held, k * held[-1] / batches)) + 1  # columns before it hold k/K of them
            cuts.append(min(max(at, cuts[-1] + 1), columns - (batches - k)))
        return Strips(np.array([*cuts, columns], dtype=np.int64), reach)

    @staticmethod
    def cut(at: np.ndarray, grid: StripGrid, batches: int) -> Strips:
        """``batches`` strips cut at ``at`` (K - 1 ascending x positions, ``region_cuts``): strip k starts at the
        column that holds cut k - 1.

        Raises:
            ParameterError: not K - 1 cuts, or cuts that leave a strip without a column.
        """
        if at.size != batches - 1:
            raise ParameterError(f"region_cuts gives {at.size} cuts; {batches} batches need {batches - 1}")
        starts = np.floor((at - grid.x0) / grid.side).astype(np.int64)
        cuts = np.concatenate([[0], starts, [grid.nx]]).astype(np.int64)
        if (np.diff(cuts) < 1).any():
            end, unit = grid.x0 + grid.nx * grid.side, f" {grid.unit}" if grid.unit else ""
            one = unit.removesuffix("es") if grid.side == 1 else unit  # (1 patch wide)
            raise ParameterError(
                f"region_cuts {at.tolist()} leave a strip with no cell column (the grid's {grid.nx} columns, "
                f"{grid.side:g}{one} wide, span x = {grid.x0:g} to {end:g}{unit})"
            )
        return Strips(cuts, grid.reach)

    @staticmethod
    def tiling(strips: list[tuple[int, int]], columns: int, reach: int = 1) -> Strips | None:
        """The strips ``strips`` ((first, last) columns, in any order) make, if they tile the ``columns`` columns
        of the grid with no gap or overlap; None if they do not (yet)."""
        ordered = sorted(strips)
        if not ordered or ordered[0][0] != 0 or ordered[-1][1] != columns - 1:
            return None
        if any(before[1] + 1 != after[0] for before, after in zip(ordered, ordered[1:])):
            return None
        return Strips(np.array([first for first, _ in ordered] + [columns], dtype=np.int64), reach)

    @property
    def batches(self) -> int:
        return self.cuts.size - 1

    def strip(self, k: int) -> tuple[int, int]:
        """The first and last column of strip k."""
        return int(self.cuts[k]), int(self.cuts[k + 1]) - 1

    def area(self, k: int) -> tuple[int, int]:
        """The first and last column of batch k's area: its strip and the halo, ``reach`` columns either side."""
        first, last = self.strip(k)
        return max(first - self.reach, 0), min(last + self.reach, int(self.cuts[-1]) - 1)

    def in_strip(self, columns: np.ndarray, k: int) -> np.ndarray:
        """Which of the robots in ``columns`` lie in strip k."""
        first, last = self.strip(k)
        return (columns >= first) & (columns <= last)

    def in_area(self, columns: np.ndarray, k: int) -> np.ndarray:
        """Which of the robots in ``columns`` lie in batch k's area."""
        first, last = self.area(k)
        return (columns >= first) & (columns <= last)


def strips_for(start: CentralRun, batches: int, region_cuts: str = "") -> Strips:
    """The strips of a run for ``batches`` batches (``start``: the run at tick 0): cut at ``region_cuts`` (x
    positions, :meth:`Strips.cut`), or, with none, :meth:`Strips.balanced` over its robots at tick 0 (every process
    that knows the run's parameters finds the same).

    Raises:
        ParameterError: cuts or a batch count the grid cannot be cut by.
    """
    grid = start.grid
    if region_cuts:
        return Strips.cut(parse_cuts(region_cuts), grid, batches)
    return Strips.balanced(grid.columns(start.robots.x), grid.nx, batches, grid.reach)


def view_of(run: CentralRun, strips: Strips, k: int, robots: Any, columns: np.ndarray | None = None) -> np.ndarray:
    """Which of ``robots`` (arrays of ``run``'s kind, their ``columns`` on its grid if known) batch k sees: those of
    its area, and those every batch sees (:meth:`~CentralRun.seen_by_all`); a mask."""
    if columns is None:
        columns = run.grid.columns(robots.x)
    return strips.in_area(columns, k) | run.seen_by_all(robots.state)


def area_of(run: CentralRun, strips: Strips, k: int) -> np.ndarray:
    """The ids of the robots batch k sees, as they stand at the run's tick (:func:`view_of`)."""
    return np.flatnonzero(view_of(run, strips, k, run.robots))


class AreaFeed:
    """The world's side of what each batch is sent after a tick: the first time, and whenever asked (a batch process
    that came back, a world that went on from its checkpoint), the rows of every robot it sees (its *whole* view);
    after that, of the robots it saw after the last tick or sees now, those whose rows changed in the tick (a robot
    that left its view is among them: it moved). A batch keeps what it was sent (:class:`AreaStore`), so a robot
    that stands still, as most stationary ones do, is sent once."""

    def __init__(self, run: CentralRun, strips: Strips) -> None:
        self.run, self.strips = run, strips
        self.seen: dict[int, np.ndarray] = {}  #: batch -> which robots it saw (a mask), as last sent
        self.last = tuple(a.copy() for a in run.robots)  #: every robot's arrays at tick ``at``
        self.at = -1
        self._changed, self._differs = np.zeros(run.params.robots, dtype=bool), np.zeros(run.params.robots, dtype=bool)

    def send(
        self,
        batches: list[int],
        whole: set[int] | frozenset[int] = frozenset(),
        columns: np.ndarray | None = None,
        among: np.ndarray | None = None,
    ) -> dict[int, tuple]:
        """What to send each of ``batches`` at the run's tick: (ids, whether they are its whole view); the whole view
        to the batches ``whole``, and to every one unless the last call was at the tick before (``columns``: every
        robot's, if known; ``among``: the robots a world shard holds, a mask, None for every one)."""
        run = self.run
        columns = run.grid.columns(run.robots.x) if columns is None else columns
        changed = self._changes() if self.at == run.tick - 1 else None
        out = {}
        for k in batches:
            view = view_of(run, self.strips, k, run.robots, columns)
            if among is not None:
                view &= among
            if changed is None or k in whole or k not in self.seen:
                out[k] = (np.flatnonzero(view), True)
            else:
                out[k] = (np.flatnonzero((self.seen[k] | view) & changed), False)
            self.seen[k] = view
        if self.at != run.tick:
            for before, now in zip(self.last, run.robots):
                np.copyto(before, now)
            self.at = run.tick
        return out

    def _changes(self) -> np.ndarray:
        """Which robots' arrays differ from ``last`` (a field at a time, in place: a few microseconds a field)."""
        changed, differs = self._changed, self._differs
        changed.fill(False)
        for now, before in zip(self.run.robots, self.last):
            np.not_equal(now, before, out=differs)
            np.logical_or(changed, differs, out=changed)
        return changed


class AreaStore:
    """A batch's copy of the robots it sees, kept from tick to tick (what an :class:`AreaFeed` sends): every robot's
    arrays, of which those it was sent hold their rows as last sent; ``seen``, the robots it sees (ascending), those
    of them in its area (``strips``' area k, by the columns of ``start``'s grid) or seen by all."""

    def __init__(self, start: CentralRun, strips: Strips, k: int) -> None:
        self.start, self.strips, self.k = start, strips, k
        self.robots = type(start.robots)(*(np.zeros_like(a) for a in start.robots))
        self.sees = np.zeros(start.params.robots, dtype=bool)
        self.seen = np.empty(0, dtype=np.int64)
        self.tick = -1  #: the tick its rows are of (-1: none yet)

    def take(self, tick: int, ids: np.ndarray, robots: Any, whole: bool) -> np.ndarray | None:
        """The rows (``robots``: arrays, position k robot ``ids[k]``'s, ids ascending) the world sent at ``tick``: its
        whole view, or the changes of the tick after its last (check :meth:`follows` first). Returns the ids that
        changed, or None for a whole view."""
        for mine, theirs in zip(self.robots, robots):
            mine[ids] = theirs
        self.tick = tick
        if whole:
            self.sees[:] = False
            self.sees[ids] = True
        else:
            self.sees[ids] = view_of(self.start, self.strips, self.k, robots)
        self.seen = np.flatnonzero(self.sees)
        return None if whole else ids

    def follows(self, tick: int) -> bool:
        """Whether changes of ``tick`` follow what it holds."""
        return self.tick >= 0 and tick == self.tick + 1


def run_batched(run: CentralRun, hosts: list[Any], max_ticks: int | None = None) -> None:
    """Run ``run`` to its end (or ``max_ticks`` more ticks) with its robots' decisions made by ``hosts`` (one per
    strip, each ``decide(tick, seen, changed, robots)`` -> (ids, decisions) from the robots it sees alone), each
    sent what the graph's world sends (an :class:`AreaFeed`, into an :class:`AreaStore`): the result equals the
    in-process run's."""
    strips = hosts[0].strips
    feed = AreaFeed(run, strips)
    stores = [AreaStore(run, strips, k) for k in range(len(hosts))]
    left = max_ticks
    while run.outcome is None and (left is None or left > 0):
        tick, decided = run.tick, []
        for k, (ids, whole) in feed.send(list(range(len(hosts)))).items():
            changed = stores[k].take(tick, ids, type(run.robots)(*(a[ids] for a in run.robots)), whole)
            decided.append(hosts[k].decide(tick + 1, stores[k].seen, changed, stores[k].robots))
        run.settle(decided)
        left = None if left is None else left - 1


def merged(ascending: np.ndarray, more: np.ndarray) -> np.ndarray:
    """The ids of ``ascending`` (ascending, no repeats) and ``more`` (any order, repeats), ascending, each once:
    ``np.union1d``'s result, but it sorts only ``more`` (a world shard's peer rows,
    :mod:`swarm_ros.core.central_shards`), not both (the robots it holds)."""
    more = np.unique(more)
    if not ascending.size:
        return more
    at = np.searchsorted(ascending, more)
    fresh = (at == ascending.size) | (ascending[np.minimum(at, ascending.size - 1)] != more)
    return np.insert(ascending, at[fresh], more[fresh]) if fresh.any() else ascending


def has_repeats(values: np.ndarray) -> bool:
    """Whether a value occurs twice in ``values`` (a sort: ``np.unique`` costs several times more; none for
    values in increasing order, as the graph's rows come: 0.03 ms instead of 0.45 for 50,000 ids)."""
    if (values[1:] > values[:-1]).all():
        return False
    ordered = np.sort(values)
    return bool((ordered[1:] == ordered[:-1]).any())
