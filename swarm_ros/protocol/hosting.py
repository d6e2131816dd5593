"""Which robot batch hosts which strip of the world, and what each receives: its region's rows, compact.

:mod:`swarm_ros.core.regions` cuts the world into strips of columns, one per batch. After
each tick the world sends each batch, on /swarm/region/<batch>, the rows it needs to
keep its regional :class:`~swarm_ros.core.replica.Replica` equal to the world's state
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


class Hosting:
    """The world's map of strips to batches (batch k: the k-th admitted), and the areas it routes rows to."""

    def __init__(self, radius: int, vision_radius: float) -> None:
        self.radius, self.width, self.halo = radius, 2 * radius + 1, halo(vision_radius)
        self.host = np.full(self.width, -1, dtype=np.int64)  # batch number hosting each column
        self.strips: list[tuple[int, int]] = []  # per batch: (first, last) column it hosts

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
        """Columns of the world that admitted batches host."""
        return int((self.host >= 0).sum())

    def hosts(self, x: np.ndarray) -> np.ndarray:
        """The batch hosting a robot at each x: the one whose strip holds its column."""
        return self.host[columns(x, self.radius)]

    def area(self, k: int) -> tuple[int, int]:
        """The columns batch ``k`` follows: its strip and the halo."""
        return area(self.strips[k], self.halo, self.width)

    def before(self, state, ids: np.ndarray) -> tuple[np.ndarray, ...]:
        """What :meth:`route` needs of robots ``ids`` (the deciders) before the tick: their columns and rows."""
        pose = tuple(getattr(state, name)[ids] for name in _POSE if getattr(state, name) is not None)
        return (columns(state.x[ids], self.radius), *pose)

    def route(
        self, rows: np.ndarray, moved: np.ndarray | None = None, before: tuple | None = None, state=None
    ) -> list[np.ndarray]:
        """A tick's rows (sorted by id) split by batch (:func:`route`). Robots ``moved`` (sorted) were
        :meth:`before` the tick as ``before`` and are as ``state`` now; one whose row did not change is
        sent to no batch (it decided to stand as it was: a walker that lost its claim)."""
        cols = None
        if moved is not None:
            assert before is not None  # given with moved
            cols, *pose = before
            same = np.ones(moved.size, dtype=bool)
            for name, was in zip((n for n in _POSE if getattr(state, n) is not None), pose):
                same &= getattr(state, name)[moved] == was
            if same.any():  # rows and moved are sorted by id, and every moved robot has a row
                keep = np.ones(rows.size, dtype=bool)
                keep[np.searchsorted(rows["id"], moved[same])] = False
                rows = rows.take(np.flatnonzero(keep))
                moved, cols = moved[~same], cols[~same]
            if moved.size != rows.size:  # rows of robots that did not decide too (removed)
                at = np.searchsorted(rows["id"], moved)
                cols, moved_cols = row_columns(rows, self.radius), cols
                cols[at] = moved_cols
        return route(rows, cols, [self.area(k) for k in range(len(self.strips))], self.radius)

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
