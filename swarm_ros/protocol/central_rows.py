"""A central world's rows (:mod:`swarm_ros.protocol.central_world`): what an algorithm gives for its robots and
decisions (its :class:`Wire`), and the metrics rows every central world sends its monitor, as numpy record types.

They travel as the ``data`` of ``sensor_msgs/PointCloud2`` messages like the study's model's rows
(:mod:`swarm_ros.protocol.rows`): little-endian, a point per row.
"""

from __future__ import annotations

import functools
from typing import Any, Protocol

import numpy as np

from swarm_ros.core.errors import Rejected
from swarm_ros.core.strips import Strips

from .cdr import register_row_types


class Wire(Protocol):
    """An algorithm's rows in the central world's graph: numpy record types (``x``, ``y``, ``z`` first, so a
    PointCloud2 viewer draws them; an ``id`` field, ascending), their conversions and checks, and its batch."""

    row: np.dtype  #: a robot's row: world -> batch (its area), world -> monitor (every robot, each record)
    decision_row: np.dtype  #: a decision's row: batch -> world

    def rows(self, ids: np.ndarray, robots: Any) -> np.ndarray: ...  # robots ``ids``' rows (every robot's arrays)

    def decision_rows(self, ids: np.ndarray, decided: Any) -> np.ndarray: ...  # decisions' rows (k: ids[k]'s)

    def robots_of(self, rows: np.ndarray) -> tuple[np.ndarray, Any]: ...  # (ids, arrays) of checked rows

    def decisions_of(self, rows: np.ndarray) -> tuple[np.ndarray, Any]: ...  # (ids, decisions) of checked rows

    def check_rows(self, run: Any, rows: np.ndarray, tick: int) -> None:
        """Whether ``rows``, of robots (``row``) or their decisions (``decision_row``: a world shard's peer's, checked
        where the robots they are of may not be known), can be of ``run`` at ``tick``: their own bounds.

        Raises:
            Rejected: by kind.
        """
        ...

    def check_decisions(self, run: Any, rows: np.ndarray, tick: int, own: np.ndarray) -> tuple[np.ndarray, Any]:
        """(ids, decisions) of rows for ``tick`` that must be exactly the robots ``own``, within the rule's bounds.

        Raises:
            Rejected: by kind.
        """
        ...

    def batch(self, run: Any, strips: Strips, k: int) -> Any: ...  # ``decide(tick, ids, robots)`` for strip k


@functools.cache
def metrics_row(columns: tuple[str, ...]) -> np.dtype:
    """World -> monitor: the metrics rows of an engine whose metrics.csv has ``columns`` (float64, exact)."""
    row = np.dtype([(name, "<f8") for name in columns])
    register_row_types(row)  # decoded at the speed of the other rows
    return row


def metrics_rows(history: np.ndarray, columns: tuple[str, ...]) -> np.ndarray:
    """Metrics rows (:func:`metrics_row`) of history rows (``columns``)."""
    rows = np.empty(history.shape[0], dtype=metrics_row(columns))
    for c, name in enumerate(columns):
        rows[name] = history[:, c]
    return rows


def check_metrics_rows(rows: np.ndarray, held: np.ndarray, columns: tuple[str, ...]) -> np.ndarray:
    """The history rows of metrics rows, one a tick in order, counts within bounds, that follow ``held`` (the
    history rows taken so far, tick 0 first): rows of ticks already held (a restarted world sends again the ticks
    since its last record) must equal those and are left out.

    Raises:
        Rejected: ticks out of order, or leaving a gap after the held ones, a count that is negative or not finite,
            or a row of a tick already held that differs from it.
    """
    history = np.column_stack([rows[name] for name in columns]) if rows.size else np.empty((0, len(columns)))
    if not np.isfinite(history).all() or np.any(history < 0):
        raise Rejected("bad number", "a metric that is negative or not a finite number")
    if not rows.size:
        return history
    first, after = int(history[0, 0]), held.shape[0] - 1
    if history[0, 0] != first or first > after + 1 or not np.array_equal(history[:, 0], first + np.arange(rows.size)):
        raise Rejected("stale tick", f"metrics of ticks other than consecutive ones from at most tick {after + 1}")
    again = min(after + 1 - first, rows.size)  # rows of ticks already held
    if not np.array_equal(history[:again], held[first : first + again]):
        raise Rejected("conflict", "metrics rows that differ from those already taken for their ticks")
    return history[again:]
