"""Which robot batch hosts which strip of the world, and what each receives: its region's rows, compact.

:mod:`swarm_ros.core.regions` cuts the world into strips of columns, one per batch. After
each tick the world sends each batch, on /swarm/region/<batch>, the rows it needs to
keep its regional :class:`~swarm_ros.core.swarm_view.SwarmView` equal to the world's state
where it decides:

* the row of every moving robot whose column before or after the tick lies in the
  batch's area (its strip and :func:`~swarm_ros.core.regions.halo` columns each side):
  one that entered, one that moved within, and one that left (so the batch forgets it);
* the row of every robot that became stationary (localized, separated, removed), for
  every batch: the frontier, which the ``walk`` rule searches anywhere, follows from them.

A snapshot for a batch (at tick 0, or for a restarted process) holds its area's moving
robots and every stationary robot. Rows travel in the compact layout
(:data:`~swarm_ros.protocol.rows.REGION_ROW`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from swarm_ros.core.errors import Rejected
from swarm_ros.core.regions import area, columns, format_strip, halo
from swarm_ros.core.state import IS_MOVING
from swarm_ros.protocol.rows import PATCH_METRES, compact


def row_columns(rows: np.ndarray, radius: int) -> np.ndarray:
    """The column of each robot row's pose."""
    return columns(rows["x"] / PATCH_METRES, radius)


def route(rows: np.ndarray, before: np.ndarray | None, areas: list[tuple[int, int]], radius: int) -> list[np.ndarray]:
    """A tick's robot rows split into what each area's batch receives, compact.

    ``before`` holds each row's robot's column before the tick (None: the rows' own
    columns, for rows of robots that did not move).
    """
    after = row_columns(rows, radius)
    low, high = (after, after) if before is None else (np.minimum(before, after), np.maximum(before, after))
    everyone = ~IS_MOVING[rows["state"]]
    rows = compact(rows)
    width = 2 * radius + 1
    # take() of the kept rows' indices: a boolean mask over records copies them several times slower
    return [
        rows
        if first == 0 and last == width - 1
        else rows.take(np.flatnonzero(everyone | ((high >= first) & (low <= last))))
        for first, last in areas
    ]


def snapshot(rows: np.ndarray, where: tuple[int, int], radius: int) -> np.ndarray:
    """Of every robot's rows (a tick's whole state), those a batch following ``where`` keeps, compact."""
    cols = row_columns(rows, radius)
    keep = ~IS_MOVING[rows["state"]] | ((cols >= where[0]) & (cols <= where[1]))
    return compact(rows[keep])


_POSE = ("state", "x", "y", "heading", "z", "pitch")  #: what a robot row carries (z, pitch: 3D only)


def poses(state, ids: np.ndarray) -> tuple[np.ndarray, ...]:
    """Robots ``ids`` (ascending) and their rows' fields in ``state`` now (state, x, y, heading; z, pitch in 3D):
    what :func:`stood` compares with after the tick."""
    return (ids, *(getattr(state, name)[ids] for name in _POSE if getattr(state, name) is not None))


def stood(before: tuple[np.ndarray, ...], state, ids: np.ndarray) -> np.ndarray:
    """Which of robots ``ids`` are among ``before``'s (:func:`poses`) with the same row in ``state`` now: deciders
    that stood as they were (a walker that lost its claim), whose row no batch needs again."""
    was_ids, *was = before
    if not was_ids.size or not ids.size:
        return np.zeros(ids.size, dtype=bool)
    at: np.ndarray | slice = slice(None)  # the deciders alone (the world's usual tick): each at its own place
    same = np.ones(ids.size, dtype=bool)
    if was_ids.size != ids.size or not np.array_equal(was_ids, ids):
        at = np.minimum(np.searchsorted(was_ids, ids), was_ids.size - 1)
        same = was_ids[at] == ids
    for name, value in zip((n for n in _POSE if getattr(state, n) is not None), was):
        same &= getattr(state, name)[ids] == value[at]
    return same


class Hosting:
    """A world process's map of its strips to batches (batch k: the k-th admitted), and the areas it routes rows
    to; ``own``: its strips (the world's: every column; a world shard's: those of its batches)."""

    def __init__(self, radius: int, vision_radius: float, own: tuple[int, int] | None = None) -> None:
        self.radius, self.width, self.halo = radius, 2 * radius + 1, halo(vision_radius)
        self.own = own if own is not None else (0, self.width - 1)
        self.host = np.full(self.width, -1, dtype=np.int64)  # batch number hosting each column
        self.strips: list[tuple[int, int]] = []  # per batch: (first, last) column it hosts

    def holds(self, strip: tuple[int, int]) -> bool:
        """Whether a batch hosting ``strip`` is this process's (False: another shard's).

        Raises:
            Rejected: a strip across the border of its strips: no shard can admit it.
        """
        first, last = self.own
        if strip[0] >= first and strip[1] <= last:
            return True
        if strip[1] < first or strip[0] > last:
            return False
        raise Rejected("columns of another shard", f"{self.text(strip)} crosses the border of {self.text(self.own)}")

    def admit(self, name: str, strip: tuple[int, int], names: list[str]) -> int:
        """Take ``strip`` as the next batch's (``name``; ``names``: the batches so far); returns its number.

        Raises:
            Rejected: a column another batch hosts.
        """
        cols = np.arange(strip[0], strip[1] + 1)
        taken = cols[self.host[cols] >= 0]
        if taken.size:
            raise Rejected(
                "columns of another batch",
                f"'{name}' names {self.text(strip)}, which overlaps {names[self.host[taken[0]]]}'s",
            )
        self.host[cols] = len(self.strips)
        self.strips.append((int(strip[0]), int(strip[1])))
        return len(self.strips) - 1

    def restore(self, strips: list) -> None:
        """The strips a world before this one admitted, in order."""
        self.strips = [(int(first), int(last)) for first, last in strips]
        for k, (first, last) in enumerate(self.strips):
            self.host[first : last + 1] = k

    def covered(self) -> int:
        """Columns hosted: of its strips, by its admitted batches; another shard's columns count as covered (that
        shard admits their batches)."""
        return int((self.host >= 0).sum()) + self.width - (self.own[1] - self.own[0] + 1)

    def hosts(self, x: np.ndarray) -> np.ndarray:
        """The batch hosting a robot at each x: the one whose strip holds its column."""
        return self.host[columns(x, self.radius)]

    def area(self, k: int) -> tuple[int, int]:
        """The columns batch ``k`` follows: its strip and the halo."""
        return area(self.strips[k], self.halo, self.width)

    def orphans(
        self, x: np.ndarray, moving_ids: Callable[[], np.ndarray], removed: set[int], pending: np.ndarray
    ) -> np.ndarray:
        """Of the moving robots (``moving_ids()``, at ``x``), those not ``pending`` removal in the strips of
        ``removed`` batches: the world decides for them itself."""
        if not removed:
            return np.empty(0, dtype=np.int64)
        moving = moving_ids()
        return moving[np.isin(self.hosts(x[moving]), sorted(removed)) & ~np.isin(moving, pending)]

    def text(self, strip: tuple[int, int]) -> str:
        return format_strip(strip[0], strip[1], self.radius)
