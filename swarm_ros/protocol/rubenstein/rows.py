"""The rubenstein algorithm's rows between the world and its robot batches, as numpy record types, and their checks.

A robot's row is everything it broadcasts and keeps (:class:`~swarm_ros.core.rubenstein.rule.Robots`): its
pose, state, gradient ``g``, position estimate (``ex``, ``ey``), whether it has an estimate and is localized,
and its counters. The world sends batch k its area's rows after each tick (:mod:`swarm_ros.core.rubenstein.strips`),
and batch k answers with a decision row per robot of its strip not joined: the same fields as they will be
after the tick, with ``x``, ``y`` the point the robot moves to if the world grants it, and ``moves``.

They travel as the ``data`` of ``sensor_msgs/PointCloud2`` messages like the study's model's rows
(:mod:`swarm_ros.protocol.rows`): little-endian, a point per robot, ``x``, ``y``, ``z`` first so viewers
draw them, and ``g``, ``ex``, ``ey`` named so a reader of the cloud finds a robot's gradient and estimate.
A PointField has no 64-bit integer, so the counters and ticks travel as int32 (a tick is at most 10^9), a
gradient unknown and a tick never reached as -1; the floats are float64, so the rows carry the exact state
and a batch decides exactly as the world would.
"""

from __future__ import annotations

import numpy as np

from swarm_ros.core.errors import Rejected
from swarm_ros.core.rubenstein.rule import Decided, Robots, decided_for
from swarm_ros.core.rubenstein.run import COLUMNS

from ..cdr import register_row_types
from .checks import ROW_FAULTS, first_fault, pack_rows, row_faults, unpack_rows

_NAMES = ["x", "y", "z", "heading", "ex", "ey", "near"]
_NAMES += ["g", "still", "began", "joined", "waited", "blind", "id", "state"]
_FORMATS = ["<f8"] * 7 + ["<i4"] * 6 + ["<u4", "<u1"]
_OFFSETS = [0, 8, 16, 24, 32, 40, 48, 56, 60, 64, 68, 72, 76, 80, 84]

#: World -> robot batch k, after each tick: the rows of its area's robots.
RUBENSTEIN_ROW = np.dtype(
    {
        "names": [*_NAMES, "est", "loc"],
        "formats": [*_FORMATS, "<u1", "<u1"],
        "offsets": [*_OFFSETS, 85, 86],
        "itemsize": 88,
    }
)
#: Robot batch k -> world, each tick: each of its robots' decision.
RUBENSTEIN_DECISION_ROW = np.dtype(
    {
        "names": [*_NAMES, "est", "loc", "moves"],
        "formats": [*_FORMATS, "<u1", "<u1", "<u1"],
        "offsets": [*_OFFSETS, 85, 86, 87],
        "itemsize": 88,
    }
)
#: World -> monitor: metrics rows, the columns of swarm_ros.core.rubenstein.run.COLUMNS (float64, exact).
RUBENSTEIN_METRICS_ROW = np.dtype([(name, "<f8") for name in COLUMNS])
RUBENSTEIN_ROW_TYPES = (
    RUBENSTEIN_ROW,
    RUBENSTEIN_DECISION_ROW,
    RUBENSTEIN_METRICS_ROW,
)  #: the rubenstein graph's row layouts
register_row_types(*RUBENSTEIN_ROW_TYPES)  # decoded at the speed of the study's model's rows


def rubenstein_rows(ids: np.ndarray, robots: Robots | Decided) -> np.ndarray:
    """The rows of robots ``ids`` (:class:`Robots`: every robot's arrays, indexed by ``ids``) or of decisions
    (:class:`Decided`: position k robot ``ids[k]``'s)."""
    decided = isinstance(robots, Decided)
    rows = np.zeros(ids.size, dtype=RUBENSTEIN_DECISION_ROW if decided else RUBENSTEIN_ROW)
    pack_rows(ids.astype(np.int64, copy=False), robots, not decided, rows)
    if isinstance(robots, Decided):
        rows["moves"] = robots.moves
    return rows


def robots_of_rows(rows: np.ndarray) -> tuple[np.ndarray, Robots]:
    """(ids, the robots' arrays, position k robot ``ids[k]``'s) of checked rows."""
    out = Robots(*decided_for(rows.size)[:-1])
    return unpack_rows(rows, out), out


def decided_of_rows(rows: np.ndarray) -> tuple[np.ndarray, Decided]:
    """(ids, decisions) of checked decision rows."""
    out = decided_for(rows.size)
    ids = unpack_rows(rows, out)
    out.moves[:] = rows["moves"]
    return ids, out


def check_rubenstein_rows(rows: np.ndarray, robots: int, tick: int) -> None:
    """Whether rows of tick ``tick`` (the state after it; decisions: the state they make at it) can be a
    swarm's of ``robots`` robots: ids ascending and in range, states and flags in their sets (and ``moves``
    0 or 1), the floats finite (``near`` may be +inf: no stationary neighbour yet), gradient and counters
    -1 or more, no tick after ``tick``, and a joined robot's joining tick set. Compiled
    (:mod:`swarm_ros.protocol.rubenstein.checks`).

    Raises:
        Rejected: the first fault found, by kind.
    """
    if "moves" in (rows.dtype.names or ()) and np.any(rows["moves"] > 1):
        raise Rejected("bad state", "moves must be 0 or 1")
    fault = first_fault(row_faults(rows, robots, tick), ROW_FAULTS)
    if fault is not None:
        kind, message = fault
        raise Rejected(kind, message.format(last=robots - 1, tick=tick))


def metrics_rows(history: np.ndarray) -> np.ndarray:
    """Metrics rows (:data:`RUBENSTEIN_METRICS_ROW`) of history rows (``COLUMNS``)."""
    rows = np.empty(history.shape[0], dtype=RUBENSTEIN_METRICS_ROW)
    for c, name in enumerate(COLUMNS):
        rows[name] = history[:, c]
    return rows


def check_metrics_rows(rows: np.ndarray, held: np.ndarray) -> np.ndarray:
    """The history rows of metrics rows, one a tick in order, counts within bounds, that follow ``held`` (the
    history rows taken so far, tick 0 first): rows of ticks already held (a restarted world sends again the ticks
    since its last record) must equal those and are left out.

    Raises:
        Rejected: ticks out of order, or leaving a gap after the held ones, a count that is negative or not finite,
            or a row of a tick already held that differs from it.
    """
    history = np.column_stack([rows[name] for name in COLUMNS]) if rows.size else np.empty((0, len(COLUMNS)))
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
